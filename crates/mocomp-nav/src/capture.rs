//! What the operator does with the pointer during registration, told apart from the stream of
//! its tip (head marker frame): each landmark in turn is touched and **held** (the median of a
//! burst of tips that agree within [`CaptureOptions::hold_within_m`]), the pointer is **taken
//! away** before the next (so one long touch is never two landmarks), then it is **swept** over
//! the scalp (tips kept [`CaptureOptions::sweep_spacing_m`] apart, so lingering adds nothing).
//! No clock, no I/O: the caller feeds tips as they arrive and says what the operator must do.

use crate::Landmark;
use mocomp_geom::nalgebra::Point3;

/// How the capture tells holding from moving.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureOptions {
    /// Tips in a burst (at 60 Hz, 20 is a third of a second).
    pub hold_samples: usize,
    /// How near the burst's median every tip of it must be, m.
    pub hold_within_m: f64,
    /// How far the tip must go from the last landmark before the next one counts, m.
    pub away_m: f64,
    /// The least distance between kept sweep points, m.
    pub sweep_spacing_m: f64,
    /// Sweep points to collect.
    pub sweep_points: usize,
}

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            hold_samples: 20,
            hold_within_m: 1e-3,
            away_m: 0.015,
            sweep_spacing_m: 0.003,
            sweep_points: 100,
        }
    }
}

/// What the operator should be doing now.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Touch this landmark and hold still.
    Touch(String),
    /// Take the pointer off the last landmark.
    TakeAway(String),
    /// Sweep the scalp: so many points so far, of so many.
    Sweep(usize, usize),
    /// All is in.
    Done,
}

/// Something captured.
#[derive(Debug, Clone, PartialEq)]
pub enum Captured {
    /// A landmark: its name, the burst's median, how far its farthest tip was from it (m).
    Landmark(Landmark, f64),
    /// The sweep is complete.
    SweepDone,
}

/// The capture's state.
#[derive(Debug, Clone)]
pub struct Capture {
    names: Vec<String>,
    options: CaptureOptions,
    burst: Vec<Point3<f64>>,
    landmarks: Vec<Landmark>,
    spreads: Vec<f64>,
    away: bool,
    sweep: Vec<Point3<f64>>,
}

impl Capture {
    /// A capture of the landmarks `names`, in that order, then the sweep.
    pub fn new(names: &[&str], options: CaptureOptions) -> Self {
        Self {
            names: names.iter().map(|n| n.to_string()).collect(),
            options,
            burst: Vec::with_capacity(options.hold_samples),
            landmarks: Vec::new(),
            spreads: Vec::new(),
            away: true,
            sweep: Vec::with_capacity(options.sweep_points),
        }
    }

    /// What the operator should do now.
    pub fn step(&self) -> Step {
        match self.names.get(self.landmarks.len()) {
            Some(next) if self.away => Step::Touch(next.clone()),
            _ if !self.away => Step::TakeAway(
                self.landmarks
                    .last()
                    .map(|l| l.name.clone())
                    .unwrap_or_default(),
            ),
            _ if self.sweep.len() < self.options.sweep_points => {
                Step::Sweep(self.sweep.len(), self.options.sweep_points)
            }
            _ => Step::Done,
        }
    }

    /// The landmarks touched so far.
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks
    }

    /// How far each landmark's burst spread about its median, m (in the order touched).
    pub fn landmark_spreads(&self) -> &[f64] {
        &self.spreads
    }

    /// The sweep's points so far.
    pub fn sweep(&self) -> &[Point3<f64>] {
        &self.sweep
    }

    /// Takes the next tip (head marker frame); says what it completed, if anything. A tip that
    /// is not finite (a marker lost) breaks a burst.
    pub fn feed(&mut self, tip: &Point3<f64>) -> Option<Captured> {
        if !tip.coords.iter().all(|c| c.is_finite()) {
            self.burst.clear();
            return None;
        }
        if !self.away {
            let last = self.landmarks.last().map(|l| l.point)?;
            if (tip - last).norm() > self.options.away_m {
                self.away = true;
                self.burst.clear();
            }
            return None;
        }
        if self.landmarks.len() < self.names.len() {
            return self.hold(tip);
        }
        if self.sweep.len() >= self.options.sweep_points {
            return None;
        }
        let spaced = self
            .sweep
            .last()
            .is_none_or(|p| (tip - p).norm() >= self.options.sweep_spacing_m);
        if spaced {
            self.sweep.push(*tip);
            if self.sweep.len() == self.options.sweep_points {
                return Some(Captured::SweepDone);
            }
        }
        None
    }

    fn hold(&mut self, tip: &Point3<f64>) -> Option<Captured> {
        if self.burst.len() == self.options.hold_samples {
            self.burst.remove(0);
        }
        self.burst.push(*tip);
        if self.burst.len() < self.options.hold_samples {
            return None;
        }
        let median = median(&self.burst);
        let spread = self
            .burst
            .iter()
            .map(|p| (p - median).norm())
            .fold(0.0, f64::max);
        if spread > self.options.hold_within_m {
            return None;
        }
        let name = self.names[self.landmarks.len()].clone();
        let landmark = Landmark::new(&name, median);
        self.landmarks.push(landmark.clone());
        self.spreads.push(spread);
        self.burst.clear();
        self.away = false;
        Some(Captured::Landmark(landmark, spread))
    }
}

/// The per-axis median: a slip at the burst's end does not move it.
fn median(points: &[Point3<f64>]) -> Point3<f64> {
    let axis = |k: usize| {
        let mut v: Vec<f64> = points.iter().map(|p| p[k]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Point3::new(axis(0), axis(1), axis(2))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    fn jitter(k: usize) -> f64 {
        // A fixed small wobble, ±0.2 mm.
        ((k * 7919) % 41) as f64 / 40.0 * 4e-4 - 2e-4
    }

    #[test]
    fn holds_then_moves_then_a_sweep_make_landmarks_and_surface_points() {
        let mut c = Capture::new(&["nasion", "lpa", "rpa"], CaptureOptions::default());
        let spots = [
            Point3::new(0.0, 0.09, 0.0),
            Point3::new(-0.08, 0.0, 0.0),
            Point3::new(0.08, 0.0, 0.0),
        ];
        let mut got = Vec::new();
        let mut k = 0;
        for (i, spot) in spots.iter().enumerate() {
            assert_eq!(c.step(), Step::Touch(["nasion", "lpa", "rpa"][i].into()));
            // On the way in: moving, so nothing is taken.
            for s in 0..30 {
                let p = spot + nalgebra_offset(0.05 * (1.0 - s as f64 / 30.0));
                assert!(c.feed(&p).is_none());
            }
            // Held for a second, one tip 5 mm off: the median ignores it, the burst waits it out.
            for s in 0..60 {
                k += 1;
                let slip = if s == 3 { 0.005 } else { 0.0 };
                let p = spot + nalgebra_offset(slip + jitter(k));
                if let Some(Captured::Landmark(l, spread)) = c.feed(&p) {
                    got.push((l, spread));
                }
            }
            assert!(matches!(c.step(), Step::TakeAway(_)));
            for s in 0..10 {
                c.feed(&(spot + nalgebra_offset(0.002 * s as f64)));
            }
            c.feed(&(spot + nalgebra_offset(0.03)));
        }
        assert_eq!(got.len(), 3, "one landmark per hold: {got:?}");
        for ((l, spread), spot) in got.iter().zip(&spots) {
            assert!((l.point - spot).norm() < 4e-4, "{l:?}");
            assert!(*spread <= 1e-3);
        }
        // Taken away from the last landmark, the pointer is already sweeping.
        let Step::Sweep(already, 100) = c.step() else {
            panic!("{:?}", c.step())
        };
        assert!((1..=4).contains(&already), "{already}");
        let mut done = false;
        for s in 0..2000 {
            let a = s as f64 * 0.002;
            let p = Point3::new(0.09 * a.cos(), 0.09 * a.sin(), 0.02);
            // Lingering: the same point ten times adds one.
            for _ in 0..3 {
                done |= c.feed(&p) == Some(Captured::SweepDone);
            }
        }
        assert!(done);
        assert_eq!(c.sweep().len(), 100);
        assert_eq!(c.step(), Step::Done);
        assert!(c.sweep().windows(2).all(|w| (w[1] - w[0]).norm() >= 3e-3));
    }

    #[test]
    fn a_long_touch_is_one_landmark_and_a_lost_marker_breaks_the_burst() {
        let mut c = Capture::new(&["nasion", "lpa", "rpa"], CaptureOptions::default());
        let spot = Point3::new(0.0, 0.09, 0.0);
        let mut n = 0;
        for k in 0..19 {
            n += usize::from(c.feed(&(spot + nalgebra_offset(jitter(k)))).is_some());
        }
        c.feed(&Point3::new(f64::NAN, 0.0, 0.0));
        // 19 good tips, then a lost one: the burst starts again.
        assert_eq!(n, 0);
        for k in 0..400 {
            n += usize::from(c.feed(&(spot + nalgebra_offset(jitter(k)))).is_some());
        }
        assert_eq!(n, 1, "held for seconds on one landmark");
        assert_eq!(c.landmarks().len(), 1);
        assert_eq!(c.step(), Step::TakeAway("nasion".into()));
    }

    fn nalgebra_offset(d: f64) -> mocomp_geom::nalgebra::Vector3<f64> {
        mocomp_geom::nalgebra::Vector3::new(d, 0.5 * d, -0.3 * d)
    }
}
