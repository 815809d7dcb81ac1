//! What a navigation command (`register --dashboard`) shows in the operator's console: it waits
//! for the page's Start, then each step, the landmarks as they are touched, the sweep's count,
//! and the outcome. Without a console it does nothing.

use crate::Console;
use crate::state::NavigationJson;
use mocomp_app::frontend::Controls;
use mocomp_nav::{Procedure, Prompt};

/// The operator stopped (the page's Stop, Ctrl-C) before the page's Start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("stopped before it started")]
pub struct StoppedBeforeStart;

/// The console's navigation panel, or nothing.
#[derive(Debug)]
pub struct Page<'a> {
    console: Option<&'a Console>,
    shown: NavigationJson,
}

impl<'a> Page<'a> {
    /// The panel for `task` on `console`, waiting.
    pub fn new(console: Option<&'a Console>, task: &'static str) -> Self {
        let shown = NavigationJson {
            task,
            state: "waiting",
            step: String::new(),
            landmarks: Vec::new(),
            samples: [0, 0],
            result: Vec::new(),
        };
        let page = Self { console, shown };
        page.show(Some(format!("{task}: waiting for the go")));
        page
    }

    fn show(&self, event: Option<String>) {
        if let Some(c) = self.console {
            c.navigation(self.shown.clone(), event);
        }
    }

    /// Waits for the page's Start (or the page's Stop, Ctrl-C: then an error, shown).
    pub fn wait_for_go(&mut self, controls: &Controls) -> Result<(), StoppedBeforeStart> {
        if !controls.wait_for_start() {
            self.failed(&StoppedBeforeStart.to_string());
            return Err(StoppedBeforeStart);
        }
        self.shown.state = "running";
        self.show(Some(format!("{}: started", self.shown.task)));
        Ok(())
    }

    /// The procedure moved on: its step, the landmarks touched, the sweep's count.
    pub fn procedure(&mut self, p: &Procedure<'_>) {
        if self.console.is_none() {
            return;
        }
        let prompt = p.prompt();
        let step = match &prompt {
            Prompt::Touch(_) | Prompt::TakeAway(_) => {
                mocomp_app::registration::register::prompt_line(&prompt).unwrap_or_default()
            }
            Prompt::Sweep {
                region: Some(r), ..
            } => {
                format!("sweep the pointer over the scalp: the {r} next")
            }
            Prompt::Sweep { region: None, .. } => "sweep the pointer over the scalp".to_string(),
            Prompt::Done => "computing the registration".to_string(),
        };
        let event = (step != self.shown.step).then(|| step.clone());
        self.shown.state = "running";
        self.shown.step = step;
        self.shown.landmarks = p
            .touched()
            .iter()
            .map(|t| (t.landmark.name.clone(), t.spread_m * 1e3))
            .collect();
        self.shown.samples = match p.prompt() {
            Prompt::Sweep { taken, of, .. } => [taken, of],
            _ => [p.swept().len(), self.shown.samples[1].max(p.swept().len())],
        };
        self.show(event);
    }

    /// A line the operator is told, as an event.
    pub fn said(&mut self, line: &str) {
        if self.console.is_some() {
            self.show(Some(line.to_string()));
        }
    }

    /// The registration is in: its report, and whether it may be used.
    pub fn registered(&mut self, lines: &[String], usable: bool) {
        self.shown.state = if usable { "done" } else { "failed" };
        self.shown.result = lines.to_vec();
        self.show(Some(
            if usable {
                "registered"
            } else {
                "registration refused"
            }
            .into(),
        ));
    }

    /// Pivot samples in, of how many (shown every tenth).
    pub fn samples(&mut self, n: usize, of: usize) {
        if self.console.is_none() || (!n.is_multiple_of(10) && n != of) {
            return;
        }
        self.shown.state = "running";
        self.shown.step = "pivot the tip in the divot, turning the pointer every way".into();
        self.shown.samples = [n, of];
        self.show(None);
    }

    /// The pointer is calibrated.
    pub fn pivoted(&mut self, p: &mocomp_app::registration::pointer::Pointer) {
        self.shown.state = "done";
        let [x, y, z] = p.tip_in_marker_mm;
        self.shown.result = vec![
            format!("{}: tip at ({x:.2}, {y:.2}, {z:.2}) mm", p.device),
            format!(
                "tips agree to {:.2} mm RMS, {:.2} mm at most",
                p.rms_mm, p.max_mm
            ),
            format!(
                "{} of {} poses kept, turned {:.0}°",
                p.kept,
                p.kept + p.rejected,
                p.spread_deg
            ),
        ];
        self.show(Some("pointer calibrated".into()));
    }

    /// It failed: why.
    pub fn failed(&mut self, why: &str) {
        self.shown.state = "failed";
        self.shown.result = vec![why.to_string()];
        self.show(Some(why.to_string()));
    }
}
