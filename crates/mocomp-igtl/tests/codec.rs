//! The codec: golden byte vectors from the OpenIGTLink project's own test data, the CRC check
//! value, round-trips of every message, one-byte-at-a-time decoding, and garbage that never
//! panics or allocates beyond the limit.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_igtl::codec::{CRC64, DEFAULT_MAX_BODY, HEADER_SIZE};
use mocomp_igtl::message::{QueryKind, QueryTarget, Status, TDataElement, query_of};
use mocomp_igtl::name::Name;
use mocomp_igtl::{
    Body, DecodeError, Decoder, DeviceName, Message, MetaEntry, Timestamp, TypeName, decode, encode,
};
use mocomp_testkit::proptest_config;
use proptest::prelude::*;

/// The floats of `Testing/igtlutil/igtl_test_data_transform.h`.
const GOLDEN_FLOATS: [f32; 12] = [
    -0.954892, 0.196632, -0.222525, -0.196632, 0.142857, 0.970014, 0.222525, 0.970014, -0.0977491,
    46.0531, 19.4709, 46.0531,
];

fn golden_header(version: u16, body_size: u64, crc: u64) -> Vec<u8> {
    let mut h = Vec::new();
    h.extend_from_slice(&version.to_be_bytes());
    h.extend_from_slice(b"TRANSFORM\0\0\0");
    h.extend_from_slice(b"DeviceName\0\0\0\0\0\0\0\0\0\0");
    h.extend_from_slice(&1_234_567_892u64.to_be_bytes());
    h.extend_from_slice(&body_size.to_be_bytes());
    h.extend_from_slice(&crc.to_be_bytes());
    assert_eq!(h.len(), HEADER_SIZE);
    h
}

fn golden_message(version: u16) -> Message {
    let mut m = Message::new("TRANSFORM", "DeviceName", Body::Transform(GOLDEN_FLOATS)).unwrap();
    m.timestamp = Timestamp(1_234_567_892);
    if version == 2 {
        m = m.with_metadata(vec![
            MetaEntry::text("First patient age", "22"),
            MetaEntry::text("Second patient age", "25"),
        ]);
        m.message_id = 1;
    }
    m
}

#[test]
fn crc_check_value() {
    assert_eq!(CRC64.checksum(b"123456789"), 0x6c40_df5f_0b49_7347);
}

#[test]
fn golden_transform_v1_byte_exact() {
    let mut expected = golden_header(1, 48, 0xf6dd_2b8e_b4df_6dd2);
    for f in GOLDEN_FLOATS {
        expected.extend_from_slice(&f.to_be_bytes());
    }
    assert_eq!(encode(&golden_message(1)), expected);
    let (m, n) = decode(&expected, DEFAULT_MAX_BODY).unwrap().unwrap();
    assert_eq!(n, expected.len());
    assert_eq!(m, golden_message(1));
}

#[test]
fn golden_transform_v2_with_metadata_byte_exact() {
    let mut expected = golden_header(2, 117, 0xf698_f64f_dae2_66dd);
    expected.extend_from_slice(&[
        0x00, 0x0c, 0x00, 0x12, 0x00, 0x00, 0x00, 0x27, 0x00, 0x00, 0x00, 0x01,
    ]);
    for f in GOLDEN_FLOATS {
        expected.extend_from_slice(&f.to_be_bytes());
    }
    expected.extend_from_slice(&2u16.to_be_bytes());
    for (k, v) in [("First patient age", "22"), ("Second patient age", "25")] {
        expected.extend_from_slice(&(k.len() as u16).to_be_bytes());
        expected.extend_from_slice(&3u16.to_be_bytes());
        expected.extend_from_slice(&(v.len() as u32).to_be_bytes());
    }
    for (k, v) in [("First patient age", "22"), ("Second patient age", "25")] {
        expected.extend_from_slice(k.as_bytes());
        expected.extend_from_slice(v.as_bytes());
    }
    assert_eq!(encode(&golden_message(2)), expected);
    let (m, _) = decode(&expected, DEFAULT_MAX_BODY).unwrap().unwrap();
    assert_eq!(m.meta("Second patient age"), Some("25"));
    assert_eq!(m.message_id, 1);
    assert_eq!(m, golden_message(2));
}

#[test]
fn a_crc_mismatch_names_device_and_type_and_the_stream_goes_on() {
    let mut bytes = encode(&golden_message(1));
    bytes[60] ^= 0x01; // a body bit
    bytes.extend(encode(
        &Message::new(
            "STRING",
            "Next",
            Body::String {
                encoding: 3,
                text: b"ok".to_vec(),
            },
        )
        .unwrap(),
    ));
    let mut d = Decoder::new(DEFAULT_MAX_BODY);
    d.feed(&bytes);
    let e = d.next_message().unwrap().unwrap_err();
    assert!(matches!(e, DecodeError::Crc { .. }));
    let text = e.to_string();
    assert!(
        text.contains("TRANSFORM") && text.contains("DeviceName"),
        "{text}"
    );
    assert!(!e.is_fatal());
    let next = d.next_message().unwrap().unwrap();
    assert_eq!(next.device, "Next");
}

#[test]
fn a_hostile_header_does_not_allocate() {
    let mut h = golden_header(1, u64::MAX / 2, 0);
    h.extend_from_slice(&[0; 100]);
    let mut d = Decoder::new(DEFAULT_MAX_BODY);
    d.feed(&h);
    let e = d.next_message().unwrap().unwrap_err();
    assert!(
        matches!(e, DecodeError::BodyTooLarge { .. }) && e.is_fatal(),
        "{e}"
    );
    assert!(
        d.next_message().is_none(),
        "refuses further input after a fatal error"
    );
    let mut bad = golden_header(7, 0, 0);
    bad.truncate(HEADER_SIZE);
    assert!(matches!(
        decode(&bad, DEFAULT_MAX_BODY),
        Err((DecodeError::HeaderVersion { version: 7 }, _))
    ));
}

#[test]
fn both_spellings_of_the_transform_query() {
    for t in ["GET_TRANS", "GET_TRANSFOR"] {
        assert_eq!(query_of(t), Some((QueryKind::Get, QueryTarget::Transform)));
        let m = Message::new(t, "HeadToTracker", Body::Query(Vec::new())).unwrap();
        let (back, _) = decode(&encode(&m), DEFAULT_MAX_BODY).unwrap().unwrap();
        assert_eq!(back.query(), Some((QueryKind::Get, QueryTarget::Transform)));
    }
    assert_eq!(
        query_of("STT_TDATA"),
        Some((QueryKind::Start, QueryTarget::TData))
    );
    assert_eq!(
        query_of("RTS_TDATA"),
        Some((QueryKind::Reply, QueryTarget::TData))
    );
    assert_eq!(
        query_of("GET_IMAGE"),
        Some((QueryKind::Get, QueryTarget::Other))
    );
    assert_eq!(query_of("TRANSFORM"), None);
}

#[test]
fn unknown_types_are_skipped_by_size() {
    let m = Message::new("IMAGE", "US", Body::Unknown { size: 1000 }).unwrap();
    let mut bytes = encode(&m);
    bytes.extend(encode(&golden_message(2)));
    let mut d = Decoder::new(DEFAULT_MAX_BODY);
    d.feed(&bytes);
    assert_eq!(
        d.next_message().unwrap().unwrap().body,
        Body::Unknown { size: 1000 }
    );
    assert_eq!(d.next_message().unwrap().unwrap(), golden_message(2));
}

fn name<const N: usize>() -> impl Strategy<Value = Name<N>> {
    proptest::string::string_regex(&format!("[A-Za-z0-9_ ]{{0,{N}}}"))
        .unwrap()
        .prop_map(|s| Name::<N>::new(&s).unwrap())
}

fn floats(n: usize) -> impl Strategy<Value = Vec<f32>> {
    proptest::collection::vec(-1.0e4f32..1.0e4, n)
}

fn body() -> impl Strategy<Value = (&'static str, Body)> {
    prop_oneof![
        floats(12).prop_map(|f| ("TRANSFORM", Body::Transform(f.try_into().unwrap()))),
        (floats(3), floats(4)).prop_map(|(p, q)| (
            "POSITION",
            Body::Position {
                position: p.try_into().unwrap(),
                quaternion: q.try_into().unwrap()
            }
        )),
        proptest::collection::vec((name::<20>(), 1u8..5, floats(12)), 0..5).prop_map(|v| (
            "TDATA",
            Body::TData(
                v.into_iter()
                    .map(|(n, k, m)| TDataElement {
                        name: n,
                        kind: k,
                        matrix: m.try_into().unwrap()
                    })
                    .collect()
            )
        )),
        (any::<u16>(), any::<i64>(), name::<20>(), "[ -~]{0,40}").prop_map(|(c, s, n, t)| (
            "STATUS",
            Body::Status(Status {
                code: c,
                subcode: s,
                error_name: n,
                message: t
            })
        )),
        ("[ -~]{0,60}").prop_map(|t| (
            "STRING",
            Body::String {
                encoding: 3,
                text: t.into_bytes()
            }
        )),
        (any::<u32>(), name::<32>()).prop_map(|(r, c)| (
            "STT_TDATA",
            Body::StartTData {
                resolution_ms: r,
                coordinate: c
            }
        )),
        (0u8..2).prop_map(|s| ("RTS_TDATA", Body::RtsTData { status: s })),
        Just(("GET_TRANS", Body::Query(Vec::new()))),
        Just(("STP_TDATA", Body::Query(Vec::new()))),
        (0usize..300).prop_map(|n| ("POLYDATA", Body::Unknown { size: n })),
    ]
}

fn message() -> impl Strategy<Value = Message> {
    (
        body(),
        name::<20>(),
        any::<u64>(),
        prop::bool::ANY,
        any::<u32>(),
        proptest::collection::vec(("[A-Za-z]{1,12}", "[ -~]{0,16}"), 0..4),
    )
        .prop_map(|((t, b), device, ts, v2, id, meta)| {
            let mut m = Message {
                header_version: 1,
                type_name: TypeName::new(t).unwrap(),
                device,
                timestamp: Timestamp(ts),
                message_id: 0,
                metadata: Vec::new(),
                body: b,
            };
            if v2 {
                m = m.with_metadata(meta.iter().map(|(k, v)| MetaEntry::text(k, v)).collect());
                m.message_id = id;
            }
            m
        })
}

proptest! {
    #![proptest_config(proptest_config(3000, 5))]

    #[test]
    fn every_message_round_trips(m in message()) {
        let bytes = encode(&m);
        let (back, n) = decode(&bytes, DEFAULT_MAX_BODY).unwrap().unwrap();
        prop_assert_eq!(n, bytes.len());
        prop_assert_eq!(back, m);
    }

    #[test]
    fn fragmented_input_one_byte_at_a_time(ms in proptest::collection::vec(message(), 1..5)) {
        let bytes: Vec<u8> = ms.iter().flat_map(encode).collect();
        let mut d = Decoder::new(DEFAULT_MAX_BODY);
        let mut got = Vec::new();
        for b in &bytes {
            d.feed(std::slice::from_ref(b));
            while let Some(r) = d.next_message() {
                got.push(r.unwrap());
            }
        }
        prop_assert_eq!(got, ms);
        prop_assert_eq!(d.buffered(), 0);
    }

    #[test]
    fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..600), version in 1u16..3, small in prop::bool::ANY) {
        // Random bytes, and random bytes behind a plausible header (version 1/2, small size).
        let _ = decode(&bytes, DEFAULT_MAX_BODY);
        let mut framed = bytes.clone();
        if framed.len() >= HEADER_SIZE {
            framed[0..2].copy_from_slice(&version.to_be_bytes());
            for b in &mut framed[2..34] { *b = b'A' + (*b % 26); }
            let size = if small { (framed.len() - HEADER_SIZE) as u64 } else { u64::from(framed[42]) << 40 };
            framed[42..50].copy_from_slice(&size.to_be_bytes());
            let crc = CRC64.checksum(&framed[HEADER_SIZE..]);
            framed[50..58].copy_from_slice(&crc.to_be_bytes());
        }
        let mut d = Decoder::new(1 << 20);
        d.feed(&framed);
        while let Some(r) = d.next_message() {
            if let Err(e) = r { prop_assert!(!e.to_string().is_empty()); }
        }
    }
}

#[test]
fn device_names_use_the_full_twenty_bytes() {
    let n = DeviceName::new("ReferenceToTracker12").unwrap();
    let m = Message::new("TRANSFORM", n.as_str(), Body::Transform([0.0; 12])).unwrap();
    let bytes = encode(&m);
    assert_eq!(&bytes[14..34], b"ReferenceToTracker12");
    assert_eq!(
        decode(&bytes, DEFAULT_MAX_BODY).unwrap().unwrap().0.device,
        "ReferenceToTracker12"
    );
}
