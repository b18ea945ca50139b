//! Measurements on rolling-shutter frames: the position of a near-vertical edge in every row
//! (its skew under motion) and the period of flicker bands along the rows.
use camsim_core::stats::{fit_line, LineFit};

/// The edge position of every row of a frame holding one near-vertical step edge.
///
/// Row r's reference levels are the means of its first and last `ref_cols` values (`a` on
/// the left, `b` on the right); the position is `Σ_c (b − v_c)/(b − a) − 1/2` (pixel
/// centres at integer columns): for a step at x = e, pixel c covering `[c − ½, c + ½]`,
/// every pixel left of e contributes 1, the pixel cut by it its left fraction, so the sum is
/// the length `e + ½` of the left part. A blur that conserves signal (optics, motion) moves
/// no weight across the edge centroid, so the position is the centroid of the blurred edge;
/// a common gain of the row (flicker) cancels in the ratio. Rows whose contrast `|b − a|` is
/// below `min_contrast_fraction` of the largest row contrast (a row that caught little of a
/// flickering light, where the ratio is mostly noise) give NaN.
pub fn row_edge_positions_px(
    plane: &[f64],
    rows: usize,
    cols: usize,
    ref_cols: usize,
    min_contrast_fraction: f64,
) -> Vec<f64> {
    let k = ref_cols.clamp(1, (cols / 2).max(1));
    let refs: Vec<(f64, f64)> = (0..rows)
        .map(|r| {
            let row = &plane[r * cols..(r + 1) * cols];
            let a = row[..k].iter().sum::<f64>() / k as f64;
            let b = row[cols - k..].iter().sum::<f64>() / k as f64;
            (a, b)
        })
        .collect();
    let max_contrast = refs.iter().map(|(a, b)| (b - a).abs()).fold(0.0, f64::max);
    refs.iter()
        .enumerate()
        .map(|(r, &(a, b))| {
            if !((b - a).abs() >= min_contrast_fraction * max_contrast && b != a) {
                return f64::NAN;
            }
            let row = &plane[r * cols..(r + 1) * cols];
            row.iter().map(|v| (b - v) / (b - a)).sum::<f64>() - 0.5
        })
        .collect()
}

/// The line fitted to the row edge positions against the row index: its slope is the skew in
/// pixels per row (ordinary least squares, [`camsim_core::stats::fit_line`]; NaN rows are
/// skipped).
pub fn edge_skew_fit(positions_px: &[f64]) -> LineFit {
    let (x, y): (Vec<f64>, Vec<f64>) = positions_px
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_finite())
        .map(|(r, &p)| (r as f64, p))
        .unzip();
    fit_line(&x, &y)
}

/// The dominant period of a sequence (flicker bands in the row means).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodEstimate {
    /// Period (samples, i.e. rows).
    pub period_rows: f64,
    /// Standard error of the period from the noise: the Cramér–Rao bound for the frequency
    /// of a sinusoid of amplitude A in white noise of variance σ² over N samples,
    /// `var(ω) = 12 σ² / (A² N (N² − 1))` (Rife & Boorstyn, IEEE Trans. Inf. Theory 20(5),
    /// 1974, eq. 17), carried to the period by `σ_P = P² σ_ω / 2π`.
    pub period_std_error_rows: f64,
    /// Amplitude A of the fundamental.
    pub amplitude: f64,
}

/// The dominant period of `values` (N samples, noise variance `noise_variance` per sample):
/// the frequency ν (cycles per N samples) maximising the magnitude of the discrete-time
/// Fourier transform of the mean-removed values, first over the integer bins 1..N/2 and then
/// refined on a grid of 1/1000 bin within ±1 bin of the best one; period N/ν. None for fewer
/// than 8 values or a constant sequence.
pub fn dominant_period(values: &[f64], noise_variance: f64) -> Option<PeriodEstimate> {
    let n = values.len();
    if n < 8 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let dev: Vec<f64> = values.iter().map(|v| v - mean).collect();
    let magnitude = |nu: f64| {
        let (mut re, mut im) = (0.0, 0.0);
        for (i, d) in dev.iter().enumerate() {
            let a = 2.0 * std::f64::consts::PI * nu * i as f64 / n as f64;
            re += d * a.cos();
            im -= d * a.sin();
        }
        (re * re + im * im).sqrt()
    };
    let best_bin =
        (1..=n / 2).max_by(|&a, &b| magnitude(a as f64).total_cmp(&magnitude(b as f64)))?;
    let mut best = (best_bin as f64, magnitude(best_bin as f64));
    if best.1 <= 0.0 {
        return None;
    }
    for i in -1000..=1000 {
        let nu = best_bin as f64 + i as f64 / 1000.0;
        if nu <= 0.5 {
            continue;
        }
        let m = magnitude(nu);
        if m > best.1 {
            best = (nu, m);
        }
    }
    let period = n as f64 / best.0;
    let amplitude = 2.0 * best.1 / n as f64;
    let nf = n as f64;
    let sigma_omega =
        (12.0 * noise_variance / (amplitude * amplitude * nf * (nf * nf - 1.0))).sqrt();
    Some(PeriodEstimate {
        period_rows: period,
        period_std_error_rows: period * period * sigma_omega / (2.0 * std::f64::consts::PI),
        amplitude,
    })
}

/// The centre of a bright (or dark) vertical bar in every row of a frame: row r's background
/// level `a` is the mean of its first and last `ref_cols` values together, and the centre is
/// the first moment `Σ_c c·(v_c − a) / Σ_c (v_c − a)` over the columns between the two
/// reference blocks (pixel centres at integer columns). A blur that conserves signal (optics,
/// motion) leaves the first moment of the bar where it was, and a common gain of the row
/// (flicker) cancels in the ratio, so under motion the centre is the bar's centre at the
/// light-weighted mean time of the row's window. Rows whose bar signal `|Σ_c (v_c − a)|` is
/// below `min_contrast_fraction` of the largest row's give NaN (rows that caught little
/// light).
pub fn row_bar_centres_px(
    plane: &[f64],
    rows: usize,
    cols: usize,
    ref_cols: usize,
    min_contrast_fraction: f64,
) -> Vec<f64> {
    let k = ref_cols.clamp(1, (cols / 2).saturating_sub(1).max(1));
    let moments: Vec<(f64, f64)> = (0..rows)
        .map(|r| {
            let row = &plane[r * cols..(r + 1) * cols];
            let a = (row[..k].iter().sum::<f64>() + row[cols - k..].iter().sum::<f64>())
                / (2 * k) as f64;
            let (mut m0, mut m1) = (0.0, 0.0);
            for (c, v) in row.iter().enumerate().take(cols - k).skip(k) {
                m0 += v - a;
                m1 += c as f64 * (v - a);
            }
            (m0, m1)
        })
        .collect();
    let max_signal = moments.iter().map(|(m0, _)| m0.abs()).fold(0.0, f64::max);
    moments
        .iter()
        .map(|&(m0, m1)| {
            if m0 != 0.0 && m0.abs() >= min_contrast_fraction * max_signal {
                m1 / m0
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// The phase (radians, in (−π, π]) of the component of period `period_rows` in `values`:
/// `arg Σ_i d_i e^{−2πi·i/P}` of the mean-removed values `d_i`, the least-squares phase φ of
/// `A cos(2π i/P + φ)` when the record holds many periods. A pattern that moves D rows up
/// (`m'(i) = m(i + D)`) has its phase advanced by `2π D / P`.
pub fn phase_at_period(values: &[f64], period_rows: f64) -> f64 {
    let n = values.len();
    let mean = values.iter().sum::<f64>() / n.max(1) as f64;
    let (mut re, mut im) = (0.0, 0.0);
    for (i, v) in values.iter().enumerate() {
        let a = 2.0 * std::f64::consts::PI * i as f64 / period_rows;
        re += (v - mean) * a.cos();
        im -= (v - mean) * a.sin();
    }
    im.atan2(re)
}
