//! Oracle for S-CIELAB's spatial filters: the closed-form frequency response of the published
//! filters (Zhang & Wandell 1996) checked through the public `scielab` API.
//!
//! Each channel filter is `Σ w_i k_i exp(−r²/σ_i²)` with every Gaussian normalised to unit sum
//! and the weights normalised to sum 1 (metrics/src/scielab.rs). Along one image axis the
//! Gaussian's factor `exp(−x²/σ²)/(σ√π)` has the Fourier transform `exp(−π²σ²f²)` (σ in
//! degrees, f in cycles per degree), so a grating along x is passed with gain
//!
//! `H_c(f) = Σ_i w_i exp(−π² σ_i² f²) / Σ_i w_i`,
//!
//! and `H_c(0) = 1` (uniform areas unchanged). A grating `δ·cos(2πf(i + ½)/spd)` added along
//! opponent channel c (`spd` samples per degree, image width a whole number of periods, phase
//! at the half-sample point) is its own symmetric (mirror) extension, so the filtered
//! difference is exactly `H_c(f)·δ·cos(…)` up to the sampled/truncated kernel (relative error
//! ≈ erfc(3) ≈ 2·10⁻⁵ at ±3σ support, aliasing `exp(−π²σ_px²)` ≈ 10⁻³⁴ for σ ≥ 2.8 px).
//! For a small δ, ΔE*ab is linear in the opponent difference: ΔE_i = ΔE_u·|H_c(f)·cos_i|, where
//! ΔE_u is the plain CIELAB ΔE of a uniform offset δ along channel c. The test compares the
//! measured mean ΔE over the image with `ΔE_u · H_c(f) · mean|cos_i|`; the residual
//! non-linearity of CIELAB at δ/Y ≈ 10⁻⁴ is O(10⁻⁴) relative, so a relative tolerance of 10⁻³
//! holds with a margin and a filter whose spreads are scaled 2× (H changes by ≥ 5 % at every
//! tested frequency) fails it, which the test also checks.
use camsim_core::colorimetry::Xyz;
use camsim_metrics::scielab::{
    cielab_delta_e_map, published_filters_1996, GaussianTerm, XYZ_TO_OPPONENT,
};
use camsim_metrics::{scielab, scielab_with_options, ScielabOptions};

/// Samples per degree of visual angle of the test images.
const SPD: f64 = 100.0;
/// Image size: 200 columns hold a whole number of 8-, 20- and 100-sample periods.
const ROWS: usize = 4;
const COLS: usize = 200;
/// Relative tolerance of the frequency-response check (see the module doc).
const REL_TOL: f64 = 1e-3;

const D65: Xyz = Xyz {
    x: 95.047,
    y: 100.0,
    z: 108.883,
};

/// A mid-grey base colour (Y = 40 % of the white).
const BASE: Xyz = Xyz {
    x: 0.4 * 95.047,
    y: 40.0,
    z: 0.4 * 108.883,
};

/// Closed-form gain of a normalised sum of Gaussians at `f_cpd` cycles per degree:
/// `Σ w_i exp(−π² σ_i² f²) / Σ w_i` (Fourier transform of `exp(−x²/σ²)/(σ√π)`).
fn closed_form_gain(terms: &[GaussianTerm], f_cpd: f64) -> f64 {
    let pi2 = std::f64::consts::PI.powi(2);
    let w: f64 = terms.iter().map(|t| t.weight).sum();
    terms
        .iter()
        .map(|t| t.weight * (-pi2 * t.spread_deg.powi(2) * f_cpd * f_cpd).exp())
        .sum::<f64>()
        / w
}

/// Inverse of a 3×3 matrix (cofactors).
fn inv3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let (a, b) = ((j + 1) % 3, (j + 2) % 3);
            let (c, d) = ((i + 1) % 3, (i + 2) % 3);
            r[i][j] = (m[a][c] * m[b][d] - m[a][d] * m[b][c]) / det;
        }
    }
    r
}

/// `BASE` moved by `delta` along opponent channel `ch`.
fn along_opponent(ch: usize, delta: f64) -> Xyz {
    let inv = inv3(&XYZ_TO_OPPONENT);
    Xyz {
        x: BASE.x + inv[0][ch] * delta,
        y: BASE.y + inv[1][ch] * delta,
        z: BASE.z + inv[2][ch] * delta,
    }
}

/// The grating factor cos(2π f (i + ½)/SPD) of column i.
fn grating(f_cpd: f64, col: usize) -> f64 {
    (2.0 * std::f64::consts::PI * f_cpd * (col as f64 + 0.5) / SPD).cos()
}

/// Measured and predicted mean ΔE*ab of a grating of `f_cpd` along channel `ch` against the
/// uniform base, with the filter terms `filters` (None: the default `scielab`).
fn grating_response(ch: usize, f_cpd: f64, filters: Option<[Vec<GaussianTerm>; 3]>) -> (f64, f64) {
    // δ: 10⁻⁴ of the base luminance along the opponent axis.
    let delta = 4e-3;
    let a: Vec<Xyz> = (0..ROWS * COLS)
        .map(|i| along_opponent(ch, delta * grating(f_cpd, i % COLS)))
        .collect();
    let b = vec![BASE; ROWS * COLS];
    let measured = match &filters {
        None => scielab(&a, &b, ROWS, COLS, D65, SPD).unwrap().mean_delta_e,
        Some(f) => {
            let opts = ScielabOptions {
                filters: f.clone(),
                ..ScielabOptions::new(SPD)
            };
            scielab_with_options(&a, &b, ROWS, COLS, D65, &opts)
                .unwrap()
                .mean_delta_e
        }
    };
    let de_u = cielab_delta_e_map(&[along_opponent(ch, delta)], &[BASE], D65).unwrap()[0];
    let mean_abs_cos = (0..COLS).map(|c| grating(f_cpd, c).abs()).sum::<f64>() / COLS as f64;
    let h = closed_form_gain(&published_filters_1996()[ch], f_cpd);
    (measured, de_u * h.abs() * mean_abs_cos)
}

/// (channel, cycles per degree): periods of 8, 20 and 100 samples; the 1 cpd cases exercise the
/// wide terms (including O1's negative 4.3° surround, with a kernel longer than the image), the
/// higher ones the narrow centres.
const CASES: [(usize, f64); 6] = [(0, 1.0), (0, 12.5), (1, 1.0), (1, 5.0), (2, 1.0), (2, 5.0)];

#[test]
fn uniform_offsets_are_unchanged_by_the_filters() {
    // H_c(0) = 1: S-CIELAB of a uniform difference equals plain CIELAB ΔE, per channel.
    for ch in 0..3 {
        let a = vec![along_opponent(ch, 0.5); ROWS * COLS];
        let b = vec![BASE; ROWS * COLS];
        let s = scielab(&a, &b, ROWS, COLS, D65, SPD).unwrap();
        let plain = cielab_delta_e_map(&a[..1], &b[..1], D65).unwrap()[0];
        assert!(plain > 0.1, "channel {ch}: offset too small ({plain})");
        for v in &s.delta_e_map {
            assert!(
                (v - plain).abs() <= 1e-9 * plain,
                "channel {ch}: S-CIELAB {v} vs CIELAB {plain} on a uniform offset"
            );
        }
    }
}

#[test]
fn grating_gain_matches_the_closed_form_frequency_response() {
    for (ch, f) in CASES {
        let (measured, predicted) = grating_response(ch, f, None);
        let h = closed_form_gain(&published_filters_1996()[ch], f);
        println!(
            "O{} at {f} cpd: H = {h:.5}; mean ΔE {measured:.6e} vs closed form {predicted:.6e}",
            ch + 1
        );
        assert!(
            (measured / predicted - 1.0).abs() <= REL_TOL,
            "O{} at {f} cpd: mean ΔE {measured:e} vs closed form {predicted:e} (H = {h})",
            ch + 1
        );
    }
    // The closed form has the published shape: luminance is band-pass (gain > 1 at 1 cpd,
    // the negative surround), the chromatic channels low-pass and lower than luminance.
    let f96 = published_filters_1996();
    assert!(closed_form_gain(&f96[0], 1.0) > 1.05);
    assert!(closed_form_gain(&f96[1], 5.0) < closed_form_gain(&f96[0], 5.0));
    assert!(closed_form_gain(&f96[2], 5.0) < closed_form_gain(&f96[0], 5.0));
}

/// The oracle can fail: filters with every spread scaled 2× (e.g. a half-width read as a σ,
/// or samples per degree off by 2) miss the closed form of the published filters at every
/// tested frequency by far more than the tolerance.
#[test]
fn filters_scaled_two_times_fail_the_oracle() {
    let scaled = published_filters_1996().map(|terms| {
        terms
            .into_iter()
            .map(|t| GaussianTerm {
                weight: t.weight,
                spread_deg: 2.0 * t.spread_deg,
            })
            .collect::<Vec<_>>()
    });
    for (ch, f) in CASES {
        let (measured, predicted) = grating_response(ch, f, Some(scaled.clone()));
        let rel = (measured / predicted - 1.0).abs();
        assert!(
            rel > 20.0 * REL_TOL,
            "O{} at {f} cpd: a 2× scaled filter is within {rel:.2e} of the closed form",
            ch + 1
        );
    }
}

/// The filter table itself against a second, independent transcription: the S-CIELAB code
/// distributed by Zhang & Wandell (`separableFilters`, the constants `x1`, `x2`, `x3`) lists
/// the same three channels with each channel's weights normalised to sum 1 and with the
/// spreads as half-widths. Its weights are these literals; the library's published-table
/// weights, normalised, must reproduce them to the 4–5 digits both are printed with (1e-3
/// relative), and each of its spreads must be the library's times the stated factor of about
/// 1.7 (all lie within 1.60–1.78; a spread typed 2× too large or too small lands outside).
/// So a typo in `published_filters_1996`, which the closed-form oracle above would share,
/// fails here.
#[test]
fn published_table_matches_the_distributed_code_constants() {
    // (weight, half-width in degrees) per channel, from the distributed code.
    let code: [&[(f64, f64)]; 3] = [
        &[(1.00327, 0.05), (0.114416, 0.225), (-0.117686, 7.0)],
        &[(0.616725, 0.0685), (0.383275, 0.826)],
        &[(0.567885, 0.0920), (0.432115, 0.6451)],
    ];
    for (ch, (lib, code)) in published_filters_1996().iter().zip(code).enumerate() {
        assert_eq!(lib.len(), code.len(), "channel {ch}: number of terms");
        let sum: f64 = lib.iter().map(|t| t.weight).sum();
        for (i, (t, &(w, hw))) in lib.iter().zip(code).enumerate() {
            let wn = t.weight / sum;
            assert!(
                ((wn - w) / w).abs() < 1e-3,
                "channel {ch} term {i}: normalised weight {wn} vs the code's {w}"
            );
            let ratio = hw / t.spread_deg;
            assert!(
                (1.60..=1.78).contains(&ratio),
                "channel {ch} term {i}: code half-width / spread = {ratio}"
            );
        }
    }
}
