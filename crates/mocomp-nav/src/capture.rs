//! A landmark told apart in the pointer's stream (head marker frame): the operator brings the tip
//! onto the skin from the air, holds it (a burst of tips that agree within
//! [`CaptureOptions::hold_within_m`]: its median is the touch), and takes it away. People pause
//! on the way in, and hover after lifting off; a pause is still, like a touch, so what tells them
//! apart is what the pointer does next:
//! - a hold the tip then leaves **further in**, along the way it arrived, was a pause in the air
//!   (the skin stops a pointer; air does not): it is dropped, and the next hold replaces it;
//! - a hold the tip leaves any other way (lifted back out, or slid off sideways) was the touch.
//!
//! A hold is not taken at all when the tip did not arrive there (a pointer resting where it
//! was), nor, for a while, when its distances to the landmarks already taken disagree with the
//! image's by more than [`CaptureOptions::consistent_within_m`] (a hover after lifting off the
//! last one): held on for [`CaptureOptions::insist_s`], it is taken, since then the landmark
//! taken before may be the wrong one (the procedure's check of them all then says which).
//!
//! No clock, no I/O: the caller feeds tips with their times.

use crate::Landmark;
use mocomp_geom::nalgebra::{Point3, Vector3};
use std::collections::VecDeque;

/// How a capture tells holding from moving.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureOptions {
    /// Tips in a burst (at 60 Hz, 20 is a third of a second).
    pub hold_samples: usize,
    /// How near the burst's median every tip of it must be, m.
    pub hold_within_m: f64,
    /// How far the tip must go from a hold for it to count as left, m.
    pub away_m: f64,
    /// A hold's arrival is the way the tip came over its last this much before it, m (the
    /// last stretch of the way in, however fast: not the travel from the last landmark).
    pub arrival_m: f64,
    /// A hold whose distances to the landmarks already taken differ from the image's by more
    /// than this is not a touch of this landmark, m.
    pub consistent_within_m: f64,
    /// A hold that disagrees with the landmarks taken but is kept this long is taken all the
    /// same (the operator insists: the landmark taken before may be the wrong one, which the
    /// landmarks' check then asks for again), s.
    pub insist_s: f64,
}

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            hold_samples: 20,
            hold_within_m: 1e-3,
            away_m: 0.015,
            arrival_m: 0.015,
            consistent_within_m: 0.01,
            insist_s: 1.0,
        }
    }
}

/// The least arrival that gives a direction, m: a tip that crept in no farther leaves by any way.
const MIN_ARRIVAL_M: f64 = 0.005;
/// A tip leaving a hold within this angle's cosine of its arrival went further in.
const FURTHER_IN_COS: f64 = 0.7;
/// How much of the stream is kept to find a hold's arrival, s.
const HISTORY_S: f64 = 2.0;

/// A landmark touched: the burst's median, and how far its farthest tip was from it, m.
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    /// The landmark, head marker frame.
    pub landmark: Landmark,
    /// The burst's spread, m.
    pub spread_m: f64,
}

/// What a capture decided.
#[derive(Debug, Clone, PartialEq)]
pub enum Captured {
    /// The landmark is in.
    Touched(Touch),
    /// A hold that was not the touch, and why.
    Dropped(String),
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Hold {
    point: Point3<f64>,
    spread: f64,
    arrival: Option<Vector3<f64>>,
}

/// One landmark's capture.
#[derive(Debug, Clone)]
pub struct LandmarkCapture {
    name: String,
    options: CaptureOptions,
    history: VecDeque<(f64, Point3<f64>)>,
    burst: Vec<Point3<f64>>,
    burst_t0: f64,
    hold: Option<Hold>,
    /// A hold refused as disagreeing, and since when the tip has stayed on it.
    refused: Option<(Point3<f64>, f64)>,
}

impl LandmarkCapture {
    /// The capture of landmark `name`.
    pub fn new(name: &str, options: CaptureOptions) -> Self {
        Self {
            name: name.to_string(),
            options,
            history: VecDeque::new(),
            burst: Vec::with_capacity(options.hold_samples),
            burst_t0: 0.0,
            hold: None,
            refused: None,
        }
    }

    /// Its landmark's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether a hold waits for the pointer to be taken away.
    pub fn holding(&self) -> bool {
        self.hold.is_some()
    }

    /// Takes the tip at time `t` (s; head marker frame; not finite: the marker lost, which breaks
    /// a burst). `consistent` says why a hold at a point is not this landmark (its distances to
    /// those already taken), or `None`.
    pub fn feed(
        &mut self,
        t: f64,
        tip: &Point3<f64>,
        consistent: &dyn Fn(&Point3<f64>) -> Option<String>,
    ) -> Option<Captured> {
        if !tip.coords.iter().all(|c| c.is_finite()) {
            self.burst.clear();
            return None;
        }
        self.history.push_back((t, *tip));
        while self
            .history
            .front()
            .is_some_and(|(t0, _)| t - t0 > HISTORY_S)
        {
            self.history.pop_front();
        }
        if let Some(hold) = self.hold {
            let d = tip - hold.point;
            if d.norm() >= self.options.away_m {
                self.hold = None;
                self.burst.clear();
                let further_in = hold
                    .arrival
                    .is_some_and(|a| d.dot(&a) >= FURTHER_IN_COS * d.norm());
                if further_in {
                    return Some(Captured::Dropped(format!(
                        "{}: a pause in the air (the pointer went on further in), not taken",
                        self.name
                    )));
                }
                return Some(Captured::Touched(Touch {
                    landmark: Landmark::new(&self.name, hold.point),
                    spread_m: hold.spread,
                }));
            }
        }
        if self.burst.is_empty() {
            self.burst_t0 = t;
        }
        if self.burst.len() == self.options.hold_samples {
            self.burst.remove(0);
            self.burst_t0 = self
                .history
                .iter()
                .rev()
                .nth(self.options.hold_samples - 1)
                .map_or(t, |(t0, _)| *t0);
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
        // The same hold going on is not a new one.
        if self
            .hold
            .is_some_and(|h| (h.point - median).norm() <= 2.0 * self.options.hold_within_m)
        {
            return None;
        }
        // A hold refused before and held on since started then.
        let start = match self.refused {
            Some((p, since)) if (p - median).norm() <= 2.0 * self.options.hold_within_m => since,
            _ => self.burst_t0,
        };
        // Back from the hold's start: the last tip `arrival_m` from it, else the oldest kept.
        let mut earlier = self.history.iter().rev().filter(|(t0, _)| *t0 < start);
        let from = earlier
            .find(|(_, p)| (median - p).norm() >= self.options.arrival_m)
            .or_else(|| self.history.iter().find(|(t0, _)| *t0 < start));
        let arrival = from
            .map(|(_, p)| median - p)
            .filter(|a| a.norm() >= MIN_ARRIVAL_M)
            .map(|a| a.normalize());
        // A pointer resting where it was is not touching anything; one held where the landmarks
        // taken say this one is not is a hover, unless it stays.
        arrival?;
        if consistent(&median).is_some() {
            self.refused = Some((median, start));
            if t - start < self.options.insist_s {
                return None;
            }
        }
        self.refused = None;
        self.hold = Some(Hold {
            point: median,
            spread,
            arrival,
        });
        None
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
    #![allow(clippy::unwrap_used, clippy::panic)] // test code
    use super::*;

    const DT: f64 = 1.0 / 60.0;

    fn jitter(k: usize) -> Vector3<f64> {
        // A fixed small wobble, ±0.2 mm.
        let j = |m: usize| ((k * m) % 41) as f64 / 40.0 * 4e-4 - 2e-4;
        Vector3::new(j(7919), j(104_729), j(1_299_709))
    }

    /// Feeds `path` (one tip a sample) and returns what was captured.
    fn run(c: &mut LandmarkCapture, t: &mut f64, path: &[Point3<f64>]) -> Vec<Captured> {
        let mut got = Vec::new();
        for (k, p) in path.iter().enumerate() {
            *t += DT;
            if let Some(x) = c.feed(*t, &(p + jitter(k)), &|_| None) {
                got.push(x);
            }
        }
        got
    }

    fn line(from: Point3<f64>, to: Point3<f64>, n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|i| from + (to - from) * (i as f64 / (n - 1) as f64))
            .collect()
    }

    fn still(at: Point3<f64>, n: usize) -> Vec<Point3<f64>> {
        vec![at; n]
    }

    #[test]
    fn a_pause_in_the_air_is_not_the_touch_and_the_lift_off_takes_it() {
        let skin = Point3::new(0.0, 0.09, 0.0);
        let out = Vector3::new(0.0, 1.0, 0.0);
        let mut c = LandmarkCapture::new("nasion", CaptureOptions::default());
        let mut t = 0.0;
        let mut path = line(skin + out * 0.15, skin + out * 0.05, 40);
        path.extend(still(skin + out * 0.05, 50)); // paused 50 mm off
        path.extend(line(skin + out * 0.05, skin, 40));
        path.extend(still(skin, 60)); // the touch
        path.extend(line(skin, skin + out * 0.06, 30)); // lifted off
        let got = run(&mut c, &mut t, &path);
        assert_eq!(got.len(), 2, "{got:?}");
        assert!(
            matches!(&got[0], Captured::Dropped(why) if why.contains("pause")),
            "{got:?}"
        );
        let Captured::Touched(touch) = &got[1] else {
            panic!("{got:?}")
        };
        assert!((touch.landmark.point - skin).norm() < 4e-4, "{touch:?}");
    }

    #[test]
    fn a_touch_slid_off_sideways_counts_a_hover_far_from_the_others_does_not_and_one_kept_does() {
        let skin = Point3::new(-0.08, 0.0, 0.0);
        let out = Vector3::new(-1.0, 0.0, 0.0);
        let mut c = LandmarkCapture::new("lpa", CaptureOptions::default());
        let mut t = 0.0;
        // A hover 50 mm off, then the pointer goes sideways (to the landmark from another side).
        let hover = skin + out * 0.05;
        let mut path = line(skin + Vector3::new(0.0, 0.1, 0.05), hover, 40);
        path.extend(still(hover, 40));
        path.extend(line(hover, hover + Vector3::new(0.0, 0.0, 0.04), 20));
        let mut got = Vec::new();
        for (k, p) in path.iter().enumerate() {
            t += DT;
            let far = |q: &Point3<f64>| {
                ((q - skin).norm() > 0.02).then(|| "42 mm from where the image has it".into())
            };
            got.extend(c.feed(t, &(p + jitter(k)), &far));
        }
        assert!(got.is_empty(), "{got:?}");
        assert!(!c.holding());
        // Then the touch, slid off along the skin.
        let mut path = line(hover + Vector3::new(0.0, 0.0, 0.04), skin, 30);
        path.extend(still(skin, 40));
        path.extend(line(skin, skin + Vector3::new(0.0, 0.0, 0.03), 20));
        let got = run(&mut c, &mut t, &path);
        assert!(matches!(&got[..], [Captured::Touched(_)]), "{got:?}");
        // Held on for 1.5 s where the others say it is not: taken all the same.
        let mut c = LandmarkCapture::new("lpa", CaptureOptions::default());
        let mut path = line(skin + Vector3::new(0.0, 0.1, 0.05), hover, 40);
        path.extend(still(hover, 90));
        path.extend(line(hover, hover + Vector3::new(0.0, 0.0, 0.04), 20));
        let mut got = Vec::new();
        for (k, p) in path.iter().enumerate() {
            t += DT;
            let far = |_: &Point3<f64>| Some("42 mm from where the image has it".to_string());
            got.extend(c.feed(t, &(p + jitter(k)), &far));
        }
        assert!(
            matches!(&got[..], [Captured::Touched(x)] if (x.landmark.point - hover).norm() < 4e-4),
            "{got:?}"
        );
    }

    #[test]
    fn a_long_touch_is_one_hold_and_a_lost_marker_breaks_the_burst() {
        let spot = Point3::new(0.0, 0.09, 0.0);
        let mut c = LandmarkCapture::new("nasion", CaptureOptions::default());
        let mut t = 0.0;
        // Resting where it was is no hold.
        assert!(
            run(
                &mut c,
                &mut t,
                &still(spot + Vector3::new(0.0, 0.05, 0.0), 60)
            )
            .is_empty()
        );
        assert!(!c.holding());
        let arrive = line(spot + Vector3::new(0.0, 0.05, 0.0), spot, 30);
        assert!(run(&mut c, &mut t, &arrive).is_empty());
        // The arrival's last tip and 18 more, then a lost one: no hold yet.
        assert!(run(&mut c, &mut t, &still(spot, 18)).is_empty());
        c.feed(t, &Point3::new(f64::NAN, 0.0, 0.0), &|_| None);
        assert!(!c.holding(), "19 good tips, then a lost one: no hold yet");
        assert!(run(&mut c, &mut t, &still(spot, 400)).is_empty());
        assert!(c.holding());
        let got = run(
            &mut c,
            &mut t,
            &line(spot, spot + Vector3::new(0.0, 0.0, 0.05), 20),
        );
        assert_eq!(got.len(), 1, "held for seconds: one landmark");
    }
}
