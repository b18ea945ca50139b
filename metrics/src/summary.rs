//! Whole-image summaries: PSNR and ΔE distribution statistics.
use crate::error::MetricsError;
use serde::Serialize;

/// Peak signal-to-noise ratio in dB: `10 log10(peak² / MSE)`, MSE the mean squared difference
/// of `a` and `b` (f64 accumulation). Infinite when the images are identical.
pub fn psnr_db(a: &[f32], b: &[f32], peak: f64) -> Result<f64, MetricsError> {
    if a.len() != b.len() {
        return Err(MetricsError::SizeMismatch {
            what: "psnr_db: b",
            expected: a.len(),
            actual: b.len(),
        });
    }
    if a.is_empty() {
        return Err(MetricsError::Empty("psnr_db: images"));
    }
    if !(peak.is_finite() && peak > 0.0) {
        return Err(MetricsError::InvalidParameter {
            name: "peak",
            value: peak.to_string(),
            reason: "must be finite and > 0 (e.g. 2^bits − 1 for DN images, 1 for [0, 1] images)",
        });
    }
    let mut se = 0.0f64;
    for (x, y) in a.iter().zip(b) {
        let d = *x as f64 - *y as f64;
        if !d.is_finite() {
            return Err(MetricsError::NonFinite("psnr_db: images"));
        }
        se += d * d;
    }
    let mse = se / a.len() as f64;
    Ok(if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak * peak / mse).log10()
    })
}

/// Distribution of a set of colour differences (e.g. a ΔE map or per-patch ΔE of a chart).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DeltaEStats {
    /// Number of values.
    pub count: usize,
    /// Arithmetic mean.
    pub mean: f64,
    /// Median (50th percentile).
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest value.
    pub max: f64,
}

/// Percentile `p` ∈ [0, 100] of ascending `sorted` by linear interpolation between order
/// statistics at rank p/100·(n − 1) (Hyndman & Fan 1996 definition 7, the numpy/R default).
fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    let n = sorted.len();
    let h = p / 100.0 * (n - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(n - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// Mean, median, 95th percentile (Hyndman–Fan definition 7) and maximum of `values`.
pub fn delta_e_stats(values: &[f64]) -> Result<DeltaEStats, MetricsError> {
    if values.is_empty() {
        return Err(MetricsError::Empty("delta_e_stats: values"));
    }
    if values.iter().any(|v| !v.is_finite()) {
        return Err(MetricsError::NonFinite("delta_e_stats: values"));
    }
    let mut s = values.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    Ok(DeltaEStats {
        count: s.len(),
        mean: s.iter().sum::<f64>() / s.len() as f64,
        median: percentile_sorted(&s, 50.0),
        p95: percentile_sorted(&s, 95.0),
        max: s[s.len() - 1],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_of_known_mse() {
        // every pixel off by 1 DN at peak 255: MSE = 1 → 20 log10(255) = 48.1308 dB
        let a = vec![10.0f32; 100];
        let b = vec![11.0f32; 100];
        let p = psnr_db(&a, &b, 255.0).unwrap();
        assert!((p - 20.0 * 255f64.log10()).abs() < 1e-12);
        assert_eq!(psnr_db(&a, &a, 255.0).unwrap(), f64::INFINITY);
        assert!(matches!(
            psnr_db(&a, &b[..5], 1.0),
            Err(MetricsError::SizeMismatch { .. })
        ));
        assert!(psnr_db(&a, &b, 0.0).is_err());
    }

    #[test]
    fn delta_e_stats_percentiles() {
        // 1..=100 in scrambled order: median 50.5, p95 at rank 94.05 → 95.05
        let v: Vec<f64> = (0..100).map(|i| ((i * 37) % 100 + 1) as f64).collect();
        let s = delta_e_stats(&v).unwrap();
        assert_eq!(s.count, 100);
        assert!((s.mean - 50.5).abs() < 1e-12);
        assert!((s.median - 50.5).abs() < 1e-12);
        assert!((s.p95 - 95.05).abs() < 1e-9);
        assert_eq!(s.max, 100.0);
        assert!(delta_e_stats(&[]).is_err());
        assert!(delta_e_stats(&[1.0, f64::NAN]).is_err());
    }
}
