//! A prediction learned from the head's own recent motion, beside the Kalman filter's.
//!
//! The filter's polynomial model (constant acceleration) cannot tell a nod that is about to
//! reverse from a head that keeps going: the jerk that reverses it is noise to the model, and at
//! the tracker's noise the filter cannot follow fast enough to see it early. A head's motion has
//! structure a polynomial does not carry (nods and sways repeat, an onset is followed by a
//! deceleration). This learns it online, as respiratory-motion predictors in radiotherapy do
//! (recursive least squares on the recent history): the displacement `STEPS` grid steps ahead
//! as a linear function of the displacements over the recent steps, one set of coefficients per
//! horizon, shared by the three axes, forgotten with a time constant of `1 / (1 − forgetting)`
//! steps. Two such models: a short one on each of the last `LAGS` steps (0.4 s), which learns
//! quickly and follows a motion that changes, and a long one on every `LONG_STRIDE`th of the last
//! `LONG_LAGS` (2.8 s), which sees a repeating motion whole and averages the tracker's noise over
//! seven times as long, at the same cost. The two are blended by their measured errors.
//!
//! What it learns is never trusted blindly: both predictions are scored against the measurements
//! that later arrive for the times they predicted, and [`Learned::predict`] gives the learned one
//! the share its running error earns against the filter's (inverse mean squared error), from
//! `MIN_TRAINED` examples on. At an onset that the history did not foresee its error rises and
//! the filter takes over: at once, by a second, fast record of both one-step predictions scored
//! as soon as each step is measured, which caps the learned share while its recent errors exceed
//! the filter's (the slow record learns of the onset a horizon late, and over fifty steps; on
//! the recorded irregular head the learned model kept 90 % of the share for a fifth of a second
//! after an onset, predicting the stillness it was trained on). Each example counts by its
//! shape, not its size, so seconds of a still head weigh as much as a fast turn. And a model is
//! not trusted beyond what it was trained on: a history larger than any it has learned from
//! (the first turn after a minute at rest, the nods growing in) is left to the filter, whose
//! measured record says nothing about it.
//!
//! The history is the measurements resampled onto a fixed grid (linear in position, spherical
//! in orientation), so an irregular tracker rate does not disturb the lags; a gap longer than
//! [`GAP_STEPS`] steps starts the history again. No allocation: everything lives in fixed arrays.

use mocomp_geom::nalgebra::{UnitQuaternion, Vector3};

/// Steps of history the short model learns from (0.4 s at 60 Hz).
pub const LAGS: usize = 24;
/// Steps of history the long model learns from (2.8 s at 60 Hz): longer than a nod, so a motion
/// that repeats is seen whole and the tracker's noise averages out over more samples. On the
/// demo's nods the excess over the oracle was 0.310 mm RMS at 1.2 s, 0.251 at 2 s, 0.233 at
/// 2.8 s and 0.219 at 4 s, where the recorded irregular head began to lose (0.551 → 0.573).
pub const LONG_LAGS: usize = 168;
/// The long model's features are every `LONG_STRIDE`th of those steps: the short model has the
/// recent detail, and the regression's cost grows with the square of its features (a long model
/// on every step of 1.6 s, 96 features instead of 24, took the cycle's p99 from 16 to 44 µs).
pub const LONG_STRIDE: usize = 7;
/// The long model's features.
const LONG_N: usize = LONG_LAGS / LONG_STRIDE;
const _: () = assert!(LONG_N * LONG_STRIDE == LONG_LAGS && LAGS <= LONG_LAGS);
/// Horizons learned, in grid steps (1 … `STEPS`: up to 100 ms at 60 Hz). Beyond them the
/// filter's own extrapolation carries on from the last one.
pub const STEPS: usize = 6;
/// A gap between measurements longer than this many steps restarts the history.
pub const GAP_STEPS: f64 = 3.0;
/// Grid points kept: the features of the oldest training example and its targets.
const CAP: usize = LONG_LAGS + STEPS + 1;
/// The running errors' weight of a new example (a time constant of 50 steps).
const ERROR_RATE: f64 = 0.02;
/// The one-step record's weight of a new step (a time constant of about three steps): fast
/// enough to see within a few samples that the learned model has stopped predicting the head.
const FRESH_RATE: f64 = 0.3;
/// The one-step record's floor, in measurement-noise σ: two records within it are the noise's,
/// and the learned share is left to the slow record. Below it the cap follows every noise
/// sample: at 1 σ the learned prediction lost its share on a still head too (the irregular
/// trace's excess over the oracle, mean of seeds 1–4, 0.442 mm RMS at 10 σ, 0.450 at 5.5 σ and
/// 0.445 at 17 σ, 0.458 with no cap; the fast nods' 0.246 and 0.247).
const FRESH_FLOOR_SIGMAS: f64 = 10.0;
/// How far beyond the largest history scale (squared) trained on a model is still trusted:
/// beyond it the model's share falls in proportion. 1 (no further) measured best on the
/// irregular trace (excess over the oracle 0.600 mm RMS with no limit, 0.575 at 4, 0.554 at 1,
/// 0.558 at ½, where the nods begin to lose).
const DOMAIN: f64 = 1.0;
/// The regression's prior: a large covariance, a weak prior towards zero coefficients.
const P0: f64 = 1e3;
/// Examples trained on before the learned prediction may be used (1.5 s at 60 Hz): a model that
/// has seen half a second of a motion's start has not seen it reverse yet, and its record is
/// too short to say so (on the nods' ramp-in it put the coil 2.8 mm off at the first reversal).
/// With the history's scale held within what was trained on, 1.25–2 s measured alike on the
/// nods' RMS; 1.5 s kept their worst moment, in the ramp-in, at 1.28 mm (1.68 at 2 s, where
/// the filter alone carries the first reversals), random motion's at 0.81 (0.63 at 2 s).
const MIN_TRAINED: u32 = 90;

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

    /// The head's move from here to `later` (position, world-frame rotation vector): what the
    /// learned models predict.
    fn moved_to(&self, later: &GridPoint) -> (Vector3<f64>, Vector3<f64>) {
        (later.p - self.p, (later.q * self.q.inverse()).scaled_axis())
    }

    /// The filter's miss at `later`, `m + 1` steps on, by its prediction from here.
    fn filter_miss(&self, later: &GridPoint, m: usize) -> (Vector3<f64>, Vector3<f64>) {
        (
            later.p - self.filter_p[m],
            (later.q * self.filter_q[m].inverse()).scaled_axis(),
        )
    }
}

/// One channel's regression: coefficients per horizon, their shared covariance, and the running
/// errors of the learned and the filter's predictions per horizon.
#[derive(Debug, Clone, Copy)]
struct Regression<const N: usize> {
    /// The measurement noise (1σ per axis) below which a motion's scale is not told apart.
    floor: f64,
    theta: [[f64; N]; STEPS],
    p: [[f64; N]; N],
    trained: u32,
    /// The largest history scale (squared) trained on, forgotten as the coefficients are.
    seen: f64,
    mse_learned: [f64; STEPS],
    mse_filter: [f64; STEPS],
    /// The running squared errors one step ahead (learned, filter), scored as soon as the step
    /// is measured ([`FRESH_RATE`]).
    fresh: (f64, f64),
}

impl<const N: usize> Regression<N> {
    fn new(floor: f64) -> Self {
        let mut p = [[0.0; N]; N];
        for (i, row) in p.iter_mut().enumerate() {
            row[i] = P0;
        }
        Self {
            floor,
            theta: [[0.0; N]; STEPS],
            p,
            trained: 0,
            seen: 0.0,
            mse_learned: [0.0; STEPS],
            mse_filter: [0.0; STEPS],
            fresh: (0.0, 0.0),
        }
    }

    /// Scores the one-step predictions made a step ago: the learned one's and the filter's
    /// squared errors (per axis).
    fn record_step(&mut self, learned: f64, filter: f64) {
        self.fresh.0 += FRESH_RATE * (learned - self.fresh.0);
        self.fresh.1 += FRESH_RATE * (filter - self.fresh.1);
    }

    /// The most of its share the learned model keeps by its one-step record: all of it while
    /// its recent errors are no larger than the filter's (or both within the noise), falling in
    /// proportion as they grow past them.
    fn fresh_cap(&self) -> f64 {
        let floor = (FRESH_FLOOR_SIGMAS * self.floor).powi(2);
        ((self.fresh.1 + floor) / (self.fresh.0 + floor)).min(1.0)
    }

    /// A history's scale, squared: its features' mean square, never below the noise's.
    fn scale2(&self, phi: &[Vector3<f64>; N]) -> f64 {
        phi.iter().map(|f| f.norm_squared()).sum::<f64>() / (3 * N) as f64 + self.floor * self.floor
    }

    /// How far a history of scale `scale2` is inside what was trained on: 1 within
    /// `DOMAIN` times the largest seen, falling to 0 beyond. A linear model learned on a still
    /// head's noise predicts stillness for any history; at a motion larger than any it has seen
    /// the filter must carry the prediction until the model has learned it.
    fn in_domain(&self, scale2: f64) -> f64 {
        (DOMAIN * self.seen / scale2).clamp(0.0, 1.0)
    }

    /// The learned displacement `m + 1` steps ahead for features `phi` (per axis).
    fn displacement(&self, m: usize, phi: &[Vector3<f64>; N]) -> Vector3<f64> {
        phi.iter()
            .zip(&self.theta[m])
            .fold(Vector3::zeros(), |acc, (f, c)| acc + f * *c)
    }

    /// Scores both predictions on one example (`targets[m]`: the displacement that came
    /// `m + 1` steps later; `filter_err[m]`: the filter's error there), then learns from it.
    fn train(
        &mut self,
        phi: &[Vector3<f64>; N],
        targets: &[Vector3<f64>; STEPS],
        filter_err: &[Vector3<f64>; STEPS],
        forgetting: f64,
    ) {
        let first = self.trained == 0;
        // Each example counts by its shape, not its size: weighed by the inverse of its
        // history's scale (never below the noise), so a fast turn does not outweigh seconds of
        // a still head, whose lesson is that its noise is not to be extrapolated. The errors
        // are scored as they are: an onset the history did not foresee must weigh at once.
        let scale2 = self.scale2(phi);
        self.seen = (self.seen * forgetting).max(scale2);
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
            let x: [f64; N] = std::array::from_fn(|j| phi[j][axis] * inv);
            // P·x as a sum of P's rows (P is symmetric): independent lanes the compiler can
            // vectorise, where a dot product per row is one long chain of additions.
            let mut px = [0.0; N];
            for (row, xj) in self.p.iter().zip(&x) {
                for (acc, pij) in px.iter_mut().zip(row) {
                    *acc += pij * xj;
                }
            }
            let denom = forgetting + (0..N).map(|i| x[i] * px[i]).sum::<f64>();
            if !(denom.is_finite() && denom > 0.0) {
                continue;
            }
            let gain: [f64; N] = std::array::from_fn(|i| px[i] / denom);
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
        let trace: f64 = (0..N).map(|i| self.p[i][i]).sum();
        if trace > N as f64 * P0 {
            let scale = N as f64 * P0 / trace;
            self.p.iter_mut().flatten().for_each(|p| *p *= scale);
        }
        // P − g·(Px)ᵀ is symmetric but for rounding, which a long run would let grow.
        if self.trained.is_multiple_of(64) {
            for i in 0..N {
                for j in i + 1..N {
                    let v = 0.5 * (self.p[i][j] + self.p[j][i]);
                    (self.p[i][j], self.p[j][i]) = (v, v);
                }
            }
        }
        self.trained = self.trained.saturating_add(1);
    }

    /// The running squared errors at fractional horizon `s` steps (0 … `STEPS`) of the learned
    /// prediction and of the filter's, or `None` until enough was learned.
    fn errors(&self, s: f64) -> Option<(f64, f64)> {
        (self.trained >= MIN_TRAINED).then(|| lerp_steps(s, &self.mse_learned, &self.mse_filter))
    }
}

/// The shares of a blend of the filter's, the short and the long model's predictions at
/// fractional horizon `s` steps. The two models are blended by the inverses of their running
/// squared errors, and the blend against the filter as the better model's error earns: their
/// errors are nearly the same errors, and counted twice they would crowd the filter out at an
/// onset neither foresaw. Returns the learned share against the filter's, and the long model's
/// within it; `long` is `None` while its history is too short (after a gap).
fn shares(s: f64, short: &Regression<LAGS>, long: Option<&Regression<LONG_N>>) -> (f64, f64) {
    let Some((ms, mf)) = short.errors(s) else {
        return (0.0, 0.0);
    };
    let Some((ml, _)) = long.and_then(|l| l.errors(s)) else {
        return (share(ms, mf), 0.0);
    };
    (share(ms.min(ml), mf), share(ml, ms))
}

/// The share of the first of two predictions whose running squared errors are `mine` and
/// `other`, weighed by their inverses.
fn share(mine: f64, other: f64) -> f64 {
    if mine + other > 0.0 {
        other / (mine + other)
    } else {
        0.0
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
    pos: Regression<LAGS>,
    rot: Regression<LAGS>,
    pos_long: Regression<LONG_N>,
    rot_long: Regression<LONG_N>,
    /// The last `STEPS + 1` points' features (position, orientation), each computed once when
    /// its point was laid: the loop predicts from the newest several times a cycle, and trains
    /// on the one `STEPS` back; `features_at` is the newest's slot.
    features: [Features; STEPS + 1],
    features_at: usize,
}

/// A point's features: its displacement from each of the `LAGS` points before it (the short
/// model's) and from every `LONG_STRIDE`th of the `LONG_LAGS` before it (the long model's), in
/// position and in orientation (a world-frame rotation vector).
#[derive(Debug, Clone, Copy)]
struct Features {
    p: [Vector3<f64>; LAGS],
    q: [Vector3<f64>; LAGS],
    long_p: [Vector3<f64>; LONG_N],
    long_q: [Vector3<f64>; LONG_N],
}

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
            pos_long: Regression::new(noise.0),
            rot_long: Regression::new(noise.1),
            features: [Features {
                p: [Vector3::zeros(); LAGS],
                q: [Vector3::zeros(); LAGS],
                long_p: [Vector3::zeros(); LONG_N],
                long_q: [Vector3::zeros(); LONG_N],
            }; STEPS + 1],
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
        if self.len > LAGS + 1 {
            self.score_step();
        }
        if self.len > LAGS + STEPS {
            self.train();
        }
    }

    /// The features at the point `back` steps before the newest; lags beyond the history
    /// repeat its oldest point (the long model waits for them).
    fn features(&self, back: usize) -> Features {
        let now = self.at(back);
        let then = |lag: usize| self.at((back + lag).min(self.len - 1));
        let dp = |lag: usize| now.p - then(lag).p;
        let dq = |lag: usize| (now.q * then(lag).q.inverse()).scaled_axis();
        Features {
            p: std::array::from_fn(|j| dp(j + 1)),
            q: std::array::from_fn(|j| dq(j + 1)),
            long_p: std::array::from_fn(|j| dp((j + 1) * LONG_STRIDE)),
            long_q: std::array::from_fn(|j| dq((j + 1) * LONG_STRIDE)),
        }
    }

    /// Scores both one-step predictions made at the point before the newest, against it.
    fn score_step(&mut self) {
        // The previous point's features: laid one step ago, with `LAGS` points before it.
        let f = self.features[(self.features_at + STEPS) % (STEPS + 1)];
        let (now, before) = (self.at(0), self.at(1));
        let (dp, dq) = before.moved_to(now);
        let (ep, eq) = before.filter_miss(now, 0);
        let lp = (dp - self.pos.displacement(0, &f.p)).norm_squared() / 3.0;
        let lq = (dq - self.rot.displacement(0, &f.q)).norm_squared() / 3.0;
        self.pos.record_step(lp, ep.norm_squared() / 3.0);
        self.rot.record_step(lq, eq.norm_squared() / 3.0);
    }

    /// Learns from the oldest complete example: its features, and what happened in the
    /// `STEPS` grid steps after it.
    fn train(&mut self) {
        // Laid `STEPS` points ago, with `LAGS` points before it: its features were kept.
        let f = self.features[(self.features_at + 1) % (STEPS + 1)];
        let origin = *self.at(STEPS);
        let ahead = |m: usize| self.at(STEPS - m - 1);
        let moved: [_; STEPS] = std::array::from_fn(|m| origin.moved_to(ahead(m)));
        let missed: [_; STEPS] = std::array::from_fn(|m| origin.filter_miss(ahead(m), m));
        let (tp, tq) = (moved.map(|d| d.0), moved.map(|d| d.1));
        let (ep, eq) = (missed.map(|d| d.0), missed.map(|d| d.1));
        self.pos.train(&f.p, &tp, &ep, self.forgetting);
        self.rot.train(&f.q, &tq, &eq, self.forgetting);
        // The example laid `STEPS` points ago had `LONG_LAGS` points before it.
        if self.len == CAP {
            self.pos_long.train(&f.long_p, &tp, &ep, self.forgetting);
            self.rot_long.train(&f.long_q, &tq, &eq, self.forgetting);
        }
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
        let f = &self.features[self.features_at];
        let newest = self.at(0);
        let at = |d: &dyn Fn(usize) -> Vector3<f64>| {
            let m0 = sc.floor() as usize;
            let f = sc - m0 as f64;
            let d = |m: usize| {
                if m == 0 {
                    Vector3::zeros()
                } else {
                    d(m.min(STEPS) - 1)
                }
            };
            d(m0) * (1.0 - f) + d(m0 + 1) * f
        };
        let whole = self.len > LONG_LAGS;
        let (w_pos, long_pos) = shares(s, &self.pos, whole.then_some(&self.pos_long));
        let (w_rot, long_rot) = shares(s, &self.rot, whole.then_some(&self.rot_long));
        let w_pos = w_pos * self.pos.in_domain(self.pos.scale2(&f.p)) * self.pos.fresh_cap();
        let w_rot = w_rot * self.rot.in_domain(self.rot.scale2(&f.q)) * self.rot.fresh_cap();
        let dp = at(&|m| self.pos.displacement(m, &f.p));
        let dq = at(&|m| self.rot.displacement(m, &f.q));
        // The long model only once it has a record (its share is 0 before).
        let (dp, dq) = if long_pos > 0.0 || long_rot > 0.0 {
            (
                dp + (at(&|m| self.pos_long.displacement(m, &f.long_p)) - dp) * long_pos,
                dq + (at(&|m| self.rot_long.displacement(m, &f.long_q)) - dq) * long_rot,
            )
        } else {
            (dp, dq)
        };
        let mut p = newest.p + dp;
        let mut q = UnitQuaternion::from_scaled_axis(dq) * newest.q;
        if s > sc {
            let (p1, q1) = filter(self.grid_t + sc * self.period);
            let (p2, q2) = filter(t);
            p += p2 - p1;
            q = q2 * q1.inverse() * q;
        }
        Some(LearnedPrediction { p, q, w_pos, w_rot })
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

    /// Seeded Gaussian-like noise of standard deviation `sigma` (a sum of uniforms).
    fn noise(seed: u64, sigma: f64) -> impl FnMut() -> Vector3<f64> {
        let mut x = seed;
        let mut uniform = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as f64 / u64::MAX as f64 - 0.5
        };
        move || Vector3::from_fn(|_, _| (0..12).map(|_| uniform()).sum::<f64>() * sigma)
    }

    #[test]
    fn the_long_model_learns_noisy_nods_closer_than_the_short_one_and_earns_its_share() {
        let (mut np, mut nq) = (noise(7, 1e-4), noise(11, 1e-3));
        let mut m = Learned::new(PERIOD, 0.999, (1e-4, 1e-3));
        for k in 0..1800 {
            let t = k as f64 * PERIOD;
            let (p, q) = sway(t);
            let (p, q) = (p + np(), UnitQuaternion::from_scaled_axis(nq()) * q);
            m.update(t, p, q, |_| (p, q));
        }
        // Four steps (67 ms) ahead, after 30 s of nods seen with the tracker's noise.
        let (ms, _) = m.rot.errors(4.0).unwrap();
        let (ml, _) = m.rot_long.errors(4.0).unwrap();
        assert!(ml < 0.7 * ms, "long {ml}, short {ms}");
        let (_, long_share) = shares(4.0, &m.rot, Some(&m.rot_long));
        assert!(long_share > 0.55, "{long_share}");
    }

    #[test]
    fn a_model_trained_on_a_still_head_leaves_a_first_motion_to_the_filter() {
        let mut np = noise(3, 1e-4);
        let mut m = Learned::new(PERIOD, 0.999, (1e-4, 1e-3));
        let q = UnitQuaternion::identity();
        let still = Vector3::new(0.1, 0.2, 0.3);
        let mut t = 0.0;
        for k in 0..600 {
            t = k as f64 * PERIOD;
            let p = still + np();
            m.update(t, p, q, |_| (p, q));
        }
        // At rest its record beats the filter's (which here predicts the last noisy sample).
        let at_rest = m.predict(t + 4.0 * PERIOD, |_| (still, q)).unwrap();
        assert!(at_rest.w_pos > 0.5, "{}", at_rest.w_pos);
        // Off at 40 mm/s: a history ten times the noise it learned from.
        for k in 1..=6 {
            let tk = t + k as f64 * PERIOD;
            let p = still + Vector3::new(0.04 * k as f64 * PERIOD, 0.0, 0.0) + np();
            m.update(tk, p, q, |_| (p, q));
        }
        let t = t + 6.0 * PERIOD;
        let moving = m.predict(t + 4.0 * PERIOD, |_| (still, q)).unwrap();
        assert!(moving.w_pos < 0.1, "{}", moving.w_pos);
    }

    /// After nods and a still spell, a sudden turn the learned model predicts as stillness:
    /// its one-step record takes its share within a few samples, where the slow record still
    /// gives it most.
    #[test]
    fn an_onset_the_learned_model_did_not_foresee_is_left_to_the_filter_within_samples() {
        let (mut np, mut nq) = (noise(5, 1e-4), noise(9, 1e-3));
        let mut m = Learned::new(PERIOD, 0.999, (1e-4, 1e-3));
        // A constant-velocity filter on the last two samples: it sees a turn a sample late.
        let mut previous = None::<UnitQuaternion<f64>>;
        let mut feed = |m: &mut Learned, t: f64, p: Vector3<f64>, q: UnitQuaternion<f64>| {
            let (p, q) = (p + np(), UnitQuaternion::from_scaled_axis(nq()) * q);
            let w = previous.map_or(Vector3::zeros(), |q0| {
                (q * q0.inverse()).scaled_axis() / PERIOD
            });
            previous = Some(q);
            m.update(t, p, q, |tt| {
                (p, UnitQuaternion::from_scaled_axis(w * (tt - t)) * q)
            });
        };
        let mut t = 0.0;
        for k in 0..1800 {
            t = k as f64 * PERIOD;
            let (p, q) = sway(t);
            feed(&mut m, t, p, q);
        }
        let (p0, q0) = sway(t);
        for _ in 0..240 {
            t += PERIOD;
            feed(&mut m, t, p0, q0);
        }
        let at_rest = m.predict(t + 4.0 * PERIOD, |_| (p0, q0)).unwrap();
        let cap_at_rest = m.rot.fresh_cap();
        // A turn at 0.6 rad/s (34°/s) about z, from rest.
        let turn = Vector3::new(0.0, 0.0, 0.6);
        let t0 = t;
        for _ in 0..4 {
            t += PERIOD;
            feed(
                &mut m,
                t,
                p0,
                UnitQuaternion::from_scaled_axis(turn * (t - t0)) * q0,
            );
        }
        let (slow, _) = shares(4.0, &m.rot, Some(&m.rot_long));
        let moving = m.predict(t + 4.0 * PERIOD, |_| (p0, q0)).unwrap();
        // At rest the learned model keeps its share; four samples into the turn the slow
        // record still gives it most, the one-step record takes it.
        assert!(
            cap_at_rest > 0.999 && at_rest.w_rot > 0.9,
            "{cap_at_rest} {}",
            at_rest.w_rot
        );
        assert!(slow > 0.8, "{slow}");
        assert!(moving.w_rot < 0.6 * slow, "{} against {slow}", moving.w_rot);
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
