//! Slanted-edge spatial frequency response (e-SFR) after ISO 12233:2017 (Annex D; the
//! algorithm of Burns' `sfrmat3`), the MTF measurement of §3 of Farrell, Catrysse & Wandell
//! (2012).
//!
//! 1. Per row of the region of interest, the first difference across the edge; the edge
//!    location is the centroid of that derivative (second pass: derivative multiplied by a
//!    Hamming window centred on the first-pass fit, to suppress noise far from the edge).
//! 2. A least-squares line through the row centroids gives the edge position and angle; the
//!    region is trimmed to a whole number of phase cycles so that all sub-pixel phases are
//!    equally represented.
//! 3. Every pixel is projected along the edge onto the horizontal axis through the fitted line
//!    and accumulated in bins of 1/`oversampling` pixel: the oversampled edge-spread function
//!    (ESF). Empty bins are interpolated.
//! 4. The line-spread function (LSF) is the centred difference of the ESF, multiplied by a
//!    Hamming window centred on its centroid.
//! 5. |DFT| normalised to 1 at zero frequency. Bin frequencies are converted from the
//!    horizontal axis to the direction normal to the edge (× 1/cos θ, as in sfrmat3), and
//!    optionally divided by the transfer function of the centred difference, sinc(2 f Δ) with
//!    Δ the bin width (ISO 12233 "derivative correction").
//! 6. MTF50: first crossing of 0.5, by linear interpolation.
//!
//! The pixel aperture is part of the measured system (an ideal edge imaged by square pixels
//! gives sinc-shaped e-SFR), exactly as in ISO 12233. Input must be linear in exposure (no OECF
//! inversion is applied).
use crate::error::MetricsError;
use camsim_core::stats::{fit_line, Rect};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use serde::Serialize;

/// Whether the edge runs roughly along the columns or along the rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum EdgeOrientation {
    /// Near-vertical edge (transition along each row); the SFR is horizontal.
    Vertical,
    /// Near-horizontal edge (transition along each column); the SFR is vertical.
    Horizontal,
}

/// Options of [`slanted_edge_mtf_with_options`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeMtfOptions {
    /// ESF bins per pixel (ISO 12233: 4).
    pub oversampling: usize,
    /// Divide by the transfer function of the discrete derivative (ISO 12233, sfrmat3).
    pub correct_derivative: bool,
    /// Hamming windows for the centroid (second pass) and the LSF (ISO 12233).
    pub hamming_window: bool,
}

impl Default for EdgeMtfOptions {
    fn default() -> Self {
        EdgeMtfOptions {
            oversampling: 4,
            correct_derivative: true,
            hamming_window: true,
        }
    }
}

/// Result of a slanted-edge measurement.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EdgeMtf {
    /// Orientation of the edge in the region.
    pub orientation: EdgeOrientation,
    /// Edge angle from the vertical (vertical edges) or from the horizontal (horizontal edges)
    /// in degrees. For a vertical edge the sign follows the capture-format `slanted_edge`
    /// convention: positive when the edge's top leans right (clockwise as displayed). For a
    /// horizontal edge it is positive when the edge's right end is lower.
    pub angle_deg: f64,
    /// Edge position across the region's first row (column, or row for a horizontal edge, in
    /// image coordinates, pixel centres at integers).
    pub edge_offset_px: f64,
    /// Spatial frequencies, cycles per pixel normal to the edge, from 0 up to half the
    /// oversampled sampling rate.
    pub frequencies_cycles_per_pixel: Vec<f64>,
    /// MTF at each frequency, 1 at zero frequency.
    pub mtf: Vec<f64>,
    /// Frequency where the MTF first falls to 0.5 (linear interpolation); None if it stays
    /// above 0.5 over the whole range.
    pub mtf50_cycles_per_pixel: Option<f64>,
    /// Number of rows (columns for a horizontal edge) used after phase-cycle trimming.
    pub lines_used: usize,
}

/// ISO 12233 e-SFR of the edge inside `roi` of a row-major `rows × cols` image, with the
/// default options (4× oversampling, Hamming windows, derivative correction).
pub fn slanted_edge_mtf(
    image: &[f32],
    rows: usize,
    cols: usize,
    roi: Rect,
) -> Result<EdgeMtf, MetricsError> {
    slanted_edge_mtf_with_options(image, rows, cols, roi, &EdgeMtfOptions::default())
}

/// Hamming window value at offset `x` from its centre, for a window `width` samples long.
fn hamming(x: f64, width: f64) -> f64 {
    if x.abs() > 0.5 * width {
        0.0
    } else {
        0.54 + 0.46 * (2.0 * std::f64::consts::PI * x / width).cos()
    }
}

/// Centroid (in column units, differences located half-way between pixels) of each line's
/// first difference, optionally Hamming-windowed around `centre(line)`.
fn centroids(
    lines: &[Vec<f64>],
    window: Option<&dyn Fn(usize) -> f64>,
) -> Result<Vec<f64>, MetricsError> {
    let n = lines[0].len();
    let mut out = Vec::with_capacity(lines.len());
    for (i, line) in lines.iter().enumerate() {
        let (mut s, mut sx) = (0.0, 0.0);
        for j in 0..n - 1 {
            let x = j as f64 + 0.5;
            let mut d = line[j + 1] - line[j];
            if let Some(c) = window {
                d *= hamming(x - c(i), n as f64);
            }
            s += d;
            sx += d * x;
        }
        if s.abs() < 1e-12 {
            return Err(MetricsError::Edge(format!(
                "line {i} of the region has no contrast across the edge"
            )));
        }
        out.push(sx / s);
    }
    Ok(out)
}

/// ISO 12233 e-SFR with explicit options.
pub fn slanted_edge_mtf_with_options(
    image: &[f32],
    rows: usize,
    cols: usize,
    roi: Rect,
    options: &EdgeMtfOptions,
) -> Result<EdgeMtf, MetricsError> {
    if image.len() != rows * cols {
        return Err(MetricsError::SizeMismatch {
            what: "slanted_edge_mtf: image",
            expected: rows * cols,
            actual: image.len(),
        });
    }
    if roi.row1 > rows || roi.col1 > cols || roi.row0 >= roi.row1 || roi.col0 >= roi.col1 {
        return Err(MetricsError::RoiOutOfBounds {
            row0: roi.row0,
            row1: roi.row1,
            col0: roi.col0,
            col1: roi.col1,
            rows,
            cols,
        });
    }
    let ov = options.oversampling;
    if !(1..=16).contains(&ov) {
        return Err(MetricsError::InvalidParameter {
            name: "oversampling",
            value: ov.to_string(),
            reason: "must be in 1..=16 (ISO 12233 uses 4)",
        });
    }
    let (rr, rc) = (roi.row1 - roi.row0, roi.col1 - roi.col0);
    if rr < 8 || rc < 8 {
        return Err(MetricsError::Edge(format!(
            "region {rr}×{rc} is too small (need ≥ 8×8)"
        )));
    }
    let px = |r: usize, c: usize| image[(roi.row0 + r) * cols + roi.col0 + c] as f64;
    if (0..rr).any(|r| (0..rc).any(|c| !px(r, c).is_finite())) {
        return Err(MetricsError::NonFinite("slanted_edge_mtf: region"));
    }

    // Orientation: the edge crosses the direction with the larger total gradient.
    let (mut gh, mut gv) = (0.0, 0.0);
    for r in 0..rr {
        for c in 0..rc {
            if c + 1 < rc {
                gh += (px(r, c + 1) - px(r, c)).abs();
            }
            if r + 1 < rr {
                gv += (px(r + 1, c) - px(r, c)).abs();
            }
        }
    }
    let orientation = if gh >= gv {
        EdgeOrientation::Vertical
    } else {
        EdgeOrientation::Horizontal
    };
    // "lines" run across the edge
    let lines: Vec<Vec<f64>> = match orientation {
        EdgeOrientation::Vertical => (0..rr)
            .map(|r| (0..rc).map(|c| px(r, c)).collect())
            .collect(),
        EdgeOrientation::Horizontal => (0..rc)
            .map(|c| (0..rr).map(|r| px(r, c)).collect())
            .collect(),
    };
    let (n_lines, n) = (lines.len(), lines[0].len());

    // 1–2. centroids and line fit, two passes
    let idx: Vec<f64> = (0..n_lines).map(|i| i as f64).collect();
    let c1 = centroids(&lines, None)?;
    let mut fit = fit_line(&idx, &c1);
    if options.hamming_window {
        let (a, b) = (fit.intercept, fit.slope);
        let w = move |i: usize| a + b * i as f64;
        let c2 = centroids(&lines, Some(&w))?;
        fit = fit_line(&idx, &c2);
    }
    let mut slope = fit.slope;
    // Phase-cycle trimming (sfrmat3): keep a whole number of one-pixel edge shifts.
    let shift = slope.abs() * (n_lines - 1) as f64;
    if shift < 1.0 {
        return Err(MetricsError::Edge(format!(
            "edge shifts only {shift:.2} px across {n_lines} lines (angle {:.2}°): use a larger \
             region or an edge slanted by ≥ 2°",
            slope.atan().to_degrees()
        )));
    }
    let cycles = shift.floor();
    let n_used = ((cycles / slope.abs()).floor() as usize + 1).min(n_lines);
    let lines = &lines[..n_used];
    if n_used < n_lines {
        let idx: Vec<f64> = (0..n_used).map(|i| i as f64).collect();
        let a = fit.intercept;
        let b = fit.slope;
        let w = move |i: usize| a + b * i as f64;
        let c = centroids(
            lines,
            options
                .hamming_window
                .then_some(&w as &dyn Fn(usize) -> f64),
        )?;
        fit = fit_line(&idx, &c);
        slope = fit.slope;
    }
    let offset = fit.intercept;

    // 3. oversampled ESF: bin k covers distances [(k/ov − n/2), (k+1)/ov − n/2)
    let nb = n * ov;
    let mut sum = vec![0.0; nb];
    let mut cnt = vec![0usize; nb];
    for (i, line) in lines.iter().enumerate() {
        let edge = offset + slope * i as f64;
        for (j, v) in line.iter().enumerate() {
            let d = j as f64 - edge + 0.5 * n as f64;
            let k = (d * ov as f64).floor();
            if k >= 0.0 && (k as usize) < nb {
                sum[k as usize] += v;
                cnt[k as usize] += 1;
            }
        }
    }
    let filled: Vec<usize> = (0..nb).filter(|&k| cnt[k] > 0).collect();
    if filled.len() < nb / 2 {
        return Err(MetricsError::Edge("too few populated ESF bins".into()));
    }
    let mut esf: Vec<f64> = (0..nb)
        .map(|k| {
            if cnt[k] > 0 {
                sum[k] / cnt[k] as f64
            } else {
                f64::NAN
            }
        })
        .collect();
    // empty bins: linear interpolation between neighbours, nearest value at the ends
    let mut prev: Option<usize> = None;
    for k in 0..nb {
        if cnt[k] > 0 {
            if let Some(p) = prev {
                for m in p + 1..k {
                    let t = (m - p) as f64 / (k - p) as f64;
                    esf[m] = esf[p] + t * (esf[k] - esf[p]);
                }
            } else {
                for v in esf.iter_mut().take(k) {
                    *v = sum[k] / cnt[k] as f64;
                }
            }
            prev = Some(k);
        }
    }
    if let Some(p) = prev {
        let v = esf[p];
        esf.iter_mut().skip(p + 1).for_each(|e| *e = v);
    }

    // 4. LSF by centred difference, polarity to positive, Hamming window on its centroid
    let mut lsf = vec![0.0; nb];
    for k in 1..nb - 1 {
        lsf[k] = 0.5 * (esf[k + 1] - esf[k - 1]);
    }
    lsf[0] = lsf[1];
    lsf[nb - 1] = lsf[nb - 2];
    let total: f64 = lsf.iter().sum();
    if total.abs() < 1e-12 {
        return Err(MetricsError::Edge(
            "the edge-spread function has no step".into(),
        ));
    }
    if total < 0.0 {
        lsf.iter_mut().for_each(|v| *v = -*v);
    }
    if options.hamming_window {
        let s: f64 = lsf.iter().sum();
        let mu = lsf
            .iter()
            .enumerate()
            .map(|(k, v)| k as f64 * v)
            .sum::<f64>()
            / s;
        for (k, v) in lsf.iter_mut().enumerate() {
            *v *= hamming(k as f64 - mu, nb as f64);
        }
    }

    // 5. DFT
    let mut buf: Vec<Complex<f64>> = lsf.iter().map(|&v| Complex::new(v, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(nb).process(&mut buf);
    let dc = buf[0].norm();
    if dc <= 0.0 {
        return Err(MetricsError::Edge("zero-frequency response is zero".into()));
    }
    let cos_t = slope.atan().cos();
    let half = nb / 2;
    let mut freqs = Vec::with_capacity(half + 1);
    let mut mtf = Vec::with_capacity(half + 1);
    for (k, z) in buf.iter().enumerate().take(half + 1) {
        let f_bins = k as f64 * ov as f64 / nb as f64; // cycles per pixel along the lines
        let mut m = z.norm() / dc;
        if options.correct_derivative && k > 0 {
            // centred difference over ±Δ, Δ = 1/ov px: H(f) = sin(2πfΔ)/(2πfΔ); capped at 10×
            let x = 2.0 * std::f64::consts::PI * f_bins / ov as f64;
            m /= (x.sin() / x).max(0.1);
        }
        freqs.push(f_bins / cos_t);
        mtf.push(m);
    }

    // 6. MTF50
    let mtf50 = (1..mtf.len())
        .find(|&k| mtf[k] < 0.5 && mtf[k - 1] >= 0.5)
        .map(|k| {
            let (f0, f1, m0, m1) = (freqs[k - 1], freqs[k], mtf[k - 1], mtf[k]);
            f0 + (m0 - 0.5) / (m0 - m1) * (f1 - f0)
        });

    let angle = slope.atan().to_degrees();
    let (angle_deg, edge_offset_px) = match orientation {
        // col = offset + slope·row; top leaning right means slope < 0
        EdgeOrientation::Vertical => (-angle, roi.col0 as f64 + offset),
        // row = offset + slope·col; right end lower means slope > 0
        EdgeOrientation::Horizontal => (angle, roi.row0 as f64 + offset),
    };
    Ok(EdgeMtf {
        orientation,
        angle_deg,
        edge_offset_px,
        frequencies_cycles_per_pixel: freqs,
        mtf,
        mtf50_cycles_per_pixel: mtf50,
        lines_used: n_used,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// erfc with fractional error < 1.2e-7 (Chebyshev fit; Press et al., Numerical Recipes,
    /// 2nd ed., §6.2 `erfcc`).
    fn erfc(x: f64) -> f64 {
        let z = x.abs();
        let t = 1.0 / (1.0 + 0.5 * z);
        let ans = t
            * (-z * z - 1.26551223
                + t * (1.00002368
                    + t * (0.37409196
                        + t * (0.09678418
                            + t * (-0.18628806
                                + t * (0.27886807
                                    + t * (-1.13520398
                                        + t * (1.48851587
                                            + t * (-0.82215223 + t * 0.17087277)))))))))
                .exp();
        if x >= 0.0 {
            ans
        } else {
            2.0 - ans
        }
    }
    fn phi_cdf(u: f64) -> f64 {
        0.5 * erfc(-u / 2f64.sqrt())
    }
    /// ∫_{-∞}^{u} Φ(t) dt = u Φ(u) + φ(u).
    fn phi_int(u: f64) -> f64 {
        u * phi_cdf(u) + (-0.5 * u * u).exp() / (2.0 * PI).sqrt()
    }

    /// A `rows × cols` image of a straight edge at `angle_deg` (capture-format convention: light
    /// side x cos a + y sin a > 0, x right, y down, from the point (x0, y0) in pixel
    /// coordinates), blurred by an isotropic Gaussian of σ = `sigma_px` and integrated over each
    /// pixel's unit square: exactly along x, by a 200-point midpoint rule along y.
    fn render_edge(
        rows: usize,
        cols: usize,
        angle_deg: f64,
        sigma_px: f64,
        x0: f64,
        y0: f64,
    ) -> Vec<f32> {
        let (dark, light) = (0.1, 0.9);
        let a = angle_deg.to_radians();
        let (ca, sa) = (a.cos(), a.sin());
        let sub = 200;
        let mut img = vec![0f32; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                let (xa, xb) = (c as f64 - x0, c as f64 + 1.0 - x0);
                let mut acc = 0.0;
                for s in 0..sub {
                    let y = r as f64 + (s as f64 + 0.5) / sub as f64 - y0;
                    let u0 = (xa * ca + y * sa) / sigma_px;
                    let u1 = (xb * ca + y * sa) / sigma_px;
                    acc += sigma_px / ca * (phi_int(u1) - phi_int(u0));
                }
                let frac = acc / sub as f64;
                img[r * cols + c] = (dark + (light - dark) * frac) as f32;
            }
        }
        img
    }

    fn sinc(x: f64) -> f64 {
        if x.abs() < 1e-12 {
            1.0
        } else {
            (PI * x).sin() / (PI * x)
        }
    }
    /// Gaussian blur × square pixel aperture seen across an edge at angle a.
    fn analytic_mtf(f: f64, sigma: f64, a: f64) -> f64 {
        (-2.0 * PI * PI * sigma * sigma * f * f).exp() * sinc(f * a.cos()) * sinc(f * a.sin())
    }
    fn analytic_mtf50(sigma: f64, a: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..100 {
            let m = 0.5 * (lo + hi);
            if analytic_mtf(m, sigma, a) > 0.5 {
                lo = m
            } else {
                hi = m
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn gaussian_blurred_slanted_edge_matches_analytic_mtf() {
        let (rows, cols) = (120, 64);
        let angle = 5.0;
        for sigma in [0.5, 1.0, 2.0] {
            let img = render_edge(rows, cols, angle, sigma, 32.3, 60.0);
            let roi = Rect {
                row0: 0,
                row1: rows,
                col0: 0,
                col1: cols,
            };
            let m = slanted_edge_mtf(&img, rows, cols, roi).unwrap();
            assert_eq!(m.orientation, EdgeOrientation::Vertical);
            assert!(
                (m.angle_deg - angle).abs() < 0.05,
                "σ {sigma}: angle {}",
                m.angle_deg
            );
            let a = (angle as f64).to_radians();
            let mut worst: f64 = 0.0;
            for (f, v) in m.frequencies_cycles_per_pixel.iter().zip(&m.mtf) {
                if *f > 0.5 {
                    break;
                }
                let e = analytic_mtf(*f, sigma, a);
                worst = worst.max((v - e).abs());
                // within 3 % of the analytic value (+0.005 absolute where the MTF is near 0)
                assert!(
                    (v - e).abs() < 0.03 * e + 0.005,
                    "σ {sigma}: f {f:.4}: MTF {v:.4}, analytic {e:.4}"
                );
            }
            let m50 = m.mtf50_cycles_per_pixel.unwrap();
            let e50 = analytic_mtf50(sigma, a);
            eprintln!(
                "σ {sigma}: angle {:.4}°, max |ΔMTF| {worst:.4}, MTF50 {m50:.4} vs {e50:.4}",
                m.angle_deg
            );
            assert!(
                (m50 / e50 - 1.0).abs() < 0.02,
                "σ {sigma}: MTF50 {m50} vs analytic {e50}"
            );
        }
    }

    #[test]
    fn angle_sign_polarity_and_horizontal_edges() {
        let (rows, cols) = (96, 96);
        // negative angle (top leans left) and reversed polarity (light on the left)
        let img = render_edge(rows, cols, 180.0 - 7.0, 1.0, 48.0, 48.0);
        let roi = Rect {
            row0: 8,
            row1: 88,
            col0: 16,
            col1: 80,
        };
        let m = slanted_edge_mtf(&img, rows, cols, roi).unwrap();
        assert_eq!(m.orientation, EdgeOrientation::Vertical);
        // the 173° edge is the −7° edge with the light side swapped
        assert!((m.angle_deg + 7.0).abs() < 0.05, "{}", m.angle_deg);
        let e50 = analytic_mtf50(1.0, 7f64.to_radians());
        assert!((m.mtf50_cycles_per_pixel.unwrap() / e50 - 1.0).abs() < 0.02);
        // near-horizontal edge: normal at 90° − 6° from the x axis
        let img = render_edge(rows, cols, 84.0, 1.0, 48.0, 48.0);
        let roi = Rect {
            row0: 16,
            row1: 80,
            col0: 0,
            col1: 96,
        };
        let m = slanted_edge_mtf(&img, rows, cols, roi).unwrap();
        assert_eq!(m.orientation, EdgeOrientation::Horizontal);
        // the edge line y = −x cot 84°: right end higher, i.e. −6° by the horizontal convention
        assert!((m.angle_deg + 6.0).abs() < 0.05, "{}", m.angle_deg);
        let e50 = analytic_mtf50(1.0, 6f64.to_radians());
        assert!((m.mtf50_cycles_per_pixel.unwrap() / e50 - 1.0).abs() < 0.02);
    }

    #[test]
    fn noisy_edge_still_gives_mtf50() {
        // σ = 1 px blur plus white noise of 0.01 (edge contrast 0.8, SNR 80 on the step)
        let (rows, cols) = (120, 64);
        let mut img = render_edge(rows, cols, 5.0, 1.0, 32.3, 60.0);
        for (i, v) in img.iter_mut().enumerate() {
            let u = |s: u64| {
                ((camsim_core::rng::splitmix64(s) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let n = (-2.0 * u(i as u64).ln()).sqrt() * (2.0 * PI * u(i as u64 ^ 0x5555_0000)).cos();
            *v += (0.01 * n) as f32;
        }
        let roi = Rect {
            row0: 0,
            row1: rows,
            col0: 0,
            col1: cols,
        };
        let m = slanted_edge_mtf(&img, rows, cols, roi).unwrap();
        let e50 = analytic_mtf50(1.0, 5f64.to_radians());
        let m50 = m.mtf50_cycles_per_pixel.unwrap();
        assert!((m.angle_deg - 5.0).abs() < 0.1, "{}", m.angle_deg);
        assert!((m50 / e50 - 1.0).abs() < 0.03, "noisy MTF50 {m50} vs {e50}");
    }

    #[test]
    fn unusable_regions_are_rejected() {
        let (rows, cols) = (40, 40);
        let flat = vec![0.5f32; rows * cols];
        let roi = Rect {
            row0: 0,
            row1: rows,
            col0: 0,
            col1: cols,
        };
        assert!(matches!(
            slanted_edge_mtf(&flat, rows, cols, roi),
            Err(MetricsError::Edge(_))
        ));
        // a perfectly vertical edge cannot be oversampled
        let img = render_edge(rows, cols, 0.0, 1.0, 20.0, 20.0);
        let e = slanted_edge_mtf(&img, rows, cols, roi).unwrap_err();
        assert!(e.to_string().contains("slanted"), "{e}");
        let big = Rect {
            row0: 0,
            row1: rows + 1,
            col0: 0,
            col1: cols,
        };
        assert!(matches!(
            slanted_edge_mtf(&img, rows, cols, big),
            Err(MetricsError::RoiOutOfBounds { .. })
        ));
    }
}
