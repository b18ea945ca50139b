//! Region statistics and the photon-transfer curve.

/// Mean, standard deviation and SNR of a set of values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionStats {
    /// Number of values.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (N − 1).
    pub std: f64,
    /// 20 log10(mean / std) (dB); infinite when std = 0.
    pub snr_db: f64,
}

/// Statistics of `values`.
pub fn stats(values: impl Iterator<Item = f64>) -> RegionStats {
    let (mut n, mut mean, mut m2) = (0usize, 0.0f64, 0.0f64);
    for v in values {
        // Welford's online update
        n += 1;
        let d = v - mean;
        mean += d / n as f64;
        m2 += d * (v - mean);
    }
    let std = if n > 1 {
        (m2 / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    RegionStats {
        count: n,
        mean,
        std,
        snr_db: 20.0 * (mean.abs() / std).log10(),
    }
}

/// A rectangle of rows [row0, row1) × cols [col0, col1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// first row
    pub row0: usize,
    /// one past the last row
    pub row1: usize,
    /// first column
    pub col0: usize,
    /// one past the last column
    pub col1: usize,
}

/// Statistics of the pixels of a row-major image inside `rect` for which `keep(row, col)`.
pub fn region_stats(
    data: &[f32],
    cols: usize,
    rect: Rect,
    keep: impl Fn(usize, usize) -> bool,
) -> RegionStats {
    stats((rect.row0..rect.row1).flat_map(|r| {
        let keep = &keep;
        (rect.col0..rect.col1)
            .filter(move |&c| keep(r, c))
            .map(move |c| data[r * cols + c] as f64)
    }))
}

/// One point of a photon-transfer curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PtcPoint {
    /// Mean signal (DN) of the two frames.
    pub mean_dn: f64,
    /// Temporal variance (DN²) = var(a − b) / 2, which removes fixed-pattern noise.
    pub variance_dn2: f64,
    /// Pixels used.
    pub count: usize,
}

/// Photon-transfer point from two frames of the same exposure (EMVA 1288 style), over the
/// pixels where `mask` is true (all when None).
pub fn ptc_point(a: &[f32], b: &[f32], mask: Option<&[bool]>) -> PtcPoint {
    let sel = |i: usize| mask.map(|m| m[i]).unwrap_or(true);
    let mean = stats(
        (0..a.len())
            .filter(|&i| sel(i))
            .map(|i| 0.5 * (a[i] as f64 + b[i] as f64)),
    );
    let diff = stats(
        (0..a.len())
            .filter(|&i| sel(i))
            .map(|i| a[i] as f64 - b[i] as f64),
    );
    PtcPoint {
        mean_dn: mean.mean,
        variance_dn2: diff.std * diff.std / 2.0,
        count: mean.count,
    }
}

/// Least-squares line y = slope·x + intercept with the slope's standard error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineFit {
    /// slope
    pub slope: f64,
    /// intercept
    pub intercept: f64,
    /// standard error of the slope
    pub slope_std_error: f64,
    /// standard error of the intercept, `√(s² (1/n + x̄²/Sxx))`
    pub intercept_std_error: f64,
}

/// Ordinary least squares fit of a line with the textbook standard errors of slope and
/// intercept (residual variance `s² = RSS/(n−2)`).
pub fn fit_line(x: &[f64], y: &[f64]) -> LineFit {
    let n = x.len() as f64;
    let mx = x.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let slope = sxy / sxx;
    let intercept = my - slope * mx;
    let rss: f64 = x
        .iter()
        .zip(y)
        .map(|(a, b)| (b - slope * a - intercept).powi(2))
        .sum();
    let s2 = if n > 2.0 { rss / (n - 2.0) } else { f64::NAN };
    LineFit {
        slope,
        intercept,
        slope_std_error: (s2 / sxx).sqrt(),
        intercept_std_error: (s2 * (1.0 / n + mx * mx / sxx)).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn stats_and_line_fit() {
        let s = stats([1.0, 2.0, 3.0, 4.0].into_iter());
        assert_relative_eq!(s.mean, 2.5);
        assert_relative_eq!(s.std, (5.0f64 / 3.0).sqrt());
        let f = fit_line(&[0.0, 1.0, 2.0], &[1.0, 3.0, 5.0]);
        assert_relative_eq!(f.slope, 2.0, epsilon = 1e-12);
        assert_relative_eq!(f.intercept, 1.0, epsilon = 1e-12);
    }

    #[test]
    fn ptc_removes_fixed_pattern() {
        // identical fixed pattern in both frames → zero temporal variance
        let a: Vec<f32> = (0..100).map(|i| (i % 10) as f32).collect();
        let p = ptc_point(&a, &a, None);
        assert_eq!(p.variance_dn2, 0.0);
        assert_relative_eq!(p.mean_dn, 4.5);
    }
}
