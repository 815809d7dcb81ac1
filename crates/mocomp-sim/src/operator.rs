//! A simulated operator with a tracked pointer, for rehearsing a registration with no hardware:
//! it does what it is asked ([`Ask`]: pivot the pointer in a divot, touch a landmark, sweep the
//! scalp), a reaction time after it is asked and once it has finished what it was doing, as a
//! person does. It touches the patient's skin ([`TrueSkin`], not the head model), near the
//! anatomical landmark (the image's landmark is itself off the anatomical point along the skin),
//! with a stated error, pressing the skin in; it brings the pointer in from the air and lifts it
//! off, may pause in the air on the way in, and may lift off and hover in the middle of a sweep.
//! It sweeps a fixed pattern (the whole head, one ring at brow level, one side), or where the
//! procedure asks.
//!
//! Pure and steppable: the pose at time `t` (s; asked with `t` increasing) from a plan of
//! keyframes; every random choice from its seed.

use crate::skin::{Field, SkinPoint, TrueSkin};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What the operator sweeps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SweepPattern {
    /// Meridians from the brow to the crown all round, then rings.
    #[default]
    Full,
    /// One ring at brow level, round and round.
    Ring,
    /// The left half of the head only.
    OneSided,
    /// No sweep: the landmarks alone.
    None,
}

/// What the operator does in the air.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum AirHabit {
    /// Straight in, straight out.
    #[default]
    None,
    /// Pauses 40–60 mm off the skin before each touch.
    Pauses,
    /// That, and lifts off and hovers in the middle of sweep strokes.
    Mixed,
}

/// `[tracker.simulated.operator]`: the simulated operator and the patient's skin. Millimetres
/// and seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OperatorConfig {
    /// A touch lands this far from where it was aimed along the skin, 1σ per axis, mm.
    pub touch_sigma_mm: f64,
    /// The anatomical landmark lies this far from the image's along the skin, 1σ per axis, mm.
    pub image_landmark_sigma_mm: f64,
    /// Landmarks placed wrong on the image: the anatomical one lies this far (image frame, mm)
    /// from the image's, by name (then on the skin).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub landmark_offsets_mm: BTreeMap<String, [f64; 3]>,
    /// The tip presses the skin in by up to this, mm.
    pub skin_compression_mm: f64,
    /// The skin is off the head model along its normal by this, 1σ, mm…
    pub model_sigma_mm: f64,
    /// …alike over this distance, mm…
    pub model_correlation_mm: f64,
    /// …and by an offset common to the whole head, 1σ, mm.
    pub model_offset_mm: f64,
    /// What it sweeps.
    pub sweep: SweepPattern,
    /// What it does in the air.
    pub air: AirHabit,
    /// Sweeps the region the procedure names, once it names one.
    pub follows_guidance: bool,
    /// Along the skin, mm/s.
    pub speed_mm_s: f64,
    /// Holds a touch this long, s.
    pub hold_s: f64,
    /// Acts this long after it is asked, s.
    pub reaction_s: f64,
    /// Pivots this long when asked to, s.
    pub pivot_s: f64,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for OperatorConfig {
    fn default() -> Self {
        Self {
            touch_sigma_mm: 0.7,
            image_landmark_sigma_mm: 0.7,
            landmark_offsets_mm: BTreeMap::new(),
            skin_compression_mm: 1.0,
            model_sigma_mm: 0.5,
            model_correlation_mm: 20.0,
            model_offset_mm: 0.3,
            sweep: SweepPattern::Full,
            air: AirHabit::None,
            follows_guidance: false,
            speed_mm_s: 50.0,
            hold_s: 1.2,
            reaction_s: 0.3,
            pivot_s: 8.0,
            seed: 1,
        }
    }
}

/// A figure out of range: its key and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {why}")]
pub struct OperatorError {
    /// The key.
    pub key: &'static str,
    /// Why.
    pub why: String,
}

impl OperatorConfig {
    /// Every figure in range.
    pub fn validate(&self) -> Result<(), OperatorError> {
        let ranges: [(&'static str, f64, f64, f64); 10] = [
            ("touch_sigma_mm", self.touch_sigma_mm, 0.0, 20.0),
            (
                "image_landmark_sigma_mm",
                self.image_landmark_sigma_mm,
                0.0,
                20.0,
            ),
            ("skin_compression_mm", self.skin_compression_mm, 0.0, 10.0),
            ("model_sigma_mm", self.model_sigma_mm, 0.0, 10.0),
            (
                "model_correlation_mm",
                self.model_correlation_mm,
                1.0,
                200.0,
            ),
            ("model_offset_mm", self.model_offset_mm, 0.0, 10.0),
            ("speed_mm_s", self.speed_mm_s, 5.0, 500.0),
            ("hold_s", self.hold_s, 0.5, 10.0),
            ("reaction_s", self.reaction_s, 0.0, 5.0),
            ("pivot_s", self.pivot_s, 1.0, 120.0),
        ];
        for (key, v, lo, hi) in ranges {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(OperatorError {
                    key,
                    why: format!("{v}: must be {lo} to {hi}"),
                });
            }
        }
        for (name, v) in &self.landmark_offsets_mm {
            if !v.iter().all(|x| x.is_finite() && x.abs() <= 100.0) {
                return Err(OperatorError {
                    key: "landmark_offsets_mm",
                    why: format!("{name} = {v:?}: within 100 mm"),
                });
            }
        }
        Ok(())
    }
}

/// What the operator is asked to do.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Ask {
    /// Pivot the pointer's tip in the divot.
    Pivot,
    /// Touch this landmark and hold.
    Touch(String),
    /// Take the pointer off this landmark: it always does after a touch, so asked while it is
    /// free, the procedure took a pause in the air for the touch, and it touches the landmark.
    TakeAway(String),
    /// Sweep the scalp, where named.
    Sweep(Option<String>),
    /// Nothing: rest the pointer.
    #[default]
    Rest,
}

/// Where the pointer's marker is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PointerAt {
    /// On the head: `image_from_pointer` (the image's frame, which the head marker carries).
    Image(Isometry3<f64>),
    /// In the divot: `tracker_from_pointer`.
    Tracker(Isometry3<f64>),
}

/// The divot the pointer is pivoted in, tracker frame, m.
pub const DIVOT_IN_TRACKER: [f64; 3] = [0.05, 0.1, 0.8];
/// Keyframes of a move are this far apart in time, s.
const KEY_S: f64 = 0.01;

/// The head's own frame: a centre some way above the ears' midpoint, x to the right, y to the
/// nose, z up.
#[derive(Debug, Clone, Copy, PartialEq)]
struct HeadFrame {
    centre: Point3<f64>,
    x: Vector3<f64>,
    y: Vector3<f64>,
    z: Vector3<f64>,
}

impl HeadFrame {
    fn direction(&self, elevation_deg: f64, azimuth_deg: f64) -> Vector3<f64> {
        let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
        (self.x * a.sin() + self.y * a.cos()) * e.cos() + self.z * e.sin()
    }
}

/// A plan: keyframes of the tip (image frame) in time, or a pivot.
#[derive(Debug, Clone, PartialEq)]
enum Plan {
    Keys(Vec<(f64, Point3<f64>)>),
    Pivot { from: f64, to: f64 },
}

impl Plan {
    fn end(&self) -> f64 {
        match self {
            Self::Keys(k) => k.last().map_or(0.0, |(t, _)| *t),
            Self::Pivot { to, .. } => *to,
        }
    }
}

/// The operator.
#[derive(Debug, Clone)]
pub struct Operator {
    config: OperatorConfig,
    skin: TrueSkin,
    frame: HeadFrame,
    landmarks: BTreeMap<String, SkinPoint>,
    tip_in_marker: Vector3<f64>,
    rng: ChaCha8Rng,
    plan: Option<Plan>,
    idle_since: f64,
    tip: Point3<f64>,
    /// Where the pointer was left in the divot, while it rests there.
    parked: Option<Isometry3<f64>>,
    stroke: usize,
}

impl Operator {
    /// An operator over `head` (the model, carried into the image by `image_from_shape`) with
    /// the image's `landmarks` (image frame, m; the anatomical ones lie near them on the skin),
    /// holding a pointer whose tip is at `tip_in_marker` (m).
    pub fn new(
        config: OperatorConfig,
        head: mocomp_head::Head,
        image_from_shape: Isometry3<f64>,
        landmarks: &[(String, Point3<f64>)],
        tip_in_marker: Vector3<f64>,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let mm = 1e-3;
        let field = Field::new(
            config.model_sigma_mm * mm,
            config.model_correlation_mm * mm,
            config.model_offset_mm * mm,
            &mut rng,
        );
        let skin = TrueSkin::new(head, image_from_shape, field);
        let mut truth = BTreeMap::new();
        for (name, p) in landmarks {
            let off = config
                .landmark_offsets_mm
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map_or_else(Vector3::zeros, |(_, v)| Vector3::from(*v) * mm);
            let on = skin.nearest(&(p + off));
            let moved = along_skin(&mut rng, &on, config.image_landmark_sigma_mm * mm);
            truth.insert(name.to_lowercase(), skin.nearest(&moved));
        }
        let find = |n: &str| truth.get(n).map(|s: &SkinPoint| s.point);
        // Forward: to the nasion, or away from the inion.
        let front = |o: Point3<f64>| {
            find("nasion")
                .map(|n| n - o)
                .or_else(|| find("inion").map(|i| o - i))
        };
        let ears = find("lpa").zip(find("rpa"));
        let frame = match ears.and_then(|(l, r)| {
            let o = Point3::from((l.coords + r.coords) / 2.0);
            front(o).map(|f| (l, r, o, f))
        }) {
            Some((l, r, o, f)) => {
                let x = (r - l).normalize();
                let y = (f - x * f.dot(&x)).normalize();
                let z = x.cross(&y);
                HeadFrame {
                    centre: o + z * 0.03,
                    x,
                    y,
                    z,
                }
            }
            None => HeadFrame {
                centre: image_from_shape * Point3::origin(),
                x: Vector3::x(),
                y: Vector3::y(),
                z: Vector3::z(),
            },
        };
        let tip = frame.centre + frame.y * 0.25;
        Self {
            config,
            skin,
            frame,
            landmarks: truth,
            tip_in_marker,
            rng,
            plan: None,
            idle_since: 0.0,
            tip,
            parked: None,
            stroke: 0,
        }
    }

    /// The anatomical landmark `name` on the skin, image frame (the truth a registration is
    /// judged against never needs it: the image-to-marker transform is the truth).
    pub fn landmark(&self, name: &str) -> Option<Point3<f64>> {
        self.landmarks.get(&name.to_lowercase()).map(|s| s.point)
    }

    /// Whether it is in the middle of something (it reads what it is asked only when not).
    pub fn busy(&self, t: f64) -> bool {
        self.plan.as_ref().is_some_and(|p| t < p.end())
    }

    /// The pointer's marker at `t` (s, increasing), doing what `ask` says once it is free.
    pub fn at(&mut self, t: f64, ask: &Ask) -> PointerAt {
        if let Some(plan) = &self.plan
            && t > plan.end()
        {
            match plan {
                Plan::Keys(k) => {
                    if let Some((_, p)) = k.last() {
                        self.tip = *p;
                    }
                    self.parked = None;
                }
                Plan::Pivot { from, to } => self.parked = Some(self.pivot_pose(to - from)),
            }
            self.idle_since = plan.end();
            self.plan = None;
        }
        if self.plan.is_none() && t - self.idle_since >= self.config.reaction_s {
            self.plan = self.plan_for(t, ask);
            if self.plan.is_none() {
                self.idle_since = t;
            }
        }
        match &self.plan {
            Some(Plan::Pivot { from, .. }) => PointerAt::Tracker(self.pivot_pose(t - from)),
            Some(Plan::Keys(keys)) => PointerAt::Image(self.pose_at(interpolate(keys, t))),
            None => match self.parked {
                Some(p) => PointerAt::Tracker(p),
                None => PointerAt::Image(self.pose_at(self.tip)),
            },
        }
    }

    /// The pointer's marker with its tip at `tip` (image frame), the shaft pointing at the
    /// head's centre, turned a little about it as a hand does.
    fn pose_at(&self, tip: Point3<f64>) -> Isometry3<f64> {
        let shaft = (self.frame.centre - tip)
            .try_normalize(1e-9)
            .unwrap_or_else(|| -self.frame.z);
        let r = UnitQuaternion::rotation_between(&self.tip_in_marker, &shaft)
            .unwrap_or_else(UnitQuaternion::identity);
        Isometry3::from_parts(Translation3::from(tip.coords - r * self.tip_in_marker), r)
    }

    /// The pointer pivoting in the divot `s` seconds in: its shaft circling a cone of 15–35°
    /// about the tracker's view axis every 2.5 s.
    fn pivot_pose(&self, s: f64) -> Isometry3<f64> {
        let tilt = (25.0 + 10.0 * (0.7 * s).sin()).to_radians();
        let around = std::f64::consts::TAU * s / 2.5;
        let shaft = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), around)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt)
            * Vector3::z();
        let r = UnitQuaternion::rotation_between(&self.tip_in_marker, &shaft)
            .unwrap_or_else(UnitQuaternion::identity)
            * UnitQuaternion::from_axis_angle(
                &mocomp_geom::nalgebra::Unit::new_normalize(self.tip_in_marker),
                0.4 * (0.9 * s).sin(),
            );
        let divot = Vector3::from(DIVOT_IN_TRACKER);
        Isometry3::from_parts(Translation3::from(divot - r * self.tip_in_marker), r)
    }

    fn plan_for(&mut self, t: f64, ask: &Ask) -> Option<Plan> {
        match ask {
            Ask::Pivot => Some(Plan::Pivot {
                from: t,
                to: t + self.config.pivot_s,
            }),
            Ask::Touch(name) | Ask::TakeAway(name) => {
                let target = *self.landmarks.get(&name.to_lowercase())?;
                Some(Plan::Keys(self.touch(t, &target)))
            }
            Ask::Sweep(region) => {
                let strokes = match (region, self.config.follows_guidance) {
                    (Some(r), true) => region_strokes(r),
                    _ => pattern_strokes(self.config.sweep),
                };
                if strokes.is_empty() {
                    return None;
                }
                let (from, to) = strokes[self.stroke % strokes.len()];
                self.stroke += 1;
                Some(Plan::Keys(self.sweep_stroke(t, from, to)))
            }
            Ask::Rest => None,
        }
    }

    /// Touching `target`: from where the tip is, out to 60 mm over the aimed point, maybe a pause
    /// in the air, in onto the skin (pressed), held, lifted off.
    fn touch(&mut self, t: f64, target: &SkinPoint) -> Vec<(f64, Point3<f64>)> {
        let mm = 1e-3;
        let aimed_at = along_skin(&mut self.rng, target, self.config.touch_sigma_mm * mm);
        let aimed = self.skin.nearest(&aimed_at);
        let pressed = aimed.point
            - aimed.normal * (self.rng.random::<f64>() * self.config.skin_compression_mm * mm);
        let mut keys = vec![(t, self.tip)];
        if self.config.air == AirHabit::None {
            self.travel(&mut keys, &(aimed.point + aimed.normal * 0.06));
        } else {
            // Coming in from farther out, and stopping on the way to look.
            self.travel(&mut keys, &(aimed.point + aimed.normal * 0.1));
            let off = 0.04 + 0.02 * self.rng.random::<f64>();
            move_to(&mut keys, aimed.point + aimed.normal * off, 0.6);
            hold(&mut keys, 0.6 + 0.4 * self.rng.random::<f64>());
        }
        move_to(&mut keys, pressed, 0.8);
        hold(&mut keys, self.config.hold_s);
        move_to(&mut keys, aimed.point + aimed.normal * 0.05, 0.6);
        keys
    }

    /// One stroke of a sweep from `from` to `to` (elevation, azimuth, degrees in the head's
    /// frame): landing, sliding along the skin pressed in by a varying amount (maybe lifting off
    /// and hovering on the way), lifting off.
    fn sweep_stroke(
        &mut self,
        t: f64,
        from: (f64, f64),
        to: (f64, f64),
    ) -> Vec<(f64, Point3<f64>)> {
        let path = self.skin_path(from, to);
        let mut keys = vec![(t, self.tip)];
        let Some(first) = path.first().copied() else {
            return keys;
        };
        let mm = 1e-3;
        let max_press = self.config.skin_compression_mm * mm;
        // The give varies smoothly along the stroke, evenly over 0…max (a triangle wave).
        let wave = 0.02 + 0.04 * self.rng.random::<f64>();
        let phase = self.rng.random::<f64>();
        let press = |s: f64| max_press * ((s / wave + phase).rem_euclid(1.0) * 2.0 - 1.0).abs();
        self.travel(&mut keys, &(first.point + first.normal * 0.02));
        move_to(&mut keys, first.point - first.normal * press(0.0), 0.4);
        let hovers: Vec<f64> = if self.config.air == AirHabit::Mixed {
            (0..2).map(|_| self.rng.random::<f64>()).collect()
        } else {
            Vec::new()
        };
        let speed = self.config.speed_mm_s * mm;
        let total = path_length(&path);
        let mut s = 0.0;
        for w in path.windows(2) {
            let step = (w[1].point - w[0].point).norm();
            s += step;
            let at = w[1].point - w[1].normal * press(s);
            let (t_last, _) = keys[keys.len() - 1];
            keys.push((t_last + step / speed, at));
            if hovers.iter().any(|h| (s - step..s).contains(&(h * total))) {
                let up = 0.01 + 0.01 * self.rng.random::<f64>();
                move_to(&mut keys, w[1].point + w[1].normal * up, 0.25);
                hold(&mut keys, 0.3);
                move_to(&mut keys, at, 0.25);
            }
        }
        let last = path[path.len() - 1];
        move_to(&mut keys, last.point + last.normal * 0.02, 0.3);
        keys
    }

    /// Carries the tip to `to` through the air: out from the head, round it 60 mm off the skin,
    /// and in again, never through it.
    fn travel(&self, keys: &mut Vec<(f64, Point3<f64>)>, to: &Point3<f64>) {
        let (_, from) = keys.last().copied().unwrap_or((0.0, *to));
        let (a, b) = (from - self.frame.centre, to - self.frame.centre);
        let (Some(da), Some(db)) = (a.try_normalize(1e-9), b.try_normalize(1e-9)) else {
            return;
        };
        let turn = da.angle(&db);
        let steps = (turn / 0.2).ceil() as usize;
        let mut at = from;
        for k in 1..steps {
            let r = UnitQuaternion::rotation_between(&da, &db).map_or(da, |q| {
                UnitQuaternion::from_scaled_axis(q.scaled_axis() * (k as f64 / steps as f64)) * da
            });
            let Some(s) = self.skin.along(&self.frame.centre, &r) else {
                continue;
            };
            let p = s.point + r * 0.06;
            move_to(keys, p, 0.1 + (p - at).norm() / 0.25);
            at = p;
        }
        move_to(keys, *to, 0.3 + (to - at).norm() / 0.25);
    }

    /// Skin points from `from` to `to` (elevation, azimuth, degrees), about 1 mm apart.
    fn skin_path(&self, from: (f64, f64), to: (f64, f64)) -> Vec<SkinPoint> {
        let coarse: Vec<SkinPoint> = (0..=90)
            .filter_map(|i| {
                let s = i as f64 / 90.0;
                let d = self
                    .frame
                    .direction(from.0 + (to.0 - from.0) * s, from.1 + (to.1 - from.1) * s);
                self.skin.along(&self.frame.centre, &d)
            })
            .collect();
        let mut fine = Vec::new();
        for w in coarse.windows(2) {
            let n = ((w[1].point - w[0].point).norm() / 1e-3).ceil().max(1.0) as usize;
            for k in 0..n {
                let s = k as f64 / n as f64;
                let p = w[0].point + (w[1].point - w[0].point) * s;
                fine.push(self.skin.nearest(&p));
            }
        }
        fine
    }
}

/// `p` moved along the skin by `sigma` (m, 1σ per axis across its normal).
fn along_skin(rng: &mut ChaCha8Rng, p: &SkinPoint, sigma: f64) -> Point3<f64> {
    let g = Vector3::new(
        rng.sample::<f64, _>(StandardNormal),
        rng.sample::<f64, _>(StandardNormal),
        rng.sample::<f64, _>(StandardNormal),
    ) * sigma;
    p.point + (g - p.normal * g.dot(&p.normal))
}

/// Appends a minimum-jerk move to `to` over `duration` s.
fn move_to(keys: &mut Vec<(f64, Point3<f64>)>, to: Point3<f64>, duration: f64) {
    let (t0, from) = keys.last().copied().unwrap_or((0.0, to));
    let n = (duration / KEY_S).ceil().max(1.0) as usize;
    for k in 1..=n {
        let s = k as f64 / n as f64;
        let m = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
        keys.push((t0 + duration * s, from + (to - from) * m));
    }
}

/// Appends a hold where the tip is for `duration` s.
fn hold(keys: &mut Vec<(f64, Point3<f64>)>, duration: f64) {
    if let Some((t0, p)) = keys.last().copied() {
        keys.push((t0 + duration, p));
    }
}

/// The tip at `t` between keyframes.
fn interpolate(keys: &[(f64, Point3<f64>)], t: f64) -> Point3<f64> {
    let i = keys.partition_point(|(tk, _)| *tk <= t);
    match (i.checked_sub(1).and_then(|j| keys.get(j)), keys.get(i)) {
        (Some((t0, p0)), Some((t1, p1))) if t1 > t0 => p0 + (p1 - p0) * ((t - t0) / (t1 - t0)),
        (Some((_, p)), _) | (None, Some((_, p))) => *p,
        (None, None) => Point3::origin(),
    }
}

fn path_length(path: &[SkinPoint]) -> f64 {
    path.windows(2)
        .map(|w| (w[1].point - w[0].point).norm())
        .sum()
}

/// A pattern's strokes (elevation, azimuth in degrees), in the order swept: every prefix spread
/// over the head.
fn pattern_strokes(p: SweepPattern) -> Vec<((f64, f64), (f64, f64))> {
    let meridian = |az: f64| ((10.0, az), (80.0, az));
    let halves = |el: f64, side: &[(f64, f64)]| -> Vec<((f64, f64), (f64, f64))> {
        side.iter().map(|(a, b)| ((el, *a), (el, *b))).collect()
    };
    match p {
        SweepPattern::Full => {
            let mut s: Vec<_> = [0.0, 180.0, 90.0, -90.0, 45.0, -135.0, 135.0, -45.0]
                .into_iter()
                .map(meridian)
                .collect();
            for el in [35.0, 60.0, 10.0] {
                s.extend(halves(el, &[(-180.0, 0.0), (0.0, 180.0)]));
            }
            s
        }
        SweepPattern::Ring => halves(5.0, &[(-180.0, 0.0), (0.0, 180.0)]),
        SweepPattern::OneSided => {
            let mut s: Vec<_> = [-90.0, -45.0, -135.0].into_iter().map(meridian).collect();
            for el in [35.0, 60.0, 10.0] {
                s.extend(halves(el, &[(-180.0, 0.0)]));
            }
            s
        }
        SweepPattern::None => Vec::new(),
    }
}

/// Strokes across a named region (as the registration names them), both ways.
fn region_strokes(region: &str) -> Vec<((f64, f64), (f64, f64))> {
    let centre = match region {
        "forehead" => (20.0, 0.0),
        "right front" => (25.0, 45.0),
        "right side" => (25.0, 90.0),
        "right back" => (25.0, 135.0),
        "back of the head" => (25.0, 180.0),
        "left back" => (25.0, -135.0),
        "left side" => (25.0, -90.0),
        "left front" => (25.0, -45.0),
        "crown" => (70.0, 0.0),
        _ => return pattern_strokes(SweepPattern::Full),
    };
    let (el, az) = centre;
    vec![
        ((el, az - 25.0), (el, az + 25.0)),
        ((el - 15.0, az), (el + 15.0, az)),
        ((el + 8.0, az + 20.0), (el + 8.0, az - 20.0)),
        ((el + 15.0, az + 10.0), (el - 12.0, az + 10.0)),
    ]
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)] // test code
    use super::*;
    use mocomp_head::{Ellipsoid, Head, HeadShape};

    fn operator(config: OperatorConfig) -> Operator {
        let head = Head::Ellipsoid(Ellipsoid::adult());
        let marks: Vec<(String, Point3<f64>)> = [
            ("nasion", Vector3::new(0.0, 1.0, -0.3)),
            ("lpa", Vector3::new(-1.0, 0.0, -0.3)),
            ("rpa", Vector3::new(1.0, 0.0, -0.3)),
        ]
        .iter()
        .map(|(n, d)| (n.to_string(), head.nearest(&Point3::from(d * 0.2)).point))
        .collect();
        Operator::new(
            config,
            head,
            Isometry3::identity(),
            &marks,
            Vector3::new(0.0025, -0.004, 0.161),
        )
    }

    fn tip(op: &Operator, at: PointerAt) -> Point3<f64> {
        match at {
            PointerAt::Image(p) => p * Point3::from(op.tip_in_marker),
            PointerAt::Tracker(p) => p * Point3::from(op.tip_in_marker),
        }
    }

    /// Asked to touch the nasion, it comes in from the air, holds on the skin (pressed, within
    /// the touch's error of the anatomical point), and lifts off; it pauses in the air first when
    /// that is its habit.
    #[test]
    fn a_touch_comes_in_from_the_air_holds_on_the_skin_and_lifts_off() {
        for air in [AirHabit::None, AirHabit::Pauses] {
            let mut op = operator(OperatorConfig {
                air,
                ..OperatorConfig::default()
            });
            let nasion = op.landmark("nasion").unwrap();
            let ask = Ask::Touch("nasion".into());
            let mut tips = Vec::new();
            let mut t = 0.0;
            while t < 8.0 {
                t += 1.0 / 60.0;
                let at = op.at(t, &ask);
                tips.push(tip(&op, at));
                if !op.busy(t) && t > 1.0 {
                    break;
                }
            }
            let dist: Vec<f64> = tips.iter().map(|p| (p - nasion).norm()).collect();
            let nearest = dist.iter().copied().fold(f64::INFINITY, f64::min);
            assert!(nearest < 5e-3, "{air:?}: {nearest}");
            // Held: a second within 0.1 mm of one point.
            let held = tips
                .windows(60)
                .any(|w| w.iter().all(|p| (p - w[0]).norm() < 1e-4));
            assert!(held, "{air:?}");
            // Out in the air at the start and the end.
            assert!(dist[0] > 0.05 && dist[dist.len() - 1] > 0.04, "{air:?}");
            // A pause in the air, 40–60 mm off, only when that is its habit.
            let paused_off = tips.windows(30).any(|w| {
                let d = (w[0] - nasion).norm();
                (0.035..0.065).contains(&d) && w.iter().all(|p| (p - w[0]).norm() < 1e-4)
            });
            assert_eq!(paused_off, air == AirHabit::Pauses, "{air:?}");
        }
    }

    /// Sweeping the full pattern, its tip slides within the skin's give of the skin, and covers
    /// the head's front, back, sides and top within a minute.
    #[test]
    fn a_sweep_slides_on_the_skin_and_covers_the_head() {
        let mut op = operator(OperatorConfig {
            model_sigma_mm: 0.0,
            model_offset_mm: 0.0,
            follows_guidance: false,
            ..OperatorConfig::default()
        });
        let ask = Ask::Sweep(None);
        let mut on = Vec::new();
        let mut t = 0.0;
        while t < 60.0 {
            t += 1.0 / 60.0;
            let at = op.at(t, &ask);
            let p = tip(&op, at);
            let d = op.skin.nearest(&p);
            let depth = (p - d.point).dot(&d.normal);
            // Never deeper than the skin gives.
            assert!(depth > -1.05e-3, "{depth}");
            if depth < 1e-4 {
                on.push(p);
            }
        }
        assert!(on.len() > 1500, "{}", on.len());
        let reach = |v: Vector3<f64>| on.iter().map(|p| p.coords.dot(&v)).fold(f64::MIN, f64::max);
        for v in [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
        ] {
            assert!(reach(v) > 0.06, "{v:?}: {}", reach(v));
        }
    }

    #[test]
    fn pivoting_keeps_the_tip_in_the_divot_and_bad_figures_are_named() {
        let mut op = operator(OperatorConfig::default());
        let mut t = 0.0;
        let mut turned: f64 = 0.0;
        let first = op.at(0.5, &Ask::Pivot);
        while t < 6.0 {
            t += 0.05;
            let at = op.at(0.5 + t, &Ask::Pivot);
            let PointerAt::Tracker(p) = at else {
                panic!("{at:?}")
            };
            let PointerAt::Tracker(p0) = first else {
                panic!()
            };
            assert!(
                (p * Point3::from(op.tip_in_marker) - Point3::from(DIVOT_IN_TRACKER)).norm()
                    < 1e-12
            );
            turned = turned.max(p.rotation.angle_to(&p0.rotation));
        }
        assert!(turned > 0.5, "{turned}");
        let bad = OperatorConfig {
            speed_mm_s: 0.0,
            ..OperatorConfig::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "speed_mm_s");
    }
}
