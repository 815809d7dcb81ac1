#![allow(clippy::print_stderr, clippy::unwrap_used)] // test support: the figures said on stderr
//! How the coil kept to its goal while tracking, read from a run's CSV log.

use serde_json::Value;

/// How the coil kept to its goal while tracking, from the run's log. A hold stands the arm while
/// the head moves on, and a coil that resumes within `servo_deviation_m` of its goal goes
/// straight to tracking and closes the rest within the command's limits (by design: no path for
/// a few millimetres): that catch-up is tracking, but not on the goal, and how far the head
/// went during the hold depends on where in its motion the hold fell, so it is judged apart.
#[derive(Debug)]
pub struct OnGoal {
    /// The largest deviation (mm) while tracking, outside catch-ups.
    pub max_mm: f64,
    /// Where it was: the row's time (s into the run), and the event before it with its time,
    /// so that a failure says what the loop had just been through.
    pub worst: Option<(f64, Option<(f64, String)>)>,
    /// Each straight resume: when (s into the run), its deviation then (mm), and how long it
    /// took to come within the caught-up deviation (`None`: held again before it did; infinite:
    /// the run ended tracking and it never did).
    pub catch_ups: Vec<(f64, f64, Option<f64>)>,
}

impl OnGoal {
    /// Reads the log at `csv_path`; a resumed coil has caught up below `caught_up_mm`.
    pub fn read(csv_path: &str, caught_up_mm: f64) -> Self {
        let mut log = csv::Reader::from_path(csv_path).unwrap();
        let header = log.headers().unwrap().clone();
        let col = |name: &str| header.iter().position(|h| h == name).unwrap();
        let (t_col, mode_col, event_col, dev_col) =
            (col("t_s"), col("mode"), col("event"), col("deviation_mm"));
        let mut on_goal = OnGoal {
            max_mm: 0.0,
            worst: None,
            catch_ups: Vec::new(),
        };
        let mut catching_up: Option<usize> = None;
        let mut last_event: Option<(f64, String)> = None;
        for row in log.records() {
            let row = row.unwrap();
            let t: f64 = row[t_col].parse().unwrap();
            let dev: f64 = row[dev_col].parse().unwrap();
            let tracking = &row[mode_col] == "tracking";
            if tracking && &row[event_col] == "Resume" {
                on_goal.catch_ups.push((t, dev, None));
                catching_up = Some(on_goal.catch_ups.len() - 1);
            }
            if !row[event_col].is_empty() {
                last_event = Some((t, row[event_col].to_string()));
            }
            if !tracking {
                catching_up = None;
                continue;
            }
            if let Some(i) = catching_up {
                if dev < caught_up_mm {
                    on_goal.catch_ups[i].2 = Some(t - on_goal.catch_ups[i].0);
                    catching_up = None;
                }
                continue;
            }
            if dev > on_goal.max_mm {
                on_goal.max_mm = dev;
                on_goal.worst = Some((t, last_event.clone()));
            }
        }
        // Tracking to the end and never caught up: as long as it could be.
        if let Some(i) = catching_up {
            on_goal.catch_ups[i].2 = Some(f64::INFINITY);
        }
        on_goal
    }

    /// The coil never left its goal by `max_mm` or more while tracking on it, and every catch-up
    /// that was not interrupted closed within `within_s`.
    pub fn check(&self, max_mm: f64, within_s: f64, v: &Value) {
        eprintln!("on the goal: {self:?}");
        assert!(
            self.max_mm < max_mm,
            "deviation max {} mm while tracking on the goal, at {:?}: {v}",
            self.max_mm,
            self.worst
        );
        assert!(
            self.catch_ups
                .iter()
                .all(|(_, _, took)| took.is_none_or(|s| s < within_s)),
            "a catch-up took longer than {within_s} s: {self:?}"
        );
    }
}
