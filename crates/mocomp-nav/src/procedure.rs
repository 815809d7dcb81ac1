//! The registration procedure as the operator goes through it, fed the pointer's tip (head
//! marker frame) sample by sample and telling what to do next:
//! 1. each landmark touched in turn ([`crate::capture`]);
//! 2. the landmarks checked against each other ([`misplaced`]): a landmark whose distances to
//!    the others disagree with the image's is asked for again, up to [`Settings::retouches`]
//!    times;
//! 3. the scalp swept ([`crate::sweep`]), the registration solved again every
//!    [`SOLVE_EVERY`] points, and the region whose sweep would help most named; the sweep ends when
//!    the error bound at every target is under [`Settings::sweep_until_m`], or at its most points;
//! 4. the registration of all of it, and its [`verdict`].
//!
//! The live command and the simulated rehearsal run this same code: no clock, no I/O.

use crate::NavError;
use crate::capture::{CaptureOptions, Captured, LandmarkCapture, Touch};
use crate::landmarks::Landmark;
use crate::noise::NoiseModel;
use crate::regions::{Region, region_to_sweep, regions};
use crate::registration::{
    ImageLandmark, Registration, on_scalp, register_checked, register_on_scalp,
};
use crate::scalp::Scalp;
use crate::solve::Pair;
use crate::sweep::{SweepCapture, SweepOptions, SweepRejects};
use crate::verdict::{Limits, Refusal, Target, misplaced, verdict};
use mocomp_geom::nalgebra::{Isometry3, Point3};

/// The sweep's registration is solved again every this many new points.
pub const SOLVE_EVERY: usize = 20;

/// How the procedure runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The landmarks to touch, in order.
    pub landmarks: Vec<String>,
    /// The noise the registration is weighed by.
    pub noise: NoiseModel,
    /// How a touch is told apart.
    pub capture: CaptureOptions,
    /// How sweep points are taken.
    pub sweep: SweepOptions,
    /// The fewest sweep points before the sweep may end early.
    pub min_points: usize,
    /// The most sweep points (0: the landmarks alone).
    pub max_points: usize,
    /// The sweep ends once the error bound at every target is under this, m (0: only at
    /// `max_points`).
    pub sweep_until_m: f64,
    /// How often a landmark that disagrees is asked for again.
    pub retouches: usize,
    /// Where the error matters.
    pub targets: Vec<Target>,
    /// What the result is held to.
    pub limits: Limits,
}

/// What the operator is to do now.
#[derive(Debug, Clone, PartialEq)]
pub enum Prompt {
    /// Touch this landmark and hold still.
    Touch(String),
    /// Take the pointer off this landmark.
    TakeAway(String),
    /// Sweep the scalp: points so far, the most, and the region to sweep when one is named.
    Sweep {
        /// Points kept so far.
        taken: usize,
        /// The most.
        of: usize,
        /// Where to sweep.
        region: Option<String>,
    },
    /// All is in.
    Done,
}

/// Something to tell the operator.
#[derive(Debug, Clone, PartialEq)]
pub enum Notice {
    /// A landmark is in.
    Touched(Touch),
    /// A hold that was not taken, and why.
    NotTaken(String),
    /// A landmark to touch again, and why.
    Again {
        /// The landmark.
        name: String,
        /// Why.
        why: String,
    },
    /// A region to sweep, the worst bound now and after it, m.
    SweepThere {
        /// The region.
        region: String,
        /// The worst bound at the targets now, m.
        now_m: f64,
        /// After a thorough sweep of it, m.
        after_m: f64,
    },
    /// The sweep is enough: the worst bound at the targets, m.
    Enough(f64),
}

impl std::fmt::Display for Notice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Touched(t) => write!(
                f,
                "{}: touched (the burst within {:.2} mm)",
                t.landmark.name,
                t.spread_m * 1e3
            ),
            Self::NotTaken(why) => f.write_str(why),
            Self::Again { name, why } => write!(f, "{why}: touch the {name} again"),
            Self::SweepThere {
                region,
                now_m,
                after_m,
            } => write!(
                f,
                "sweep the {region} (the error bound at the targets {:.1} mm now, {:.1} mm after it)",
                now_m * 1e3,
                after_m * 1e3
            ),
            Self::Enough(b) => write!(
                f,
                "enough sweep: the error bound at every target is {:.1} mm at most",
                b * 1e3
            ),
        }
    }
}

/// What the procedure ended with.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The registration (an error when none could be computed).
    pub registration: Result<Registration, NavError>,
    /// Why it may not be used (empty: it may).
    pub refusals: Vec<Refusal>,
    /// The error bound at each target, m.
    pub bounds: Vec<(String, f64)>,
    /// The landmarks as touched, head marker frame.
    pub touched: Vec<Touch>,
    /// The sweep's points, head marker frame.
    pub swept: Vec<Point3<f64>>,
    /// The tips not taken as sweep points.
    pub rejects: SweepRejects,
}

enum Stage {
    Landmarks(Box<LandmarkCapture>),
    Sweep,
    Done,
}

/// The procedure's state.
pub struct Procedure<'a> {
    scalp: Scalp<'a>,
    settings: Settings,
    image: Vec<ImageLandmark>,
    regions: Vec<Region>,
    stage: Stage,
    touched: Vec<Option<Touch>>,
    queue: Vec<usize>,
    asked_again: Vec<usize>,
    sweep: SweepCapture,
    estimate: Option<Registration>,
    solved_at: usize,
    region: Option<String>,
}

impl std::fmt::Debug for Procedure<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Procedure")
            .field("prompt", &self.prompt())
            .finish_non_exhaustive()
    }
}

impl<'a> Procedure<'a> {
    /// The procedure on `scalp` (image frame) with the `image`'s landmarks, which are put on the
    /// scalp (a landmark far off it, or on a scan's cut, is refused).
    pub fn new(scalp: Scalp<'a>, image: &[Landmark], settings: Settings) -> Result<Self, NavError> {
        settings
            .noise
            .validate()
            .map_err(|e| NavError::Noise(e.to_string()))?;
        let mut wanted = Vec::new();
        for name in &settings.landmarks {
            let l = image
                .iter()
                .find(|l| l.name.eq_ignore_ascii_case(name))
                .ok_or_else(|| NavError::NoImageLandmark { name: name.clone() })?;
            wanted.push(l.clone());
        }
        let image = on_scalp(&scalp, &wanted)?;
        let regions = regions(&scalp, &image);
        let first = LandmarkCapture::new(&image[0].name, settings.capture);
        let n = image.len();
        if n < 3 {
            return Err(NavError::TooFewLandmarks {
                paired: image.iter().map(|l| l.name.clone()).collect(),
            });
        }
        Ok(Self {
            scalp,
            sweep: SweepCapture::new(settings.sweep),
            settings,
            image,
            regions,
            stage: Stage::Landmarks(Box::new(first)),
            touched: vec![None; n],
            queue: (1..n).collect(),
            asked_again: vec![0; n],
            estimate: None,
            solved_at: 0,
            region: None,
        })
    }

    /// The image's landmarks on the scalp.
    pub fn image_landmarks(&self) -> &[ImageLandmark] {
        &self.image
    }

    /// The landmarks touched so far, in the image's order.
    pub fn touched(&self) -> Vec<Touch> {
        self.touched.iter().flatten().cloned().collect()
    }

    /// The sweep's points so far.
    pub fn swept(&self) -> &[Point3<f64>] {
        self.sweep.points()
    }

    /// What the operator is to do now.
    pub fn prompt(&self) -> Prompt {
        match &self.stage {
            Stage::Landmarks(c) if c.holding() => Prompt::TakeAway(c.name().to_string()),
            Stage::Landmarks(c) => Prompt::Touch(c.name().to_string()),
            Stage::Sweep => Prompt::Sweep {
                taken: self.sweep.points().len(),
                of: self.settings.max_points,
                region: self.region.clone(),
            },
            Stage::Done => Prompt::Done,
        }
    }

    /// Takes the tip at time `t` (s; head marker frame; not finite: a marker lost); returns what
    /// to tell the operator.
    pub fn feed(&mut self, t: f64, tip: &Point3<f64>) -> Vec<Notice> {
        let mut said = Vec::new();
        match &mut self.stage {
            Stage::Landmarks(capture) => {
                let index = self.image.iter().position(|l| l.name == capture.name());
                let consistent = |p: &Point3<f64>| {
                    index.and_then(|i| {
                        far_from_others(
                            &self.image,
                            &self.touched,
                            i,
                            p,
                            self.settings.capture.consistent_within_m,
                        )
                    })
                };
                match capture.feed(t, tip, &consistent) {
                    Some(Captured::Touched(touch)) => {
                        if let Some(i) = index {
                            self.touched[i] = Some(touch.clone());
                        }
                        said.push(Notice::Touched(touch));
                        self.next_landmark(&mut said);
                    }
                    Some(Captured::Dropped(why)) => said.push(Notice::NotTaken(why)),
                    None => {}
                }
            }
            Stage::Sweep => {
                let pose = self
                    .estimate
                    .as_ref()
                    .map_or_else(Isometry3::identity, |e| e.image_from_marker);
                if self.sweep.feed(t, tip, &self.scalp, &pose) {
                    self.after_sweep_point(&mut said);
                }
            }
            Stage::Done => {}
        }
        said
    }

    /// After a landmark: the next in the queue, or the check of them all, then the sweep.
    fn next_landmark(&mut self, said: &mut Vec<Notice>) {
        if let Some(i) = self.queue.first().copied() {
            self.queue.remove(0);
            self.stage = Stage::Landmarks(Box::new(LandmarkCapture::new(
                &self.image[i].name,
                self.settings.capture,
            )));
            return;
        }
        let pairs: Vec<Pair> = self
            .image
            .iter()
            .zip(&self.touched)
            .filter_map(|(l, t)| {
                t.as_ref().map(|t| Pair {
                    name: l.name.clone(),
                    image: l.point,
                    normal: l.normal,
                    touched: t.landmark.point,
                })
            })
            .collect();
        let again: Vec<(usize, String)> = misplaced(&pairs, &self.settings.noise)
            .into_iter()
            .filter_map(|(k, why)| {
                let i = self.image.iter().position(|l| l.name == pairs[k].name)?;
                Some((i, why))
            })
            .collect();
        let mut asked = false;
        for (i, why) in again {
            if self.asked_again[i] < self.settings.retouches {
                self.asked_again[i] += 1;
                said.push(Notice::Again {
                    name: self.image[i].name.clone(),
                    why,
                });
                self.queue.push(i);
                asked = true;
            }
        }
        if asked {
            self.next_landmark(said);
            return;
        }
        let touched: Vec<Landmark> = self.touched().into_iter().map(|t| t.landmark).collect();
        self.estimate = register_on_scalp(
            &self.scalp,
            &self.image,
            &touched,
            &[],
            &self.settings.noise,
        )
        .ok();
        if self.settings.max_points == 0 || self.estimate.is_none() {
            self.stage = Stage::Done;
        } else {
            self.stage = Stage::Sweep;
            self.name_region(said);
        }
    }

    /// After a sweep point: solve again every [`SOLVE_EVERY`] points, and end the sweep when it
    /// is enough or full.
    fn after_sweep_point(&mut self, said: &mut Vec<Notice>) {
        let n = self.sweep.points().len();
        if n >= self.settings.max_points {
            self.stage = Stage::Done;
            return;
        }
        if n < self.solved_at + SOLVE_EVERY {
            return;
        }
        self.solved_at = n;
        let touched: Vec<Landmark> = self.touched().into_iter().map(|t| t.landmark).collect();
        if let Ok(r) = register_on_scalp(
            &self.scalp,
            &self.image,
            &touched,
            self.sweep.points(),
            &self.settings.noise,
        ) {
            self.estimate = Some(r);
        }
        let worst = self.worst_bound();
        if n >= self.settings.min_points && worst <= self.settings.sweep_until_m {
            said.push(Notice::Enough(worst));
            self.stage = Stage::Done;
            return;
        }
        self.name_region(said);
    }

    /// The worst error bound at the targets now, m.
    fn worst_bound(&self) -> f64 {
        self.estimate.as_ref().map_or(f64::INFINITY, |e| {
            self.settings
                .targets
                .iter()
                .map(|t| e.error_bound_at(&t.point))
                .fold(0.0, f64::max)
        })
    }

    /// Names the region to sweep when it changed.
    fn name_region(&mut self, said: &mut Vec<Notice>) {
        let Some(e) = &self.estimate else { return };
        let Some(information) = e.covariance.try_inverse() else {
            return;
        };
        let points: Vec<Point3<f64>> = self.settings.targets.iter().map(|t| t.point).collect();
        let now_m = self.worst_bound();
        let swept = on_skin(&self.scalp, &e.image_from_marker, self.sweep.points());
        let best = region_to_sweep(
            &self.regions,
            &information,
            &swept,
            &self.settings.noise,
            &points,
        );
        let name = best.map(|(r, _)| r.name.to_string());
        if name != self.region {
            if let (Some(region), Some((_, after_m))) = (&name, best) {
                said.push(Notice::SweepThere {
                    region: region.clone(),
                    now_m,
                    after_m,
                });
            }
            self.region = name;
        }
    }

    /// Whether all is in.
    pub fn done(&self) -> bool {
        matches!(self.stage, Stage::Done)
    }

    /// The registration of all that was taken, and its verdict.
    pub fn finish(self) -> Outcome {
        let touched_all = self.touched();
        let touched: Vec<Landmark> = touched_all.iter().map(|t| t.landmark.clone()).collect();
        let registration = register_checked(
            &self.scalp,
            &self.image,
            &touched,
            self.sweep.points(),
            &self.settings.noise,
        );
        let (refusals, bounds) = match &registration {
            Ok(r) => (
                verdict(
                    r,
                    &self.settings.targets,
                    &self.settings.limits,
                    &self.regions,
                    &on_skin(&self.scalp, &r.image_from_marker, self.sweep.points()),
                ),
                self.settings
                    .targets
                    .iter()
                    .map(|t| (t.name.clone(), r.error_bound_at(&t.point)))
                    .collect(),
            ),
            Err(_) => (Vec::new(), Vec::new()),
        };
        Outcome {
            registration,
            refusals,
            bounds,
            touched: touched_all,
            swept: self.sweep.points().to_vec(),
            rejects: self.sweep.rejects(),
        }
    }
}

/// The swept points (head marker frame) carried into the image by `image_from_marker`, on the
/// scalp, with its normals there.
fn on_skin(
    scalp: &Scalp<'_>,
    image_from_marker: &Isometry3<f64>,
    swept: &[Point3<f64>],
) -> Vec<(Point3<f64>, mocomp_geom::nalgebra::Vector3<f64>)> {
    swept
        .iter()
        .map(|p| {
            let s = scalp.nearest(&(image_from_marker * p));
            (s.point, s.normal.into_inner())
        })
        .collect()
}

/// Why a hold at `p` is not landmark `i`: its distance to a landmark already touched differs
/// from the image's by more than `within` (m).
fn far_from_others(
    image: &[ImageLandmark],
    touched: &[Option<Touch>],
    i: usize,
    p: &Point3<f64>,
    within: f64,
) -> Option<String> {
    image
        .iter()
        .zip(touched)
        .enumerate()
        .find_map(|(j, (l, t))| {
            let t = t.as_ref().filter(|_| j != i)?;
            let off = (p - t.landmark.point).norm() - (image[i].point - l.point).norm();
            (off.abs() > within).then(|| {
                format!(
                    "{:.0} mm {} the {} than the image has it",
                    off.abs() * 1e3,
                    if off > 0.0 {
                        "farther from"
                    } else {
                        "nearer to"
                    },
                    l.name
                )
            })
        })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)] // test code
    use super::*;
    use crate::{CaptureOptions, SweepOptions};
    use mocomp_geom::nalgebra::Vector3;
    use mocomp_head::{Ellipsoid, HeadShape};

    fn settings(targets: Vec<Target>) -> Settings {
        Settings {
            landmarks: vec!["nasion".into(), "lpa".into(), "rpa".into()],
            noise: NoiseModel::default(),
            capture: CaptureOptions::default(),
            sweep: SweepOptions::default(),
            min_points: 40,
            max_points: 0,
            sweep_until_m: 0.0,
            retouches: 2,
            targets,
            limits: Limits {
                max_fre_m: 4e-3,
                max_error_m: 1.0,
            },
        }
    }

    /// A touch at `at` on `head` (image frame = marker frame here): the pointer brought straight
    /// from where the last touch left it to 50 mm out along the normal, in, held 1.5 s, lifted;
    /// 60 tips a second from `t`. Its half-second before the touch spans the jump from the last
    /// landmark: what counts as its arrival is the last stretch in.
    fn touch(p: &mut Procedure<'_>, head: &Ellipsoid, at: Point3<f64>, t: &mut f64) -> Vec<Notice> {
        let n = head.nearest(&at).normal.into_inner();
        let mut said = Vec::new();
        let mut feed = |q: Point3<f64>, said: &mut Vec<Notice>| {
            *t += 1.0 / 60.0;
            said.extend(p.feed(*t, &q));
        };
        for k in 0..30 {
            feed(at + n * (0.05 * (1.0 - k as f64 / 29.0)), &mut said);
        }
        for _ in 0..90 {
            feed(at, &mut said);
        }
        for k in 0..30 {
            feed(at + n * (0.05 * k as f64 / 29.0), &mut said);
        }
        said
    }

    /// The lpa touched 15 mm behind its place (held on, so it is taken): the landmarks' check asks
    /// for it again by name (with the nasion, the one distance that disagrees being theirs), and
    /// touched right as asked, the procedure goes on to its end.
    #[test]
    fn a_landmark_touched_in_the_wrong_place_is_asked_for_again_by_name() {
        let head = Ellipsoid::adult();
        let on = |d: Vector3<f64>| head.nearest(&Point3::from(d * 0.2)).point;
        let image = vec![
            Landmark::new("nasion", on(Vector3::new(0.0, 1.0, -0.3))),
            Landmark::new("lpa", on(Vector3::new(-1.0, 0.0, -0.3))),
            Landmark::new("rpa", on(Vector3::new(1.0, 0.0, -0.3))),
        ];
        let scalp = Scalp::whole(&head);
        let mut p = Procedure::new(scalp, &image, settings(Vec::new())).unwrap();
        let mut t = 0.0;
        assert_eq!(p.prompt(), Prompt::Touch("nasion".into()));
        touch(&mut p, &head, image[0].point, &mut t);
        assert_eq!(p.prompt(), Prompt::Touch("lpa".into()));
        let wrong = head
            .nearest(&(image[1].point + Vector3::new(0.0, -0.015, 0.0)))
            .point;
        touch(&mut p, &head, wrong, &mut t);
        let said = touch(&mut p, &head, image[2].point, &mut t);
        assert!(
            said.iter()
                .any(|n| matches!(n, Notice::Again { name, .. } if name == "lpa")),
            "{said:?}"
        );
        // Touched where asked, now right.
        for _ in 0..4 {
            let Prompt::Touch(name) = p.prompt() else {
                break;
            };
            let at = image.iter().find(|l| l.name == name).unwrap().point;
            touch(&mut p, &head, at, &mut t);
        }
        assert!(p.done(), "{:?}", p.prompt());
        let out = p.finish();
        let r = out.registration.unwrap();
        let lpa = r.landmarks.iter().find(|l| l.name == "lpa").unwrap();
        assert!(lpa.error_m < 2e-3, "{lpa:?}");
        assert!(out.refusals.is_empty(), "{:?}", out.refusals);
    }
}
