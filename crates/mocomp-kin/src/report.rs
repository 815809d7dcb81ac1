//! What `fk`, `ik` and the model table report, as values: each serialises to the JSON a tool
//! reads and displays as the text a person reads, so every front end prints the same thing.

use crate::{Arm, Choice, KinError, MODELS, Metric, Selection, Solutions, UrGeometry};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::text::{row, transform};
use mocomp_geom::{rows_from_iso, ur_pose_from_iso};
use serde::Serialize;
use std::fmt;

/// Forward kinematics of one joint configuration: the flange and, with a tool, the tool.
#[derive(Debug, Clone, Serialize)]
pub struct FkReport {
    /// `base_from_flange`, metres.
    pub base_from_flange: [[f64; 4]; 4],
    /// The flange as a UR pose vector (m, rotation vector).
    pub pose: [f64; 6],
    /// `base_from_tool`, metres, when the arm has a tool.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_from_tool: Option<[[f64; 4]; 4]>,
    /// The tool as a UR pose vector, when the arm has a tool.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tool_pose: Option<[f64; 6]>,
    #[serde(skip)]
    title: String,
    #[serde(skip)]
    flange: Isometry3<f64>,
    #[serde(skip)]
    tool: Option<Isometry3<f64>>,
}

impl FkReport {
    /// The flange (and, when `has_tool`, the tool) of `arm` at `joints`.
    pub fn new(arm: &Arm, joints: &[f64; 6], has_tool: bool) -> Self {
        let flange = arm.fk_flange(joints);
        let tool = has_tool.then(|| arm.fk(joints));
        let calibrated = if arm.is_calibrated() {
            ", calibrated"
        } else {
            ""
        };
        Self {
            base_from_flange: rows_from_iso(&flange),
            pose: ur_pose_from_iso(&flange),
            base_from_tool: tool.as_ref().map(rows_from_iso),
            tool_pose: tool.as_ref().map(ur_pose_from_iso),
            title: format!("base_from_flange ({}{calibrated}; metres)", arm.model()),
            flange,
            tool,
        }
    }
}

impl fmt::Display for FkReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", transform(&self.title, &self.flange, false))?;
        writeln!(
            f,
            "pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
            row(&self.pose)
        )?;
        if let (Some(tool), Some(pose)) = (&self.tool, &self.tool_pose) {
            write!(f, "{}", transform("base_from_tool (metres)", tool, false))?;
            writeln!(
                f,
                "tool pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
                row(pose)
            )?;
        }
        Ok(())
    }
}

/// One inverse kinematics solution with its branch.
#[derive(Debug, Clone, Serialize)]
pub struct SolutionReport {
    /// Joint angles, radians.
    pub joints: [f64; 6],
    /// Shoulder branch.
    pub shoulder: &'static str,
    /// Elbow branch.
    pub elbow: &'static str,
    /// Wrist branch.
    pub wrist: &'static str,
}

/// Every inverse kinematics solution of a pose and the one chosen.
#[derive(Debug, Clone, Serialize)]
pub struct IkReport {
    /// The solutions, each once.
    pub solutions: Vec<SolutionReport>,
    /// The chosen joints (the ±2π variant nearest the current ones).
    pub chosen: [f64; 6],
    /// Index of the chosen solution in `solutions`.
    pub chosen_index: usize,
    /// The singular cases met: `shoulder`, `elbow`, `wrist`.
    pub singular: Vec<&'static str>,
    #[serde(skip)]
    text: IkText,
}

#[derive(Debug, Clone, Default)]
struct IkText {
    model: String,
    cost: f64,
    angle_sum: bool,
    from_current: bool,
    wrist: bool,
}

impl IkReport {
    /// Solves `base_from_target` on `arm` from `current` and chooses by `selection`;
    /// `current_given` says whether `current` came from the user (the text names it) or is the
    /// zero configuration.
    pub fn solve(
        arm: &Arm,
        base_from_target: &Isometry3<f64>,
        current: &[f64; 6],
        current_given: bool,
        selection: &Selection,
    ) -> Result<Self, KinError> {
        let sols = arm.ik(base_from_target, current[5])?;
        let chosen = arm.choose(&sols, current, selection)?;
        Ok(Self::new(arm, &sols, &chosen, current_given, selection))
    }

    fn new(
        arm: &Arm,
        sols: &Solutions,
        chosen: &Choice,
        current_given: bool,
        selection: &Selection,
    ) -> Self {
        let s = &sols.singular;
        let singular = [
            (s.shoulder, "shoulder"),
            (s.elbow, "elbow"),
            (s.wrist, "wrist"),
        ]
        .into_iter()
        .filter_map(|(on, name)| on.then_some(name))
        .collect();
        Self {
            solutions: sols
                .iter()
                .map(|s| SolutionReport {
                    joints: s.joints,
                    shoulder: s.branch.shoulder.as_str(),
                    elbow: s.branch.elbow.as_str(),
                    wrist: s.branch.wrist.as_str(),
                })
                .collect(),
            chosen: chosen.joints,
            chosen_index: chosen.index,
            singular,
            text: IkText {
                model: arm.model().to_string(),
                cost: chosen.cost,
                angle_sum: !matches!(selection.metric, Metric::TimeToReach),
                from_current: current_given,
                wrist: s.wrist,
            },
        }
    }
}

impl fmt::Display for IkReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.solutions.len();
        let t = &self.text;
        writeln!(
            f,
            "{}: {n} solution{} (radians), * = chosen",
            t.model,
            if n == 1 { "" } else { "s" }
        )?;
        writeln!(
            f,
            "     shoulder elbow wrist  {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
            "q1", "q2", "q3", "q4", "q5", "q6"
        )?;
        for (i, s) in self.solutions.iter().enumerate() {
            writeln!(
                f,
                "{} {:>2} {:<8} {:<5} {:<6} {}",
                if i == self.chosen_index { "*" } else { " " },
                i + 1,
                s.shoulder,
                s.elbow,
                s.wrist,
                row(&s.joints)
            )?;
        }
        let from = if t.from_current {
            "--current"
        } else {
            "the zero configuration (no --current given)"
        };
        let metric = if t.angle_sum {
            format!("sum of |Δq| {:.4} rad", t.cost)
        } else {
            format!("time to reach {:.4} s", t.cost)
        };
        writeln!(
            f,
            "chosen: #{} as [{}] (nearest ±2π variant to {from}; {metric})",
            self.chosen_index + 1,
            row(&self.chosen)
        )?;
        if !self.singular.is_empty() {
            writeln!(
                f,
                "note: singular ({}); merged solutions are listed once{}",
                self.singular.join(", "),
                if t.wrist {
                    ", q6 taken from --current where reachable"
                } else {
                    ""
                }
            )?;
        }
        Ok(())
    }
}

/// One row of the model table.
#[derive(Debug, Clone, Serialize)]
pub struct ModelRow {
    /// The model's name.
    pub name: &'static str,
    /// DH `d1`, `a2`, `a3`, `d4`, `d5`, `d6`, metres (as keys of the row).
    #[serde(flatten)]
    pub geometry: UrGeometry,
    /// Maximum joint speeds, rad/s.
    pub max_speed_rad_s: [f64; 6],
    /// Lower joint limits, rad (`None`: unlimited).
    pub lower_limits_rad: [Option<f64>; 6],
    /// Upper joint limits, rad (`None`: unlimited).
    pub upper_limits_rad: [Option<f64>; 6],
    /// The controller's period, seconds.
    pub control_period_s: f64,
}

/// The model table: DH parameters, maximum joint speeds, control periods (serialises as the
/// list of its rows).
#[derive(Debug, Clone, Serialize)]
#[serde(transparent)]
pub struct ModelTable(pub Vec<ModelRow>);

impl ModelTable {
    /// Every model mocomp knows.
    pub fn all() -> Self {
        let finite = |v: &[f64; 6]| v.map(|x| x.is_finite().then_some(x));
        Self(
            MODELS
                .iter()
                .map(|m| ModelRow {
                    name: m.name,
                    geometry: m.geometry,
                    max_speed_rad_s: m.max_speed,
                    lower_limits_rad: finite(&m.lower_limits),
                    upper_limits_rad: finite(&m.upper_limits),
                    control_period_s: m.series.period_s(),
                })
                .collect(),
        )
    }
}

impl fmt::Display for ModelTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "model  {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}  max joint speed (deg/s)    period",
            "d1 (m)", "a2", "a3", "d4", "d5", "d6"
        )?;
        for m in &self.0 {
            let speeds: Vec<String> = m
                .max_speed_rad_s
                .iter()
                .map(|v| format!("{:.0}", v.to_degrees()))
                .collect();
            writeln!(
                f,
                "{:<6} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5}  {:<26} {:.0} ms",
                m.name,
                m.geometry.d1,
                m.geometry.a2,
                m.geometry.a3,
                m.geometry.d4,
                m.geometry.d5,
                m.geometry.d6,
                speeds.join(","),
                m.control_period_s * 1000.0
            )?;
        }
        writeln!(
            f,
            "joint limits: ±360° on every joint; UR3/UR3e wrist 3 turns without limit"
        )
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::{BranchPolicy, Model};

    #[test]
    fn the_chosen_solution_is_marked_and_reaches_the_pose() {
        let arm = Arm::new(Model::Ur5);
        let q = [0.3, -1.2, 1.4, -1.8, -1.5, 0.2];
        let target = arm.fk(&q);
        let selection = Selection {
            metric: Metric::TimeToReach,
            branch: BranchPolicy::Any,
            limit_margin: 0.0,
        };
        let r = IkReport::solve(&arm, &target, &q, true, &selection).unwrap();
        assert_eq!(r.solutions.len(), 8);
        let reached = arm.fk(&r.chosen);
        assert!((reached.translation.vector - target.translation.vector).norm() < 1e-9);
        let text = r.to_string();
        let marked: Vec<&str> = text.lines().filter(|l| l.starts_with('*')).collect();
        assert_eq!(marked.len(), 1);
        assert!(marked[0].starts_with(&format!("* {:>2}", r.chosen_index + 1)));
        assert!(text.contains("nearest ±2π variant to --current; time to reach"));
    }

    #[test]
    fn fk_shows_the_tool_only_when_there_is_one() {
        let arm = Arm::new(Model::Ur3);
        let q = [0.0; 6];
        let bare = FkReport::new(&arm, &q, false);
        assert!(bare.tool_pose.is_none() && !bare.to_string().contains("tool"));
        let with = FkReport::new(&arm, &q, true);
        assert!(with.to_string().contains("base_from_tool (metres):"));
        let table = ModelTable::all();
        assert_eq!(table.0.len(), MODELS.len());
        assert_eq!(table.to_string().lines().count(), MODELS.len() + 2);
    }
}
