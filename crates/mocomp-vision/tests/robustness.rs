//! Arbitrary input never panics: geometry parsers, the PNG decoder, and whole frames of random
//! pixels through the pipeline (a result or an error, never a crash).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::Point3;
use mocomp_testkit::proptest_config;
use mocomp_vision::codec::decode_gray16_png;
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use proptest::prelude::*;

proptest! {
    #![proptest_config(proptest_config(2000, 4))]

    #[test]
    fn rom_parser_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..900), fix_magic in any::<bool>()) {
        let mut b = bytes;
        if fix_magic && b.len() >= 6 {
            b[0..3].copy_from_slice(b"NDI");
            let sum = b[6..b.len().min(752)].iter().fold(0u16, |s, x| s.wrapping_add(u16::from(*x)));
            b[4..6].copy_from_slice(&sum.to_le_bytes());
        }
        let _ = MarkerGeometry::from_ndi_rom(&b, "fuzz.rom");
    }

    #[test]
    fn ini_parser_never_panics(text in "(\\[(geometry|fiducial[0-9])\\]\n|(count|x|y|z|id)=-?[0-9.e]{0,6}\n|[;#a-z=\\[\\] ]{0,12}\n){0,30}") {
        let _ = MarkerGeometry::from_atracsys_ini(&text, "fuzz.ini");
    }

    #[test]
    fn png_decoder_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut b = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        b.extend(bytes);
        prop_assert!(decode_gray16_png(&b, "fuzz.png").is_err());
    }
}

proptest! {
    #![proptest_config(proptest_config(60, 4))]

    #[test]
    fn random_frames_give_results_not_panics(
        seed in any::<u64>(),
        bright in 0.0..0.2f64,
        threshold in 1u16..60_000,
    ) {
        let k = Intrinsics { width: 96, height: 80, fx: 80.0, fy: 80.0, cx: 48.0, cy: 40.0, ..Intrinsics::kinect_v2() };
        let g = MarkerGeometry::new("m", vec![Point3::new(0.0, 0.0, 0.0), Point3::new(0.05, 0.0, 0.0), Point3::new(0.0, 0.06, 0.0), Point3::new(0.02, 0.02, 0.04)]).unwrap();
        let params = TrackParams { ir_threshold: threshold, ..TrackParams::default() };
        let mut t = Tracker::new(k, params, g).unwrap();
        let mut s = seed;
        let mut next = || { s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407); s };
        let ir: Vec<u16> = (0..96 * 80).map(|_| { let v = next(); if (v >> 11) as f64 / (1u64 << 53) as f64 <= bright { (v >> 48) as u16 | 0x8000 } else { (v >> 52) as u16 } }).collect();
        let depth: Vec<u16> = (0..96 * 80).map(|_| (next() >> 52) as u16).collect();
        let r = t.process(&Frame::new(96, 80, &ir, &depth).unwrap()).unwrap();
        prop_assert!(r.detection.is_some() || r.not_found.is_some());
    }
}
