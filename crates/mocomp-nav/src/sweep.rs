//! The scalp swept with the pointer, told apart from the pointer in the air: a tip is a skin
//! point only while it slides along the skin. Over a short window (head marker frame, carried
//! into the image by the registration so far) the tip's distance to the scalp must be within
//! [`SweepOptions::near_m`] (the registration so far is a few millimetres off at worst), that
//! distance must not be changing faster than [`SweepOptions::max_normal_speed_m_s`] (approaching,
//! lifting off), and the tip must be moving at least [`SweepOptions::min_speed_m_s`] (a pause is
//! as likely in the air as on the skin, and lingering adds nothing). Kept points are
//! [`SweepOptions::spacing_m`] apart. The fit's own gate ([`crate::solve`]) then leaves out what
//! slipped through.

use crate::scalp::Scalp;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use std::collections::VecDeque;

/// How a sweep is taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepOptions {
    /// The least distance between kept points, m.
    pub spacing_m: f64,
    /// The window the tip's motion is judged over, s.
    pub window_s: f64,
    /// A tip farther from the scalp than this is in the air, m.
    pub near_m: f64,
    /// A tip whose distance to the scalp changes faster than this is approaching or lifting, m/s.
    pub max_normal_speed_m_s: f64,
    /// A tip slower than this is paused, m/s.
    pub min_speed_m_s: f64,
}

impl Default for SweepOptions {
    /// 3 mm apart; judged over 0.1 s; within 8 mm of the scalp; 20 mm/s across it at most;
    /// sliding at 10 mm/s at least.
    fn default() -> Self {
        Self {
            spacing_m: 3e-3,
            window_s: 0.1,
            near_m: 8e-3,
            max_normal_speed_m_s: 0.02,
            min_speed_m_s: 0.01,
        }
    }
}

/// Why tips were not kept.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SweepRejects {
    /// Approaching or lifting off.
    pub moving_across: usize,
    /// Paused.
    pub paused: usize,
    /// Too far from the scalp.
    pub in_the_air: usize,
}

/// The sweep's state.
#[derive(Debug, Clone)]
pub struct SweepCapture {
    options: SweepOptions,
    window: VecDeque<(f64, Point3<f64>, f64)>,
    points: Vec<Point3<f64>>,
    rejects: SweepRejects,
}

impl SweepCapture {
    /// An empty sweep.
    pub fn new(options: SweepOptions) -> Self {
        Self {
            options,
            window: VecDeque::new(),
            points: Vec::new(),
            rejects: SweepRejects::default(),
        }
    }

    /// The points kept, head marker frame.
    pub fn points(&self) -> &[Point3<f64>] {
        &self.points
    }

    /// Why others were not.
    pub fn rejects(&self) -> SweepRejects {
        self.rejects
    }

    /// Takes the tip at time `t` (s; head marker frame; not finite: the marker lost, which
    /// empties the window), judged against `scalp` through `image_from_marker`; true when it
    /// was kept.
    pub fn feed(
        &mut self,
        t: f64,
        tip: &Point3<f64>,
        scalp: &Scalp<'_>,
        image_from_marker: &Isometry3<f64>,
    ) -> bool {
        if !tip.coords.iter().all(|c| c.is_finite()) {
            self.window.clear();
            return false;
        }
        let q = image_from_marker * tip;
        let d = scalp.nearest(&q).signed_distance;
        self.window.push_back((t, *tip, d));
        while self
            .window
            .front()
            .is_some_and(|(t0, ..)| t - t0 > self.options.window_s)
        {
            self.window.pop_front();
        }
        let spaced = self
            .points
            .last()
            .is_none_or(|p| (tip - p).norm() >= self.options.spacing_m);
        let Some((first_t, first, _)) = self.window.front().copied() else {
            return false;
        };
        let span = t - first_t;
        if !spaced || self.window.len() < 4 || span < 0.6 * self.options.window_s {
            return false;
        }
        let speed = (tip - first).norm() / span;
        let across = slope(&self.window);
        if d.abs() > self.options.near_m {
            self.rejects.in_the_air += 1;
        } else if across.abs() > self.options.max_normal_speed_m_s {
            self.rejects.moving_across += 1;
        } else if speed < self.options.min_speed_m_s {
            self.rejects.paused += 1;
        } else {
            self.points.push(*tip);
            return true;
        }
        false
    }
}

/// The least-squares slope of the distance over time in the window, m/s.
fn slope(window: &VecDeque<(f64, Point3<f64>, f64)>) -> f64 {
    let n = window.len() as f64;
    let tm = window.iter().map(|(t, ..)| t).sum::<f64>() / n;
    let dm = window.iter().map(|(.., d)| d).sum::<f64>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (t, _, d) in window {
        num += (t - tm) * (d - dm);
        den += (t - tm).powi(2);
    }
    if den > 0.0 { num / den } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::Vector3;
    use mocomp_head::Ellipsoid;

    #[test]
    fn sliding_on_the_skin_is_kept_and_approaching_lifting_and_hovering_are_not() {
        let r = 0.09;
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(r, r, r)).expect("sphere");
        let scalp = Scalp::whole(&head);
        let mut s = SweepCapture::new(SweepOptions::default());
        let id = Isometry3::identity();
        let mut t = 0.0;
        let dt = 1.0 / 60.0;
        // Down onto the crown from 60 mm at 60 mm/s.
        for k in 0..60 {
            t += dt;
            let z = r + 0.06 - 0.001 * k as f64;
            assert!(!s.feed(t, &Point3::new(0.0, 0.0, z), &scalp, &id), "{z}");
        }
        let approaching = s.rejects();
        assert!(
            approaching.moving_across + approaching.in_the_air > 10,
            "{approaching:?}"
        );
        // Along a meridian at 40 mm/s, 0.5 mm into the skin: 0.4 rad in a second.
        let before = s.points().len();
        for k in 0..60 {
            t += dt;
            let a = 0.4 * k as f64 / 60.0;
            let p = Point3::new((r - 5e-4) * a.sin(), 0.0, (r - 5e-4) * a.cos());
            s.feed(t, &p, &scalp, &id);
        }
        let kept = s.points().len() - before;
        // 36 mm of path, 3 mm apart: about 11, less the window's start.
        assert!((8..=13).contains(&kept), "{kept}");
        // Hovering 5 mm above the skin: near enough, but still.
        let hover = Point3::new(0.0, 0.0, r + 0.005);
        let before = s.points().len();
        for _ in 0..60 {
            t += dt;
            s.feed(t, &hover, &scalp, &id);
        }
        assert_eq!(s.points().len(), before);
        assert!(s.rejects().paused >= 1, "{:?}", s.rejects());
        assert!(s.points().windows(2).all(|w| (w[1] - w[0]).norm() >= 3e-3));
    }
}
