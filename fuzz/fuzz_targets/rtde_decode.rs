//! Arbitrary bytes into the RTDE frame decoder and the package decoders of both directions and
//! both protocol versions, and into a recipe's unpacking: nothing may panic, and a package that
//! decodes re-encodes to bytes that decode and re-encode identically.
//!
//! `cargo +nightly fuzz run rtde_decode` (from `fuzz/`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use mocomp_ur::codec::{
    Direction, FrameDecoder, Recipe, decode_reply, decode_request, encode_reply, encode_request,
};

fuzz_target!(|data: &[u8]| {
    let recipe = Recipe::from_table(
        1,
        &["timestamp", "actual_q", "robot_mode", "joint_mode", "runtime_state", "payload_cog"],
        Direction::Output,
    )
    .expect("known variables");
    let step = usize::from(data.first().copied().unwrap_or(1)).max(1);
    let mut d = FrameDecoder::new();
    let mut values = Vec::new();
    for chunk in data.chunks(step) {
        d.push(chunk);
        loop {
            let f = match d.next_frame() {
                Ok(Some(f)) => f,
                Ok(None) | Err(_) => break,
            };
            for version in [1u16, 2] {
                if let Ok(r) = decode_request(f.kind, f.payload, version) {
                    let mut b = Vec::new();
                    if encode_request(&r, version, &mut b).is_ok() {
                        let back = decode_request(b[2], &b[3..], version).expect("re-decodes");
                        let mut again = Vec::new();
                        encode_request(&back, version, &mut again).expect("re-encodes");
                        assert_eq!(again, b, "stable encoding (NaN-safe comparison)");
                    }
                }
                if let Ok(r) = decode_reply(f.kind, f.payload, version) {
                    let mut b = Vec::new();
                    if encode_reply(&r, version, &mut b).is_ok() {
                        let back = decode_reply(b[2], &b[3..], version).expect("re-decodes");
                        let mut again = Vec::new();
                        encode_reply(&back, version, &mut again).expect("re-encodes");
                        assert_eq!(again, b, "stable encoding (NaN-safe comparison)");
                    }
                }
            }
            let _ = recipe.unpack(f.payload, &mut values);
        }
        if d.pending() > 1 << 17 {
            break;
        }
    }
});
