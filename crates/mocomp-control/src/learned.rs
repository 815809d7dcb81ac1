//! A prediction learned from the head's own recent motion, beside the Kalman filter's.
//!
//! The filter's polynomial model (constant acceleration) cannot tell a nod that is about to
//! reverse from a head that keeps going: the jerk that reverses it is noise to the model, and at
//! the tracker's noise the filter cannot follow fast enough to see it early. A head's motion has
//! structure a polynomial does not carry (nods and sways repeat, an onset is followed by a
//! deceleration). This learns it online, as respiratory-motion predictors in radiotherapy do
//! (recursive least squares on the recent history): the displacement `STEPS` grid steps ahead
//! as a linear function of the displacements over the last `LAGS` steps, one set of
//! coefficients per horizon, shared by the three axes, forgotten with a time constant of
//! `1 / (1 − forgetting)` steps.
//!
//! What it learns is never trusted blindly: both predictions are scored against the measurements
//! that later arrive for the times they predicted, and [`Learned::predict`] gives the learned one
//! the share its running error earns against the filter's (inverse mean squared error), from
//! `MIN_TRAINED` examples on. At an onset that the history did not foresee its error rises and
//! the filter takes over. Each example counts by its shape, not its size, so seconds of a still
//! head weigh as much as a fast turn.
//!
//! The history is the measurements resampled onto a fixed grid (linear in position, spherical
//! in orientation), so an irregular tracker rate does not disturb the lags; a gap longer than
//! [`GAP_STEPS`] steps starts the history again. No allocation: everything lives in fixed arrays.

use mocomp_geom::nalgebra::{UnitQuaternion, Vector3};

/// Steps of history the prediction is learned from (0.4 s at 60 Hz).
pub const LAGS: usize = 24;
/// Horizons learned, in grid steps (1 … `STEPS`: up to 100 ms at 60 Hz). Beyond them the
/// filter's own extrapolation carries on from the last one.
pub const STEPS: usize = 6;
/// A gap between measurements longer than this many steps restarts the history.
pub const GAP_STEPS: f64 = 3.0;
/// Grid points kept: the features of the oldest training example and its targets.
const CAP: usize = LAGS + STEPS + 1;
/// The running errors' weight of a new example (a time constant of 50 steps).
const ERROR_RATE: f64 = 0.02;
/// The regression's prior: a large covariance, a weak prior towards zero coefficients.
const P0: f64 = 1e3;
/// Examples trained on before the learned prediction may be used (3 s at 60 Hz): a model that
/// has seen half a second of a motion's start has not seen it reverse yet, and its record is
/// too short to say so (on the nods' ramp-in it put the coil 2.8 mm off at the first reversal).
const MIN_TRAINED: u32 = 180;

/// One grid point: the resampled measurement, and what the filter predicted from it.
#[derive(Debug, Clone, Copy)]
struct GridPoint {
    p: Vector3<f64>,
    q: UnitQuaternion<f64>,
    /// The filter's prediction 1 … `STEPS` steps ahead, made when this point was laid.
    filter_p: [Vector3<f64>; STEPS],
    filter_q: [UnitQuaternion<f64>; STEPS],
}

impl GridPoint {
    fn new(p: Vector3<f64>, q: UnitQuaternion<f64>) -> Self {
        Self {
            p,
            q,
            filter_p: [p; STEPS],
            filter_q: [q; STEPS],
        }
    }
}

/// One channel's regression: coefficients per horizon, their shared covariance, and the running
/// errors of the learned and the filter's predictions per horizon.
#[derive(Debug, Clone, Copy)]
struct Regression {
    /// The measurement noise (1σ per axis) below which a motion's scale is not told apart.
    floor: f64,
    theta: [[f64; LAGS]; STEPS],
    p: [[f64; LAGS]; LAGS],
    trained: u32,
    mse_learned: [f64; STEPS],
    mse_filter: [f64; STEPS],
}

impl Regression {
    fn new(floor: f64) -> Self {
        let mut p = [[0.0; LAGS]; LAGS];
        for (i, row) in p.iter_mut().enumerate() {
            row[i] = P0;
        }
        Self {
            floor,
            theta: [[0.0; LAGS]; STEPS],
            p,
            trained: 0,
            mse_learned: [0.0; STEPS],
            mse_filter: [0.0; STEPS],
        }
    }

    /// The learned displacement `m + 1` steps ahead for features `phi` (per axis).
    fn displacement(&self, m: usize, phi: &[Vector3<f64>; LAGS]) -> Vector3<f64> {
        phi.iter()
            .zip(&self.theta[m])
            .fold(Vector3::zeros(), |acc, (f, c)| acc + f * *c)
    }

    /// Scores both predictions on one example (`targets[m]`: the displacement that came
    /// `m + 1` steps later; `filter_err[m]`: the filter's error there), then learns from it.
    fn train(
        &mut self,
        phi: &[Vector3<f64>; LAGS],
        targets: &[Vector3<f64>; STEPS],
        filter_err: &[Vector3<f64>; STEPS],
        forgetting: f64,
    ) {
        let first = self.trained == 0;
        // Each example counts by its shape, not its size: weighed by the inverse of its
        // history's scale (never below the noise), so a fast turn does not outweigh seconds of
        // a still head, whose lesson is that its noise is not to be extrapolated. The errors
        // are scored as they are: an onset the history did not foresee must weigh at once.
        let scale2 = phi.iter().map(|f| f.norm_squared()).sum::<f64>() / (3 * LAGS) as f64
            + self.floor * self.floor;
        let inv = 1.0 / scale2.sqrt();
        for m in 0..STEPS {
            let learned = (targets[m] - self.displacement(m, phi)).norm_squared() / 3.0;
            let filter = filter_err[m].norm_squared() / 3.0;
            if first {
                (self.mse_learned[m], self.mse_filter[m]) = (learned, filter);
            } else {
                self.mse_learned[m] += ERROR_RATE * (learned - self.mse_learned[m]);
                self.mse_filter[m] += ERROR_RATE * (filter - self.mse_filter[m]);
            }
        }
        for axis in 0..3 {
            let x: [f64; LAGS] = std::array::from_fn(|j| phi[j][axis] * inv);
            // P·x as a sum of P's rows (P is symmetric): independent lanes the compiler can
            // vectorise, where a dot product per row is one long chain of additions.
            let mut px = [0.0; LAGS];
            for (row, xj) in self.p.iter().zip(&x) {
                for (acc, pij) in px.iter_mut().zip(row) {
                    *acc += pij * xj;
                }
            }
            let denom = forgetting + (0..LAGS).map(|i| x[i] * px[i]).sum::<f64>();
            if !(denom.is_finite() && denom > 0.0) {
                continue;
            }
            let gain: [f64; LAGS] = std::array::from_fn(|i| px[i] / denom);
            for (theta, target) in self.theta.iter_mut().zip(targets) {
                let e = target[axis] * inv - theta.iter().zip(&x).map(|(t, x)| t * x).sum::<f64>();
                for (t, g) in theta.iter_mut().zip(&gain) {
                    *t += g * e;
                }
            }
            let inv_forgetting = 1.0 / forgetting;
            for (row, g) in self.p.iter_mut().zip(&gain) {
                for (p, pxj) in row.iter_mut().zip(&px) {
                    *p = (*p - g * pxj) * inv_forgetting;
                }
            }
        }
        // A still head excites nothing, and forgetting alone would grow the covariance without
        // bound (and the next movement's first examples would throw the coefficients about):
        // it is held to its prior's size.
        let trace: f64 = (0..LAGS).map(|i| self.p[i][i]).sum();
        if trace > LAGS as f64 * P0 {
            let scale = LAGS as f64 * P0 / trace;
            self.p.iter_mut().flatten().for_each(|p| *p *= scale);
        }
        // P − g·(Px)ᵀ is symmetric but for rounding, which a long run would let grow.
        if self.trained.is_multiple_of(64) {
            for i in 0..LAGS {
                for j in i + 1..LAGS {
                    let v = 0.5 * (self.p[i][j] + self.p[j][i]);
                    (self.p[i][j], self.p[j][i]) = (v, v);
                }
            }
        }
        self.trained = self.trained.saturating_add(1);
    }

    /// The learned prediction's share at fractional horizon `s` steps (0 … `STEPS`): each
    /// prediction weighed by the inverse of its running squared error, so the share is the
    /// filter's error over both; 0 until enough was learned.
    fn weight(&self, s: f64) -> f64 {
        if self.trained < MIN_TRAINED {
            return 0.0;
        }
        let (ml, mf) = lerp_steps(s, &self.mse_learned, &self.mse_filter);
        if ml + mf > 0.0 { mf / (ml + mf) } else { 0.0 }
    }
}

/// Both arrays at fractional horizon `s` steps (index `m` is `m + 1` steps; 0 steps is 0).
fn lerp_steps(s: f64, a: &[f64; STEPS], b: &[f64; STEPS]) -> (f64, f64) {
    let s = s.clamp(1.0, STEPS as f64);
    let m0 = (s.floor() as usize).clamp(1, STEPS);
    let m1 = (m0 + 1).min(STEPS);
    let f = s - m0 as f64;
    (
        a[m0 - 1] * (1.0 - f) + a[m1 - 1] * f,
        b[m0 - 1] * (1.0 - f) + b[m1 - 1] * f,
    )
}

/// The learned prediction of a pose: position and orientation, each its own regression.
#[derive(Debug, Clone)]
pub struct Learned {
    period: f64,
    forgetting: f64,
    grid: [GridPoint; CAP],
    /// Index of the newest grid point, and how many are valid.
    head: usize,
    len: usize,
    /// Time of the newest grid point, and of the newest measurement with its pose.
    grid_t: f64,
    last: Option<(f64, Vector3<f64>, UnitQuaternion<f64>)>,
    pos: Regression,
    rot: Regression,
    /// The last `STEPS + 1` points' features (position, orientation), each computed once when
    /// its point was laid: the loop predicts from the newest several times a cycle, and trains
    /// on the one `STEPS` back; `features_at` is the newest's slot.
    features: [Features; STEPS + 1],
    features_at: usize,
}

/// A point's features: its displacement from each of the `LAGS` points before it, in position
/// and in orientation.
type Features = ([Vector3<f64>; LAGS], [Vector3<f64>; LAGS]);

/// What [`Learned::predict`] returns: the learned pose at a time, and the share each channel
/// has earned in a blend with the filter's.
#[derive(Debug, Clone, Copy)]
pub struct LearnedPrediction {
    /// The learned position.
    pub p: Vector3<f64>,
    /// The learned orientation.
    pub q: UnitQuaternion<f64>,
    /// The learned position's share (0 … 1).
    pub w_pos: f64,
    /// The learned orientation's share (0 … 1).
    pub w_rot: f64,
}

impl Learned {
    /// Nothing learned, a grid of `period` s, forgetting factor `forgetting` (< 1), the
    /// measurement noise (1σ per axis) of position (m) and orientation (rad) in `noise`.
    pub fn new(period: f64, forgetting: f64, noise: (f64, f64)) -> Self {
        let blank = GridPoint::new(Vector3::zeros(), UnitQuaternion::identity());
        Self {
            period,
            forgetting,
            grid: [blank; CAP],
            head: 0,
            len: 0,
            grid_t: 0.0,
            last: None,
            pos: Regression::new(noise.0),
            rot: Regression::new(noise.1),
            features: [([Vector3::zeros(); LAGS], [Vector3::zeros(); LAGS]); STEPS + 1],
            features_at: 0,
        }
    }

    /// The grid point `back` steps before the newest.
    fn at(&self, back: usize) -> &GridPoint {
        &self.grid[(self.head + CAP - back) % CAP]
    }

    /// Takes the measurement at `t`, lays the grid points up to it, learns from each; `filter`
    /// is the filter's prediction (after this measurement) at a time.
    pub fn update(
        &mut self,
        t: f64,
        p: Vector3<f64>,
        q: UnitQuaternion<f64>,
        filter: impl Fn(f64) -> (Vector3<f64>, UnitQuaternion<f64>),
    ) {
        let previous = self.last.replace((t, p, q));
        let Some((t0, p0, q0)) = previous
            .filter(|(t0, ..)| t > *t0 && self.len > 0 && t - *t0 <= GAP_STEPS * self.period)
        else {
            if previous.is_some_and(|(t0, ..)| t <= t0) {
                self.last = previous;
                return;
            }
            // The first measurement, or one after a gap: the history starts here.
            self.len = 0;
            self.grid_t = t;
            self.push(t, p, q, &filter);
            return;
        };
        while self.grid_t + self.period <= t {
            let tg = self.grid_t + self.period;
            let f = (tg - t0) / (t - t0);
            let qg = q0.try_slerp(&q, f, 1e-9).unwrap_or(q);
            self.grid_t = tg;
            self.push(tg, p0.lerp(&p, f), qg, &filter);
        }
    }

    fn push(
        &mut self,
        t: f64,
        p: Vector3<f64>,
        q: UnitQuaternion<f64>,
        filter: &impl Fn(f64) -> (Vector3<f64>, UnitQuaternion<f64>),
    ) {
        let mut g = GridPoint::new(p, q);
        for m in 0..STEPS {
            (g.filter_p[m], g.filter_q[m]) = filter(t + (m + 1) as f64 * self.period);
        }
        self.head = (self.head + 1) % CAP;
        self.grid[self.head] = g;
        self.len = (self.len + 1).min(CAP);
        if self.len > LAGS {
            self.features_at = (self.features_at + 1) % (STEPS + 1);
            self.features[self.features_at] = self.features(0);
        }
        if self.len == CAP {
            self.train();
        }
    }

    /// The features at the point `back` steps before the newest: its displacement from each of
    /// the `LAGS` points before it (position, then orientation as a world-frame rotation
    /// vector).
    fn features(&self, back: usize) -> Features {
        let now = self.at(back);
        (
            std::array::from_fn(|j| now.p - self.at(back + j + 1).p),
            std::array::from_fn(|j| (now.q * self.at(back + j + 1).q.inverse()).scaled_axis()),
        )
    }

    /// Learns from the oldest complete example: its features, and what happened in the
    /// `STEPS` grid steps after it.
    fn train(&mut self) {
        // Laid `STEPS` points ago, with `LAGS` points before it: its features were kept.
        let (fp, fq) = self.features[(self.features_at + 1) % (STEPS + 1)];
        let origin = *self.at(STEPS);
        let ahead = |m: usize| self.at(STEPS - m - 1);
        let tp: [Vector3<f64>; STEPS] = std::array::from_fn(|m| ahead(m).p - origin.p);
        let tq: [Vector3<f64>; STEPS] =
            std::array::from_fn(|m| (ahead(m).q * origin.q.inverse()).scaled_axis());
        let ep: [Vector3<f64>; STEPS] = std::array::from_fn(|m| ahead(m).p - origin.filter_p[m]);
        let eq: [Vector3<f64>; STEPS] =
            std::array::from_fn(|m| (ahead(m).q * origin.filter_q[m].inverse()).scaled_axis());
        self.pos.train(&fp, &tp, &ep, self.forgetting);
        self.rot.train(&fq, &tq, &eq, self.forgetting);
    }

    /// The learned pose at `t` (no earlier than the newest grid point), with each channel's
    /// share, or `None` while the history is too short. Beyond `STEPS` steps it is the pose
    /// learned at `STEPS` steps moved on by the filter's own extrapolation from there (`filter`).
    pub fn predict(
        &self,
        t: f64,
        filter: impl Fn(f64) -> (Vector3<f64>, UnitQuaternion<f64>),
    ) -> Option<LearnedPrediction> {
        if self.len <= LAGS {
            return None;
        }
        let s = ((t - self.grid_t) / self.period).max(0.0);
        let sc = s.min(STEPS as f64);
        let (fp, fq) = &self.features[self.features_at];
        let newest = self.at(0);
        let at = |r: &Regression, phi: &[Vector3<f64>; LAGS]| {
            let m0 = sc.floor() as usize;
            let f = sc - m0 as f64;
            let d = |m: usize| {
                if m == 0 {
                    Vector3::zeros()
                } else {
                    r.displacement(m.min(STEPS) - 1, phi)
                }
            };
            d(m0) * (1.0 - f) + d(m0 + 1) * f
        };
        let mut p = newest.p + at(&self.pos, fp);
        let mut q = UnitQuaternion::from_scaled_axis(at(&self.rot, fq)) * newest.q;
        if s > sc {
            let (p1, q1) = filter(self.grid_t + sc * self.period);
            let (p2, q2) = filter(t);
            p += p2 - p1;
            q = q2 * q1.inverse() * q;
        }
        Some(LearnedPrediction {
            p,
            q,
            w_pos: self.pos.weight(s),
            w_rot: self.rot.weight(s),
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    const PERIOD: f64 = 1.0 / 60.0;

    fn sway(t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        (
            Vector3::new(0.02 * (4.0 * t).sin(), 0.01 * (4.0 * t).sin(), 0.0),
            UnitQuaternion::from_scaled_axis(Vector3::new(
                0.0,
                0.08 * (2.8 * t).sin(),
                0.15 * (4.0 * t).sin(),
            )),
        )
    }

    /// A filter that knows nothing: the pose stays where it was measured last.
    fn frozen(m: &Learned) -> impl Fn(f64) -> (Vector3<f64>, UnitQuaternion<f64>) + use<> {
        let (p, q) = m
            .last
            .map(|(_, p, q)| (p, q))
            .unwrap_or((Vector3::zeros(), UnitQuaternion::identity()));
        move |_| (p, q)
    }

    #[test]
    fn a_repeating_motion_is_learned_and_earns_its_share() {
        let mut m = Learned::new(PERIOD, 0.999, (1e-4, 1e-3));
        for k in 0..600 {
            let t = k as f64 * PERIOD;
            let (p, q) = sway(t);
            let f = frozen(&m);
            m.update(t, p, q, f);
        }
        let t = 599.0 * PERIOD;
        let h = 0.058;
        let pr = m.predict(t + h, frozen(&m)).unwrap();
        let (p, q) = sway(t + h);
        let (p_now, _) = sway(t);
        // The frozen filter is off by the whole motion in 58 ms; the learned one by far less.
        assert!(
            (pr.p - p).norm() < 0.02 * (p - p_now).norm().max(1e-4),
            "{}",
            (pr.p - p).norm()
        );
        assert!(q.angle_to(&pr.q) < 1e-3, "{}", q.angle_to(&pr.q));
        assert!(
            pr.w_pos > 0.9 && pr.w_rot > 0.9,
            "{} {}",
            pr.w_pos,
            pr.w_rot
        );
    }

    #[test]
    fn nothing_is_predicted_before_the_history_is_long_enough_or_after_a_gap() {
        let mut m = Learned::new(PERIOD, 0.999, (1e-4, 1e-3));
        for k in 0..=LAGS {
            let t = k as f64 * PERIOD;
            let (p, q) = sway(t);
            m.update(t, p, q, |_| (p, q));
        }
        assert!(m.predict(LAGS as f64 * PERIOD, |_| sway(0.0)).is_some());
        // A gap of four periods starts the history again.
        let t = (LAGS as f64 + 5.0) * PERIOD;
        let (p, q) = sway(t);
        m.update(t, p, q, |_| (p, q));
        assert!(m.predict(t, |_| (p, q)).is_none());
    }

    #[test]
    fn an_untrained_prediction_has_no_share_and_a_still_head_stays_bounded() {
        let mut m = Learned::new(PERIOD, 0.99, (1e-4, 1e-3));
        let p = Vector3::new(0.1, 0.2, 0.3);
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.1, 0.0, 0.0));
        for k in 0..=LAGS + 2 {
            m.update(k as f64 * PERIOD, p, q, |_| (p, q));
        }
        let pr = m.predict((LAGS as f64 + 2.5) * PERIOD, |_| (p, q)).unwrap();
        assert_eq!((pr.w_pos, pr.w_rot), (0.0, 0.0));
        // An hour of a perfectly still head: forgetting must not grow the covariance unbounded.
        for k in 0..216_000 {
            m.update((LAGS as f64 + 3.0 + k as f64) * PERIOD, p, q, |_| (p, q));
        }
        let trace: f64 = (0..LAGS).map(|i| m.pos.p[i][i]).sum();
        assert!(
            trace.is_finite() && trace <= LAGS as f64 * P0 * 1.0001,
            "{trace}"
        );
        let pr = m.predict(3600.0, |_| (p, q)).unwrap();
        assert!((pr.p - p).norm() < 1e-12 && pr.q.angle_to(&q) < 1e-12);
    }
}
