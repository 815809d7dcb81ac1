//! A configuration read, checked and resolved for a command: [`Setup`].

use super::*;

/// The configuration, read and checked, with what follows from it.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The configuration.
    pub file: Config,
    /// Where it came from (`None`: the defaults alone).
    pub path: Option<PathBuf>,
    /// Its directory (relative paths in it are relative to this).
    pub dir: PathBuf,
    /// The robot model.
    pub model: Model,
    /// Its kinematics (flange).
    pub arm: Arm,
    /// The configured base_from_tracker (the calibration).
    pub base_from_tracker: Isometry3<f64>,
}

impl Setup {
    /// Reads and checks the file at `path`.
    pub fn load(path: &Path) -> Result<Self, AppError> {
        Self::load_with(path, |_| {})
    }

    /// [`Setup::load`], with `edit` applied to the file as read, before it is checked: a
    /// command line's options that override the file are checked as the file's own values
    /// are, and the checked setup is never edited afterwards.
    pub fn load_with(path: &Path, edit: impl FnOnce(&mut Config)) -> Result<Self, AppError> {
        let text = std::fs::read_to_string(path).what(|| format!("--config {}", path.display()))?;
        let mut file = Config::parse(&path.display().to_string(), &text)?;
        edit(&mut file);
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::new(file, Some(path.to_path_buf()), dir)
    }

    /// A setup of a configuration already read (its relative paths relative to `dir`).
    pub fn new(mut file: Config, path: Option<PathBuf>, dir: PathBuf) -> Result<Self, AppError> {
        file.check()?;
        file.load_head(&dir)?;
        let model = file.robot.model;
        let base_from_tracker = file.base_from_tracker(&dir)?;
        // The coil's mounting, named now rather than once the robot moves (the goal may be
        // missing yet: teaching it is what `teach-goal` is for).
        file.flange_from_coil()?;
        Ok(Self {
            file,
            path,
            dir,
            model,
            arm: Arm::new(model),
            base_from_tracker,
        })
    }

    /// Refuses `tracker.source = "ros2"` for `job`, which reads the tracker over OpenIGTLink.
    pub fn needs_igtl_tracker(&self, job: &str) -> Result<(), AppError> {
        if self.file.tracker.source == TrackerSource::Ros2 {
            return Err(AppError::Config(format!(
                "tracker.source = \"ros2\": {job} reads the tracker over OpenIGTLink (only \
                 `mocomp run` takes the head's poses from ROS 2)"
            )));
        }
        Ok(())
    }

    /// The robot's control period, s.
    pub fn period(&self) -> f64 {
        self.model.spec().series.period_s()
    }

    /// The loop's configuration.
    pub fn loop_config(&self) -> Result<LoopConfig, AppError> {
        self.file.loop_config(self.base_from_tracker, self.period())
    }

    /// The simulated robot's joints at start: `robot.initial_joints_rad`, or the coil 15 cm out
    /// on the goal's axis for the head at rest.
    pub fn initial_joints(&self) -> Result<[f64; 6], AppError> {
        self.initial_joints_at(&self.file.tracker.simulated.base_from_head.iso())
    }

    /// [`Self::initial_joints`] with the head at `rest` (a placement tried).
    pub fn initial_joints_at(&self, rest: &Isometry3<f64>) -> Result<[f64; 6], AppError> {
        if let Some(q) = self.file.robot.initial_joints_rad {
            return Ok(q);
        }
        let cfg = self.loop_config()?;
        let out = rest
            * cfg.head_from_coil_goal
            * Isometry3::translation(0.0, 0.0, -0.15)
            * cfg.flange_from_coil.inverse();
        let seeds = [
            [0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
            [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
            [1.57, -1.3, 1.6, -1.87, -1.57, 0.0],
        ];
        for seed in seeds {
            if let Ok(c) = self.arm.ik_closest(&out, &seed, &Selection::tracking(0.1)) {
                return Ok(c.joints);
            }
        }
        Err(AppError::Config(
            "robot.initial_joints_rad: needed, the default start (15 cm out on the goal's axis) \
             is out of reach"
                .into(),
        ))
    }
}
