//! S-CIELAB, the spatial extension of CIELAB (X. Zhang & B. A. Wandell, "A spatial extension of
//! CIELAB for digital color image reproduction", SID Symposium Digest 27, 731–734 (1996); J. Soc.
//! Inf. Display 5(1), 61–63 (1997)), used in §3 of Farrell, Catrysse & Wandell (2012) to compare
//! simulated and ideal renderings.
//!
//! Steps: XYZ → opponent space (O1 luminance, O2 red–green, O3 blue–yellow; the XYZ→opponent
//! matrix of Poirson & Wandell as distributed with S-CIELAB, CIE 1931 2° observer) → each
//! channel convolved with a weighted sum of Gaussians `Σ w_i k_i exp(−(x² + y²)/σ_i²)` (σ_i in
//! degrees of visual angle, each Gaussian normalised to unit sum, the weights normalised to
//! sum 1 so that uniform areas are unchanged) → back to XYZ → CIELAB against the white point →
//! per-pixel ΔE.
//!
//! Image borders use symmetric (mirror) extension, which also keeps the mean of every uniform
//! region exactly.
use crate::color_difference::delta_e_2000;
use crate::error::MetricsError;
use camsim_core::colorimetry::{delta_e_76, xyz_to_lab, Xyz};
use rayon::prelude::*;
use serde::Serialize;

/// XYZ (CIE 1931 2°) → opponent (O1, O2, O3), rows = output channels: the matrix distributed
/// with the S-CIELAB code (X. Zhang, `cmatrix('xyz2opp')`, 1996; the same values are in
/// ISETCam `metrics/scielab/cmatrix.m`), derived from the Poirson & Wandell (1993) pattern-colour
/// separable model.
pub const XYZ_TO_OPPONENT: [[f64; 3]; 3] = [
    [0.2787336, 0.7218031, -0.1065520],
    [-0.4487736, 0.2898056, 0.0771569],
    [0.0859513, -0.5899859, 0.5011089],
];

/// XYZ (CIE 1964 10°) → opponent (O1, O2, O3): the 10° matrix distributed with S-CIELAB
/// (X. Zhang, `cmatrix('xyz2opp', 10)`, 1996–98; ISETCam `metrics/scielab/cmatrix.m`), used by
/// ISETCam's default `imageFormat = 'xyz10'` ([`ScielabOptions::isetcam`]).
pub const XYZ10_TO_OPPONENT: [[f64; 3]; 3] = [
    [0.2885613, 0.6597617, -0.1305654],
    [-0.4648864, 0.3262702, 0.0624200],
    [0.0798787, -0.5547976, 0.4814746],
];

/// The S-CIELAB filters as distributed with the S-CIELAB code and used by ISETCam by default
/// (`scGaussianParameters`, version 'distribution', the parameters Johnson & Fairchild also
/// print): per channel `(half-width at half maximum in degrees, weight)`, each Gaussian
/// `exp(−ln 2 · r² / h²)`; returned as [`GaussianTerm`]s with `spread = h / √ln 2`.
pub fn isetcam_distribution_filters() -> [Vec<GaussianTerm>; 3] {
    let t = |hwhm_deg: f64, weight| GaussianTerm {
        weight,
        spread_deg: hwhm_deg / std::f64::consts::LN_2.sqrt(),
    };
    [
        vec![t(0.05, 1.00327), t(0.225, 0.114416), t(7.0, -0.117686)],
        vec![t(0.0685, 0.616725), t(0.826, 0.383275)],
        vec![t(0.0920, 0.567885), t(0.6451, 0.432115)],
    ]
}

/// How the channel filters meet the image borders.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum ScielabBoundary {
    /// Symmetric (mirror) extension; the map has the image's size (camsim's default).
    Mirror,
    /// ISETCam's `scApplyFilters`: circular (FFT) convolution over the image, or over the
    /// image mirror-padded to the filter's size when the filter is larger; an even image side is
    /// first cut by its last row/column (ISETCam keeps the filter centred that way), so the
    /// ΔE map has odd sides unless a side equals the filter size.
    IsetcamCircular,
}

/// One Gaussian of an S-CIELAB channel filter: `weight · k · exp(−r²/spread²)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GaussianTerm {
    /// Weight w_i (before normalising the channel's weights to sum 1).
    pub weight: f64,
    /// Spread σ_i in degrees of visual angle (the σ of `exp(−r²/σ²)`).
    pub spread_deg: f64,
}

/// The published S-CIELAB filter parameters (Zhang & Wandell 1996, table on p. 3, as
/// transcribed in ISETCam `scGaussianParameters`, version 'published1996'): luminance,
/// red–green and blue–yellow channels, each `Σ w_i k_i exp(−r²/σ_i²)`. (The code distributed
/// with S-CIELAB uses the same weights normalised to sum 1, with spreads given as half-widths
/// about 1.7× larger.)
pub fn published_filters_1996() -> [Vec<GaussianTerm>; 3] {
    let t = |weight, spread_deg| GaussianTerm { weight, spread_deg };
    [
        vec![t(0.921, 0.0283), t(0.105, 0.133), t(-0.108, 4.336)],
        vec![t(0.531, 0.0392), t(0.330, 0.494)],
        vec![t(0.488, 0.0536), t(0.371, 0.386)],
    ]
}

/// Which per-pixel colour difference S-CIELAB reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum DeltaEFormula {
    /// ΔE*ab (CIE 1976), as in Zhang & Wandell (1996).
    Cie76,
    /// CIEDE2000 (the default of current ISETCam `scielab`).
    Ciede2000,
}

/// Options of [`scielab_with_options`].
#[derive(Debug, Clone, PartialEq)]
pub struct ScielabOptions {
    /// Image samples per degree of visual angle (viewing distance and pixel pitch together).
    pub samples_per_degree: f64,
    /// Per-pixel colour-difference formula.
    pub formula: DeltaEFormula,
    /// Filter terms of the O1, O2, O3 channels (weights are normalised to sum 1 per channel).
    pub filters: [Vec<GaussianTerm>; 3],
    /// Each sampled Gaussian extends to ± this many spreads σ_i (then renormalised to sum 1).
    pub support_spreads: f64,
    /// A fixed filter support instead: every Gaussian sampled on the same odd width (samples),
    /// ISETCam's `filterSize` (one degree, `ceil(samples_per_degree)`, minus 1 if even).
    pub fixed_support_samples: Option<usize>,
    /// XYZ → opponent matrix (rows = O1, O2, O3): [`XYZ_TO_OPPONENT`] (2°) or
    /// [`XYZ10_TO_OPPONENT`] (10°; the images and the white point must then be 10° XYZ).
    pub opponent: [[f64; 3]; 3],
    /// Border handling.
    pub boundary: ScielabBoundary,
    /// Clip each XYZ component to `[0, white]` before filtering (ISETCam `ClipXYZImage`).
    pub clip_to_white: bool,
}

impl ScielabOptions {
    /// ΔE*ab with the published 1996 filters and ±3σ support.
    pub fn new(samples_per_degree: f64) -> Self {
        ScielabOptions {
            samples_per_degree,
            formula: DeltaEFormula::Cie76,
            filters: published_filters_1996(),
            support_spreads: 3.0,
            fixed_support_samples: None,
            opponent: XYZ_TO_OPPONENT,
            boundary: ScielabBoundary::Mirror,
            clip_to_white: false,
        }
    }

    /// ISETCam's S-CIELAB (`scielab` with `scParams`, ISETCam metrics/scielab): CIEDE2000, the
    /// distributed filters ([`isetcam_distribution_filters`]), a fixed one-degree support
    /// (`ceil(samples_per_degree)`, made odd), the 10° opponent matrix (`imageFormat = 'xyz10'`:
    /// give 10° XYZ images and white point), circular filtering ([`ScielabBoundary`]) and XYZ
    /// clipped to `[0, white]`. ISETCam rounds `samples_per_degree` of a display to an integer
    /// (`scParams`); pass it rounded to match.
    pub fn isetcam(samples_per_degree: f64) -> Self {
        let s = samples_per_degree.ceil().max(1.0) as usize;
        ScielabOptions {
            samples_per_degree,
            formula: DeltaEFormula::Ciede2000,
            filters: isetcam_distribution_filters(),
            support_spreads: 3.0,
            fixed_support_samples: Some(if s % 2 == 1 { s } else { s - 1 }.max(1)),
            opponent: XYZ10_TO_OPPONENT,
            boundary: ScielabBoundary::IsetcamCircular,
            clip_to_white: true,
        }
    }
}

/// Result of an S-CIELAB comparison.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScielabResult {
    /// Rows of the map (the image's, or one fewer with [`ScielabBoundary::IsetcamCircular`]).
    pub rows: usize,
    /// Columns of the map.
    pub cols: usize,
    /// Per-pixel ΔE, row-major `rows × cols`.
    pub delta_e_map: Vec<f64>,
    /// Mean of `delta_e_map`.
    pub mean_delta_e: f64,
    /// The formula used for `delta_e_map`.
    pub formula: DeltaEFormula,
}

/// S-CIELAB ΔE*ab map between two row-major XYZ images viewed at `samples_per_degree`, with
/// CIELAB computed against `white_xyz` (same units as the images).
pub fn scielab(
    xyz_a: &[Xyz],
    xyz_b: &[Xyz],
    rows: usize,
    cols: usize,
    white_xyz: Xyz,
    samples_per_degree: f64,
) -> Result<ScielabResult, MetricsError> {
    scielab_with_options(
        xyz_a,
        xyz_b,
        rows,
        cols,
        white_xyz,
        &ScielabOptions::new(samples_per_degree),
    )
}

/// S-CIELAB with explicit options (formula, filter parameters, support).
pub fn scielab_with_options(
    xyz_a: &[Xyz],
    xyz_b: &[Xyz],
    rows: usize,
    cols: usize,
    white_xyz: Xyz,
    options: &ScielabOptions,
) -> Result<ScielabResult, MetricsError> {
    let n = rows * cols;
    if n == 0 {
        return Err(MetricsError::Empty("scielab: image (rows × cols = 0)"));
    }
    for (what, img) in [("scielab: xyz_a", xyz_a), ("scielab: xyz_b", xyz_b)] {
        if img.len() != n {
            return Err(MetricsError::SizeMismatch {
                what,
                expected: n,
                actual: img.len(),
            });
        }
        if img
            .iter()
            .any(|p| !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()))
        {
            return Err(MetricsError::NonFinite(what));
        }
    }
    let spd = options.samples_per_degree;
    if !(spd.is_finite() && spd > 0.0) {
        return Err(MetricsError::InvalidParameter {
            name: "samples_per_degree",
            value: spd.to_string(),
            reason: "must be finite and > 0",
        });
    }
    if !(white_xyz.x > 0.0 && white_xyz.y > 0.0 && white_xyz.z > 0.0) {
        return Err(MetricsError::InvalidParameter {
            name: "white_xyz",
            value: format!("({}, {}, {})", white_xyz.x, white_xyz.y, white_xyz.z),
            reason: "every component must be > 0",
        });
    }
    if !(options.support_spreads.is_finite() && options.support_spreads > 0.0) {
        return Err(MetricsError::InvalidParameter {
            name: "support_spreads",
            value: options.support_spreads.to_string(),
            reason: "must be finite and > 0",
        });
    }
    for f in &options.filters {
        let wsum: f64 = f.iter().map(|t| t.weight).sum();
        if f.is_empty() || wsum.abs() < 1e-12 || f.iter().any(|t| !(t.spread_deg >= 0.0)) {
            return Err(MetricsError::InvalidParameter {
                name: "filters",
                value: format!("{f:?}"),
                reason: "each channel needs terms with spreads ≥ 0 and weights not summing to 0",
            });
        }
    }
    if let Some(s) = options.fixed_support_samples {
        if s == 0 || s % 2 == 0 {
            return Err(MetricsError::InvalidParameter {
                name: "fixed_support_samples",
                value: s.to_string(),
                reason: "must be odd (a centred filter)",
            });
        }
    }
    let det = {
        let m = &options.opponent;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    if !(det.is_finite() && det.abs() > 1e-12) {
        return Err(MetricsError::InvalidParameter {
            name: "opponent",
            value: format!("{:?}", options.opponent),
            reason: "must be an invertible 3×3 matrix",
        });
    }
    let inv = invert3(&options.opponent);
    // ISETCam cuts an even side by its last row/column (see ScielabBoundary).
    let (orows, ocols) = match (options.boundary, options.fixed_support_samples) {
        (ScielabBoundary::IsetcamCircular, s) => {
            let cut = |m: usize| {
                let odd_support = s.unwrap_or(1);
                if m == odd_support || m % 2 == 1 || m == 1 {
                    m
                } else {
                    m - 1
                }
            };
            (cut(rows), cut(cols))
        }
        (ScielabBoundary::Mirror, _) => (rows, cols),
    };
    let on = orows * ocols;
    let filtered_lab = |img: &[Xyz]| -> Vec<camsim_core::colorimetry::Lab> {
        let clip = |v: f64, w: f64| {
            if options.clip_to_white {
                v.clamp(0.0, w)
            } else {
                v
            }
        };
        let opp: Vec<Vec<f64>> = (0..3)
            .map(|ch| {
                let m = options.opponent[ch];
                (0..on)
                    .map(|i| {
                        let p = img[(i / ocols) * cols + i % ocols];
                        m[0] * clip(p.x, white_xyz.x)
                            + m[1] * clip(p.y, white_xyz.y)
                            + m[2] * clip(p.z, white_xyz.z)
                    })
                    .collect()
            })
            .collect();
        let filt: Vec<Vec<f64>> = opp
            .into_par_iter()
            .enumerate()
            .map(|(ch, plane)| filter_opponent_plane(&plane, orows, ocols, ch, options))
            .collect();
        (0..on)
            .map(|i| {
                let o = [filt[0][i], filt[1][i], filt[2][i]];
                let xyz = Xyz {
                    x: inv[0][0] * o[0] + inv[0][1] * o[1] + inv[0][2] * o[2],
                    y: inv[1][0] * o[0] + inv[1][1] * o[1] + inv[1][2] * o[2],
                    z: inv[2][0] * o[0] + inv[2][1] * o[1] + inv[2][2] * o[2],
                };
                xyz_to_lab(xyz, white_xyz)
            })
            .collect()
    };
    let la = filtered_lab(xyz_a);
    let lb = filtered_lab(xyz_b);
    let delta_e_map: Vec<f64> = la
        .iter()
        .zip(&lb)
        .map(|(p, q)| match options.formula {
            DeltaEFormula::Cie76 => delta_e_76(*p, *q),
            DeltaEFormula::Ciede2000 => delta_e_2000(*p, *q),
        })
        .collect();
    let mean_delta_e = delta_e_map.iter().sum::<f64>() / on as f64;
    Ok(ScielabResult {
        rows: orows,
        cols: ocols,
        delta_e_map,
        mean_delta_e,
        formula: options.formula,
    })
}

/// Plain per-pixel CIELAB ΔE*ab map (no spatial filtering), for comparison with S-CIELAB.
pub fn cielab_delta_e_map(
    xyz_a: &[Xyz],
    xyz_b: &[Xyz],
    white_xyz: Xyz,
) -> Result<Vec<f64>, MetricsError> {
    if xyz_a.len() != xyz_b.len() {
        return Err(MetricsError::SizeMismatch {
            what: "cielab_delta_e_map: xyz_b",
            expected: xyz_a.len(),
            actual: xyz_b.len(),
        });
    }
    Ok(xyz_a
        .iter()
        .zip(xyz_b)
        .map(|(p, q)| delta_e_76(xyz_to_lab(*p, white_xyz), xyz_to_lab(*q, white_xyz)))
        .collect())
}

/// Inverse of a 3×3 matrix by cofactors.
fn invert3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let c = |r: usize, k: usize| {
        let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
        let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
        m[r1][k1] * m[r2][k2] - m[r1][k2] * m[r2][k1]
    };
    let det = m[0][0] * c(0, 0) + m[0][1] * c(0, 1) + m[0][2] * c(0, 2);
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = c(j, i) / det;
        }
    }
    out
}

/// Sampled 1-D factor of `exp(−r²/σ²)` (σ in pixels), truncated at ±`support_spreads`·σ and
/// normalised to unit sum. A spread below 1e-6 px is a delta.
fn gaussian_kernel(spread_px: f64, support_spreads: f64) -> Vec<f64> {
    if spread_px < 1e-6 {
        return vec![1.0];
    }
    let r = (support_spreads * spread_px).ceil().max(1.0) as usize;
    let mut k: Vec<f64> = (0..=2 * r)
        .map(|i| (-((i as f64 - r as f64) / spread_px).powi(2)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// `exp(−r²/σ²)` (σ = `spread_px`) sampled on `support` (odd) samples centred on 0,
/// normalised to unit sum (ISETCam `gauss`: `exp(−ln 2 x²/h²)` on `(1:S) − round(S/2)`).
fn gaussian_kernel_fixed(spread_px: f64, support: usize) -> Vec<f64> {
    let r = (support / 2) as f64;
    if spread_px < 1e-6 {
        let mut k = vec![0.0; support];
        k[support / 2] = 1.0;
        return k;
    }
    let mut k: Vec<f64> = (0..support)
        .map(|i| (-((i as f64 - r) / spread_px).powi(2)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// ISETCam's 1-D filtering of `scApplyFilters` (odd kernel of length S centred): for
/// `n ≥ S` the circular convolution over the n samples (the kernel zero-padded to n); for
/// `n < S` the signal mirror-padded by `(S − n)/2` each side to S samples, convolved
/// circularly over S and cut back to the centre n.
fn isetcam_conv_1d(x: &[f64], k: &[f64], out: &mut [f64]) {
    let n = x.len();
    let s = k.len();
    let r = (s / 2) as isize;
    let (ext, pad): (Vec<f64>, usize) = if s > n {
        let pad = (s - n) / 2;
        (
            (0..s)
                .map(|i| x[mirror(i as isize - pad as isize, n)])
                .collect(),
            pad,
        )
    } else {
        (x.to_vec(), 0)
    };
    let m = ext.len() as isize;
    for (i, o) in out.iter_mut().enumerate() {
        let c = (i + pad) as isize;
        *o = k
            .iter()
            .enumerate()
            .map(|(j, w)| w * ext[(c - (j as isize - r)).rem_euclid(m) as usize])
            .sum();
    }
}

/// Index into a signal of length n under symmetric (half-sample) extension, period 2n.
fn mirror(i: isize, n: usize) -> usize {
    let p = 2 * n as isize;
    let m = i.rem_euclid(p);
    if m < n as isize {
        m as usize
    } else {
        (p - 1 - m) as usize
    }
}

/// 1-D convolution with a centred odd-length kernel under symmetric extension. Kernels longer
/// than the period 2n are folded modulo 2n first (exact for the periodic extension).
fn convolve_1d(x: &[f64], k: &[f64], out: &mut [f64]) {
    let n = x.len();
    let r = (k.len() / 2) as isize;
    if k.len() > 2 * n {
        let p = 2 * n;
        let mut folded = vec![0.0; p];
        for (j, w) in k.iter().enumerate() {
            folded[(j as isize - r).rem_euclid(p as isize) as usize] += w;
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = folded
                .iter()
                .enumerate()
                .map(|(m, w)| w * x[mirror(i as isize - m as isize, n)])
                .sum();
        }
    } else {
        for (i, o) in out.iter_mut().enumerate() {
            *o = k
                .iter()
                .enumerate()
                .map(|(j, w)| w * x[mirror(i as isize - (j as isize - r), n)])
                .sum();
        }
    }
}

/// Separable convolution of a row-major plane with `kernel` along rows and columns.
fn separable(plane: &[f64], rows: usize, cols: usize, kernel: &[f64]) -> Vec<f64> {
    separable_with(plane, rows, cols, kernel, convolve_1d)
}

/// Separable filtering with the 1-D convolution `conv` along rows, then columns.
fn separable_with(
    plane: &[f64],
    rows: usize,
    cols: usize,
    kernel: &[f64],
    conv: fn(&[f64], &[f64], &mut [f64]),
) -> Vec<f64> {
    let mut tmp = vec![0.0; rows * cols];
    tmp.par_chunks_mut(cols)
        .zip(plane.par_chunks(cols))
        .for_each(|(o, x)| conv(x, kernel, o));
    // columns: transpose, filter, transpose back
    let mut t = vec![0.0; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            t[c * rows + r] = tmp[r * cols + c];
        }
    }
    let mut t2 = vec![0.0; rows * cols];
    t2.par_chunks_mut(rows)
        .zip(t.par_chunks(rows))
        .for_each(|(o, x)| conv(x, kernel, o));
    for r in 0..rows {
        for c in 0..cols {
            tmp[r * cols + c] = t2[c * rows + r];
        }
    }
    tmp
}

/// One opponent channel filtered by its normalised sum of Gaussians.
/// Filter one opponent plane (`rows × cols`, channel `channel` = 0 O1, 1 O2, 2 O3) with the
/// channel's filter of `options` and its border handling: the step between the opponent
/// transform and the inverse transform of [`scielab_with_options`] (for tests of the filters;
/// with [`ScielabBoundary::IsetcamCircular`] the sides must already be cut).
pub fn filter_opponent_plane(
    plane: &[f64],
    rows: usize,
    cols: usize,
    channel: usize,
    options: &ScielabOptions,
) -> Vec<f64> {
    let terms = &options.filters[channel];
    let spd = options.samples_per_degree;
    let wsum: f64 = terms.iter().map(|t| t.weight).sum();
    let mut out = vec![0.0; rows * cols];
    for t in terms {
        let spread_px = t.spread_deg * spd;
        let k = match options.fixed_support_samples {
            Some(s) => gaussian_kernel_fixed(spread_px, s),
            None => gaussian_kernel(spread_px, options.support_spreads),
        };
        let f = match options.boundary {
            ScielabBoundary::Mirror => separable(plane, rows, cols, &k),
            ScielabBoundary::IsetcamCircular => {
                separable_with(plane, rows, cols, &k, isetcam_conv_1d)
            }
        };
        let w = t.weight / wsum;
        out.iter_mut().zip(&f).for_each(|(o, v)| *o += w * v);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use camsim_core::rng::splitmix64;

    const D65: Xyz = Xyz {
        x: 95.047,
        y: 100.0,
        z: 108.883,
    };

    fn uniform(n: usize, p: Xyz) -> Vec<Xyz> {
        vec![p; n]
    }

    /// A uniform image plus ±`amp` per-pixel noise along opponent channel `ch`.
    fn opponent_noise(
        rows: usize,
        cols: usize,
        base: Xyz,
        ch: usize,
        amp: f64,
        seed: u64,
    ) -> Vec<Xyz> {
        let inv = invert3(&XYZ_TO_OPPONENT);
        (0..rows * cols)
            .map(|i| {
                let s = if splitmix64(seed ^ i as u64) & 1 == 0 {
                    amp
                } else {
                    -amp
                };
                Xyz {
                    x: base.x + inv[0][ch] * s,
                    y: base.y + inv[1][ch] * s,
                    z: base.z + inv[2][ch] * s,
                }
            })
            .collect()
    }

    #[test]
    fn opponent_matrix_round_trip() {
        let inv = invert3(&XYZ_TO_OPPONENT);
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|k| XYZ_TO_OPPONENT[i][k] * inv[k][j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn identical_images_give_zero() {
        let (rows, cols) = (24, 32);
        let a = opponent_noise(
            rows,
            cols,
            Xyz {
                x: 40.0,
                y: 42.0,
                z: 45.0,
            },
            1,
            3.0,
            1,
        );
        for formula in [DeltaEFormula::Cie76, DeltaEFormula::Ciede2000] {
            let o = ScielabOptions {
                formula,
                ..ScielabOptions::new(40.0)
            };
            let r = scielab_with_options(&a, &a, rows, cols, D65, &o).unwrap();
            assert!(r.delta_e_map.iter().all(|v| *v == 0.0));
            assert_eq!(r.mean_delta_e, 0.0);
        }
    }

    #[test]
    fn uniform_difference_equals_plain_cielab() {
        // the filters sum to 1 and the border is mirrored, so uniform fields pass unchanged
        let (rows, cols) = (20, 30);
        let p = Xyz {
            x: 30.0,
            y: 35.0,
            z: 20.0,
        };
        let q = Xyz {
            x: 33.0,
            y: 34.0,
            z: 25.0,
        };
        let expected = delta_e_76(xyz_to_lab(p, D65), xyz_to_lab(q, D65));
        // 4.336° · 100 samples/deg ≫ image size: exercises the folded long kernel too
        let r = scielab(
            &uniform(rows * cols, p),
            &uniform(rows * cols, q),
            rows,
            cols,
            D65,
            100.0,
        )
        .unwrap();
        for v in &r.delta_e_map {
            assert!((v - expected).abs() < 1e-9 * expected, "{v} vs {expected}");
        }
        assert!((r.mean_delta_e - expected).abs() < 1e-9 * expected);
        let o = ScielabOptions {
            formula: DeltaEFormula::Ciede2000,
            ..ScielabOptions::new(100.0)
        };
        let r = scielab_with_options(
            &uniform(rows * cols, p),
            &uniform(rows * cols, q),
            rows,
            cols,
            D65,
            &o,
        )
        .unwrap();
        let e00 = delta_e_2000(xyz_to_lab(p, D65), xyz_to_lab(q, D65));
        assert!((r.mean_delta_e - e00).abs() < 1e-9 * e00);
    }

    #[test]
    fn chromatic_noise_is_attenuated_more_than_luminance_noise() {
        // Per-pixel ±2 noise of equal amplitude along O1 (luminance), O2 (red–green) and O3
        // (blue–yellow) on a mid grey, viewed at 60 samples/degree (Nyquist 30 cycles/deg).
        let (rows, cols, spd) = (64, 64, 60.0);
        let grey = Xyz {
            x: 0.5 * D65.x,
            y: 0.5 * D65.y,
            z: 0.5 * D65.z,
        };
        let reference = uniform(rows * cols, grey);
        let ratio = |ch: usize| {
            let noisy = opponent_noise(rows, cols, grey, ch, 2.0, 7 + ch as u64);
            let s = scielab(&reference, &noisy, rows, cols, D65, spd)
                .unwrap()
                .mean_delta_e;
            let plain = cielab_delta_e_map(&reference, &noisy, D65).unwrap();
            let p = plain.iter().sum::<f64>() / plain.len() as f64;
            (s / p, s, p)
        };
        let (lum, lum_s, _) = ratio(0);
        let (rg, rg_s, _) = ratio(1);
        let (by, by_s, _) = ratio(2);
        eprintln!("S-CIELAB/CIELAB ratio: lum {lum:.4}, rg {rg:.4}, by {by:.4}; s {lum_s:.4} {rg_s:.4} {by_s:.4}");
        assert!(
            lum < 0.5,
            "luminance pixel noise must itself be attenuated: {lum}"
        );
        assert!(rg < 0.6 * lum, "red–green {rg} vs luminance {lum}");
        assert!(by < 0.6 * lum, "blue–yellow {by} vs luminance {lum}");
    }

    #[test]
    fn bad_input_is_reported() {
        let a = uniform(6, D65);
        assert!(matches!(
            scielab(&a, &a[..5], 2, 3, D65, 50.0),
            Err(MetricsError::SizeMismatch { .. })
        ));
        assert!(scielab(&a, &a, 2, 3, D65, 0.0).is_err());
        assert!(scielab(
            &a,
            &a,
            2,
            3,
            Xyz {
                x: 0.0,
                y: 1.0,
                z: 1.0
            },
            50.0
        )
        .is_err());
    }
}
