//! Step 6: identify the fiducials among the measured points by their distances.
//!
//! An interpretation tree assigns each model fiducial a measured point (or, within the allowance,
//! none), keeping only branches where every assigned pair's measured distance matches the model's
//! within the tolerance. Extra points (reflections, sunlight) are simply never assigned. The two
//! best complete assignments are kept so the caller can reject ambiguous ones.

use crate::geometry::MarkerGeometry;
use mocomp_geom::nalgebra::Point3;

/// One assignment of measured points to model fiducials.
#[derive(Debug, Clone, PartialEq)]
pub struct Assignment {
    /// For each model fiducial, the index of its measured point.
    pub pairs: Vec<Option<usize>>,
    /// Fiducials matched.
    pub matched: usize,
    /// RMS difference between matched measured and model distances, metres.
    pub residual_m: f64,
}

impl Assignment {
    fn better_than(&self, o: &Assignment) -> bool {
        self.matched > o.matched || (self.matched == o.matched && self.residual_m < o.residual_m)
    }
}

/// The best and the runner-up assignment (if any).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Matches {
    /// The best assignment.
    pub best: Option<Assignment>,
    /// The second best, for ambiguity checks.
    pub second: Option<Assignment>,
}

struct Search<'a> {
    model: &'a MarkerGeometry,
    measured: &'a [Point3<f64>],
    dist: Vec<f64>,
    tol: f64,
    needed: usize,
    max_missing: usize,
    current: Vec<Option<usize>>,
    used: Vec<bool>,
    out: Matches,
}

impl Search<'_> {
    fn d(&self, i: usize, j: usize) -> f64 {
        self.dist[i * self.measured.len() + j]
    }

    fn go(&mut self, k: usize, missing: usize, sq_sum: f64, pair_count: usize) {
        let n = self.model.len();
        if k == n {
            let matched = n - missing;
            if matched < self.needed {
                return;
            }
            let a = Assignment {
                pairs: self.current.clone(),
                matched,
                residual_m: if pair_count > 0 {
                    (sq_sum / pair_count as f64).sqrt()
                } else {
                    0.0
                },
            };
            match &self.out.best {
                Some(b) if !a.better_than(b) => {
                    if self.out.second.as_ref().is_none_or(|s| a.better_than(s)) {
                        self.out.second = Some(a);
                    }
                }
                _ => {
                    self.out.second = self.out.best.take();
                    self.out.best = Some(a);
                }
            }
            return;
        }
        for j in 0..self.measured.len() {
            if self.used[j] {
                continue;
            }
            let mut add = 0.0;
            let mut pairs = 0;
            let mut ok = true;
            for i in 0..k {
                if let Some(mi) = self.current[i] {
                    let diff = self.d(mi, j) - self.model.distance(i, k);
                    if diff.abs() > self.tol {
                        ok = false;
                        break;
                    }
                    add += diff * diff;
                    pairs += 1;
                }
            }
            if !ok {
                continue;
            }
            self.used[j] = true;
            self.current.push(Some(j));
            self.go(k + 1, missing, sq_sum + add, pair_count + pairs);
            self.current.pop();
            self.used[j] = false;
        }
        if missing < self.max_missing {
            self.current.push(None);
            self.go(k + 1, missing + 1, sq_sum, pair_count);
            self.current.pop();
        }
    }
}

/// The best two assignments of `measured` to `model` whose distances agree within `tol`
/// (metres), allowing `max_missing` fiducials to be unmatched (only when the geometry has 4 or
/// more, and at least 3 must match).
pub fn match_points(
    model: &MarkerGeometry,
    measured: &[Point3<f64>],
    tol: f64,
    max_missing: usize,
) -> Matches {
    let n = model.len();
    let max_missing = if n >= 4 { max_missing.min(n - 3) } else { 0 };
    let m = measured.len();
    let mut dist = vec![0.0; m * m];
    for i in 0..m {
        for j in 0..m {
            dist[i * m + j] = (measured[i] - measured[j]).norm();
        }
    }
    let mut s = Search {
        model,
        measured,
        dist,
        tol,
        needed: n - max_missing,
        max_missing,
        current: Vec::with_capacity(n),
        used: vec![false; m],
        out: Matches::default(),
    };
    s.go(0, 0, 0.0, 0);
    s.out
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::{Isometry3, Translation3, Vector3};
    use mocomp_geom::quat_from_rotvec;

    fn geometry() -> MarkerGeometry {
        MarkerGeometry::ndi_8700449()
    }

    fn seen(g: &MarkerGeometry) -> Vec<Point3<f64>> {
        let t = Isometry3::from_parts(
            Translation3::new(0.05, -0.02, 0.9),
            quat_from_rotvec(&Vector3::new(0.3, 2.0, -0.4)),
        );
        g.points.iter().map(|p| t * p).collect()
    }

    #[test]
    fn finds_shuffled_points_among_distractors() {
        let g = geometry();
        let q = seen(&g);
        let measured = vec![
            Point3::new(0.3, 0.3, 1.0),
            q[2],
            q[0],
            Point3::new(0.06, -0.01, 0.95),
            q[3],
            q[1],
        ];
        let m = match_points(&g, &measured, 0.003, 1);
        let best = m.best.unwrap();
        assert_eq!(best.pairs, vec![Some(2), Some(5), Some(1), Some(4)]);
        assert_eq!(best.matched, 4);
    }

    #[test]
    fn tolerates_one_missing_fiducial_of_four() {
        let g = geometry();
        let q = seen(&g);
        let m = match_points(&g, &[q[3], q[0], q[2]], 0.003, 1);
        assert_eq!(m.best.unwrap().pairs, vec![Some(1), None, Some(2), Some(0)]);
        // Not allowed: nothing.
        assert!(
            match_points(&g, &[q[3], q[0], q[2]], 0.003, 0)
                .best
                .is_none()
        );
    }

    #[test]
    fn symmetric_geometries_give_a_runner_up() {
        let sq = crate::geometry::square_5cm();
        let q = seen(&sq);
        let m = match_points(&sq, &q, 0.002, 0);
        assert_eq!(m.best.as_ref().unwrap().matched, 4);
        assert_eq!(
            m.second.as_ref().unwrap().matched,
            4,
            "a square matches 8 ways"
        );
    }
}
