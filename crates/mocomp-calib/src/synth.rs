//! Seeded synthetic calibration pairs: robot poses rotated 15°–40° about random axes around a
//! centre pose, the tracker's view computed from known X and Y, and Gaussian noise on both sides.

use crate::error::CalibError;
use crate::noise::NoiseModel;
use crate::pairs::Pair;
use mocomp_geom::nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};
use mocomp_geom::quat_from_rotvec;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// What to synthesise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthOptions {
    /// Number of pairs.
    pub count: usize,
    /// True `X = flange_from_marker`.
    pub flange_from_marker: Isometry3<f64>,
    /// True `Y = base_from_tracker`.
    pub base_from_tracker: Isometry3<f64>,
    /// The centre flange pose the robot rotates about.
    pub center: Isometry3<f64>,
    /// Rotation angles from the centre, radians (min, max).
    pub rotation_range_rad: (f64, f64),
    /// Translation offsets from the centre, per axis uniform in ±this, metres.
    pub translation_spread_m: f64,
    /// Noise added to the measurements (`None`: exact data).
    pub noise: Option<NoiseModel>,
    /// RNG seed.
    pub seed: u64,
}

impl Default for SynthOptions {
    /// A UR3-sized setup: a marker 12 cm out on the flange, a tracker 1.5 m away looking at the
    /// robot, rotations of 15°–40°, offsets of ±20 cm (positions pin down Y's rotation far better
    /// than 0.1° orientations do, so a run should move the marker through the tracker's volume;
    /// this spread reproduces the OpenCV figures in the reference notes), the default noise.
    fn default() -> Self {
        Self {
            count: 20,
            flange_from_marker: Isometry3::from_parts(
                Translation3::new(0.01, 0.05, 0.12),
                quat_from_rotvec(&Vector3::new(0.2, -0.3, 1.0)),
            ),
            base_from_tracker: Isometry3::from_parts(
                Translation3::new(1.1, -0.9, 0.7),
                quat_from_rotvec(&Vector3::new(1.9, -0.6, 0.4)),
            ),
            center: Isometry3::from_parts(
                Translation3::new(0.30, -0.15, 0.35),
                quat_from_rotvec(&Vector3::new(2.2, -2.2, 0.0)),
            ),
            rotation_range_rad: (15f64.to_radians(), 40f64.to_radians()),
            translation_spread_m: 0.20,
            noise: Some(NoiseModel::default()),
            seed: 1,
        }
    }
}

fn gaussian3(rng: &mut ChaCha8Rng, sigma: f64) -> Vector3<f64> {
    Vector3::new(
        rng.sample::<f64, _>(StandardNormal) * sigma,
        rng.sample::<f64, _>(StandardNormal) * sigma,
        rng.sample::<f64, _>(StandardNormal) * sigma,
    )
}

/// A uniformly random unit vector.
fn random_axis(rng: &mut ChaCha8Rng) -> Unit<Vector3<f64>> {
    loop {
        let v = gaussian3(rng, 1.0);
        if v.norm() > 1e-6 {
            return Unit::new_normalize(v);
        }
    }
}

/// A pairs file of `pairs` synthesised with `options`: a comment header naming the seed and the
/// true X and Y (UR pose vectors), then the pairs in the pose format.
pub fn pairs_file(options: &SynthOptions, pairs: &[Pair]) -> Result<String, CalibError> {
    let mut text = format!(
        "# mocomp synthetic calibration pairs: seed {}, {} pairs\n# true X = flange_from_marker: {:?}\n# true Y = base_from_tracker: {:?}\n",
        options.seed,
        options.count,
        mocomp_geom::ur_pose_from_iso(&options.flange_from_marker),
        mocomp_geom::ur_pose_from_iso(&options.base_from_tracker)
    );
    text.push_str(&crate::pairs::write_pairs_csv(
        pairs,
        crate::PairsFormat::Pose,
    )?);
    Ok(text)
}

/// Synthesises pairs. The robot rotates about the marker's centre (so the marker stays in view)
/// and shifts by the translation spread; measurements are `M_i` and `Y⁻¹·M_i·X` with noise.
pub fn synthesize(options: &SynthOptions) -> Result<Vec<Pair>, CalibError> {
    let (lo, hi) = options.rotation_range_rad;
    if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi >= lo) {
        return Err(CalibError::InvalidOption(format!(
            "rotation range [{lo}, {hi}] rad is not an interval of non-negative angles"
        )));
    }
    if let Some(n) = &options.noise {
        // Zero noise is allowed here (exact data); negative or NaN is not.
        for v in [
            n.tracker_translation_m,
            n.tracker_rotation_rad,
            n.robot_translation_m,
            n.robot_rotation_rad,
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(CalibError::InvalidOption(format!(
                    "noise must be finite and non-negative, got {v}"
                )));
            }
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let x = options.flange_from_marker;
    let y_inv = options.base_from_tracker.inverse();
    let mut pairs = Vec::with_capacity(options.count);
    for _ in 0..options.count {
        let axis = random_axis(&mut rng);
        let angle = lo + (hi - lo) * rng.random::<f64>();
        let turn = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&axis, angle),
        );
        let s = options.translation_spread_m;
        let shift = Vector3::new(
            s * (2.0 * rng.random::<f64>() - 1.0),
            s * (2.0 * rng.random::<f64>() - 1.0),
            s * (2.0 * rng.random::<f64>() - 1.0),
        );
        // Rotate about the marker centre: M = C · X · R · X⁻¹, then shift in the base frame.
        let mut m = options.center * x * turn * x.inverse();
        m.translation.vector += shift;
        let mut n = y_inv * m * x;
        let mut m_meas = m;
        if let Some(noise) = &options.noise {
            // Robot: noise in the flange frame. Tracker: position noise in the tracker frame,
            // rotation noise in the marker frame.
            let dr = gaussian3(&mut rng, noise.robot_rotation_rad);
            let dt = gaussian3(&mut rng, noise.robot_translation_m);
            m_meas = m * Isometry3::from_parts(Translation3::from(dt), quat_from_rotvec(&dr));
            let nr = gaussian3(&mut rng, noise.tracker_rotation_rad);
            let nt = gaussian3(&mut rng, noise.tracker_translation_m);
            n.rotation *= quat_from_rotvec(&nr);
            n.translation.vector += nt;
        }
        pairs.push(Pair::new(m_meas, n));
    }
    Ok(pairs)
}
