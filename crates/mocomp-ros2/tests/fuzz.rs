//! Structure-aware fuzzing of what the node takes from the network (seeded, bounded;
//! `MOCOMP_FUZZ_CASES` for a long campaign): a head pose (`geometry_msgs/PoseStamped`, the
//! tracker input) and a hold or resume request (`std_srvs/Trigger`), in CDR as any DDS
//! participant may send them. ros2-client decodes both with `cdr-encoding`, the decoder
//! `msg::from_cdr` calls; the pose then goes through `convert::iso` as
//! the node's `take_head` does. Every case either decodes to a pose the loop may use or is
//! refused by name; none panics.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_ros2::convert;
use mocomp_ros2::msg::{
    Header, Point, Pose, PoseStamped, Quaternion, Time, TriggerRequest, from_cdr, to_cdr,
};
use mocomp_testkit::fuzz::{Field, Fuzzer, Input, Kind, Outcome, campaign, variant};

/// The 4-byte encapsulation header before every CDR body.
const ENCAPSULATION: usize = 4;

/// A value a sender might put in a pose: within a metre, or now and then an edge (0, huge,
/// NaN, infinite, any bits).
fn value(f: &mut Fuzzer) -> f64 {
    match f.below(40) {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => -f64::INFINITY,
        3 => f64::MAX,
        4 => f.f64(),
        _ => unit(f),
    }
}

/// A finite number in [-1, 1].
fn unit(f: &mut Fuzzer) -> f64 {
    (f.below(2_000_001) as f64 - 1e6) * 1e-6
}

/// A valid head pose with a random frame name, stamp and pose (its quaternion usually unit),
/// and the map of its CDR: the encapsulation tag, the stamp, the frame name's length and bytes.
fn pose_stamped(f: &mut Fuzzer) -> Input {
    let frame_id = f.name(24);
    let (x, y, z, w) = if f.chance(0.8) {
        let (a, b, c, d) = (unit(f), unit(f), unit(f), unit(f) + 2.0);
        let n = (a * a + b * b + c * c + d * d).sqrt();
        (a / n, b / n, c / n, d / n)
    } else {
        (value(f), value(f), value(f), value(f))
    };
    let m = PoseStamped {
        header: Header {
            stamp: Time {
                sec: f.below(u64::from(u32::MAX)) as u32 as i32,
                nanosec: f.below(2_000_000_000) as u32,
            },
            frame_id: frame_id.clone(),
        },
        pose: Pose {
            position: Point {
                x: value(f),
                y: value(f),
                z: value(f),
            },
            orientation: Quaternion { x, y, z, w },
        },
    };
    let bytes = to_cdr(&m).unwrap();
    // The body: sec (4), nanosec (4), the frame name's length with its NUL (4), its bytes.
    let at = ENCAPSULATION;
    let fields = vec![
        Field::be(0, 2, Kind::Tag),
        Field::le(at, 4, Kind::Count),
        Field::le(at + 4, 4, Kind::Count),
        Field::le(at + 8, 4, Kind::Size),
        Field::text(at + 12, frame_id.len()),
    ];
    Input { bytes, fields }
}

/// A pose the node would hand the loop, or the refusal's name.
fn take_pose(bytes: &[u8]) -> Outcome {
    let m = from_cdr::<PoseStamped>(bytes).map_err(|e| variant(&e))?;
    let pose = convert::iso(&m.pose).map_err(|e| variant(&e))?;
    assert!(
        pose.translation.vector.iter().all(|v| v.is_finite())
            && (pose.rotation.norm() - 1.0).abs() < 1e-9,
        "a pose taken is a rigid motion: {pose:?}"
    );
    Ok(())
}

#[test]
fn a_head_pose_from_any_participant_decodes_to_a_rigid_motion_or_is_refused_by_name() {
    let tally = campaign(
        "PoseStamped",
        0x2052_0501,
        20_000,
        &mut pose_stamped,
        &mut |_| {},
        &mut take_pose,
    );
    // Both ways out were taken, and by the reasons a broken sender gives.
    assert!(tally.decoded > tally.cases / 10, "{tally:?}");
    for kind in ["Body", "NotFinite"] {
        assert!(tally.refused.contains_key(kind), "{kind}: {tally:?}");
    }
    eprintln!("PoseStamped: {tally:?}");
}

#[test]
fn a_hold_or_resume_request_decodes_or_is_refused_by_name() {
    let tally = campaign(
        "Trigger request",
        0x2052_0502,
        2_000,
        &mut |f| {
            let m = TriggerRequest {
                structure_needs_at_least_one_member: f.below(256) as u8,
            };
            let mut bytes = to_cdr(&m).unwrap();
            // What a sender may pad after it.
            let pad = f.below(8) as usize;
            bytes.extend(f.bytes(pad));
            Input {
                bytes,
                fields: vec![
                    Field::be(0, 2, Kind::Tag),
                    Field::le(ENCAPSULATION, 1, Kind::Count),
                ],
            }
        },
        &mut |_| {},
        &mut |b| {
            from_cdr::<TriggerRequest>(b)
                .map(|_| ())
                .map_err(|e| variant(&e))
        },
    );
    assert!(tally.refused.contains_key("Encapsulation"), "{tally:?}");
}

/// Hostile lengths no fuzzer needs luck to find: a frame name claiming 4 GiB, a body cut inside
/// the pose, a big-endian header. Each refused by name, nothing allocated for the claim.
#[test]
fn a_frame_name_longer_than_the_message_is_refused_not_allocated() {
    let m = PoseStamped {
        header: Header {
            stamp: Time { sec: 1, nanosec: 2 },
            frame_id: "tracker".into(),
        },
        pose: Pose::default(),
    };
    let good = to_cdr(&m).unwrap();
    assert!(take_pose(&good).is_ok());
    let mut huge = good.clone();
    huge[ENCAPSULATION + 8..ENCAPSULATION + 12].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(take_pose(&huge), Err("Body".into()));
    for cut in [ENCAPSULATION + 2, ENCAPSULATION + 11, good.len() - 1] {
        assert!(take_pose(&good[..cut]).is_err(), "{cut} bytes");
    }
    let mut big_endian = good.clone();
    big_endian[1] = 0x00;
    assert_eq!(take_pose(&big_endian), Err("Encapsulation".into()));
}
