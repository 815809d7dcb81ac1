//! The coil's error split into the prediction's share and the execution's: each command's aim
//! is judged at the time it aimed for, against the goal on the true head then and against where
//! the arm put the coil then. Pure arithmetic on the run's ticks.

use mocomp_geom::nalgebra::Vector3;

/// What one tick of a run knows for the split, in the loop's own frames (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    /// The coil this tick's command aimed for, and the run time it aimed for (s).
    pub aimed: Option<(f64, Vector3<f64>)>,
    /// The coil's goal on the true head at this tick.
    pub goal: Vector3<f64>,
    /// The coil where the arm put it at this tick.
    pub model: Vector3<f64>,
}

/// Each tick's (prediction, execution) shares, m, `None` where no command aimed for it. Tick
/// `i` is at `(i + 1)·period_s`; an aim is judged at its own time, the truth and the arm
/// interpolated between the ticks around it, and goes to the tick nearest that time (the newest
/// aim, when several aimed for one tick).
pub fn shares(ticks: &[Tick], period_s: f64) -> Vec<Option<(f64, f64)>> {
    let n = ticks.len();
    let mut out = vec![None; n];
    let Some(last) = n.checked_sub(1) else {
        return out;
    };
    for tick in ticks {
        let Some((t, coil)) = tick.aimed else {
            continue;
        };
        let x = t / period_s - 1.0;
        if !(0.0..=last as f64).contains(&x) {
            continue;
        }
        let i = (x.floor() as usize).min(last.saturating_sub(1));
        let (a, b) = (&ticks[i], &ticks[(i + 1).min(last)]);
        let s = x - i as f64;
        let goal = a.goal + (b.goal - a.goal) * s;
        let arm = a.model + (b.model - a.model) * s;
        out[(x.round() as usize).min(last)] = Some(((coil - goal).norm(), (arm - coil).norm()));
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    const PERIOD: f64 = 0.008;

    /// The goal moving along x at 0.1 m/s, the arm 1 mm behind it.
    fn ticks(n: usize) -> Vec<Tick> {
        (0..n)
            .map(|i| {
                let t = (i + 1) as f64 * PERIOD;
                Tick {
                    aimed: None,
                    goal: Vector3::new(0.1 * t, 0.0, 0.0),
                    model: Vector3::new(0.1 * t - 0.001, 0.0, 0.0),
                }
            })
            .collect()
    }

    #[test]
    fn an_aim_is_judged_at_its_own_time_between_ticks() {
        let mut t = ticks(10);
        // Aimed 0.5 mm beyond the true goal at 4.5 periods (between ticks 3 and 4).
        let at = 4.5 * PERIOD;
        t[1].aimed = Some((at, Vector3::new(0.1 * at + 0.0005, 0.0, 0.0)));
        let s = shares(&t, PERIOD);
        let (prediction, execution) = s[4].or(s[3]).unwrap();
        assert!((prediction - 0.0005).abs() < 1e-12, "{prediction}");
        assert!((execution - 0.0015).abs() < 1e-12, "{execution}");
        assert_eq!(s.iter().filter(|x| x.is_some()).count(), 1);
    }

    #[test]
    fn the_newest_aim_for_a_tick_counts_and_aims_outside_the_run_do_not() {
        let mut t = ticks(5);
        let at = 3.0 * PERIOD;
        t[0].aimed = Some((at, Vector3::new(1.0, 0.0, 0.0)));
        t[1].aimed = Some((at, Vector3::new(0.1 * at, 0.0, 0.0)));
        t[2].aimed = Some((10.0, Vector3::zeros()));
        let s = shares(&t, PERIOD);
        let (prediction, _) = s[2].unwrap();
        assert!(prediction < 1e-12, "{prediction}");
        assert_eq!(s.iter().filter(|x| x.is_some()).count(), 1);
        assert!(shares(&[], PERIOD).is_empty());
    }
}
