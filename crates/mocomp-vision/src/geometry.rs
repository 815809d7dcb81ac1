//! Marker geometries: the fiducial positions in the marker frame, read from our TOML, from Atracsys
//! `.ini` geometry files and from NDI `.rom` files, and checked for distinct distances and symmetry.

use crate::error::VisionError;
use mocomp_geom::nalgebra::{Point3, Vector3};
use mocomp_geom::units::mm_to_m;
use serde::Deserialize;

/// A rigid marker: fiducial positions in its own frame (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerGeometry {
    /// A name for messages.
    pub name: String,
    /// Fiducial positions, metres.
    pub points: Vec<Point3<f64>>,
}

/// What [`MarkerGeometry::analyze`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct GeometryReport {
    /// Smallest inter-fiducial distance, metres.
    pub min_distance_m: f64,
    /// Smallest gap between two different inter-fiducial distances, metres (how distinct the
    /// distances are; identification needs it well above the matching tolerance).
    pub min_distance_gap_m: f64,
    /// Distance-preserving relabellings other than the identity (within the tolerance): when
    /// non-zero, the marker is symmetric and its pose can flip.
    pub symmetries: usize,
    /// Human-readable warnings.
    pub warnings: Vec<String>,
}

fn geometry_error(location: Option<String>, message: impl Into<String>) -> VisionError {
    VisionError::Geometry {
        location,
        message: message.into(),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryToml {
    name: Option<String>,
    points_mm: Vec<[f64; 3]>,
}

impl MarkerGeometry {
    /// A geometry from points in metres; needs 3 or more finite, non-collinear, distinct points.
    pub fn new(name: &str, points: Vec<Point3<f64>>) -> Result<Self, VisionError> {
        if points.len() < 3 {
            return Err(geometry_error(
                None,
                format!("{} fiducial(s): a marker needs at least 3", points.len()),
            ));
        }
        for (i, p) in points.iter().enumerate() {
            if !p.coords.iter().all(|v| v.is_finite()) {
                return Err(geometry_error(
                    None,
                    format!("fiducial {} is not finite", i + 1),
                ));
            }
        }
        for i in 0..points.len() {
            for j in i + 1..points.len() {
                if (points[i] - points[j]).norm() < 1e-4 {
                    return Err(geometry_error(
                        None,
                        format!("fiducials {} and {} coincide", i + 1, j + 1),
                    ));
                }
            }
        }
        // Non-collinear: some point off the line through the first two.
        let d = (points[1] - points[0]).normalize();
        let spread = points
            .iter()
            .map(|p| {
                let v = p - points[0];
                (v - d * v.dot(&d)).norm()
            })
            .fold(0.0, f64::max);
        if spread < 1e-3 {
            return Err(geometry_error(
                None,
                "all fiducials lie on one line: the pose is not determined",
            ));
        }
        Ok(Self {
            name: name.to_string(),
            points,
        })
    }

    /// Our TOML: `name = "head"` (optional) and `points_mm = [[x, y, z], ...]` (millimetres).
    pub fn from_toml_str(text: &str, file: &str) -> Result<Self, VisionError> {
        let g: GeometryToml = toml::from_str(text).map_err(|e| {
            geometry_error(
                Some(file.to_string()),
                e.to_string().trim_end().replace('\n', " "),
            )
        })?;
        let points = g
            .points_mm
            .iter()
            .map(|p| Point3::new(mm_to_m(p[0]), mm_to_m(p[1]), mm_to_m(p[2])))
            .collect();
        Self::new(g.name.as_deref().unwrap_or(file), points).map_err(|e| with_location(e, file))
    }

    /// An Atracsys geometry `.ini`: `[geometry]` with `count` (and `id`), then `[fiducial0]` …
    /// `[fiducial<count−1>]` with `x`, `y`, `z` in mm. `;` and `#` start comments; other keys are
    /// ignored, as Atracsys does.
    pub fn from_atracsys_ini(text: &str, file: &str) -> Result<Self, VisionError> {
        let mut section = String::new();
        let mut count: Option<(usize, usize)> = None; // (count, line)
        let mut id: Option<String> = None;
        let mut fids: Vec<(usize, [Option<f64>; 3], usize)> = Vec::new(); // (index, xyz, line)
        for (n, raw) in text.lines().enumerate() {
            let line = n + 1;
            let l = raw.split([';', '#']).next().unwrap_or("").trim();
            if l.is_empty() {
                continue;
            }
            let loc = || Some(format!("{file}, line {line}"));
            if let Some(name) = l.strip_prefix('[') {
                let name = name
                    .strip_suffix(']')
                    .ok_or_else(|| {
                        geometry_error(loc(), format!("unterminated section header {l:?}"))
                    })?
                    .trim()
                    .to_ascii_lowercase();
                if let Some(k) = name.strip_prefix("fiducial") {
                    let idx: usize = k.parse().map_err(|_| {
                        geometry_error(loc(), format!("section [{name}]: expected fiducial<N>"))
                    })?;
                    if fids.iter().any(|f| f.0 == idx) {
                        return Err(geometry_error(
                            loc(),
                            format!("section [{name}] appears twice"),
                        ));
                    }
                    fids.push((idx, [None; 3], line));
                }
                section = name;
                continue;
            }
            let (key, value) = l.split_once('=').ok_or_else(|| {
                geometry_error(loc(), format!("expected key = value, found {l:?}"))
            })?;
            let key = key.trim().to_ascii_lowercase();
            let value = value.trim();
            if section == "geometry" {
                match key.as_str() {
                    "count" => {
                        let c: usize = value.parse().map_err(|_| {
                            geometry_error(loc(), format!("count: {value:?} is not a whole number"))
                        })?;
                        count = Some((c, line));
                    }
                    "id" => id = Some(value.to_string()),
                    _ => {}
                }
            } else if section.starts_with("fiducial") {
                let axis = match key.as_str() {
                    "x" => 0,
                    "y" => 1,
                    "z" => 2,
                    _ => continue,
                };
                let v: f64 = value
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or_else(|| {
                        geometry_error(
                            loc(),
                            format!("[{section}] {key}: {value:?} is not a number"),
                        )
                    })?;
                if let Some(f) = fids.last_mut() {
                    f.1[axis] = Some(v);
                }
            }
        }
        let (count, count_line) =
            count.ok_or_else(|| geometry_error(Some(file.to_string()), "no [geometry] count"))?;
        let mut points = Vec::with_capacity(count);
        for i in 0..count {
            let (_, xyz, line) = fids.iter().find(|f| f.0 == i).ok_or_else(|| {
                geometry_error(
                    Some(format!("{file}, line {count_line}")),
                    format!("count = {count} but there is no [fiducial{i}] section"),
                )
            })?;
            let mut p = [0.0; 3];
            for (a, v) in xyz.iter().enumerate() {
                p[a] = v.ok_or_else(|| {
                    geometry_error(
                        Some(format!("{file}, line {line}")),
                        format!("[fiducial{i}] has no {}", ["x", "y", "z"][a]),
                    )
                })?;
            }
            points.push(Point3::new(mm_to_m(p[0]), mm_to_m(p[1]), mm_to_m(p[2])));
        }
        if let Some(extra) = fids.iter().find(|f| f.0 >= count) {
            return Err(geometry_error(
                Some(format!("{file}, line {}", extra.2)),
                format!("[fiducial{}] is beyond count = {count}", extra.0),
            ));
        }
        let name = id
            .map(|i| format!("atracsys geometry {i}"))
            .unwrap_or_else(|| file.to_string());
        Self::new(&name, points).map_err(|e| with_location(e, file))
    }

    /// An NDI `.rom` tool definition (binary, 752 bytes, little-endian): "NDI" magic, a 16-bit
    /// checksum of bytes 6.. at offset 4, the marker count at 28 and the marker positions as f32
    /// triples (mm) from offset 72. Errors name the byte offset.
    pub fn from_ndi_rom(bytes: &[u8], file: &str) -> Result<Self, VisionError> {
        const SIZE: usize = 752;
        let at = |off: usize| Some(format!("{file}, byte {off}"));
        if bytes.len() < SIZE {
            return Err(geometry_error(
                at(bytes.len()),
                format!("{} bytes: an NDI .rom has {SIZE}", bytes.len()),
            ));
        }
        if &bytes[0..3] != b"NDI" {
            return Err(geometry_error(
                at(0),
                "no \"NDI\" magic: not an NDI .rom file",
            ));
        }
        let stored = u16::from_le_bytes([bytes[4], bytes[5]]);
        let computed = bytes[6..SIZE]
            .iter()
            .fold(0u16, |s, b| s.wrapping_add(u16::from(*b)));
        if stored != computed {
            return Err(geometry_error(
                at(4),
                format!(
                    "checksum {stored:#06x} stored, {computed:#06x} computed: the file is damaged"
                ),
            ));
        }
        let count = usize::from(bytes[28]);
        if !(3..=20).contains(&count) {
            return Err(geometry_error(
                at(28),
                format!("marker count {count} (expected 3..20)"),
            ));
        }
        let mut points = Vec::with_capacity(count);
        for i in 0..count {
            let off = 72 + 12 * i;
            let f = |k: usize| {
                let b = off + 4 * k;
                f32::from_le_bytes([bytes[b], bytes[b + 1], bytes[b + 2], bytes[b + 3]])
            };
            let (x, y, z) = (f(0), f(1), f(2));
            if !(x.is_finite() && y.is_finite() && z.is_finite()) {
                return Err(geometry_error(
                    at(off),
                    format!("marker {} is not finite", i + 1),
                ));
            }
            points.push(Point3::new(
                mm_to_m(f64::from(x)),
                mm_to_m(f64::from(y)),
                mm_to_m(f64::from(z)),
            ));
        }
        Self::new(file, points).map_err(|e| with_location(e, file))
    }

    /// Reads a geometry file by its extension (`.toml`, `.ini`, `.rom`) from its bytes.
    pub fn from_file_bytes(bytes: &[u8], file: &str) -> Result<Self, VisionError> {
        let lower = file.to_ascii_lowercase();
        if lower.ends_with(".rom") {
            return Self::from_ndi_rom(bytes, file);
        }
        let text = std::str::from_utf8(bytes).map_err(|e| {
            geometry_error(
                Some(format!("{file}, byte {}", e.valid_up_to())),
                "not UTF-8 text",
            )
        })?;
        if lower.ends_with(".ini") {
            Self::from_atracsys_ini(text, file)
        } else if lower.ends_with(".toml") {
            Self::from_toml_str(text, file)
        } else {
            Err(geometry_error(
                Some(file.to_string()),
                "unknown geometry format: use .toml, .ini (Atracsys) or .rom (NDI)",
            ))
        }
    }

    /// NDI's passive tool 8700449 (4 fiducials in its x = 0 plane; distances 50.0–89.1 mm with
    /// gaps ≥ 5 mm), values from its `.rom` as listed in the reference notes. The face is +x.
    pub fn ndi_8700449() -> Self {
        Self {
            name: "NDI 8700449".into(),
            points: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.0, 0.04738, 0.02899),
                Point3::new(0.0, 0.0, 0.0891),
                Point3::new(0.0, -0.03536, 0.03536),
            ],
        }
    }

    /// Number of fiducials.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Always false (a geometry has at least 3 points).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Distance between fiducials `i` and `j`, metres.
    pub fn distance(&self, i: usize, j: usize) -> f64 {
        (self.points[i] - self.points[j]).norm()
    }

    /// How identifiable the geometry is at a matching tolerance (metres): distinct distances,
    /// symmetries (distance-preserving relabellings), with warnings for each problem.
    pub fn analyze(&self, tolerance_m: f64) -> GeometryReport {
        let n = self.len();
        let mut d: Vec<(f64, usize, usize)> = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                d.push((self.distance(i, j), i, j));
            }
        }
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let min_distance_m = d.first().map(|x| x.0).unwrap_or(0.0);
        let mut min_gap = f64::INFINITY;
        let mut closest = None;
        for w in d.windows(2) {
            let gap = w[1].0 - w[0].0;
            if gap < min_gap {
                min_gap = gap;
                closest = Some((w[0], w[1]));
            }
        }
        let symmetries = count_symmetries(self, tolerance_m);
        let mut warnings = Vec::new();
        if symmetries > 0 {
            warnings.push(format!(
                "the geometry is symmetric ({symmetries} relabelling(s) keep every distance within \
                 {:.1} mm): its pose can flip; use distinct distances",
                tolerance_m * 1e3
            ));
        } else if let Some((a, b)) = closest
            && min_gap < 2.0 * tolerance_m
        {
            warnings.push(format!(
                "distances {}–{} ({:.1} mm) and {}–{} ({:.1} mm) differ by only {:.1} mm, under twice \
                 the matching tolerance: fiducials may be confused",
                a.1 + 1,
                a.2 + 1,
                a.0 * 1e3,
                b.1 + 1,
                b.2 + 1,
                b.0 * 1e3,
                min_gap * 1e3
            ));
        }
        GeometryReport {
            min_distance_m,
            min_distance_gap_m: min_gap,
            symmetries,
            warnings,
        }
    }

    /// Centroid of the fiducials.
    pub fn centroid(&self) -> Point3<f64> {
        let s: Vector3<f64> = self.points.iter().map(|p| p.coords).sum();
        Point3::from(s / self.len() as f64)
    }
}

fn with_location(e: VisionError, file: &str) -> VisionError {
    match e {
        VisionError::Geometry {
            location: None,
            message,
        } => VisionError::Geometry {
            location: Some(file.to_string()),
            message,
        },
        other => other,
    }
}

/// Permutations other than the identity under which every pairwise distance is preserved within
/// `tol`. Backtracking with pruning; geometries have few points.
fn count_symmetries(g: &MarkerGeometry, tol: f64) -> usize {
    fn go(
        g: &MarkerGeometry,
        tol: f64,
        perm: &mut Vec<usize>,
        used: &mut [bool],
        count: &mut usize,
    ) {
        let k = perm.len();
        if k == g.len() {
            if perm.iter().enumerate().any(|(i, &p)| i != p) {
                *count += 1;
            }
            return;
        }
        for c in 0..g.len() {
            if used[c] {
                continue;
            }
            if perm
                .iter()
                .enumerate()
                .all(|(i, &pi)| (g.distance(i, k) - g.distance(pi, c)).abs() <= tol)
            {
                used[c] = true;
                perm.push(c);
                go(g, tol, perm, used, count);
                perm.pop();
                used[c] = false;
            }
        }
    }
    let mut count = 0;
    let mut used = vec![false; g.len()];
    go(g, tol, &mut Vec::new(), &mut used, &mut count);
    count
}

/// A 5 cm square of four fiducials: the symmetric geometry the tests use.
#[cfg(test)]
pub(crate) fn square_5cm() -> MarkerGeometry {
    let pts = [(0.0, 0.0), (0.05, 0.0), (0.05, 0.05), (0.0, 0.05)];
    match MarkerGeometry::new(
        "square",
        pts.iter().map(|&(x, y)| Point3::new(x, y, 0.0)).collect(),
    ) {
        Ok(g) => g,
        Err(e) => unreachable!("a valid square: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An NDI .rom image built to the documented layout.
    pub(crate) fn rom_bytes(points_mm: &[[f32; 3]]) -> Vec<u8> {
        let mut b = vec![0u8; 752];
        b[0..3].copy_from_slice(b"NDI");
        b[28] = points_mm.len() as u8;
        b[32] = 3;
        b[36..40].copy_from_slice(&2.0f32.to_le_bytes());
        for (i, p) in points_mm.iter().enumerate() {
            for (k, v) in p.iter().enumerate() {
                let off = 72 + 12 * i + 4 * k;
                b[off..off + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        b[655] = 41;
        let sum = b[6..]
            .iter()
            .fold(0u16, |s, x| s.wrapping_add(u16::from(*x)));
        b[4..6].copy_from_slice(&sum.to_le_bytes());
        b
    }

    #[test]
    fn reads_ndi_rom_and_checks_it() {
        // NDI 8700339's markers (verified values in the reference notes).
        let pts = [
            [0.0, 0.0, 0.0],
            [0.0, 28.59, 41.02],
            [0.0, 0.0, 88.0],
            [0.0, -44.32, 40.45],
        ];
        let bytes = rom_bytes(&pts);
        let g = MarkerGeometry::from_ndi_rom(&bytes, "8700339.rom").unwrap();
        assert_eq!(g.len(), 4);
        assert!((g.points[2].z - 0.088).abs() < 1e-9);
        let r = g.analyze(0.002);
        assert_eq!(r.symmetries, 0);
        assert!(r.min_distance_m > 0.049);
        let mut damaged = bytes.clone();
        damaged[80] ^= 0x40;
        let e = MarkerGeometry::from_ndi_rom(&damaged, "t.rom")
            .unwrap_err()
            .to_string();
        assert!(e.contains("byte 4") && e.contains("checksum"), "{e}");
        let e = MarkerGeometry::from_ndi_rom(&bytes[..700], "t.rom")
            .unwrap_err()
            .to_string();
        assert!(e.contains("700 bytes"), "{e}");
        let mut not_ndi = bytes.clone();
        not_ndi[0] = b'X';
        assert!(
            MarkerGeometry::from_ndi_rom(&not_ndi, "t.rom")
                .unwrap_err()
                .to_string()
                .contains("byte 0")
        );
        let two = rom_bytes(&pts[..2]);
        assert!(
            MarkerGeometry::from_ndi_rom(&two, "t.rom")
                .unwrap_err()
                .to_string()
                .contains("byte 28")
        );
    }

    #[test]
    fn reads_atracsys_ini() {
        let ini = "; geometry 101\n[geometry]\ncount=4\nid=101\n\n[fiducial0]\nx=0.0\ny=0.0\nz=0.0\n[fiducial1]\nx=-24.3012\ny=-29.5377\nz=0.14917\n[fiducial2]\nx=40\ny=0\nz=0\nnormalx=0\n[fiducial3]\nx=10\ny=55\nz=5\n";
        let g = MarkerGeometry::from_atracsys_ini(ini, "geometry101.ini").unwrap();
        assert_eq!(g.len(), 4);
        assert_eq!(g.name, "atracsys geometry 101");
        assert!((g.points[1].x + 0.0243012).abs() < 1e-12);
        let e = MarkerGeometry::from_atracsys_ini(&ini.replace("count=4", "count=5"), "g.ini")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[fiducial4]") && e.contains("line 3"), "{e}");
        let e = MarkerGeometry::from_atracsys_ini(&ini.replace("y=55", "y=abc"), "g.ini")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 21") && e.contains("abc"), "{e}");
        let e = MarkerGeometry::from_atracsys_ini(&ini.replace("z=5\n", ""), "g.ini")
            .unwrap_err()
            .to_string();
        assert!(e.contains("[fiducial3] has no z"), "{e}");
    }

    #[test]
    fn toml_and_bad_geometries() {
        let g = MarkerGeometry::from_toml_str(
            "name = \"head\"\npoints_mm = [[0,0,0],[50,0,0],[0,60,0],[20,20,40]]\n",
            "h.toml",
        )
        .unwrap();
        assert_eq!(g.name, "head");
        let e = MarkerGeometry::from_toml_str("points_mm = [[0,0,0],[50,0,0]]\n", "two.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("at least 3") && e.contains("two.toml"), "{e}");
        let e = MarkerGeometry::from_toml_str(
            "points_mm = [[0,0,0],[50,0,0],[100,0,0]]\n",
            "line.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("one line"), "{e}");
        let e = MarkerGeometry::from_toml_str("pts = []\n", "k.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("pts"), "{e}");
        assert!(
            MarkerGeometry::from_file_bytes(b"x", "marker.obj")
                .unwrap_err()
                .to_string()
                .contains("unknown geometry format")
        );
    }

    #[test]
    fn symmetric_and_near_symmetric_geometries_are_flagged() {
        let square = square_5cm();
        let r = square.analyze(0.002);
        assert_eq!(
            r.symmetries, 7,
            "a square has 8 distance-preserving labellings"
        );
        assert!(r.warnings[0].contains("symmetric"));
        let near = MarkerGeometry::new(
            "near",
            // Distances 50, 51, 53, 64, 72.9, 83.1 mm: 50 and 51 are close, yet no relabelling keeps
            // them all.
            vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.050, 0.0, 0.0),
                Point3::new(0.0, 0.053, 0.0),
                Point3::new(0.04, 0.0, 0.05),
            ],
        )
        .unwrap();
        let r = near.analyze(0.002);
        assert_eq!(r.symmetries, 0);
        assert!(
            r.warnings.iter().any(|w| w.contains("differ by only")),
            "{:?}",
            r.warnings
        );
    }
}
