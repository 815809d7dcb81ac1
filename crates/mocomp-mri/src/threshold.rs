//! The intensity that separates head from air: Otsu's, the threshold that maximises the
//! between-class variance of the volume's histogram (what InVesalius and most segmentation tools
//! start from), or the operator's own.

/// Histogram bins Otsu's method uses (scikit-image's default).
pub const OTSU_BINS: usize = 256;

/// The least and greatest value of `data` (`None` when it is empty).
pub fn range(data: &[f32]) -> Option<(f32, f32)> {
    let first = *data.first()?;
    Some(
        data.iter()
            .fold((first, first), |(lo, hi), &v| (lo.min(v), hi.max(v))),
    )
}

/// Otsu's threshold of `data` over [`OTSU_BINS`] equal bins between its least and greatest
/// value: the upper edge of the lower class's last bin, for the split that maximises the
/// between-class variance, so the upper class is the values at or above it (`None` when every
/// value is the same, where nothing separates). scikit-image's `threshold_otsu` reports the
/// centre of that bin and takes the values above it: the same split, half a bin lower.
pub fn otsu(data: &[f32]) -> Option<f64> {
    let (lo, hi) = range(data)?;
    let (lo, hi) = (f64::from(lo), f64::from(hi));
    if hi <= lo {
        return None;
    }
    let width = (hi - lo) / OTSU_BINS as f64;
    let mut counts = [0u64; OTSU_BINS];
    for &v in data {
        let b = ((f64::from(v) - lo) / width) as usize;
        counts[b.min(OTSU_BINS - 1)] += 1;
    }
    let centre = |b: usize| lo + (b as f64 + 0.5) * width;
    let upper_edge = |b: usize| lo + (b + 1) as f64 * width;
    let total = data.len() as f64;
    let sum_all: f64 = (0..OTSU_BINS).map(|b| counts[b] as f64 * centre(b)).sum();
    let (mut below, mut sum_below) = (0.0, 0.0);
    let mut best = (f64::NEG_INFINITY, lo);
    // Between bins b and b+1: the classes are [0, b] and [b+1, end).
    for (b, &count) in counts.iter().enumerate().take(OTSU_BINS - 1) {
        below += count as f64;
        sum_below += count as f64 * centre(b);
        let above = total - below;
        if below == 0.0 || above == 0.0 {
            continue;
        }
        let (m0, m1) = (sum_below / below, (sum_all - sum_below) / above);
        let between = below * above * (m0 - m1) * (m0 - m1);
        if between > best.0 {
            best = (between, upper_edge(b));
        }
    }
    Some(best.1)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn two_separated_populations_split_between_them() {
        let mut data = vec![10.0f32; 5000];
        data.extend(std::iter::repeat_n(200.0f32, 3000));
        data.extend((0..100).map(|i| 12.0 + i as f32 * 0.01));
        let t = otsu(&data).unwrap();
        assert!(t > 12.0 && t < 200.0, "{t}");
    }

    #[test]
    fn a_constant_volume_has_no_threshold() {
        assert_eq!(otsu(&[3.0; 10]), None);
        assert_eq!(otsu(&[]), None);
    }

    proptest! {
        /// Wherever two clusters sit, the threshold falls between them.
        #[test]
        fn the_threshold_separates_any_two_clusters(a in 0.0f32..100.0, gap in 20.0f32..500.0,
                                                    na in 10usize..2000, nb in 10usize..2000) {
            let b = a + gap;
            let mut data: Vec<f32> = (0..na).map(|i| a + (i % 7) as f32 * 0.1).collect();
            data.extend((0..nb).map(|i| b + (i % 5) as f32 * 0.1));
            let t = otsu(&data).unwrap();
            prop_assert!(t > f64::from(a) + 0.6 && t <= f64::from(b) + 0.5, "{} {} {}", a, b, t);
        }
    }
}
