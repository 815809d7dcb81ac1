//! Property tests over every model: `fk(ik(T)) == T` for every returned solution (1e-9 m, 1e-9 rad)
//! on seeded random reachable poses, including poses at and near each singularity; every solution
//! distinct; no reachable pose reported unreachable; the generating joints recovered; the branch
//! choice against brute force.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
use mocomp_geom::nalgebra::{Isometry3, Translation3, Vector3};
use mocomp_geom::units::wrap_pi;
use mocomp_geom::{quat_from_rotvec, rotation_error, translation_error};
use mocomp_kin::ik::MERGE_TOL;
use mocomp_kin::{
    Arm, Branch, BranchCoordinates, BranchPolicy, DhCalibration, DhParams, KinError, Metric, Model,
    Selection, Solutions, Unreachable, fk_nominal,
};
use mocomp_testkit::proptest_config as config;
use proptest::prelude::*;
use std::f64::consts::{PI, TAU};

fn any_model() -> impl Strategy<Value = Model> {
    prop::sample::select(Model::ALL.to_vec())
}

fn angle() -> impl Strategy<Value = f64> {
    -PI..PI
}

fn joints() -> impl Strategy<Value = [f64; 6]> {
    prop::array::uniform6(angle())
}

/// Angles at and near 0 and π: exact, and 1e-k away for k = 1..14, both sides.
fn near_zero_or_pi() -> impl Strategy<Value = f64> {
    (
        prop::sample::select(vec![0.0, PI, -PI]),
        prop_oneof![Just(0.0), (1i32..15).prop_map(|k| 10f64.powi(-k))],
        prop::bool::ANY,
    )
        .prop_map(|(base, off, neg)| if neg { base - off } else { base + off })
}

const TOL: f64 = 1e-9;

fn max_wrapped_diff(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter()
        .zip(b.iter())
        .map(|(x, y)| wrap_pi(x - y).abs())
        .fold(0.0, f64::max)
}

/// Every solution reproduces the target; solutions are pairwise distinct.
fn check_solutions(
    arm: &Arm,
    target: &Isometry3<f64>,
    sols: &Solutions,
) -> Result<(), TestCaseError> {
    prop_assert!(!sols.is_empty());
    for s in sols {
        let back = arm.fk(&s.joints);
        let dt = translation_error(&back, target);
        let dr = rotation_error(&back, target);
        prop_assert!(
            dt < TOL && dr < TOL,
            "{}: solution {:?} misses by {dt:.3e} m, {dr:.3e} rad",
            arm.model(),
            s.joints
        );
        prop_assert!(arm.limits().contains(&s.joints, 0.0));
    }
    let all = sols.as_slice();
    for i in 0..all.len() {
        for j in i + 1..all.len() {
            prop_assert!(
                max_wrapped_diff(&all[i].joints, &all[j].joints) > MERGE_TOL,
                "solutions {i} and {j} coincide: {:?}",
                all[i].joints
            );
        }
    }
    Ok(())
}

/// The full check for a pose generated from joints `q`: reachable, all solutions exact and
/// distinct, the generating joints among them where they are well conditioned.
fn check_roundtrip(arm: &Arm, q: &[f64; 6]) -> Result<(), TestCaseError> {
    let target = arm.fk(q);
    let sols = match arm.ik(&target, q[5]) {
        Ok(s) => s,
        Err(e) => {
            return Err(TestCaseError::fail(format!(
                "{}: reachable pose from q = {q:?} reported: {e}",
                arm.model()
            )));
        }
    };
    check_solutions(arm, &target, &sols)?;
    let margin = arm.singularity(q).margin(arm.geometry());
    if margin > 1e-4 {
        let best = sols
            .iter()
            .map(|s| max_wrapped_diff(&s.joints, q))
            .fold(f64::INFINITY, f64::min);
        prop_assert!(
            best < 1e-8,
            "{}: q = {q:?} not among the solutions (closest {best:.3e})",
            arm.model()
        );
        for s in &sols {
            // Branch labels agree with the labels of the joints themselves.
            prop_assert_eq!(
                BranchCoordinates::of(arm.geometry(), &s.joints).branch(),
                s.branch
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(3000, 0x6d6f_636f_6d70))]

    #[test]
    fn fk_ik_roundtrip_random(model in any_model(), q in joints()) {
        check_roundtrip(&Arm::new(model), &q)?;
    }
}

proptest! {
    #![proptest_config(config(2000, 2))]

    #[test]
    fn fk_ik_roundtrip_near_wrist_singularity(model in any_model(), mut q in joints(), q5 in near_zero_or_pi()) {
        q[4] = q5;
        check_roundtrip(&Arm::new(model), &q)?;
    }

    #[test]
    fn fk_ik_roundtrip_near_elbow_singularity(model in any_model(), mut q in joints(), q3 in near_zero_or_pi()) {
        q[2] = q3;
        check_roundtrip(&Arm::new(model), &q)?;
    }

    #[test]
    fn fk_ik_roundtrip_near_shoulder_singularity(
        model in any_model(),
        q in joints(),
        eps in prop_oneof![Just(0.0), (1i32..12).prop_map(|k| 10f64.powi(-k)), (1i32..12).prop_map(|k| -10f64.powi(-k))],
        elbow_sign in prop::bool::ANY,
    ) {
        // Keep q1, q2, q234 = q2 + q3 + q4 and q5, q6 random; choose q23 so that
        // ρ = a2 c2 + a3 c23 + d5 s234 = eps.
        let g = model.spec().geometry;
        let q234 = q[1] + q[2] + q[3];
        let c23 = (eps - g.a2 * q[1].cos() - g.d5 * q234.sin()) / g.a3;
        prop_assume!(c23.abs() <= 1.0);
        let q23 = if elbow_sign { c23.acos() } else { -c23.acos() };
        let mut q = q;
        q[2] = wrap_pi(q23 - q[1]);
        q[3] = wrap_pi(q234 - q23);
        let rho = BranchCoordinates::of(&g, &q).rho_m;
        prop_assert!((rho - eps).abs() < 1e-12);
        check_roundtrip(&Arm::new(model), &q)?;
    }

    #[test]
    fn fk_ik_roundtrip_at_combined_singularities(model in any_model(), mut q in joints(), q3 in near_zero_or_pi(), q5 in near_zero_or_pi()) {
        q[2] = q3;
        q[4] = q5;
        check_roundtrip(&Arm::new(model), &q)?;
    }

    #[test]
    fn closed_form_fk_equals_dh_chain(model in any_model(), q in joints()) {
        let g = model.spec().geometry;
        let a = fk_nominal(&g, &q);
        let b = DhParams::nominal(&g).flange(&q);
        prop_assert!(translation_error(&a, &b) < 1e-14);
        prop_assert!(rotation_error(&a, &b) < 1e-14);
    }

    #[test]
    fn tool_offset_is_respected(model in any_model(), q in joints(),
        t in prop::array::uniform3(-0.2..0.2f64), r in prop::array::uniform3(-2.0..2.0f64)) {
        let tool = Isometry3::from_parts(Translation3::new(t[0], t[1], t[2]), quat_from_rotvec(&Vector3::new(r[0], r[1], r[2])));
        let arm = Arm::new(model).with_tool(tool);
        let base_from_tool = arm.fk(&q);
        let expected = arm.fk_flange(&q) * tool;
        prop_assert!(translation_error(&base_from_tool, &expected) < 1e-15);
        check_roundtrip(&arm, &q)?;
    }

    #[test]
    fn jacobian_matches_finite_differences(model in any_model(), q in joints()) {
        let arm = Arm::new(model);
        let j = arm.jacobian(&q);
        let t0 = arm.fk(&q);
        let h = 1e-6;
        for k in 0..6 {
            let mut qp = q;
            qp[k] += h;
            let t1 = arm.fk(&qp);
            let v = (t1.translation.vector - t0.translation.vector) / h;
            let w = mocomp_geom::rotvec_from_quat(&(t1.rotation * t0.rotation.inverse())) / h;
            for r in 0..3 {
                prop_assert!((j[(r, k)] - v[r]).abs() < 1e-5, "linear J[{r},{k}]");
                prop_assert!((j[(r + 3, k)] - w[r]).abs() < 1e-5, "angular J[{r},{k}]");
            }
        }
    }

    #[test]
    fn jacobian_determinant_factors_into_the_three_singularities(model in any_model(), q in joints()) {
        // |det J| = |a2 · a3 · sin q3 · sin q5 · ρ|: each factor is one singularity.
        let arm = Arm::new(model);
        let g = arm.geometry();
        let s = arm.singularity(&q);
        let expected = (g.a2 * g.a3 * s.elbow * s.wrist * s.shoulder_m).abs();
        prop_assert!((s.manipulability - expected).abs() < 1e-12 + 1e-9 * expected,
            "{} vs {}", s.manipulability, expected);
    }
}

proptest! {
    #![proptest_config(config(1000, 3))]

    /// Choosing with the seed paper's metric (sum of |Δq|) matches brute force over every ±2π
    /// variant of every solution within the limits (the paper's 16 sets and more).
    #[test]
    fn choice_matches_brute_force(model in any_model(), q in joints(), current in prop::array::uniform6(-TAU..TAU)) {
        let arm = Arm::new(model);
        let sols = arm.ik(&arm.fk(&q), current[5]).unwrap();
        let sel = Selection { metric: Metric::WeightedSum([1.0; 6]), branch: BranchPolicy::Any, limit_margin: 0.0 };
        let chosen = arm.choose(&sols, &current, &sel).unwrap();
        let mut best = f64::INFINITY;
        for s in &sols {
            for v in arm.limits().variants(&s.joints) {
                let cost: f64 = v.iter().zip(current.iter()).map(|(a, b)| (a - b).abs()).sum();
                best = best.min(cost);
            }
        }
        prop_assert!((chosen.cost - best).abs() < 1e-9, "chosen {} vs brute force {}", chosen.cost, best);
        prop_assert!(arm.limits().contains(&chosen.joints, 0.0));
        let back = arm.fk(&chosen.joints);
        prop_assert!(translation_error(&back, &arm.fk(&q)) < TOL);
    }

    /// Tracking a slowly moving goal never changes the branch; each step's choice is the solution
    /// on the current branch that is continuous with the current joints.
    #[test]
    fn tracking_keeps_branch(model in any_model(), q in joints(), dq in prop::array::uniform6(-1e-3..1e-3f64)) {
        let arm = Arm::new(model);
        prop_assume!(arm.singularity(&q).margin(arm.geometry()) > 1e-2);
        let start: Branch = BranchCoordinates::of(arm.geometry(), &q).branch();
        let mut current = q;
        for step in 1..=20 {
            let goal_q: [f64; 6] = std::array::from_fn(|k| q[k] + dq[k] * step as f64);
            // The goal's own path must not cross a singularity (it would change branch itself).
            prop_assume!(BranchCoordinates::of(arm.geometry(), &goal_q).branch() == start);
            let goal = arm.fk(&goal_q);
            let c = arm.ik_closest(&goal, &current, &Selection::tracking(0.0)).unwrap();
            prop_assert_eq!(c.branch, start);
            prop_assert!(max_wrapped_diff(&c.joints, &goal_q) < 1e-8);
            // Continuous: the commanded joints are the goal's, not a 2π away variant.
            for (now, before) in c.joints.iter().zip(current.iter()) {
                prop_assert!((now - before).abs() < 0.01);
            }
            current = c.joints;
        }
    }

    /// No pose beyond the arm's reach is reported reachable, and the error says why.
    #[test]
    fn far_poses_are_unreachable(model in any_model(), dir in prop::array::uniform3(-1.0..1.0f64), r in prop::array::uniform3(-3.0..3.0f64)) {
        let arm = Arm::new(model);
        let g = arm.geometry();
        let v = Vector3::new(dir[0], dir[1], dir[2]);
        prop_assume!(v.norm() > 0.1);
        let reach = g.a2.abs() + g.a3.abs() + g.d1.abs() + g.d4 + g.d5 + g.d6;
        let p = v.normalize() * (reach * 1.05);
        let t = Isometry3::from_parts(Translation3::from(p), quat_from_rotvec(&Vector3::new(r[0], r[1], r[2])));
        // Far away: beyond the reach, or (straight above or below the base) inside the cylinder.
        match arm.ik(&t, 0.0) {
            Err(KinError::Unreachable(Unreachable::TooFar { distance_m, reach_m })) => prop_assert!(distance_m > reach_m),
            Err(KinError::Unreachable(Unreachable::InsideShoulderCylinder { distance_m, radius_m })) => prop_assert!(distance_m < radius_m),
            other => prop_assert!(false, "expected unreachable, got {:?}", other),
        }
    }
}

#[test]
fn choice_prefers_the_full_turn_variant_near_current() {
    // The peer's `inverse_kinematics_closest` tries one ±2π direction only, so a base at 0.3 − 2π
    // can be answered with 0.3 (a full-turn swing). Ours keeps the variant next to the current
    // joints.
    let arm = Arm::new(Model::Ur5e);
    let q = [0.3, -1.2, 1.3, -0.4, 0.7, 0.2];
    let mut current = q;
    current[0] -= TAU;
    let c = arm
        .ik_closest(&arm.fk(&q), &current, &Selection::default())
        .unwrap();
    assert!((c.joints[0] - (0.3 - TAU)).abs() < 1e-9, "{:?}", c.joints);
    assert!(c.cost < 1e-9);
}

/// Deterministic uniform samples in [−π, π) (a fixed LCG) for searches in plain tests.
fn lcg_joints(state: &mut u64) -> [f64; 6] {
    std::array::from_fn(|_| {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 11) as f64 / (1u64 << 53) as f64) * TAU - PI
    })
}

#[test]
fn keep_current_refuses_a_pose_only_another_branch_reaches() {
    let arm = Arm::new(Model::Ur10e);
    let mut state = 7u64;
    // Find a pose where some branch has no solution, and joints on that missing branch.
    let (target, sols, missing) = loop {
        let q = lcg_joints(&mut state);
        let t = arm.fk(&q);
        let sols = arm.ik(&t, q[5]).unwrap();
        if sols.len() < 8 && !sols.singular.wrist && !sols.singular.shoulder && !sols.singular.elbow
        {
            let present: Vec<Branch> = sols.iter().map(|s| s.branch).collect();
            let missing = [mocomp_kin::Shoulder::Left, mocomp_kin::Shoulder::Right]
                .into_iter()
                .flat_map(|shoulder| {
                    [mocomp_kin::Elbow::Up, mocomp_kin::Elbow::Down]
                        .into_iter()
                        .flat_map(move |elbow| {
                            [mocomp_kin::Wrist::NoFlip, mocomp_kin::Wrist::Flip]
                                .into_iter()
                                .map(move |wrist| Branch {
                                    shoulder,
                                    elbow,
                                    wrist,
                                })
                        })
                })
                .find(|b| !present.contains(b));
            if let Some(b) = missing {
                break (t, sols, b);
            }
        }
    };
    let current = loop {
        let q = lcg_joints(&mut state);
        let c = BranchCoordinates::of(arm.geometry(), &q);
        if c.branch() == missing && arm.singularity(&q).margin(arm.geometry()) > 1e-3 {
            break q;
        }
    };
    match arm.choose(&sols, &current, &Selection::tracking(0.0)) {
        Err(KinError::BranchUnavailable { branch }) => assert_eq!(branch, missing),
        other => panic!("expected BranchUnavailable, got {other:?}"),
    }
    // Asked to, it may change branch.
    let any = arm.choose(&sols, &current, &Selection::default()).unwrap();
    assert_ne!(any.branch, missing);
    assert!(translation_error(&arm.fk(&any.joints), &target) < TOL);
}

#[test]
fn limit_margin_excludes_solutions_at_the_limits() {
    let arm = Arm::new(Model::Ur5);
    let q = [TAU - 0.01, -1.2, 1.3, -0.4, 0.7, 0.2];
    let target = arm.fk(&q);
    let sols = arm.ik(&target, q[5]).unwrap();
    let current = q;
    let c = arm.choose(&sols, &current, &Selection::default()).unwrap();
    assert!((c.joints[0] - q[0]).abs() < 1e-9);
    // With a 0.05 rad margin, q1 = 2π − 0.01 is not allowed: on the same branch the variant −0.01
    // is taken instead.
    let sel = Selection {
        limit_margin: 0.05,
        ..Selection::tracking(0.05)
    };
    let c = arm.choose(&sols, &current, &sel).unwrap();
    assert!((c.joints[0] - (-0.01)).abs() < 1e-9, "{:?}", c.joints);
}

#[test]
fn calibrated_model_ik_is_exact_on_the_calibrated_chain() {
    // A real factory calibration of a UR10 (ur_calibration test data).
    let cal = DhCalibration::from_toml_str(
        r#"
model = "ur10"
[delta]
d = [0.00065609212979853, 1.4442162376284788, 0.854147723854608, -2.2989425877563705, -1.573498686836816e-05, 1.9072435590711256e-05]
a = [4.6311376834935676e-05, -0.00012568315331862312, 0.00186216581161458, 9.918593870679266e-05, 4.215462720453189e-06, 0]
theta = [-7.290070070824746e-05, -0.01713897289704999, -0.03707159413492756, 0.054279462160583214, 1.488984257025741e-07, 1.551499479707493e-05]
alpha = [0.000211987863869334, -0.0072553625957652995, -0.013483226769541364, 0.0013495820227329425, -0.001263136163679901, 0]
"#,
    )
    .unwrap();
    let arm = Arm::calibrated(&cal).unwrap();
    let nominal = Arm::new(Model::Ur10);
    let mut runner = proptest::test_runner::TestRunner::new(config(500, 4));
    runner
        .run(&joints(), |q| {
            let target = arm.fk(&q);
            // The nominal model would miss this pose by millimetres; the calibrated one is exact.
            let sols = arm
                .ik(&target, q[5])
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            check_solutions(&arm, &target, &sols)?;
            let nominal_miss = translation_error(&nominal.fk(&q), &target);
            prop_assert!(nominal_miss > 1e-4);
            // Recovering the generating joints needs the nominal closed-form start on the right
            // side of each singularity. This robot's calibration tilts axes by up to 0.013 rad
            // (its alpha deltas), so within a few times that of a singularity the nominal start
            // may land on the neighbouring solution; every returned solution is exact regardless.
            if arm.singularity(&q).margin(arm.geometry()) > 0.05 {
                let best = sols
                    .iter()
                    .map(|s| max_wrapped_diff(&s.joints, &q))
                    .fold(f64::INFINITY, f64::min);
                prop_assert!(best < 1e-8, "q not recovered ({best:.3e})");
            }
            Ok(())
        })
        .unwrap();
}

#[test]
fn variants_are_the_papers_sixteen_and_more() {
    let arm = Arm::new(Model::Ur5);
    let q = [0.3, -1.2, 1.3, -0.4, 0.7, 0.2];
    // Every non-zero joint has two values in ±2π: 2^6 variants.
    let v = arm.limits().variants(&q);
    assert_eq!(v.len(), 64);
    assert!(v.iter().all(|x| arm.limits().contains(x, 0.0)));
    let ur3 = Arm::new(Model::Ur3);
    // UR3's wrist 3 turns without limit: three listed values for it (−2π, 0, +2π shifts).
    assert_eq!(ur3.limits().variants(&q).len(), 96);
}
