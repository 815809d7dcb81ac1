//! Structure-aware fuzzing of the OpenIGTLink decoder (seeded, bounded; `MOCOMP_FUZZ_CASES` for a
//! long campaign), and the hostile messages it or others found, kept as regression cases: each is
//! refused as damaged, by name, and the stream goes on to decode the valid message after it.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_igtl::codec::{CRC64, EXT_HEADER_SIZE, HEADER_SIZE};
use mocomp_igtl::message::{Status, TDataElement};
use mocomp_igtl::name::Name;
use mocomp_igtl::{Body, Decoder, DeviceName, Message, MetaEntry, encode};
use mocomp_testkit::fuzz::{Field, Fuzzer, Input, Kept, Kind, campaign, kept_cases, variant};

const LIMIT: u64 = 64 * 1024;

fn floats(f: &mut Fuzzer) -> [f32; 12] {
    std::array::from_fn(|_| f.f64() as f32)
}

/// A valid message of a random type and header version, with the map of its fields.
fn generate(f: &mut Fuzzer) -> Input {
    let device = f.name(19);
    let (type_name, body) = match f.below(7) {
        0 | 1 => ("TRANSFORM", Body::Transform(floats(f))),
        2 => (
            "POSITION",
            Body::Position {
                position: [1.0, 2.0, 3.0],
                quaternion: [0.0, 0.0, 0.0, 1.0],
            },
        ),
        3 => {
            let n = f.below(4) as usize;
            let tools = (0..n)
                .map(|_| TDataElement {
                    name: DeviceName::new(&f.name(19)).unwrap(),
                    kind: 2,
                    matrix: floats(f),
                })
                .collect();
            ("TDATA", Body::TData(tools))
        }
        4 => (
            "STATUS",
            Body::Status(Status {
                code: 1,
                subcode: 0,
                error_name: Name::<20>::new(&f.name(19)).unwrap(),
                message: f.name(30),
            }),
        ),
        5 => (
            "STRING",
            Body::String {
                encoding: 3,
                text: f.name(40).into_bytes(),
            },
        ),
        _ => ("RTS_TDATA", Body::RtsTData { status: 1 }),
    };
    let mut m = Message::new(type_name, &device, body).unwrap();
    let v2 = f.chance(0.6);
    if v2 {
        m.header_version = 2;
        let n = f.below(4) as usize;
        let entries = (0..n)
            .map(|_| MetaEntry::text(&f.name(12), &f.name(8)))
            .collect();
        m = m.with_metadata(entries);
    }
    let bytes = encode(&m);
    let mut fields = vec![
        Field::be(0, 2, Kind::Tag),
        Field::text(2, 12),
        Field::text(14, 20),
        Field::be(42, 8, Kind::Size),
    ];
    let content_at = if v2 {
        fields.extend([
            Field::be(HEADER_SIZE, 2, Kind::Size),
            Field::be(HEADER_SIZE + 2, 2, Kind::Size),
            Field::be(HEADER_SIZE + 4, 4, Kind::Size),
        ]);
        HEADER_SIZE + EXT_HEADER_SIZE
    } else {
        HEADER_SIZE
    };
    match &m.body {
        Body::String { text, .. } => fields.extend([
            Field::be(content_at, 2, Kind::Tag),
            Field::be(content_at + 2, 2, Kind::Size),
            Field::text(content_at + 4, text.len()),
        ]),
        Body::TData(tools) => {
            for i in 0..tools.len() {
                fields.push(Field::text(content_at + 70 * i, 20));
            }
        }
        Body::Status(_) => fields.push(Field::text(content_at + 10, 20)),
        _ => {}
    }
    if v2 {
        let meta_size: usize = m.metadata.iter().map(|e| e.key.len() + e.value.len()).sum();
        let mh = bytes.len() - meta_size - (2 + 8 * m.metadata.len());
        fields.push(Field::be(mh, 2, Kind::Count));
        let mut at = mh + 2 + 8 * m.metadata.len();
        for (i, e) in m.metadata.iter().enumerate() {
            let o = mh + 2 + 8 * i;
            fields.extend([
                Field::be(o, 2, Kind::Size),
                Field::be(o + 2, 2, Kind::Tag),
                Field::be(o + 4, 4, Kind::Size),
                Field::text(at, e.key.len()),
            ]);
            at += e.key.len() + e.value.len();
        }
    }
    Input { bytes, fields }
}

/// Recomputes the CRC over whatever body the (possibly corrupted) header announces and the bytes
/// hold, as any sender can: a hostile message has a valid CRC.
fn fix_crc(b: &mut [u8]) {
    if b.len() < HEADER_SIZE {
        return;
    }
    let size = u64::from_be_bytes(b[42..50].try_into().unwrap());
    let end = (HEADER_SIZE as u64)
        .saturating_add(size)
        .min(b.len() as u64) as usize;
    let crc = CRC64.checksum(&b[HEADER_SIZE..end]);
    b[50..58].copy_from_slice(&crc.to_be_bytes());
}

/// Feeds the bytes in two pieces and takes out everything; the decoder never holds more than
/// one message within the limit plus the pieces fed.
fn check(bytes: &[u8]) -> Result<(), String> {
    let mut d = Decoder::new(LIMIT);
    let cut = bytes.len() / 3;
    let mut outcome = Ok(());
    for piece in [&bytes[..cut], &bytes[cut..]] {
        d.feed(piece);
        while let Some(r) = d.next_message() {
            if let Err(e) = r {
                assert!(!e.to_string().is_empty());
                outcome = Err(variant(&e));
            }
        }
        assert!(d.buffered() as u64 <= LIMIT + HEADER_SIZE as u64 + bytes.len() as u64);
    }
    outcome
}

#[test]
fn structure_aware_campaign_never_panics() {
    let tally = campaign(
        "igtl",
        0x4947_544c,
        20_000,
        &mut generate,
        &mut |b| fix_crc(b),
        &mut check,
    );
    // The corruptions must reach past the envelope: the body's own checks refuse some.
    assert!(tally.refused.contains_key("Malformed"), "{tally:?}");
    eprintln!("igtl campaign: {tally:?}");
}

fn valid_pose() -> Vec<u8> {
    encode(&Message::new("TRANSFORM", "HeadToTracker", Body::Transform([0.0; 12])).unwrap())
}

#[test]
fn kept_hostile_messages_are_refused_by_name_and_the_stream_goes_on() {
    let kept = kept_cases(include_str!("data/hostile.tsv"));
    assert_eq!(kept.len(), 4);
    for Kept {
        what,
        expected,
        mut bytes,
    } in kept
    {
        // Each carries a valid CRC over what it holds: it is refused for its layout, not its CRC.
        let held = &bytes[HEADER_SIZE..];
        assert_eq!(
            u64::from_be_bytes(bytes[50..58].try_into().unwrap()),
            CRC64.checksum(held),
            "{what}"
        );
        bytes.extend(valid_pose());
        let mut d = Decoder::new(LIMIT);
        d.feed(&bytes);
        let e = d.next_message().unwrap().unwrap_err();
        assert_eq!(variant(&e), expected, "{what}: {e}");
        assert!(e.to_string().contains("TRANSFORM"), "{what}: {e}");
        if e.is_fatal() {
            assert!(e.to_string().contains("9223372036854775808"), "{e}");
            assert!(d.next_message().is_none(), "out of step: nothing more");
            d.reset();
            d.feed(&valid_pose());
        }
        let next = d.next_message().unwrap().unwrap();
        assert_eq!(next.device, "HeadToTracker", "{what}");
    }
}
