//! Arbitrary bytes into the OpenIGTLink decoder, whole and in pieces: it must never panic, hang
//! or allocate beyond its body limit, and a message it accepts must re-encode to the same message.
//!
//! `cargo +nightly fuzz run igtl_decode` (from `fuzz/`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use mocomp_igtl::{Decoder, decode, encode};

fuzz_target!(|data: &[u8]| {
    if let Ok(Some((m, _))) = decode(data, 1 << 20) {
        let again = encode(&m);
        let (back, _) = decode(&again, 1 << 20).ok().flatten().expect("re-encoded message decodes");
        assert_eq!(back, m);
    }
    // The same bytes through the streaming decoder, in pieces sized by the first byte.
    let step = usize::from(data.first().copied().unwrap_or(1)).max(1);
    let mut d = Decoder::new(1 << 20);
    for chunk in data.chunks(step) {
        d.feed(chunk);
        while let Some(r) = d.next_message() {
            let _ = r;
        }
    }
});
