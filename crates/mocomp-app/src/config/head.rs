//! `[head]`: the patient's head (a scan or an ellipsoid), its landmarks and registration, and
//! what is loaded from them.

use super::*;

/// What [`Config::load_head`] read from the files `[head]` names: not part of the file, so the
/// file's schema holds keys only.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LoadedHead {
    /// The registration as read, and the file's absolute path.
    pub registered: Option<(PathBuf, registration_file::Record)>,
    /// The mesh as read, mended and built.
    pub model: Option<HeadModel>,
    /// Where the loaded mesh's scalp came from (a T1's segmented now or kept from before).
    pub scalp_from: Option<crate::files::head::ScalpFrom>,
}

/// `[head]`: the patient's scalp from a scan (`mesh`), or else an ellipsoid, in the head
/// marker's frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeadSection {
    /// Where the ellipsoid lies in the image's frame (without a mesh; the image's frame is the
    /// head marker's until `head_from_image` says otherwise).
    pub head_from_ellipsoid: Pose,
    /// Semi-axes, m (without a mesh).
    pub radii_m: [f64; 3],
    /// The scalp's surface file (STL, OBJ, PLY, GIfTI, FreeSurfer), or a T1 MRI in NIfTI
    /// (`.nii`, `.nii.gz`) whose scalp is segmented (relative to the configuration's
    /// directory): the head model instead of the ellipsoid.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<PathBuf>,
    /// The unit of a mesh format that carries none (STL, OBJ, PLY), or of a NIfTI whose header
    /// states none: "mm" or "m".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub units: Option<String>,
    /// A NIfTI's intensity at and above which a voxel is head (without it: Otsu's threshold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// The most triangles a scalp segmented from a NIfTI may have.
    pub max_triangles: usize,
    /// head_from_image: the image's frame (a mesh file's, an MRI's RAS; the ellipsoid's and the
    /// landmarks') in the head marker's frame, until registration measures it.
    pub head_from_image: Pose,
    /// Landmarks in the image (RAS, **millimetres**), by name: `nasion`, `inion`, `lpa`, `rpa`
    /// (the 10-20 system is measured from these four; registration pairs any it shares with
    /// the touched ones), e.g. `nasion = [1.5, 85.1, -34.8]`.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub landmarks: std::collections::BTreeMap<String, [f64; 3]>,
    /// Landmarks from a file (relative to the configuration's directory): 3D Slicer markups
    /// (`.mrk.json`, LPS or RAS) or a SimNIBS positions CSV (its `Fiducial` rows); a landmark
    /// also in `[head.landmarks]` is taken from there.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmarks_file: Option<PathBuf>,
    /// The registration `mocomp register` wrote (relative to the configuration's directory):
    /// its head_from_image replaces the one above.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registration: Option<PathBuf>,
    /// The largest estimated target registration error at the goal compensation starts with,
    /// mm; above it `mocomp run` refuses unless the operator overrides it (logged in the
    /// registration file).
    pub max_tre_mm: f64,
}

impl Default for HeadSection {
    fn default() -> Self {
        Self {
            head_from_ellipsoid: pose_const([0.0; 6]),
            radii_m: [0.075, 0.095, 0.11],
            mesh: None,
            units: None,
            threshold: None,
            max_triangles: mocomp_mri::DEFAULT_MAX_TRIANGLES,
            head_from_image: pose_const([0.0; 6]),
            landmarks: std::collections::BTreeMap::new(),
            landmarks_file: None,
            registration: None,
            max_tre_mm: 3.0,
        }
    }
}

impl Config {
    /// A warning when the scalp of `[head] mesh` was segmented from a scan that ends inside
    /// the head anywhere but at the neck: the model is flat there while the real head (an ear,
    /// the brow) goes on, and goals near those faces are refused. In full when the scan was
    /// segmented now; a line when its scalp was kept from before (the user has read it, and a
    /// goal refused there says why itself).
    pub fn head_note(&self) -> Option<String> {
        let head = self.loaded.model.as_ref()?;
        let sides: Vec<&str> = head
            .scan_cuts()
            .iter()
            .map(|c| c.side)
            .filter(|s| *s != "inferior")
            .collect();
        let kept = self.loaded.scalp_from == Some(crate::files::head::ScalpFrom::Kept);
        (!sides.is_empty()).then(|| {
            if kept {
                return format!(
                    "the scan of [head] mesh ends inside the head at its {} face{} (segmented \
                     before; goals near them are refused)",
                    sides.join(", "),
                    if sides.len() == 1 { "" } else { "s" },
                );
            }
            format!(
                "the scan of [head] mesh ends inside the head at its {} face{}: the model is the \
                 scan's flat face there, not the patient, and a goal whose coil comes within {:.0} \
                 mm of it is refused (a scan that holds the whole head avoids this)",
                sides.join(", "),
                if sides.len() == 1 { "" } else { "s" },
                mocomp_control::goal::SCAN_CUT_KEEP_M * 1e3
            )
        })
    }

    /// `[head]` as the loop's model: the scalp [`Self::load_head`] built, or the ellipsoid.
    pub fn head_model(&self) -> Result<HeadModel, AppError> {
        if let Some(head) = &self.loaded.model {
            return Ok(head.clone());
        }
        if let Some(mesh) = &self.head.mesh {
            return Err(AppError::Config(format!(
                "head.mesh = {}: not loaded (the configuration was not read through a setup)",
                mesh.display()
            )));
        }
        // The ellipsoid is given in the image's frame too, so that a registration moves it.
        HeadModel::ellipsoid(
            self.head.head_from_image.iso() * self.head.head_from_ellipsoid.iso(),
            Vector3::from(self.head.radii_m),
        )
        .map_err(|e| AppError::Config(format!("head.radii_m: {e}")))
    }

    /// Reads `[head] landmarks_file` (relative to `dir`) into `[head.landmarks]`, which keeps
    /// its own where both name a landmark; the path becomes the one read (reading it again adds
    /// nothing).
    pub fn load_landmarks(&mut self, dir: &Path) -> Result<(), AppError> {
        let Some(file) = self.head.landmarks_file.take() else {
            return Ok(());
        };
        let path = dir.join(&file);
        let name = path.display().to_string();
        let text = std::fs::read_to_string(&path)
            .map_err(|e| AppError::Config(format!("head.landmarks_file = {name}: {e}")))?;
        let read = if name.ends_with(".json") {
            mocomp_navfiles::read::slicer_points(&name, &text)
        } else {
            mocomp_navfiles::read::simnibs_fiducials(&name, &text)
        }
        .map_err(|e| AppError::Config(format!("head.landmarks_file: {e}")))?;
        for l in read {
            let mm: [f64; 3] = (l.point.coords * 1000.0).into();
            self.head.landmarks.entry(l.name).or_insert(mm);
        }
        self.head.landmarks_file = Some(std::fs::canonicalize(&path).unwrap_or(path));
        Ok(())
    }

    /// Reads `[head] registration` (relative to `dir`) once: its head_from_image becomes
    /// `[head]`'s, before the mesh is carried into the marker's frame by it.
    pub fn load_registration(&mut self, dir: &Path) -> Result<(), AppError> {
        let Some(file) = &self.head.registration else {
            return Ok(());
        };
        if self.loaded.registered.is_some() {
            return Ok(());
        }
        let path = dir.join(file);
        let read = registration_file::load(&path)
            .map_err(|e| AppError::Config(format!("head.registration: {e}")))?;
        let record = read.registration;
        self.head.head_from_image = Pose::try_from(record.head_from_image)
            .map_err(|e| AppError::Config(format!("head.registration: head_from_image: {e}")))?;
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.head.registration = Some(path.clone());
        self.loaded.registered = Some((path, record));
        Ok(())
    }

    /// Reads, mends and builds `[head] mesh` (relative to `dir`) once, in the head marker's
    /// frame (through `[head] registration`'s head_from_image when there is one, read first);
    /// the path becomes the one read. Nothing to do without a mesh or once loaded. `[coil]
    /// model`'s path is made absolute here too (the files a configuration names are found
    /// where it is).
    pub fn load_head(&mut self, dir: &Path) -> Result<(), AppError> {
        self.load_registration(dir)?;
        coil::resolve(&mut self.coil, dir)?;
        self.load_landmarks(dir)?;
        let Some(mesh) = &self.head.mesh else {
            return Ok(());
        };
        if self.loaded.model.is_some() {
            return Ok(());
        }
        let path = dir.join(mesh);
        let units = match self.head.units.as_deref() {
            None => None,
            Some(u) => Some(
                mocomp_head::formats::parse_unit(u)
                    .map_err(|e| AppError::Config(format!("head.units = {u:?}: {e}")))?,
            ),
        };
        let segment = self.segment_options()?;
        let (head, from) = crate::files::head::load_head(
            &path,
            units,
            &segment,
            &self.head.head_from_image.iso(),
        )?;
        self.loaded.scalp_from = Some(from);
        // Absolute from now on, so a printed configuration reads the same file wherever it is.
        self.head.mesh = Some(std::fs::canonicalize(&path).unwrap_or(path));
        self.loaded.model = Some(head);
        Ok(())
    }

    /// How `[head]` segments a NIfTI's scalp.
    pub fn segment_options(&self) -> Result<mocomp_mri::SegmentOptions, AppError> {
        mocomp_mri::SegmentOptions::new(self.head.threshold, self.head.max_triangles)
            .map_err(|e| AppError::Config(format!("head.{} = {}: {}", e.option, e.value, e.why)))
    }
}
