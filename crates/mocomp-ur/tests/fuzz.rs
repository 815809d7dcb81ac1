//! Structure-aware fuzzing of the RTDE codec as both sides use it (seeded, bounded;
//! `MOCOMP_FUZZ_CASES` for a long campaign): valid packages of every kind in both protocol
//! versions, their frame sizes, kinds, text lengths, recipe ids and name lists corrupted; the
//! frame decoder, both package decoders and a recipe negotiated from the replies take them.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_testkit::fuzz::{Field, Fuzzer, Input, Kind, campaign, variant};
use mocomp_ur::codec::{
    ControllerVersion, FrameDecoder, Recipe, Reply, Request, TextMessage, decode_reply,
    decode_request, encode_reply, encode_request,
};
use mocomp_ur::types::DataType;

fn names(f: &mut Fuzzer) -> Vec<String> {
    (0..1 + f.below(5)).map(|_| f.name(16)).collect()
}

fn types(f: &mut Fuzzer, n: usize) -> Vec<String> {
    (0..n)
        .map(|_| {
            DataType::ALL[f.below(DataType::ALL.len() as u64) as usize]
                .name()
                .to_string()
        })
        .collect()
}

fn text(f: &mut Fuzzer) -> TextMessage {
    TextMessage {
        level: f.below(4) as u8,
        message: f.name(40),
        source: f.name(10),
    }
}

/// A valid package (with its map) of either side, in protocol `version`.
fn generate(f: &mut Fuzzer) -> Input {
    let version = 1 + f.below(2) as u16;
    let mut bytes = vec![version as u8];
    let payload = vec![0u8; 8 * f.below(12) as usize];
    let request = f.chance(0.5);
    bytes.push(u8::from(request));
    let mut out = Vec::new();
    if request {
        let r = match f.below(7) {
            0 => Request::ProtocolVersion(2),
            1 => Request::ControllerVersion,
            2 => Request::Text(text(f)),
            3 => Request::Data {
                recipe_id: 1,
                payload: &payload,
            },
            4 => Request::SetupOutputs {
                frequency: (version == 2).then_some(500.0),
                names: names(f),
            },
            5 => Request::SetupInputs { names: names(f) },
            _ => Request::Start,
        };
        encode_request(&r, version, &mut out).unwrap();
    } else {
        let n = names(f).len();
        let r = match f.below(7) {
            0 => Reply::ProtocolVersion(true),
            1 => Reply::ControllerVersion(ControllerVersion {
                major: 5,
                minor: 11,
                bugfix: 0,
                build: 1,
            }),
            2 => Reply::Text(text(f)),
            3 => {
                // The outputs' recipe first, then a package of its size: the unpacking is
                // reached.
                let t = types(f, n);
                let size: usize = t
                    .iter()
                    .map(|t| DataType::from_name(t).unwrap().size())
                    .sum();
                let setup = Reply::SetupOutputs {
                    recipe_id: (version == 2).then_some(1),
                    types: t,
                };
                encode_reply(&setup, version, &mut out).unwrap();
                let data = vec![0x3f; size];
                encode_reply(
                    &Reply::Data {
                        recipe_id: (version == 2).then_some(1),
                        payload: &data,
                    },
                    version,
                    &mut out,
                )
                .unwrap();
                Reply::Start(true)
            }
            4 => Reply::SetupOutputs {
                recipe_id: (version == 2).then_some(1),
                types: types(f, n),
            },
            5 => Reply::SetupInputs {
                recipe_id: 1,
                types: types(f, n),
            },
            _ => Reply::Start(true),
        };
        encode_reply(&r, version, &mut out).unwrap();
    }
    // Two bytes of our own up front: the version and the side, corrupted like the rest.
    let mut fields = vec![
        Field::be(0, 1, Kind::Tag),
        Field::be(1, 1, Kind::Tag),
        Field::be(2, 2, Kind::Size),
        Field::be(4, 1, Kind::Tag),
    ];
    let len = out.len();
    if len > 5 {
        fields.push(Field::be(5, 1, Kind::Size));
        fields.push(Field::text(6, (len - 6).min(64)));
    }
    bytes.extend(out);
    Input { bytes, fields }
}

/// The frame's size made right again (as a sender would).
fn fix_size(b: &mut [u8]) {
    if b.len() >= 4 {
        let n = (b.len() - 2).min(u16::MAX as usize) as u16;
        b[2..4].copy_from_slice(&n.to_be_bytes());
    }
}

fn check(bytes: &[u8]) -> Result<(), String> {
    let (Some(&version), Some(&side)) = (bytes.first(), bytes.get(1)) else {
        return Err("Empty".into());
    };
    let version = u16::from(version);
    let mut d = FrameDecoder::new();
    let rest = bytes.get(2..).unwrap_or_default();
    let cut = rest.len() / 2;
    let mut outcome = Ok(());
    let mut recipe: Option<Recipe> = None;
    let mut vals = Vec::new();
    for piece in [&rest[..cut], &rest[cut..]] {
        d.push(piece);
        loop {
            let frame = match d.next_frame() {
                Ok(Some(f)) => f,
                Ok(None) => break,
                Err(e) => return Err(variant(&e)),
            };
            let r = if side == 1 {
                decode_request(frame.kind, frame.payload, version).map(|_| ())
            } else {
                match decode_reply(frame.kind, frame.payload, version) {
                    Ok(Reply::SetupOutputs { types, .. }) => {
                        let names: Vec<String> =
                            (0..types.len()).map(|i| format!("v{i}")).collect();
                        Recipe::from_reply(1, &names, &types).map(|r| recipe = Some(r))
                    }
                    Ok(Reply::Data { payload, .. }) => match &recipe {
                        Some(r) => r.unpack(payload, &mut vals),
                        None => Ok(()),
                    },
                    Ok(_) => Ok(()),
                    Err(e) => Err(e),
                }
            };
            if let Err(e) = r {
                assert!(!e.to_string().is_empty());
                outcome = Err(variant(&e));
            }
        }
        assert!(d.pending() <= 2 * u16::MAX as usize + bytes.len());
    }
    outcome
}

#[test]
fn structure_aware_campaign_never_panics() {
    let tally = campaign(
        "rtde",
        0x5254_4445,
        20_000,
        &mut generate,
        &mut |b| fix_size(b),
        &mut check,
    );
    assert!(tally.refused.contains_key("Malformed"), "{tally:?}");
    eprintln!("rtde campaign: {tally:?}");
}
