//! OpenIGTLink timestamps: 32.32 fixed point, upper 32 bits Unix seconds, lower 32 bits the
//! fraction of a second (`frac / 2³²`). Raw 0 means "no timestamp".

/// A raw 32.32 timestamp.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Timestamp(pub u64);

const FRAC: f64 = 4_294_967_296.0; // 2^32

impl Timestamp {
    /// The "unused" timestamp.
    pub const NONE: Timestamp = Timestamp(0);

    /// True for the "unused" value 0.
    pub fn is_none(self) -> bool {
        self.0 == 0
    }

    /// From seconds since the Unix epoch (rounded to the nearest 2⁻³² s; clamped to the format's
    /// range).
    pub fn from_secs_f64(s: f64) -> Self {
        if !s.is_finite() || s <= 0.0 {
            return Timestamp(0);
        }
        let sec = s.floor();
        if sec >= FRAC {
            return Timestamp(u64::MAX);
        }
        let mut frac = ((s - sec) * FRAC).round();
        let mut sec = sec as u64;
        if frac >= FRAC {
            frac -= FRAC;
            sec += 1;
        }
        Timestamp((sec << 32) | frac as u64)
    }

    /// Seconds since the Unix epoch.
    pub fn to_secs_f64(self) -> f64 {
        (self.0 >> 32) as f64 + (self.0 & 0xFFFF_FFFF) as f64 / FRAC
    }

    /// From nanoseconds since the Unix epoch: `frac = round(ns · 2³² / 10⁹)`.
    pub fn from_unix_nanos(ns: u128) -> Self {
        let sec = ns / 1_000_000_000;
        let rem = ns % 1_000_000_000;
        let frac = ((rem << 32) + 500_000_000) / 1_000_000_000;
        let (mut sec, mut frac) = (sec as u64, frac as u64);
        if frac >= 1 << 32 {
            frac -= 1 << 32;
            sec += 1;
        }
        Timestamp((sec.min(u64::from(u32::MAX)) << 32) | frac)
    }

    /// Nanoseconds since the Unix epoch (rounded).
    pub fn to_unix_nanos(self) -> u128 {
        let sec = u128::from(self.0 >> 32);
        let frac = u128::from(self.0 & 0xFFFF_FFFF);
        sec * 1_000_000_000 + ((frac * 1_000_000_000 + (1 << 31)) >> 32)
    }

    /// The current wall-clock time.
    pub fn now() -> Self {
        let ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        Self::from_unix_nanos(ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn known_values() {
        assert_eq!(Timestamp::from_secs_f64(1.5).0, (1u64 << 32) | (1 << 31));
        assert_eq!(
            Timestamp::from_unix_nanos(1_500_000_000).0,
            (1u64 << 32) | (1 << 31)
        );
        assert_eq!(Timestamp((7u64 << 32) | (1 << 30)).to_secs_f64(), 7.25);
        assert_eq!(Timestamp::from_secs_f64(0.0), Timestamp::NONE);
        // The golden vectors carry the raw value 1234567892: 0 s and 0x499602d4 / 2^32 s.
        assert!((Timestamp(1_234_567_892).to_secs_f64() - 0.287_445_236_928_761).abs() < 1e-12);
    }

    proptest! {
        #![proptest_config(mocomp_testkit::proptest_config(256, 13))]

        #[test]
        fn nanos_round_trip_within_a_nanosecond(ns in 1u128..4_000_000_000_000_000_000u128) {
            let t = Timestamp::from_unix_nanos(ns);
            let back = t.to_unix_nanos();
            prop_assert!(back.abs_diff(ns) <= 1, "{ns} -> {back}");
        }

        #[test]
        fn seconds_round_trip(s in 1.0e-3..4.0e9f64) {
            let back = Timestamp::from_secs_f64(s).to_secs_f64();
            // f64 carries ~1e-7 s at 4e9 s; the format resolves 2.3e-10 s.
            prop_assert!((back - s).abs() <= 1e-9 + s * 4e-16, "{s} -> {back}");
        }
    }
}
