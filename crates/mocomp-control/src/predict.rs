//! Head pose prediction: a Kalman filter on SE(3), position and orientation each with their
//! rates, which also smooths tracker noise, extrapolates the pose to the time a command will take
//! effect, and says how uncertain that extrapolation is.
//!
//! Two motion models (`[predictor] model`):
//! - `ca` (default): constant acceleration, driven by white jerk. A nodding head reverses every
//!   second or so; a constant-velocity model overshoots each reversal by ½·a·h² (1.1 mm at the
//!   patient studies' 89 mm/s nods and an 80 ms horizon), a constant-acceleration one by about
//!   j·h³/6 (0.1 mm).
//! - `cv`: constant velocity, driven by white acceleration (the filter before issue 16, kept
//!   for comparison and for very noisy trackers).
//!
//! Position: three axes sharing one covariance (isotropic noise). Orientation: an error-state
//! filter, the innovation being the rotation vector `log(q_measured · q_estimate⁻¹)` (world
//! frame), with the same model per axis. With `adaptive`, each channel is an
//! interacting-multiple-model (IMM) filter over three process-noise levels, so a still head is
//! smoothed hard, a fast one followed closely, and the step from one to the other is taken
//! within a sample or two of an onset, without retuning. No allocation.

use crate::learned::Learned;
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// The motion model of the predictor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionModel {
    /// Constant velocity (white-acceleration noise `accel_noise`).
    Cv,
    /// Constant acceleration (white-jerk noise `jerk_noise`).
    Ca,
}

/// Filter settings (section `[predictor]` of `mocomp run`'s configuration).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PredictorConfig {
    /// `ca` (constant acceleration) or `cv` (constant velocity).
    pub model: MotionModel,
    /// Tracker position noise, 1σ per axis, m.
    pub position_noise_m: f64,
    /// Tracker rotation noise, 1σ per axis, rad.
    pub rotation_noise_rad: f64,
    /// `cv`: white-acceleration spectral density for position, m²/s³.
    pub accel_noise: f64,
    /// `cv`: the same for rotation, rad²/s³.
    pub angular_accel_noise: f64,
    /// `ca`: white-jerk spectral density for position, m²/s⁵.
    pub jerk_noise: f64,
    /// `ca`: the same for rotation, rad²/s⁵.
    pub angular_jerk_noise: f64,
    /// An interacting-multiple-model filter over the configured density and
    /// 1/`adapt_range` and `adapt_range` times it (a still head, a moving one, an onset), each
    /// mode weighed by how well it predicted the samples; otherwise one Kalman filter at the
    /// configured density.
    pub adaptive: bool,
    /// How far the quiet and the loud mode's process noise lie from the configured density
    /// either way (≥ 1).
    pub adapt_range: f64,
    /// Longest extrapolation, s (longer horizons are clamped). Covers the command horizon plus
    /// the longest coasted dropout.
    pub max_horizon_s: f64,
    /// `ca`: the acceleration is extrapolated this long at most, s; beyond it the velocity
    /// carries on (an acceleration never lasts: a head reverses within half a second).
    pub accel_horizon_s: f64,
    /// How strongly rates within their own uncertainty are shrunk before extrapolating
    /// (0: never; 4: a rate of 2σ is halved; 0.5: a rate of 1σ keeps 2/3).
    pub velocity_shrink: f64,
    /// `ca`: the largest head acceleration the filter believes, m/s².
    pub max_accel_m_s2: f64,
    /// `ca`: the same for rotation, rad/s². [5] Lower than a head's fastest turns reach for an
    /// instant: an onset within a sample is a step in velocity, which a constant-acceleration
    /// model takes for an acceleration and carries on past the step; at the coil, a third of
    /// a metre from the marker, the overshoot is millimetres. The demo's nods peak at 2.4 (the
    /// irregular trace's excess over the oracle, mean of seeds 1–4: 0.450 mm RMS at 10 and at
    /// 50, where it never binds, 0.442 at 5, 0.444 at 3; the nods' alike at all four).
    pub max_angular_accel_rad_s2: f64,
    /// Blend in a prediction learned online from the head's own recent motion, by the share
    /// its measured error earns against the filter's (see [`crate::learned`]).
    pub learned: bool,
    /// The learned prediction's grid, s: its history is `learned::LAGS` steps, its horizons
    /// `learned::STEPS` steps. About the tracker's period.
    pub learned_period_s: f64,
    /// Forgetting factor of its regression per step (memory `1 / (1 − this)` steps).
    pub learned_forgetting: f64,
}

impl Default for PredictorConfig {
    fn default() -> Self {
        Self {
            model: MotionModel::Ca,
            position_noise_m: 1e-4,
            rotation_noise_rad: 1e-3,
            accel_noise: 3e-4,
            angular_accel_noise: 0.03,
            jerk_noise: 0.1,
            angular_jerk_noise: 0.5,
            adaptive: true,
            adapt_range: 30.0,
            max_horizon_s: 0.3,
            accel_horizon_s: 0.07,
            velocity_shrink: 0.5,
            max_accel_m_s2: 2.0,
            max_angular_accel_rad_s2: 5.0,
            learned: true,
            learned_period_s: 1.0 / 60.0,
            learned_forgetting: 0.999,
        }
    }
}

impl PredictorConfig {
    /// The filter before issue 16: constant velocity, fixed noise, 150 ms horizon.
    pub fn constant_velocity() -> Self {
        Self {
            model: MotionModel::Cv,
            adaptive: false,
            learned: false,
            max_horizon_s: 0.15,
            ..Self::default()
        }
    }

    /// Checks every value's range; the error names the first key out of range.
    pub fn validate(&self) -> Result<(), crate::ParamError> {
        for (key, value, positive) in [
            ("position_noise_m", self.position_noise_m, true),
            ("rotation_noise_rad", self.rotation_noise_rad, true),
            ("accel_noise", self.accel_noise, true),
            ("angular_accel_noise", self.angular_accel_noise, true),
            ("jerk_noise", self.jerk_noise, true),
            ("angular_jerk_noise", self.angular_jerk_noise, true),
            ("max_horizon_s", self.max_horizon_s, false),
            ("accel_horizon_s", self.accel_horizon_s, false),
            ("velocity_shrink", self.velocity_shrink, false),
            ("max_accel_m_s2", self.max_accel_m_s2, true),
            (
                "max_angular_accel_rad_s2",
                self.max_angular_accel_rad_s2,
                true,
            ),
        ] {
            let ok = value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 };
            if !ok {
                return Err(crate::ParamError {
                    key,
                    value,
                    problem: if positive {
                        "must be finite and > 0"
                    } else {
                        "must be finite and ≥ 0"
                    },
                });
            }
        }
        if !(self.learned_period_s.is_finite() && self.learned_period_s > 0.0) {
            return Err(crate::ParamError {
                key: "learned_period_s",
                value: self.learned_period_s,
                problem: "must be finite and > 0",
            });
        }
        if !(self.learned_forgetting > 0.9 && self.learned_forgetting <= 1.0) {
            return Err(crate::ParamError {
                key: "learned_forgetting",
                value: self.learned_forgetting,
                problem: "must be in (0.9, 1]",
            });
        }
        if !(self.adapt_range.is_finite() && self.adapt_range >= 1.0) {
            return Err(crate::ParamError {
                key: "adapt_range",
                value: self.adapt_range,
                problem: "must be finite and ≥ 1",
            });
        }
        Ok(())
    }
}

/// One 3-state (value, rate, acceleration) covariance, shared by three axes. The constant-velocity
/// model is the same filter with the acceleration pinned at zero.
#[derive(Debug, Clone, Copy)]
struct Cov3 {
    p: [[f64; 3]; 3],
}

impl Cov3 {
    fn initial(r: f64, model: MotionModel) -> Self {
        let mut p = [[0.0; 3]; 3];
        p[0][0] = r;
        p[1][1] = 0.01;
        if model == MotionModel::Ca {
            p[2][2] = 1.0;
        }
        Self { p }
    }

    /// The transition over `dt`.
    fn f(dt: f64, model: MotionModel) -> [[f64; 3]; 3] {
        match model {
            MotionModel::Ca => [[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]],
            MotionModel::Cv => [[1.0, dt, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]],
        }
    }

    /// The process noise over `dt` for density `q` (white jerk, or white acceleration).
    fn q(dt: f64, q: f64, model: MotionModel) -> [[f64; 3]; 3] {
        let (d2, d3) = (dt * dt, dt * dt * dt);
        match model {
            MotionModel::Ca => [
                [q * d3 * d2 / 20.0, q * d2 * d2 / 8.0, q * d3 / 6.0],
                [q * d2 * d2 / 8.0, q * d3 / 3.0, q * d2 / 2.0],
                [q * d3 / 6.0, q * d2 / 2.0, q * dt],
            ],
            MotionModel::Cv => [
                [q * d3 / 3.0, q * d2 / 2.0, 0.0],
                [q * d2 / 2.0, q * dt, 0.0],
                [0.0, 0.0, 0.0],
            ],
        }
    }

    /// `F P Fᵀ + Q`.
    fn propagated(&self, dt: f64, q: f64, model: MotionModel) -> [[f64; 3]; 3] {
        let f = Self::f(dt, model);
        let qm = Self::q(dt, q, model);
        let p = &self.p;
        let fp: [[f64; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| f[i][k] * p[k][j]).sum())
        });
        std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| fp[i][k] * f[j][k]).sum::<f64>() + qm[i][j])
        })
    }

    fn propagate(&mut self, dt: f64, q: f64, model: MotionModel) {
        self.p = self.propagated(dt, q, model);
    }

    /// Kalman gains for a value measurement with variance `r`, and the innovation variance;
    /// updates the covariance.
    fn update(&mut self, r: f64) -> ([f64; 3], f64) {
        let s = self.p[0][0] + r;
        let k = [self.p[0][0] / s, self.p[1][0] / s, self.p[2][0] / s];
        let row = self.p[0];
        for (i, ki) in k.iter().enumerate() {
            for (j, rj) in row.iter().enumerate() {
                self.p[i][j] -= ki * rj;
            }
        }
        (k, s)
    }
}

/// Motion modes of the interacting-multiple-model filter: the same model at process noise
/// `1/adapt_range`, 1 and `adapt_range` times the configured density (a still head, a moving one,
/// an onset or a reversal).
const MODES: usize = 3;
/// How long a mode is expected to last, s: the chance of a switch between two samples `dt`
/// apart is `1 − exp(−dt / MODE_DWELL_S)`.
const MODE_DWELL_S: f64 = 0.5;

/// One mode's estimate: its value relative to the channel's shared value, its rates, and its
/// covariance.
#[derive(Debug, Clone, Copy)]
struct Mode {
    offset: Vector3<f64>,
    rate: Vector3<f64>,
    accel: Vector3<f64>,
    cov: Cov3,
}

impl Mode {
    fn parts(&self) -> [Vector3<f64>; 3] {
        [self.offset, self.rate, self.accel]
    }
}

/// One channel (position, or orientation as an error state): its rates and covariance.
///
/// With `adaptive`, an interacting-multiple-model (IMM) filter: a bank of [`MODES`] filters at
/// different process noise, mixed at each sample by their modes' probabilities, each mode's
/// probability following how well it predicted the sample. A still head is smoothed by the
/// quiet mode; an onset is seen by the first sample that the quiet mode could not have produced,
/// and the loud mode, which followed it all along, takes over within a sample or two (a single
/// adaptive noise scale needed a third of a second to rise thirtyfold). Without `adaptive`, the
/// middle mode alone: a plain Kalman filter.
#[derive(Debug, Clone, Copy)]
struct Channel {
    /// The modes' moment-matched combination: what the channel extrapolates with.
    rate: Vector3<f64>,
    accel: Vector3<f64>,
    cov: Cov3,
    /// The process-noise scale of the uncertainty's filter (1 = as configured).
    sigma_scale: f64,
    /// Running mean of the normalised innovation squared (1 when σ is right).
    nis: f64,
    /// The covariance of one filter at `sigma_scale`: the uncertainty the safety filter keeps the
    /// coil away by. The modes' own mixture follows every sample's verdict (its 200 ms σ on
    /// nods swung between 9 and 24 mrad from one fifth of a second to the next): a standoff
    /// that swings moves the coil for nothing, and over a coasted dropout it grew past 5 mm.
    sigma_cov: Cov3,
    modes: [Mode; MODES],
    mu: [f64; MODES],
}

/// The process-noise scale of mode `j` for adaptation range `range`.
fn mode_scale(j: usize, range: f64) -> f64 {
    range.powi(j as i32 - 1)
}

/// Adds `w` times the outer product of `d` (shared by three axes: its mean over them) to `p`.
fn add_spread(p: &mut [[f64; 3]; 3], w: f64, d: &[Vector3<f64>; 3]) {
    for a in 0..3 {
        for b in 0..3 {
            p[a][b] += w * d[a].dot(&d[b]) / 3.0;
        }
    }
}

/// The mean (value offset, rate, acceleration) and covariance of the `active` modes weighed by
/// `w` (summing to 1), the spread of their means included.
fn moments(
    modes: &[Mode; MODES],
    w: &[f64; MODES],
    active: &[usize],
) -> ([Vector3<f64>; 3], [[f64; 3]; 3]) {
    let mean = |part: usize| -> Vector3<f64> {
        active.iter().map(|&i| modes[i].parts()[part] * w[i]).sum()
    };
    let x = [mean(0), mean(1), mean(2)];
    let mut p = [[0.0; 3]; 3];
    for &i in active {
        let parts = modes[i].parts();
        let d = [parts[0] - x[0], parts[1] - x[1], parts[2] - x[2]];
        for (row, src) in p.iter_mut().zip(&modes[i].cov.p) {
            for (v, s) in row.iter_mut().zip(src) {
                *v += w[i] * s;
            }
        }
        add_spread(&mut p, w[i], &d);
    }
    (x, p)
}

impl Channel {
    fn new(r: f64, model: MotionModel, adaptive: bool) -> Self {
        let mode = Mode {
            offset: Vector3::zeros(),
            rate: Vector3::zeros(),
            accel: Vector3::zeros(),
            cov: Cov3::initial(r, model),
        };
        Self {
            rate: Vector3::zeros(),
            accel: Vector3::zeros(),
            cov: mode.cov,
            sigma_scale: 1.0,
            nis: 1.0,
            sigma_cov: mode.cov,
            modes: [mode; MODES],
            mu: if adaptive {
                [1.0 / MODES as f64; MODES]
            } else {
                [0.0, 1.0, 0.0]
            },
        }
    }

    /// Propagates over `dt` (the shared value was moved on by the combined rates before), takes
    /// the innovation `y` (measured − shared predicted value), returns the correction of the
    /// shared value.
    fn step(
        &mut self,
        dt: f64,
        y: &Vector3<f64>,
        (r, q, max_accel): (f64, f64, f64),
        c: &PredictorConfig,
    ) -> Vector3<f64> {
        let active: &[usize] = if c.adaptive { &[0, 1, 2] } else { &[1] };
        let prior = self.mix(dt, active, c);
        // Each mode's update, and how likely it made the sample.
        let mut log_l = [f64::NEG_INFINITY; MODES];
        for &j in active {
            let m = &mut self.modes[j];
            m.cov
                .propagate(dt, q * mode_scale(j, c.adapt_range), c.model);
            let (k, s) = m.cov.update(r);
            let yj = y - m.offset;
            log_l[j] = -1.5 * s.ln() - yj.norm_squared() / (2.0 * s);
            m.offset += yj * k[0];
            m.rate += yj * k[1];
            if c.model == MotionModel::Ca {
                m.accel += yj * k[2];
                // A gap in the samples (a dropout) makes the first innovation after it look
                // like a burst of acceleration; no head accelerates beyond the bound.
                let n = m.accel.norm();
                if n > max_accel {
                    m.accel *= max_accel / n;
                }
            }
        }
        self.weigh(active, &prior, &log_l);
        // The combination, moment-matched; the shared value moves to its value.
        let (x, p) = moments(&self.modes, &self.mu, active);
        for &j in active {
            self.modes[j].offset -= x[0];
        }
        self.rate = x[1];
        self.accel = x[2];
        self.cov.p = p;
        self.calibrate(dt, y, (r, q), c);
        x[0]
    }

    /// The uncertainty's own filter: one covariance whose process noise is scaled by the
    /// normalised innovation squared of the combined prediction, so its σ matches the errors
    /// the prediction makes (on noisy nods within 10 % at 30–100 ms).
    fn calibrate(&mut self, dt: f64, y: &Vector3<f64>, (r, q): (f64, f64), c: &PredictorConfig) {
        self.sigma_cov.propagate(dt, q * self.sigma_scale, c.model);
        let (_, s) = self.sigma_cov.update(r);
        if c.adaptive {
            // Normalised innovation squared per axis: 1 on average when σ is right. Its running
            // mean (not a single sample, which is χ²-distributed and mostly below 1) steers the
            // scale, in small steps so one outlier moves it little.
            let nis = (y.norm_squared() / (3.0 * s)).min(25.0);
            self.nis += 0.05 * (nis - self.nis);
            let lo = 1.0 / c.adapt_range;
            self.sigma_scale = (self.sigma_scale * self.nis.powf(0.05)).clamp(lo, c.adapt_range);
        }
    }

    /// The IMM's mixing: each mode starts from the blend of all, weighed by the chance it came
    /// from each, moved on over `dt` relative to the shared value (which went on at the
    /// combined rates). Returns each mode's prior probability.
    fn mix(&mut self, dt: f64, active: &[usize], c: &PredictorConfig) -> [f64; MODES] {
        let switch = if c.adaptive {
            1.0 - (-dt / MODE_DWELL_S).exp()
        } else {
            0.0
        };
        let pi = |i: usize, j: usize| {
            if i == j {
                1.0 - switch
            } else {
                switch / (MODES - 1) as f64
            }
        };
        let before = self.modes;
        let mut prior = [0.0; MODES];
        for &j in active {
            prior[j] = active.iter().map(|&i| pi(i, j) * self.mu[i]).sum();
            if prior[j] <= 0.0 {
                continue;
            }
            let w: [f64; MODES] = std::array::from_fn(|i| pi(i, j) * self.mu[i] / prior[j]);
            let (x0, p0) = moments(&before, &w, active);
            let m = &mut self.modes[j];
            m.offset = x0[0] + (x0[1] - self.rate) * dt + (x0[2] - self.accel) * (0.5 * dt * dt);
            m.rate = x0[1] + x0[2] * dt;
            m.accel = if c.model == MotionModel::Ca {
                x0[2]
            } else {
                Vector3::zeros()
            };
            m.cov.p = p0;
        }
        prior
    }

    /// The modes' probabilities after a sample: each prior times how likely its mode made the
    /// sample (`log_l`), normalised.
    fn weigh(&mut self, active: &[usize], prior: &[f64; MODES], log_l: &[f64; MODES]) {
        let best = log_l.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mut total = 0.0;
        for &j in active {
            self.mu[j] = prior[j] * (log_l[j] - best).exp();
            total += self.mu[j];
        }
        if !(total.is_finite() && total > 0.0) {
            // No mode could be scored: start them level.
            for &j in active {
                self.mu[j] = 1.0 / active.len() as f64;
            }
            return;
        }
        for &j in active {
            // A floor, so a mode unlikely for minutes can still be found within a sample.
            self.mu[j] = (self.mu[j] / total).max(1e-6);
        }
        let norm: f64 = active.iter().map(|&j| self.mu[j]).sum();
        active.iter().for_each(|&j| self.mu[j] /= norm);
    }

    /// The modes' process-noise scale, their probabilities' geometric mean (1 = as configured).
    fn typical_scale(&self, range: f64) -> f64 {
        self.mu
            .iter()
            .enumerate()
            .filter(|(_, mu)| **mu > 0.0)
            .map(|(j, mu)| mu * mode_scale(j, range).ln())
            .sum::<f64>()
            .exp()
    }

    /// The rate and acceleration to extrapolate with (shrunk by their own uncertainty).
    fn shrunk(&self, c: &PredictorConfig) -> (Vector3<f64>, Vector3<f64>) {
        let shrink = |v: &Vector3<f64>, var: f64| {
            let s2 = v.norm_squared();
            let noise = c.velocity_shrink * 3.0 * var;
            if s2 > 0.0 { s2 / (s2 + noise) } else { 0.0 }
        };
        (
            self.rate * shrink(&self.rate, self.cov.p[1][1]),
            self.accel * shrink(&self.accel, self.cov.p[2][2]),
        )
    }

    /// The displacement after `h` (s).
    fn displacement(&self, h: f64, c: &PredictorConfig) -> Vector3<f64> {
        let (v, a) = self.shrunk(c);
        let ha = h.min(c.accel_horizon_s);
        // Accelerate for `ha`, then carry on at the velocity reached.
        v * h + a * (ha * (h - 0.5 * ha))
    }

    /// 1σ per axis of the value extrapolated by `h`.
    fn sigma(&self, h: f64, q: f64, model: MotionModel) -> f64 {
        self.sigma_cov.propagated(h, q * self.sigma_scale, model)[0][0]
            .max(0.0)
            .sqrt()
    }
}

/// The filter's pose at `t` from its state at `t0` (`now`: time, position, orientation):
/// rates within their own uncertainty shrunk towards zero (a Wiener-type gain), so a still
/// head's noise-driven velocity is not extrapolated and a moving head's is, in full.
fn extrapolate(
    c: &PredictorConfig,
    (t0, p, q): (f64, Vector3<f64>, UnitQuaternion<f64>),
    (pos, rot): (&Channel, &Channel),
    t: f64,
) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let h = (t - t0).clamp(0.0, c.max_horizon_s);
    (
        p + pos.displacement(h, c),
        UnitQuaternion::from_scaled_axis(rot.displacement(h, c)) * q,
    )
}

/// The filter.
#[derive(Debug, Clone)]
pub struct PosePredictor {
    config: PredictorConfig,
    t: f64,
    p: Vector3<f64>,
    q: UnitQuaternion<f64>,
    pos: Channel,
    rot: Channel,
    initialised: bool,
    learned: Learned,
}

impl PosePredictor {
    /// An empty filter.
    pub fn new(config: PredictorConfig) -> Self {
        Self {
            config,
            t: 0.0,
            p: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            pos: Channel::new(1.0, config.model, config.adaptive),
            rot: Channel::new(1.0, config.model, config.adaptive),
            initialised: false,
            learned: Learned::new(
                config.learned_period_s,
                config.learned_forgetting,
                (config.position_noise_m, config.rotation_noise_rad),
            ),
        }
    }

    /// The settings.
    pub fn config(&self) -> &PredictorConfig {
        &self.config
    }

    /// Forgets everything (after a dropout longer than the filter should bridge).
    pub fn reset(&mut self) {
        *self = Self::new(self.config);
    }

    /// Whether a measurement has been taken.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// Time of the newest measurement, s.
    pub fn time_s(&self) -> f64 {
        self.t
    }

    /// Estimated linear velocity (m/s) and angular velocity (rad/s, world frame) at the newest
    /// measurement.
    pub fn velocity(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.pos.rate, self.rot.rate)
    }

    /// The process-noise scales the modes' probabilities arrive at (their geometric mean;
    /// position, rotation; 1 = as configured).
    pub fn noise_scale(&self) -> (f64, f64) {
        let range = self.config.adapt_range;
        (self.pos.typical_scale(range), self.rot.typical_scale(range))
    }

    fn densities(&self) -> (f64, f64) {
        let c = &self.config;
        match c.model {
            MotionModel::Ca => (c.jerk_noise, c.angular_jerk_noise),
            MotionModel::Cv => (c.accel_noise, c.angular_accel_noise),
        }
    }

    /// Takes a measurement of `tracker_from_marker` acquired at `t` (s). Measurements older than
    /// the newest one are ignored.
    pub fn update(&mut self, t: f64, pose: &Isometry3<f64>) {
        let pm = pose.translation.vector;
        let qm = pose.rotation;
        let c = self.config;
        if !self.initialised {
            self.p = pm;
            self.q = qm;
            self.pos = Channel::new(c.position_noise_m.powi(2), c.model, c.adaptive);
            self.rot = Channel::new(c.rotation_noise_rad.powi(2), c.model, c.adaptive);
            self.t = t;
            self.initialised = true;
            self.learn(t, pm, qm);
            return;
        }
        let dt = t - self.t;
        if dt <= 0.0 {
            return;
        }
        let (qp, qr) = self.densities();
        // Predict to t (the full model, unshrunk: this is the filter, not the extrapolation);
        // each channel moves its rates on in its step.
        self.p += self.pos.rate * dt + self.pos.accel * (0.5 * dt * dt);
        self.q =
            UnitQuaternion::from_scaled_axis(self.rot.rate * dt + self.rot.accel * (0.5 * dt * dt))
                * self.q;
        // Update.
        let y = pm - self.p;
        self.p += self.pos.step(
            dt,
            &y,
            (c.position_noise_m.powi(2), qp, c.max_accel_m_s2),
            &c,
        );
        let r = (qm * self.q.inverse()).scaled_axis();
        let corr = self.rot.step(
            dt,
            &r,
            (c.rotation_noise_rad.powi(2), qr, c.max_angular_accel_rad_s2),
            &c,
        );
        self.q = UnitQuaternion::from_scaled_axis(corr) * self.q;
        self.t = t;
        self.learn(t, pm, qm);
    }

    /// Lays the measurement into the learned prediction's history, which scores the filter's
    /// predictions from here.
    fn learn(&mut self, t: f64, pm: Vector3<f64>, qm: UnitQuaternion<f64>) {
        if !self.config.learned {
            return;
        }
        let (c, t0, p, q, pos, rot) = (&self.config, self.t, self.p, self.q, &self.pos, &self.rot);
        self.learned
            .update(t, pm, qm, |tt| extrapolate(c, (t0, p, q), (pos, rot), tt));
    }

    /// The pose extrapolated to time `t` (clamped to `max_horizon_s` past the newest
    /// measurement). `None` before the first measurement.
    pub fn predict(&self, t: f64) -> Option<Isometry3<f64>> {
        if !self.initialised {
            return None;
        }
        let c = &self.config;
        let t = self.t + (t - self.t).clamp(0.0, c.max_horizon_s);
        let now = (self.t, self.p, self.q);
        let filter = |tt: f64| extrapolate(c, now, (&self.pos, &self.rot), tt);
        let (mut p, mut q) = filter(t);
        if c.learned
            && let Some(l) = self.learned.predict(t, filter)
        {
            // Each channel leans towards the learned pose by the share its record earned.
            p += (l.p - p) * l.w_pos;
            q = UnitQuaternion::from_scaled_axis((l.q * q.inverse()).scaled_axis() * l.w_rot) * q;
        }
        Some(Isometry3::from_parts(Translation3::from(p), q))
    }

    /// The uncertainty (1σ per axis) of [`Self::predict`] at `t`: position (m) and rotation
    /// (rad). It grows with the horizon, so a coasted dropout widens the standoff.
    pub fn sigma(&self, t: f64) -> (f64, f64) {
        if !self.initialised {
            return (f64::INFINITY, f64::INFINITY);
        }
        let h = (t - self.t).max(0.0);
        let (qp, qr) = self.densities();
        (
            self.pos.sigma(h, qp, self.config.model),
            self.rot.sigma(h, qr, self.config.model),
        )
    }

    /// The filtered pose at the newest measurement's time.
    pub fn estimate(&self) -> Option<Isometry3<f64>> {
        self.predict(self.t)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn a_bad_noise_value_is_named() {
        assert!(PredictorConfig::default().validate().is_ok());
        let bad = PredictorConfig {
            angular_accel_noise: -1.0,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "angular_accel_noise");
        let bad = PredictorConfig {
            max_horizon_s: f64::NAN,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "max_horizon_s");
    }
    use mocomp_geom::{rotation_error, translation_error};

    fn pose_at(t: f64) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.05 * t, -0.02 * t, 0.8),
            Vector3::new(0.0, 0.3 * t, 0.1 * t),
        )
    }

    #[test]
    fn constant_velocity_motion_is_predicted_exactly_without_noise() {
        let exact = PredictorConfig {
            velocity_shrink: 0.0,
            ..PredictorConfig::default()
        };
        let mut f = PosePredictor::new(exact);
        for k in 0..120 {
            let t = k as f64 / 60.0;
            f.update(t, &pose_at(t));
        }
        let t_last = 119.0 / 60.0;
        let p = f.predict(t_last + 0.05).unwrap();
        let truth = pose_at(t_last + 0.05);
        assert!(
            translation_error(&p, &truth) < 1e-5,
            "{}",
            translation_error(&p, &truth)
        );
        assert!(rotation_error(&p, &truth) < 1e-4);
        // Without prediction the pose would be 2.7 mm and 0.016 rad off.
        assert!(translation_error(&f.estimate().unwrap(), &truth) > 2e-3);
        // The default shrinkage keeps most of a moving head's prediction (54 mm/s here: 0.8 mm
        // left of the 2.7 mm lag).
        let mut g = PosePredictor::new(PredictorConfig::default());
        for k in 0..120 {
            let t = k as f64 / 60.0;
            g.update(t, &pose_at(t));
        }
        let p = g.predict(t_last + 0.05).unwrap();
        assert!(
            translation_error(&p, &truth) < 1.0e-3,
            "{}",
            translation_error(&p, &truth)
        );
    }

    #[test]
    fn a_still_head_noise_is_not_extrapolated() {
        // Seeded noise 0.1 mm on a still pose: the 60 ms prediction stays within the noise.
        let mut f = PosePredictor::new(PredictorConfig::default());
        let mut x = 0x1234_5678_u64;
        let mut noise = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x as f64 / u64::MAX as f64 - 0.5) * 3.46e-4 // uniform, σ = 0.1 mm
        };
        let truth = pose_at(0.0);
        let mut worst: f64 = 0.0;
        for k in 0..600 {
            let t = k as f64 / 60.0;
            let mut m = truth;
            m.translation.vector += Vector3::new(noise(), noise(), noise());
            f.update(t, &m);
            if k > 60 {
                worst = worst.max(translation_error(&f.predict(t + 0.06).unwrap(), &truth));
            }
        }
        assert!(worst < 0.6e-3, "{worst}");
    }

    #[test]
    fn horizon_is_clamped_and_stale_measurements_ignored() {
        let mut f = PosePredictor::new(PredictorConfig::default());
        assert!(f.predict(1.0).is_none());
        for k in 0..60 {
            let t = k as f64 / 60.0;
            f.update(t, &pose_at(t));
        }
        let t_last = 59.0 / 60.0;
        let far = f.predict(t_last + 10.0).unwrap();
        let clamp = f
            .predict(t_last + PredictorConfig::default().max_horizon_s)
            .unwrap();
        assert_eq!(far, clamp);
        let before = f.estimate().unwrap();
        f.update(0.5, &Isometry3::identity());
        assert_eq!(f.estimate().unwrap(), before);
    }

    fn accelerating(t: f64) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.02 * t + 0.15 * t * t, -0.01 * t, 0.8 - 0.1 * t * t),
            // About a fixed axis, so the angular acceleration is constant too.
            Vector3::new(0.0, 0.8, 0.6) * (0.2 * t + 0.5 * t * t),
        )
    }

    #[test]
    fn constant_acceleration_is_predicted_where_constant_velocity_overshoots() {
        let exact = |model| PredictorConfig {
            model,
            velocity_shrink: 0.0,
            adaptive: false,
            accel_horizon_s: 1.0,
            ..PredictorConfig::default()
        };
        let mut ca = PosePredictor::new(exact(MotionModel::Ca));
        let mut cv = PosePredictor::new(exact(MotionModel::Cv));
        for k in 0..120 {
            let t = k as f64 / 60.0;
            ca.update(t, &accelerating(t));
            cv.update(t, &accelerating(t));
        }
        let t = 119.0 / 60.0 + 0.08;
        let truth = accelerating(t);
        let e_ca = translation_error(&ca.predict(t).unwrap(), &truth);
        let e_cv = translation_error(&cv.predict(t).unwrap(), &truth);
        // ½·a·h² is 0.6 mm here; the CV filter also lags in velocity.
        assert!(e_ca < 5e-5, "{e_ca}");
        assert!(e_cv > 5e-4, "{e_cv}");
        assert!(rotation_error(&ca.predict(t).unwrap(), &truth) < 1e-4);
    }

    #[test]
    fn the_uncertainty_grows_with_the_horizon() {
        for model in [MotionModel::Ca, MotionModel::Cv] {
            let mut f = PosePredictor::new(PredictorConfig {
                model,
                ..PredictorConfig::default()
            });
            assert_eq!(f.sigma(0.0).0, f64::INFINITY);
            for k in 0..60 {
                let t = k as f64 / 60.0;
                f.update(t, &pose_at(t));
            }
            let t = f.time_s();
            let (p0, r0) = f.sigma(t);
            let (p1, r1) = f.sigma(t + 0.05);
            let (p2, r2) = f.sigma(t + 0.15);
            // At the newest sample: below the tracker's own noise (it was filtered).
            assert!(p0 < 1e-4 && r0 < 1e-3, "{p0} {r0}");
            assert!(p0 < p1 && p1 < p2, "{p0} {p1} {p2}");
            assert!(r0 < r1 && r1 < r2, "{r0} {r1} {r2}");
        }
    }

    /// Seeded uniform noise of unit standard deviation (xorshift).
    fn unit_noise(mut x: u64) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x as f64 / u64::MAX as f64 - 0.5) * 3.46
        }
    }

    /// The demo's fast nods about the marker: sway, turn and nod (peaks 80 mm/s, 34°/s).
    fn nods(t: f64) -> Isometry3<f64> {
        let x = 0.02 * (4.0 * t).sin();
        Isometry3::new(
            Vector3::new(x, 0.5 * x, 0.0),
            Vector3::new(0.0, 0.08 * (2.8 * t).sin(), 0.15 * (4.0 * t).sin()),
        )
    }

    /// One sample of the tracker's noise: 0.1 mm and 1 mrad per axis.
    fn tracker_noise(unit: &mut impl FnMut() -> f64) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(unit(), unit(), unit()) * 1e-4,
            Vector3::new(unit(), unit(), unit()) * 1e-3,
        )
    }

    #[test]
    fn the_process_noise_adapts_up_for_a_nodding_head_and_down_for_a_still_one() {
        let mut unit = unit_noise(0x9e37_79b9);
        let mut noise = move || unit() * 1e-4;
        let run = |amplitude: f64, noise: &mut dyn FnMut() -> f64| {
            let mut f = PosePredictor::new(PredictorConfig::default());
            for k in 0..1200 {
                let t = k as f64 / 60.0;
                let mut m = Isometry3::new(
                    Vector3::new(amplitude * (4.0 * t).sin(), 0.0, 0.8),
                    Vector3::zeros(),
                );
                m.translation.vector += Vector3::new(noise(), noise(), noise());
                f.update(t, &m);
            }
            f.noise_scale().0
        };
        let fast = run(0.022, &mut noise);
        let still = run(0.0, &mut noise);
        assert!(fast > 2.0 * still, "fast {fast}, still {still}");
        assert!(still < 1.0, "{still}");
    }

    #[test]
    fn an_onset_after_a_still_spell_is_followed_within_a_few_samples() {
        // Three seconds at rest (the quiet mode earns every sample), then off at 40 mm/s and
        // 30°/s at once, as the recorded head in examples/ does. The prediction 58 ms ahead,
        // 100 ms after the onset: a single noise scale adapting upwards took a third of a
        // second and was still 1.6 mm off here (the IMM: 0.4).
        let onset = 3.0;
        let pose = |t: f64| {
            let s = (t - onset).max(0.0);
            Isometry3::new(
                Vector3::new(0.04 * s, 0.0, 0.8),
                Vector3::new(0.0, 0.0, 0.52 * s),
            )
        };
        let mut unit = unit_noise(0x00dd_ba11);
        let mut f = PosePredictor::new(PredictorConfig {
            learned: false,
            ..PredictorConfig::default()
        });
        let coil = mocomp_geom::nalgebra::Point3::new(0.0, 0.0, 0.113);
        let mut error_at = |until: f64, f: &mut PosePredictor| {
            let mut last = 0.0;
            for k in 0..=(until * 60.0).round() as usize {
                let t = k as f64 / 60.0;
                if t <= f.time_s() && f.is_initialised() {
                    continue;
                }
                let noise = tracker_noise(&mut unit);
                f.update(t, &(pose(t) * noise));
                last = t;
            }
            (f.predict(last + 0.058).unwrap() * coil - pose(last + 0.058) * coil).norm()
        };
        let still = error_at(onset - 0.1, &mut f);
        assert!(still < 3e-4, "at rest: {still}");
        let quiet = f.noise_scale().0;
        error_at(onset, &mut f);
        let after = error_at(onset + 0.1, &mut f);
        assert!(after < 1.0e-3, "100 ms after the onset: {after}");
        // The loud mode has taken over.
        assert!(
            f.noise_scale().0 > 10.0 * quiet,
            "{} {quiet}",
            f.noise_scale().0
        );
    }

    #[test]
    fn the_uncertainty_matches_the_errors_the_prediction_makes_on_noisy_nods() {
        // The safety filter keeps the coil 2σ further off: a σ too small brings it closer
        // than the prediction deserves, one too large (the modes' mixture) backs it off for
        // nothing. At the horizons the loop predicts over, within a fifth either way.
        let pose_at = |t: f64| Isometry3::translation(0.0, 0.0, 0.8) * nods(t);
        let mut unit = unit_noise(0x1234_5678);
        for h in [0.03, 0.06, 0.1] {
            let mut f = PosePredictor::new(PredictorConfig {
                learned: false,
                ..PredictorConfig::default()
            });
            let (mut err, mut sigma) = ([0.0; 2], [0.0; 2]);
            for k in 0..1800 {
                let t = k as f64 / 60.0;
                let noise = tracker_noise(&mut unit);
                f.update(t, &(pose_at(t) * noise));
                if k > 300 {
                    let (p, truth) = (f.predict(t + h).unwrap(), pose_at(t + h));
                    err[0] +=
                        (p.translation.vector - truth.translation.vector).norm_squared() / 3.0;
                    err[1] += p.rotation.angle_to(&truth.rotation).powi(2) / 3.0;
                    let (sp, sr) = f.sigma(t + h);
                    sigma[0] += sp * sp;
                    sigma[1] += sr * sr;
                }
            }
            for i in 0..2 {
                let ratio = (sigma[i] / err[i]).sqrt();
                assert!(
                    (0.8..1.25).contains(&ratio),
                    "{h} s, channel {i}: σ/error {ratio}"
                );
            }
        }
    }

    /// RMS error (mm) of the prediction 58 ms ahead at a point 113 mm from the marker (the
    /// coil), over `from`..`to` s, for a head `pose(t)` seen at 60 Hz with 0.1 mm and 1 mrad of
    /// seeded noise per axis.
    fn rms_58ms(
        cfg: PredictorConfig,
        pose: &dyn Fn(f64) -> Isometry3<f64>,
        from: f64,
        to: f64,
    ) -> f64 {
        let mut unit = unit_noise(0x2545_f491_4f6c_dd1d);
        let coil = mocomp_geom::nalgebra::Point3::new(0.0, 0.0, 0.113);
        let mut f = PosePredictor::new(cfg);
        let (mut sum, mut n) = (0.0, 0);
        for k in 0..(to * 60.0) as usize {
            let t = k as f64 / 60.0;
            let noise = tracker_noise(&mut unit);
            f.update(t, &(noise * pose(t)));
            if t >= from {
                let e = (f.predict(t + 0.058).unwrap() * coil - pose(t + 0.058) * coil).norm();
                sum += e * e;
                n += 1;
            }
        }
        (sum / n as f64).sqrt() * 1e3
    }

    /// [`rms_58ms`] with the default predictor, and with the filter alone.
    fn learned_and_filter(pose: &dyn Fn(f64) -> Isometry3<f64>, from: f64, to: f64) -> (f64, f64) {
        let alone = PredictorConfig {
            learned: false,
            ..Default::default()
        };
        (
            rms_58ms(PredictorConfig::default(), pose, from, to),
            rms_58ms(alone, pose, from, to),
        )
    }

    #[test]
    fn the_learned_prediction_follows_nods_closer_than_the_filter_alone() {
        let (learned, filter) = learned_and_filter(&nods, 5.0, 30.0);
        assert!(
            learned < 0.75 * filter,
            "learned {learned} mm, filter {filter} mm"
        );
    }

    #[test]
    fn after_a_fast_turn_a_still_head_is_predicted_no_worse_than_by_the_filter() {
        // 0.6 rad in 0.2 s (258°/s at its peak), then still: what was learned from the turn
        // must not be carried into the stillness.
        let turn = |t: f64| {
            let s = ((t - 0.5) / 0.2).clamp(0.0, 1.0);
            Isometry3::new(
                Vector3::zeros(),
                Vector3::new(0.0, 0.0, 0.6 * s * s * (3.0 - 2.0 * s)),
            )
        };
        let (learned, filter) = learned_and_filter(&turn, 1.5, 6.0);
        assert!(
            learned < 1.1 * filter,
            "learned {learned} mm, filter {filter} mm"
        );
    }
}
