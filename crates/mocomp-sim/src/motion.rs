//! Head-motion generators: `rest_from_head(t)`, the head's displacement from its rest pose at time
//! `t` (seconds), a deterministic function of time (and, for random motion, of a seed), so a
//! controller can be run twice on exactly the same motion.
//!
//! Every motion holds still until `start_s`, then ramps in, so a controller starts on a still
//! head. The displacement is applied in the head's own frame:
//! `base_from_head(t) = base_from_head_rest · rest_from_head(t)`.

use mocomp_geom::nalgebra::{Isometry3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// A motion parameter out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key} = {value}: {problem}")]
pub struct MotionError {
    /// The parameter's name, as in the configuration file.
    pub key: &'static str,
    /// Its value.
    pub value: f64,
    /// What is wrong with it.
    pub problem: &'static str,
}

/// A head motion. In a TOML file: `kind = "still" | "drift" | "nods" | "random" | "file"` and the
/// kind's fields (every field has a default; unknown fields are rejected).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum HeadMotion {
    /// No motion.
    Still,
    /// Constant velocity from `start_s`: a slow drift (a patient settling).
    Drift(Drift),
    /// Sinusoidal nods and turns, as measured on patients.
    Nods(Nods),
    /// Smooth random motion: a seeded sum of sinusoids per axis, bounded in speed and range.
    Random(RandomMotion),
    /// A quick head turn away and back (a free head turning to look at something).
    Turn(Turn),
    /// A recorded motion replayed from a CSV file (see [`crate::trace`]).
    File(FileMotion),
}

/// A recorded motion: a tracker's head poses from a CSV file, replayed from `start_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FileMotion {
    /// The CSV file (`t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz`); relative to the configuration file's
    /// directory, or to the working directory on the command line.
    pub path: String,
    /// When the first sample plays, s.
    pub start_s: f64,
    /// The trace, once [`HeadMotion::load_file`] has read it.
    #[serde(skip)]
    pub trace: Option<std::sync::Arc<crate::trace::MotionTrace>>,
}

impl Default for FileMotion {
    /// No file yet; from t = 1 s.
    fn default() -> Self {
        Self {
            path: String::new(),
            start_s: 1.0,
            trace: None,
        }
    }
}

/// Constant-velocity drift.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Drift {
    /// Start, s.
    pub start_s: f64,
    /// Velocity in the head frame, m/s.
    pub velocity_m_s: [f64; 3],
    /// Angular velocity in the head frame (rotation vector rate), rad/s.
    pub angular_rad_s: [f64; 3],
}

impl Default for Drift {
    /// 11 mm/s and 2.9°/s from t = 1 s.
    fn default() -> Self {
        Self {
            start_s: 1.0,
            velocity_m_s: [0.01, -0.005, 0.0],
            angular_rad_s: [0.0, 0.0, 0.05],
        }
    }
}

/// Nods and turns: sideways sway with a turn (yaw) at `frequency_hz`, and a nod (pitch) at 0.7 of
/// it, ramped in over a second by a smoothstep (a head does not start with a step in its
/// acceleration; the linear half-second ramp before gave two).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Nods {
    /// Start, s.
    pub start_s: f64,
    /// Sway amplitude along head x (half of it along y), m.
    pub sway_m: f64,
    /// Turn (about head z) amplitude, rad.
    pub turn_rad: f64,
    /// Nod (about head y) amplitude, rad.
    pub nod_rad: f64,
    /// Frequency of sway and turn, Hz.
    pub frequency_hz: f64,
}

/// How long nods take to ramp in, s.
const NODS_RAMP_S: f64 = 1.0;

impl Default for Nods {
    /// Peaks of about 89 mm/s and 34°/s (the patient studies' fast movements).
    fn default() -> Self {
        Self {
            start_s: 1.0,
            sway_m: 0.02,
            turn_rad: 0.15,
            nod_rad: 0.08,
            frequency_hz: 4.0 / TAU,
        }
    }
}

/// A quick turn about head z: away by `angle_rad` with a raised-cosine speed profile peaking at
/// `peak_rad_s`, held for `hold_s`, and back the same way.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Turn {
    /// Start, s.
    pub start_s: f64,
    /// How far the head turns, rad.
    pub angle_rad: f64,
    /// The turn's peak angular speed, rad/s.
    pub peak_rad_s: f64,
    /// How long the head stays turned, s.
    pub hold_s: f64,
}

impl Default for Turn {
    /// 40° at up to 250°/s (a free head turning away, as measured on patients), back after 1 s.
    fn default() -> Self {
        Self {
            start_s: 1.0,
            angle_rad: 40f64.to_radians(),
            peak_rad_s: 250f64.to_radians(),
            hold_s: 1.0,
        }
    }
}

impl Turn {
    /// The turn's angle at `t` (s from `start_s`): a raised-cosine speed profile lasts
    /// `2 · angle / peak` and covers the angle exactly.
    fn angle_at(&self, t: f64) -> f64 {
        let d = 2.0 * self.angle_rad / self.peak_rad_s;
        let ramp = |x: f64| {
            let x = (x / d).clamp(0.0, 1.0);
            self.angle_rad * (x - (TAU * x).sin() / TAU)
        };
        ramp(t) - ramp(t - d - self.hold_s)
    }
}

/// Smooth random motion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomMotion {
    /// Start, s (ramped in over `ramp_s`).
    pub start_s: f64,
    /// Ramp-in, s.
    pub ramp_s: f64,
    /// Bound on the translational speed, m/s.
    pub max_speed_m_s: f64,
    /// Bound on the angular speed, rad/s.
    pub max_angular_rad_s: f64,
    /// Bound on the displacement per axis, m.
    pub range_m: f64,
    /// Bound on the rotation per axis, rad.
    pub range_rad: f64,
    /// Lowest and highest component frequency, Hz.
    pub band_hz: [f64; 2],
    /// Seed.
    pub seed: u64,
}

impl Default for RandomMotion {
    /// Up to 20 mm/s and 10°/s, within ±30 mm and ±10°, 0.05–0.4 Hz.
    fn default() -> Self {
        Self {
            start_s: 1.0,
            ramp_s: 1.0,
            max_speed_m_s: 0.02,
            max_angular_rad_s: 10f64.to_radians(),
            range_m: 0.03,
            range_rad: 10f64.to_radians(),
            band_hz: [0.05, 0.4],
            seed: 1,
        }
    }
}

/// Sinusoids per axis of random motion.
const COMPONENTS: usize = 4;

/// Random motion, prepared: per axis (x, y, z, rx, ry, rz) the amplitude, frequency and phase of
/// each component.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Prepared {
    amp: [[f64; COMPONENTS]; 6],
    freq: [[f64; COMPONENTS]; 6],
    phase: [[f64; COMPONENTS]; 6],
}

impl RandomMotion {
    fn prepare(&self) -> Prepared {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut p = Prepared {
            amp: [[0.0; COMPONENTS]; 6],
            freq: [[0.0; COMPONENTS]; 6],
            phase: [[0.0; COMPONENTS]; 6],
        };
        let [lo, hi] = self.band_hz;
        for axis in 0..6 {
            let (speed, range) = if axis < 3 {
                (self.max_speed_m_s, self.range_m)
            } else {
                (self.max_angular_rad_s, self.range_rad)
            };
            let mut weights = [0.0; COMPONENTS];
            for (c, weight) in weights.iter_mut().enumerate() {
                *weight = 0.3 + rng.random::<f64>();
                p.freq[axis][c] = lo + (hi - lo) * rng.random::<f64>();
                p.phase[axis][c] = TAU * rng.random::<f64>();
            }
            // Per axis x = Σ a_c (sin(ω_c t + φ_c) − sin φ_c) / 2 with Σ a_c = A: |x| ≤ A and
            // |ẋ| ≤ A·π·Σwf/Σw. The speed bound is on the norm of three axes, so each axis gets
            // 1/√3 of it.
            let w: f64 = weights.iter().sum();
            let wf: f64 = (0..COMPONENTS).map(|c| weights[c] * p.freq[axis][c]).sum();
            let a = range.min(speed / 3f64.sqrt() / (std::f64::consts::PI * wf / w));
            for (amp, weight) in p.amp[axis].iter_mut().zip(weights) {
                *amp = a * weight / w;
            }
        }
        p
    }
}

impl HeadMotion {
    /// The motion called `name`, with default parameters: still, drift, nods or random.
    pub fn named(name: &str) -> Option<Self> {
        Some(match name {
            "still" => Self::Still,
            "drift" => Self::Drift(Drift::default()),
            "nods" => Self::Nods(Nods::default()),
            "random" => Self::Random(RandomMotion::default()),
            "turn" => Self::Turn(Turn::default()),
            _ => return None,
        })
    }

    /// The kind's name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Still => "still",
            Self::Drift(_) => "drift",
            Self::Nods(_) => "nods",
            Self::Random(_) => "random",
            Self::Turn(_) => "turn",
            Self::File(_) => "file",
        }
    }

    /// A recorded motion from `path`, read now (relative paths from `base_dir`).
    pub fn from_file(
        path: &str,
        base_dir: &std::path::Path,
    ) -> Result<Self, crate::trace::TraceError> {
        let mut m = Self::File(FileMotion {
            path: path.to_string(),
            ..FileMotion::default()
        });
        m.load_file(base_dir)?;
        Ok(m)
    }

    /// Reads a recorded motion's file (relative paths from `base_dir`); other motions have none.
    pub fn load_file(
        &mut self,
        base_dir: &std::path::Path,
    ) -> Result<(), crate::trace::TraceError> {
        if let Self::File(f) = self {
            let path = base_dir.join(&f.path);
            f.trace = Some(std::sync::Arc::new(crate::trace::MotionTrace::load(&path)?));
            // Absolute from now on, so a configuration written beside a report repeats the run
            // from wherever it is read.
            if let Ok(abs) = path.canonicalize() {
                f.path = abs.to_string_lossy().into_owned();
            }
        }
        Ok(())
    }

    /// The same motion at other speeds (`None` keeps the motion's own): `speed_m_s` bounds the
    /// translational speed, `angular_rad_s` the angular speed.
    /// - random motion takes them as its bounds;
    /// - a drift moves at exactly these speeds, in its own directions (along head x, or about
    ///   head z, if it had none);
    /// - nods and turns are scaled in amplitude so that their peaks are these speeds.
    ///
    /// A still head, or nods at zero frequency, has no speed to set.
    pub fn with_speeds(
        &self,
        speed_m_s: Option<f64>,
        angular_rad_s: Option<f64>,
    ) -> Result<Self, MotionError> {
        for (key, v) in [("speed_m_s", speed_m_s), ("angular_rad_s", angular_rad_s)] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                return Err(MotionError {
                    key,
                    value: v,
                    problem: "must be finite and ≥ 0",
                });
            }
        }
        if speed_m_s.is_none() && angular_rad_s.is_none() {
            return Ok(self.clone());
        }
        let scaled = |v: [f64; 3], norm: f64, fallback: [f64; 3]| {
            let n = Vector3::from(v).norm();
            if n > 0.0 {
                v.map(|x| x * norm / n)
            } else {
                fallback.map(|x| x * norm)
            }
        };
        Ok(match self.clone() {
            Self::File(_) => {
                return Err(MotionError {
                    key: "speed_m_s",
                    value: speed_m_s.or(angular_rad_s).unwrap_or(0.0),
                    problem: "a recorded motion moves at its own speeds",
                });
            }
            Self::Still => {
                let (key, value) = match (speed_m_s, angular_rad_s) {
                    (Some(v), _) => ("speed_m_s", v),
                    (None, w) => ("angular_rad_s", w.unwrap_or(0.0)),
                };
                return Err(MotionError {
                    key,
                    value,
                    problem: "a still head has no speed to set",
                });
            }
            Self::Drift(mut d) => {
                if let Some(v) = speed_m_s {
                    d.velocity_m_s = scaled(d.velocity_m_s, v, [1.0, 0.0, 0.0]);
                }
                if let Some(w) = angular_rad_s {
                    d.angular_rad_s = scaled(d.angular_rad_s, w, [0.0, 0.0, 1.0]);
                }
                Self::Drift(d)
            }
            Self::Turn(mut turn) => {
                if let Some(w) = angular_rad_s.filter(|w| *w > 0.0) {
                    turn.peak_rad_s = w;
                }
                if speed_m_s.is_some() {
                    return Err(MotionError {
                        key: "speed_m_s",
                        value: speed_m_s.unwrap_or(0.0),
                        problem: "a turn does not translate",
                    });
                }
                Self::Turn(turn)
            }
            Self::Random(mut r) => {
                if let Some(v) = speed_m_s {
                    r.max_speed_m_s = v;
                }
                if let Some(w) = angular_rad_s {
                    r.max_angular_rad_s = w;
                }
                Self::Random(r)
            }
            Self::Nods(mut n) => {
                if !(n.frequency_hz.is_finite() && n.frequency_hz > 0.0) {
                    return Err(MotionError {
                        key: "frequency_hz",
                        value: n.frequency_hz,
                        problem: "nods at zero frequency have no speed to set",
                    });
                }
                // Turn and nod beat with a period of ten turns: the peaks are within it.
                let window = n.start_s + 0.5 + 10.0 / n.frequency_hz;
                let peaks = |n: &Nods| Self::Nods(*n).trajectory().peak_speeds(window);
                if let Some(v) = speed_m_s {
                    if n.sway_m == 0.0 {
                        n.sway_m = 0.01;
                    }
                    // The sway's speed is linear in its amplitude.
                    n.sway_m *= v / peaks(&n).0;
                }
                if let Some(w) = angular_rad_s {
                    if n.turn_rad == 0.0 && n.nod_rad == 0.0 {
                        n.turn_rad = 0.1;
                    }
                    // Nearly linear in the amplitudes (the turn and the nod compose): a few
                    // rescalings converge.
                    for _ in 0..4 {
                        let k = w / peaks(&n).1;
                        n.turn_rad *= k;
                        n.nod_rad *= k;
                    }
                }
                Self::Nods(n)
            }
        })
    }

    /// Checks every parameter; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), MotionError> {
        let finite = |key, value: f64| {
            if value.is_finite() {
                Ok(())
            } else {
                Err(MotionError {
                    key,
                    value,
                    problem: "must be finite",
                })
            }
        };
        let nonneg = |key, value: f64| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(MotionError {
                    key,
                    value,
                    problem: "must be finite and ≥ 0",
                })
            }
        };
        match self {
            Self::Still => Ok(()),
            Self::File(f) => {
                nonneg("start_s", f.start_s)?;
                if f.trace.is_none() {
                    return Err(MotionError {
                        key: "path",
                        value: f64::NAN,
                        problem: "the motion file has not been read",
                    });
                }
                Ok(())
            }
            Self::Drift(d) => {
                nonneg("start_s", d.start_s)?;
                for v in d.velocity_m_s {
                    finite("velocity_m_s", v)?;
                }
                for v in d.angular_rad_s {
                    finite("angular_rad_s", v)?;
                }
                Ok(())
            }
            Self::Turn(turn) => {
                nonneg("start_s", turn.start_s)?;
                nonneg("angle_rad", turn.angle_rad)?;
                nonneg("hold_s", turn.hold_s)?;
                if !(turn.peak_rad_s.is_finite() && turn.peak_rad_s > 0.0) {
                    return Err(MotionError {
                        key: "peak_rad_s",
                        value: turn.peak_rad_s,
                        problem: "must be finite and > 0",
                    });
                }
                Ok(())
            }
            Self::Nods(n) => {
                nonneg("start_s", n.start_s)?;
                nonneg("sway_m", n.sway_m)?;
                nonneg("turn_rad", n.turn_rad)?;
                nonneg("nod_rad", n.nod_rad)?;
                nonneg("frequency_hz", n.frequency_hz)
            }
            Self::Random(r) => {
                nonneg("start_s", r.start_s)?;
                nonneg("ramp_s", r.ramp_s)?;
                nonneg("max_speed_m_s", r.max_speed_m_s)?;
                nonneg("max_angular_rad_s", r.max_angular_rad_s)?;
                nonneg("range_m", r.range_m)?;
                nonneg("range_rad", r.range_rad)?;
                let [lo, hi] = r.band_hz;
                if !(lo.is_finite() && lo > 0.0) {
                    return Err(MotionError {
                        key: "band_hz",
                        value: lo,
                        problem: "the lowest frequency must be > 0",
                    });
                }
                if !(hi.is_finite() && hi >= lo) {
                    return Err(MotionError {
                        key: "band_hz",
                        value: hi,
                        problem: "the highest frequency must be ≥ the lowest",
                    });
                }
                Ok(())
            }
        }
    }

    /// Prepares the motion for evaluation (random motion draws its components once here).
    pub fn trajectory(&self) -> Trajectory {
        Trajectory {
            motion: self.clone(),
            random: match self {
                Self::Random(r) => Some(r.prepare()),
                _ => None,
            },
        }
    }
}

/// A motion ready to evaluate at any time.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    motion: HeadMotion,
    random: Option<Prepared>,
}

/// A smooth 0 → 1 ramp (zero slope at both ends).
fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Trajectory {
    /// The motion.
    pub fn motion(&self) -> &HeadMotion {
        &self.motion
    }

    /// The head's displacement from rest at time `t`, s: `rest_from_head`.
    pub fn rest_from_head(&self, t: f64) -> Isometry3<f64> {
        match (&self.motion, &self.random) {
            (HeadMotion::Still, _) => Isometry3::identity(),
            (HeadMotion::Turn(turn), _) => Isometry3::new(
                Vector3::zeros(),
                Vector3::new(0.0, 0.0, turn.angle_at(t - turn.start_s)),
            ),
            (HeadMotion::File(f), _) => f
                .trace
                .as_ref()
                .map_or_else(Isometry3::identity, |tr| tr.rest_from_head(t - f.start_s)),
            (HeadMotion::Drift(d), _) => {
                let t = (t - d.start_s).max(0.0);
                Isometry3::new(
                    Vector3::from(d.velocity_m_s) * t,
                    Vector3::from(d.angular_rad_s) * t,
                )
            }
            (HeadMotion::Nods(n), _) => {
                let t = (t - n.start_s).max(0.0);
                let ramp = smoothstep(t / NODS_RAMP_S);
                let w = TAU * n.frequency_hz;
                let x = n.sway_m * ramp * (w * t).sin();
                let yaw = n.turn_rad * ramp * (w * t).sin();
                let pitch = n.nod_rad * ramp * (0.7 * w * t).sin();
                Isometry3::new(Vector3::new(x, 0.5 * x, 0.0), Vector3::new(0.0, pitch, yaw))
            }
            (HeadMotion::Random(r), Some(p)) => {
                let tt = t - r.start_s;
                if tt <= 0.0 {
                    return Isometry3::identity();
                }
                let ramp = if r.ramp_s > 0.0 {
                    smoothstep(tt / r.ramp_s)
                } else {
                    1.0
                };
                let mut v = [0.0; 6];
                for (axis, out) in v.iter_mut().enumerate() {
                    // Each component starts at zero displacement: sin(ωt + φ) − sin φ.
                    *out = ramp
                        * (0..COMPONENTS)
                            .map(|c| {
                                let (a, f, ph) =
                                    (p.amp[axis][c], p.freq[axis][c], p.phase[axis][c]);
                                a * ((TAU * f * tt + ph).sin() - ph.sin()) * 0.5
                            })
                            .sum::<f64>();
                }
                Isometry3::new(
                    Vector3::new(v[0], v[1], v[2]),
                    Vector3::new(v[3], v[4], v[5]),
                )
            }
            (HeadMotion::Random(_), None) => Isometry3::identity(),
        }
    }

    /// Translational (m/s) and angular (rad/s) speed of the head at `t`, by central difference.
    pub fn speed_at(&self, t: f64) -> (f64, f64) {
        let h = 1e-4;
        let a = self.rest_from_head(t - h);
        let b = self.rest_from_head(t + h);
        let d = a.inverse() * b;
        (
            d.translation.vector.norm() / (2.0 * h),
            d.rotation.angle() / (2.0 * h),
        )
    }

    /// The largest translational and angular speeds over `[0, duration_s]`, sampled every ms.
    pub fn peak_speeds(&self, duration_s: f64) -> (f64, f64) {
        let n = (duration_s * 1000.0).ceil().max(1.0) as usize;
        (0..=n).fold((0.0f64, 0.0f64), |(v, w), i| {
            let (a, b) = self.speed_at(i as f64 * 1e-3);
            (v.max(a), w.max(b))
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn a_turn_goes_away_at_its_peak_speed_holds_and_comes_back() {
        let m = HeadMotion::named("turn").unwrap();
        m.validate().unwrap();
        let tr = m.trajectory();
        let (v, w) = tr.peak_speeds(5.0);
        assert_eq!(v, 0.0);
        assert!((w.to_degrees() - 250.0).abs() < 1.0, "{}", w.to_degrees());
        // Away for the hold, then back at rest.
        let d = 2.0 * 40f64.to_radians() / 250f64.to_radians();
        let away = tr.rest_from_head(1.0 + d + 0.5).rotation.angle();
        assert!(
            (away.to_degrees() - 40.0).abs() < 1e-9,
            "{}",
            away.to_degrees()
        );
        assert!(
            tr.rest_from_head(1.0 + 2.0 * d + 1.0 + 0.1)
                .rotation
                .angle()
                < 1e-12
        );
        assert_eq!(tr.rest_from_head(0.5), Isometry3::identity());
        // Its speed is set by the angular speed, and it has no translation to set.
        let slow = m.with_speeds(None, Some(1.0)).unwrap().trajectory();
        assert!((slow.peak_speeds(8.0).1 - 1.0).abs() < 0.01);
        assert!(m.with_speeds(Some(0.1), None).is_err());
        let bad = HeadMotion::Turn(Turn {
            peak_rad_s: 0.0,
            ..Turn::default()
        });
        assert_eq!(bad.validate().unwrap_err().key, "peak_rad_s");
    }

    #[test]
    fn every_motion_is_still_before_its_start() {
        for name in ["still", "drift", "nods", "random"] {
            let tr = HeadMotion::named(name).unwrap().trajectory();
            for t in [0.0, 0.5, 0.99] {
                let p = tr.rest_from_head(t);
                assert!(p.translation.vector.norm() < 1e-12, "{name} at {t}");
                assert!(p.rotation.angle() < 1e-12, "{name} at {t}");
            }
        }
    }

    #[test]
    fn nods_peak_at_the_patient_speeds() {
        let tr = HeadMotion::named("nods").unwrap().trajectory();
        let (v, w) = tr.peak_speeds(10.0);
        // Sway 20 mm at 4 rad/s along x and half along y: 80·√1.25 ≈ 89 mm/s; turn 0.15·4 rad/s
        // with the nod: about 34°/s.
        assert!((0.085..0.095).contains(&v), "{v}");
        assert!((30f64.to_radians()..40f64.to_radians()).contains(&w), "{w}");
    }

    #[test]
    fn random_motion_keeps_its_bounds_and_depends_on_the_seed() {
        for seed in 1..6 {
            let m = RandomMotion {
                seed,
                ..Default::default()
            };
            let tr = HeadMotion::Random(m).trajectory();
            let (v, w) = tr.peak_speeds(40.0);
            // The ramp-in may add a little on top of the steady bound.
            assert!(v <= m.max_speed_m_s * 1.15, "seed {seed}: {v}");
            assert!(w <= m.max_angular_rad_s * 1.15, "seed {seed}: {w}");
            // And the motion is not trivially small: at least a third of the bound.
            assert!(v >= m.max_speed_m_s / 3.0, "seed {seed}: {v}");
            for i in 0..4000 {
                let p = tr.rest_from_head(f64::from(i) * 0.01);
                for k in 0..3 {
                    assert!(p.translation.vector[k].abs() <= m.range_m + 1e-12);
                }
            }
        }
        let a = HeadMotion::Random(RandomMotion::default()).trajectory();
        let b = HeadMotion::Random(RandomMotion {
            seed: 2,
            ..Default::default()
        })
        .trajectory();
        let same = a.rest_from_head(5.0);
        assert_eq!(same, a.rest_from_head(5.0), "deterministic");
        assert!((same.translation.vector - b.rest_from_head(5.0).translation.vector).norm() > 1e-4);
    }

    #[test]
    fn speeds_set_the_bound_of_random_motion_and_the_peaks_of_the_others() {
        let (v, w) = (0.03, 12f64.to_radians());
        for name in ["drift", "nods"] {
            let m = HeadMotion::named(name)
                .unwrap()
                .with_speeds(Some(v), Some(w))
                .unwrap();
            let (pv, pw) = m.trajectory().peak_speeds(30.0);
            assert!((pv / v - 1.0).abs() < 0.01, "{name}: {pv}");
            assert!((pw / w - 1.0).abs() < 0.01, "{name}: {pw}");
        }
        // One of the two: the other stays.
        let nods = HeadMotion::named("nods").unwrap();
        let (_, w0) = nods.trajectory().peak_speeds(30.0);
        let (pv, pw) = nods
            .with_speeds(Some(v), None)
            .unwrap()
            .trajectory()
            .peak_speeds(30.0);
        assert!((pv / v - 1.0).abs() < 0.01 && (pw / w0 - 1.0).abs() < 1e-9);
        match HeadMotion::named("random")
            .unwrap()
            .with_speeds(Some(v), None)
            .unwrap()
        {
            HeadMotion::Random(r) => {
                assert_eq!(r.max_speed_m_s, v);
                assert_eq!(
                    r.max_angular_rad_s,
                    RandomMotion::default().max_angular_rad_s
                );
            }
            other => panic!("{other:?}"),
        }
        // A drift without a direction gets one.
        let still_drift = HeadMotion::Drift(Drift {
            velocity_m_s: [0.0; 3],
            ..Default::default()
        });
        let (pv, _) = still_drift
            .with_speeds(Some(v), None)
            .unwrap()
            .trajectory()
            .peak_speeds(5.0);
        assert!((pv / v - 1.0).abs() < 1e-6, "{pv}");
        assert_eq!(
            HeadMotion::Still
                .with_speeds(Some(v), None)
                .unwrap_err()
                .key,
            "speed_m_s"
        );
        assert_eq!(
            HeadMotion::Still.with_speeds(None, None),
            Ok(HeadMotion::Still)
        );
        assert_eq!(
            nods.with_speeds(Some(-1.0), None).unwrap_err().key,
            "speed_m_s"
        );
    }

    #[test]
    fn motions_parse_from_toml_and_bad_fields_are_named() {
        #[derive(Deserialize)]
        struct F {
            motion: HeadMotion,
        }
        let f: F = toml::from_str("[motion]\nkind = \"random\"\nmax_speed_m_s = 0.01\nseed = 7\n")
            .unwrap();
        match f.motion {
            HeadMotion::Random(r) => {
                assert_eq!((r.max_speed_m_s, r.seed), (0.01, 7));
                assert_eq!(r.range_m, RandomMotion::default().range_m);
            }
            other => panic!("{other:?}"),
        }
        let e = toml::from_str::<F>("[motion]\nkind = \"nods\"\nspeed = 3\n")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("speed"), "{e}");
        let bad = HeadMotion::Random(RandomMotion {
            band_hz: [0.0, 1.0],
            ..Default::default()
        });
        assert_eq!(bad.validate().unwrap_err().key, "band_hz");
    }
}
