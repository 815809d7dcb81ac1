//! Structure-aware fuzzing, seeded, inside the test command.
//!
//! Random bytes rarely get past a decoder's first check (a version, a CRC, a magic number), so
//! they test little. Here a case starts from a *valid* message or file that a generator builds,
//! with a map of where its sizes, counts, offsets, encodings and texts are ([`Field`]); the
//! mutator then corrupts exactly those (to 0, 1, one off, the largest value, the sign bit, the
//! buffer's length, …), truncates, extends, duplicates or splices regions (wrong nesting), or
//! flips a byte. A `fixup` can make the outer envelope right again (a CRC, an outer size) so the
//! corruption reaches the inner decoder. The check decodes and says how it ended; a panic is
//! caught and reported with the case's seed, mutations and bytes in hex, to be kept as a
//! regression case.
//!
//! [`campaign`] runs `cases` of them (the environment's `MOCOMP_FUZZ_CASES` overrides the count,
//! for long campaigns outside the test command) and fails unless both valid decodes and refusals
//! were seen: a fuzzer whose every case is refused at the first byte would test nothing.

use crate::SplitMix64;
use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// What a field of the input is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A size in bytes of something that follows.
    Size,
    /// A count of entries.
    Count,
    /// An offset into the input.
    Offset,
    /// An encoding, type or version tag.
    Tag,
    /// Text or a name (its bytes are corrupted, not its value).
    Text,
}

/// Byte order of a numeric field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Endian {
    /// Most significant byte first (network order).
    Big,
    /// Least significant byte first.
    Little,
}

/// A field of a generated input: where, how wide (1, 2, 4 or 8 bytes for numbers; any width for
/// text), what.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// Byte offset.
    pub at: usize,
    /// Width in bytes.
    pub width: usize,
    /// What it holds.
    pub kind: Kind,
    /// Byte order (numbers).
    pub endian: Endian,
}

impl Field {
    /// A big-endian numeric field.
    pub fn be(at: usize, width: usize, kind: Kind) -> Self {
        Self {
            at,
            width,
            kind,
            endian: Endian::Big,
        }
    }

    /// A little-endian numeric field.
    pub fn le(at: usize, width: usize, kind: Kind) -> Self {
        Self {
            at,
            width,
            kind,
            endian: Endian::Little,
        }
    }

    /// A text field.
    pub fn text(at: usize, width: usize) -> Self {
        Self {
            at,
            width,
            kind: Kind::Text,
            endian: Endian::Big,
        }
    }

    fn read(&self, b: &[u8]) -> Option<u64> {
        let s = b.get(self.at..self.at + self.width)?;
        let mut v = 0u64;
        match self.endian {
            Endian::Big => s.iter().for_each(|&x| v = (v << 8) | u64::from(x)),
            Endian::Little => s.iter().rev().for_each(|&x| v = (v << 8) | u64::from(x)),
        }
        Some(v)
    }

    fn write(&self, b: &mut [u8], v: u64) {
        let Some(s) = b.get_mut(self.at..self.at + self.width) else {
            return;
        };
        let w = s.len();
        for (i, x) in s.iter_mut().enumerate() {
            let shift = match self.endian {
                Endian::Big => 8 * (w - 1 - i),
                Endian::Little => 8 * i,
            };
            *x = if shift < 64 { (v >> shift) as u8 } else { 0 };
        }
    }
}

/// A generated input: its bytes and the map of its fields.
#[derive(Debug, Clone, Default)]
pub struct Input {
    /// The bytes.
    pub bytes: Vec<u8>,
    /// Where its fields are.
    pub fields: Vec<Field>,
}

/// How a check ended, for the campaign's tally: `Ok` decoded, `Err(kind)` refused with a named
/// kind of error.
pub type Outcome = Result<(), String>;

/// One case's generator and mutator.
#[derive(Debug)]
pub struct Fuzzer {
    rng: SplitMix64,
    log: Vec<String>,
}

impl Fuzzer {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            rng: SplitMix64(seed),
            log: Vec::new(),
        }
    }

    /// A number below `n` (0 when `n` is 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.rng.next_u64() % n }
    }

    /// A random byte vector of length below `n`.
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        let len = self.below(n as u64) as usize;
        (0..len).map(|_| self.rng.next_u64() as u8).collect()
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.rng.next_f64() < p
    }

    /// A random float, finite or not.
    pub fn f64(&mut self) -> f64 {
        match self.below(8) {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => -0.0,
            3 => f64::from_bits(self.rng.next_u64()),
            _ => (self.rng.next_f64() - 0.5) * 2000.0,
        }
    }

    /// A short ASCII name.
    pub fn name(&mut self, max: usize) -> String {
        let len = 1 + self.below(max.max(1) as u64) as usize;
        (0..len)
            .map(|_| char::from(b'a' + self.below(26) as u8))
            .collect()
    }

    /// The mutations applied so far in this case, in words.
    pub fn log(&self) -> &[String] {
        &self.log
    }

    fn interesting(&mut self, f: &Field, b: &[u8]) -> u64 {
        let bits = 8 * f.width.min(8) as u32;
        let max = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        let v = f.read(b).unwrap_or(0);
        let len = b.len() as u64;
        let choices = [
            0,
            1,
            v.wrapping_sub(1),
            v.wrapping_add(1),
            v.wrapping_mul(2),
            v / 2,
            max,
            max / 2 + 1,
            max / 2,
            len,
            len.wrapping_sub(f.at as u64),
            len + 1,
            len.wrapping_sub(1),
            self.rng.next_u64(),
        ];
        choices[self.below(choices.len() as u64) as usize] & max
    }

    /// Corrupts `input` once: a field set to an edge value, a text's bytes made invalid, a
    /// truncation, an extension, a region duplicated or removed, a byte flipped.
    pub fn mutate(&mut self, input: &mut Input) {
        let b = &mut input.bytes;
        let pick_field = !input.fields.is_empty() && self.chance(0.6);
        if pick_field {
            let f = input.fields[self.below(input.fields.len() as u64) as usize];
            if f.kind == Kind::Text {
                let junk: &[u8] = match self.below(5) {
                    0 => &[0xff],
                    1 => &[0xc3],
                    2 => &[0],
                    3 => b",\"",
                    _ => &[0xed, 0xa0, 0x80],
                };
                let at = f.at + self.below(f.width.max(1) as u64) as usize;
                for (k, x) in junk.iter().enumerate() {
                    if let Some(y) = b.get_mut(at + k) {
                        *y = *x;
                    }
                }
                self.log.push(format!("text at {at} ← {junk:02x?}"));
            } else {
                let v = self.interesting(&f, b);
                f.write(b, v);
                self.log.push(format!(
                    "{:?} field at {} ({} B) ← {v}",
                    f.kind, f.at, f.width
                ));
            }
            return;
        }
        let len = b.len() as u64;
        match self.below(6) {
            0 => {
                let at = self.below(len + 1) as usize;
                b.truncate(at);
                self.log.push(format!("truncated to {at}"));
            }
            1 => {
                let extra = self.bytes(64);
                self.log.push(format!("{} bytes appended", extra.len()));
                b.extend(extra);
            }
            2 if len > 0 => {
                let from = self.below(len) as usize;
                let n = 1 + self.below((len - from as u64).min(256)) as usize;
                let region: Vec<u8> = b[from..from + n].to_vec();
                let to = self.below(len + 1) as usize;
                b.splice(to..to, region);
                self.log
                    .push(format!("{n} bytes at {from} repeated at {to}"));
            }
            3 if len > 0 => {
                let from = self.below(len) as usize;
                let n = 1 + self.below((len - from as u64).min(64)) as usize;
                b.drain(from..from + n);
                self.log.push(format!("{n} bytes removed at {from}"));
            }
            _ if len > 0 => {
                let at = self.below(len) as usize;
                b[at] ^= 1 << self.below(8);
                self.log.push(format!("bit flipped at {at}"));
            }
            _ => {}
        }
    }
}

/// What a campaign did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tally {
    /// Cases run.
    pub cases: u64,
    /// Cases that decoded.
    pub decoded: u64,
    /// Refusals by the kind the check named.
    pub refused: BTreeMap<String, u64>,
}

/// The cases to run: `MOCOMP_FUZZ_CASES` when set (a long campaign), else `default`.
pub fn cases(default: u64) -> u64 {
    std::env::var("MOCOMP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Runs a seeded campaign: each case generates a valid input, applies 1–3 mutations, lets
/// `fixup` repair the envelope (or not, at random), and checks it. Panics — naming the case, its
/// mutations and its bytes — when a check panics, or when the campaign never decoded anything or
/// never refused anything.
pub fn campaign(
    name: &str,
    seed: u64,
    default_cases: u64,
    generate: &mut dyn FnMut(&mut Fuzzer) -> Input,
    fixup: &mut dyn FnMut(&mut Vec<u8>),
    check: &mut dyn FnMut(&[u8]) -> Outcome,
) -> Tally {
    let n = cases(default_cases);
    let mut tally = Tally::default();
    for case in 0..n {
        let case_seed = seed ^ case.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut f = Fuzzer::new(case_seed);
        let mut input = generate(&mut f);
        // One case in eight stays valid: the generator's own output must decode.
        if case % 8 != 0 {
            for _ in 0..1 + f.below(3) {
                f.mutate(&mut input);
            }
            if f.chance(0.75) {
                fixup(&mut input.bytes);
                f.log.push("envelope repaired".into());
            }
        }
        let bytes = input.bytes;
        let out = catch_unwind(AssertUnwindSafe(|| check(&bytes)));
        match out {
            Ok(Ok(())) => tally.decoded += 1,
            Ok(Err(kind)) => *tally.refused.entry(kind).or_default() += 1,
            Err(p) => {
                let what = mocomp_geom::watch::panic_message(&*p);
                panic!(
                    "{name}: case {case} (seed {case_seed:#x}) panicked: {what}\nmutations: {:?}\nbytes ({}): {}",
                    f.log,
                    bytes.len(),
                    bytes.iter().map(|b| format!("{b:02x}")).collect::<String>()
                );
            }
        }
        tally.cases += 1;
    }
    assert!(
        tally.decoded > 0 && !tally.refused.is_empty(),
        "{name}: a campaign that never decodes or never refuses tests nothing: {tally:?}"
    );
    tally
}

/// An error enum's variant name (`Malformed` of `Malformed { .. }`): the kind a campaign tallies.
pub fn variant(e: &impl std::fmt::Debug) -> String {
    format!("{e:?}")
        .split([' ', '{', '('])
        .next()
        .unwrap_or("")
        .to_string()
}

/// A case a campaign (or a report) found, kept for good.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Kept {
    /// What it is, in words.
    pub what: String,
    /// The error the decoder must answer with.
    pub expected: String,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

/// The kept cases of a corpus file: `#` comments, then one case a line, `what<TAB>expected<TAB>
/// bytes in hex`.
pub fn kept_cases(text: &str) -> Vec<Kept> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 3, "a kept case is what, expected, hex: {l:?}");
            let hex = f[2].trim();
            let bytes = (0..hex.len())
                .step_by(2)
                .map(|i| {
                    u8::from_str_radix(hex.get(i..i + 2).unwrap_or("?"), 16)
                        .unwrap_or_else(|_| panic!("not hex at {i}: {l:?}"))
                })
                .collect();
            Kept {
                what: f[0].to_string(),
                expected: f[1].to_string(),
                bytes,
            }
        })
        .collect()
}
