//! Closed-form and statistical checks of the EMVA 1288 equations.
use super::spatial::*;
use super::*;
use camsim_core::rng::stream;
use camsim_sensor::normal::standard_normal;

fn z(est: f64, truth: f64, se: f64) -> f64 {
    (est - truth) / se
}

#[test]
fn pair_stats_removes_a_mean_change_between_the_frames() {
    // B = A + 2 everywhere: the difference has no temporal part at all.
    let a = [1u16, 3, 7, 11];
    let b = [3u16, 5, 9, 13];
    let s = pair_stats(&a, &b);
    assert_eq!(s.mean_dn, 6.5);
    assert!(s.var_dn2.abs() < 1e-12);
    // Hand-computed: A = [0, 2], B = [2, 0]: Σ(A−B)² = 8, /(2·2) = 2, means equal → 2.
    let s = pair_stats(&[0, 2], &[2, 0]);
    assert_eq!(s.var_dn2, 2.0);
    assert!(pair_stats(&[1, 2], &[1]).mean_dn.is_nan());
}

#[test]
fn pair_variance_is_unbiased_for_gaussian_noise() {
    // N(100, 9²) per pixel and frame: E[σ²_y] = 81, se ≈ 81·√(2/N).
    let n = 20_000;
    let mut rng = stream(11, &[1]);
    let mut f = || -> Vec<u16> {
        (0..n)
            .map(|_| (1000.0 + 9.0 * standard_normal(&mut rng)) as u16)
            .collect()
    };
    let (a, b) = (f(), f());
    let s = pair_stats(&a, &b);
    // truncation to u16 adds 1/12 DN² of quantisation variance
    let truth = 81.0 + 1.0 / 12.0;
    assert!(z(s.var_dn2, truth, truth * (2.0 / n as f64).sqrt()).abs() < 4.0);
}

/// A noise-free series of an ideal linear camera: μ_y = K η μ_p + 10 DN, σ²_y = K² η μ_p +
/// σ²_dark + K² μ_I t (dark current), clipped at μ_p.sat.
fn ideal_series(
    k: f64,
    eta: f64,
    dark_var: f64,
    sat_photons: f64,
    dark_e_per_s: f64,
) -> Vec<TemporalPoint> {
    (1..=60)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let up = sat_photons * i as f64 / 50.0;
            let dark_mean = 10.0 + k * dark_e_per_s * t;
            let dark_v = dark_var + k * k * dark_e_per_s * t;
            let (mean, var) = if i <= 50 {
                (dark_mean + k * eta * up, dark_v + k * k * eta * up)
            } else {
                // saturated: constant signal, variance collapses
                (dark_mean + k * eta * sat_photons, 0.1 * (60 - i) as f64)
            };
            TemporalPoint {
                exposure_s: t,
                photons_per_pixel: up,
                bright: PairStats {
                    mean_dn: mean,
                    var_dn2: var,
                },
                dark: PairStats {
                    mean_dn: dark_mean,
                    var_dn2: dark_v,
                },
            }
        })
        .collect()
}

#[test]
fn ideal_series_gives_the_closed_form_datasheet() {
    let (k, eta, dvar, sat, idark) = (0.25, 0.6, 4.0, 20_000.0, 50.0);
    let r = analyse_temporal(&ideal_series(k, eta, dvar, sat, idark)).unwrap();
    assert_eq!(r.saturation_index, 49);
    assert!((r.system_gain_dn_per_e.slope - k).abs() < 1e-12);
    assert!((r.quantum_efficiency.value - eta).abs() < 1e-12);
    assert!((r.dark_var_dn2.value - dvar).abs() < 1e-9);
    let sd = (dvar - 1.0 / 12.0_f64).sqrt() / k;
    assert!((r.dark_noise_e.value - sd).abs() < 1e-9);
    let up_min = (dvar.sqrt() / k + 0.5) / eta;
    assert!((r.sensitivity_threshold_photons.value - up_min).abs() < 1e-9);
    assert_eq!(r.saturation_photons.value, sat);
    assert!((r.saturation_e.value - eta * sat).abs() < 1e-6);
    assert!((r.snr_max.value - (eta * sat).sqrt()).abs() < 1e-9);
    assert!((r.dynamic_range.value - sat / up_min).abs() < 1e-6);
    let lin = r.linearity.unwrap();
    assert!(
        lin.le_percent.abs() < 1e-9,
        "an exact line has no linearity error"
    );
    assert!((r.dark_current_mean_e_per_s.unwrap().value - idark).abs() < 1e-6);
    assert!((r.dark_current_var_e_per_s.unwrap().value - idark).abs() < 1e-6);
    // the 0.24 DN² floor of the dark variance
    let r = analyse_temporal(&ideal_series(k, eta, 0.1, sat, 0.0)).unwrap();
    assert_eq!(r.dark_var_dn2.value, MIN_DARK_VAR_DN2);
}

#[test]
fn linearity_error_of_a_quadratic_response() {
    // y = a μ_p (1 − c μ_p/μ_sat): the relative deviation from the best line is of order c.
    let mut pts = ideal_series(0.25, 0.6, 4.0, 20_000.0, 0.0);
    for p in pts.iter_mut().take(50) {
        let s = p.bright.mean_dn - p.dark.mean_dn;
        p.bright.mean_dn = p.dark.mean_dn + s * (1.0 - 0.02 * p.photons_per_pixel / 20_000.0);
    }
    let lin = linearity(&pts, 49).unwrap();
    assert!(
        lin.le_percent > 0.1 && lin.le_percent < 2.0,
        "LE = {}",
        lin.le_percent
    );
    assert!(lin.le_min_percent < 0.0 && lin.le_max_percent > 0.0);
}

#[test]
fn too_short_series_is_an_error() {
    let pts = ideal_series(0.25, 0.6, 4.0, 20_000.0, 0.0);
    assert!(analyse_temporal(&pts[..2]).is_err());
}

#[test]
fn spectrogram_of_a_cosine_peaks_at_its_frequency_and_obeys_parseval() {
    let (rows, cols) = (4, 64);
    let img: Vec<f64> = (0..rows * cols)
        .map(|i| {
            5.0 + 3.0 * (2.0 * std::f64::consts::PI * 8.0 * (i % cols) as f64 / cols as f64).cos()
        })
        .collect();
    let s = spectrogram(&img, rows, cols, false);
    assert_eq!(s.power_dn2.len(), cols / 2 + 1);
    // |DFT|² / N of A cos at bin 8 = N A² / 4
    assert!((s.power_dn2[8] - cols as f64 * 9.0 / 4.0).abs() < 1e-9);
    assert!((s.frequency_per_px[8] - 0.125).abs() < 1e-12);
    // Parseval: full-spectrum mean = variance; the half spectrum holds half of it (bins 1…N/2−1)
    let var = 4.5;
    let half_sum: f64 = s.power_dn2[1..cols / 2].iter().sum();
    assert!((2.0 * half_sum / cols as f64 - var).abs() < 1e-9);
    let v = spectrogram(&img, rows, cols, true);
    // each column is constant: only the DC bin (the column's offset from the global mean)
    assert!(
        v.power_dn2[1..].iter().all(|p| p.abs() < 1e-9),
        "columns are constant"
    );
    assert!((v.power_dn2[0] - rows as f64 * 4.5).abs() < 1e-9);
}

#[test]
fn nonuniformity_parts_and_dsnu_prnu_recover_the_patterns() {
    // Dark: per-pixel offsets σ_p = 3 DN plus a row pattern σ_r = 2 DN, temporal σ = 1.5 DN.
    // Bright: dark + 1000 DN × (1 + 1 % gain pattern), temporal σ = 10 DN.
    let (m, n, l) = (64usize, 96usize, 8u32);
    let mut rng = stream(5, &[0]);
    let pix: Vec<f64> = (0..m * n)
        .map(|_| 3.0 * standard_normal(&mut rng))
        .collect();
    let row: Vec<f64> = (0..m).map(|_| 2.0 * standard_normal(&mut rng)).collect();
    let gain: Vec<f64> = (0..m * n)
        .map(|_| 0.01 * standard_normal(&mut rng))
        .collect();
    let mut dark = StackAccumulator::new(m, n);
    let mut bright = StackAccumulator::new(m, n);
    for f in 0..l {
        let mut rng = stream(5, &[1, f as u64]);
        let d: Vec<u16> = (0..m * n)
            .map(|i| (200.0 + pix[i] + row[i / n] + 1.5 * standard_normal(&mut rng)).round() as u16)
            .collect();
        let b: Vec<u16> = (0..m * n)
            .map(|i| {
                (200.0
                    + pix[i]
                    + row[i / n]
                    + 1000.0 * (1.0 + gain[i])
                    + 10.0 * standard_normal(&mut rng))
                .round() as u16
            })
            .collect();
        dark.add(&d).unwrap();
        bright.add(&b).unwrap();
    }
    assert!(dark.add(&[0u16; 3]).is_err());
    let k = LineFit {
        slope: 0.5,
        slope_se: 0.0,
        offset: 0.0,
        offset_se: 0.0,
    };
    let r = analyse_spatial(&bright, &dark, &k).unwrap();
    // sample variances of the drawn patterns are the truth the estimator must find
    let svar = |v: &[f64]| {
        let mu = v.iter().sum::<f64>() / v.len() as f64;
        v.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (v.len() - 1) as f64
    };
    let (vp, vr) = (svar(&pix), svar(&row));
    // temporal σ_stack: 1.5² + 1/12 quantisation
    assert!(
        (r.dark.var_stack_dn2 - (2.25 + 1.0 / 12.0)).abs() < 0.1,
        "σ²_stack {}",
        r.dark.var_stack_dn2
    );
    let se = spatial_variance_uncertainty(&r.dark);
    assert!(
        z(
            r.dark.s2_dn2,
            vp + vr * (m as f64 - 1.0) / m as f64 * 1.0,
            se
        )
        .abs()
            < 4.0
    );
    assert!(
        (r.dark_parts.row_dn2 - vr).abs() < 0.1 * vr + 0.3,
        "row {}",
        r.dark_parts.row_dn2
    );
    assert!(
        r.dark_parts.col_dn2.abs() < 0.3,
        "col {}",
        r.dark_parts.col_dn2
    );
    assert!(
        (r.dark_parts.pixel_dn2 - vp).abs() < 0.05 * vp,
        "pixel {}",
        r.dark_parts.pixel_dn2
    );
    assert!((r.dsnu_e.value - r.dark.s2_dn2.sqrt() / 0.5).abs() < 1e-12);
    // PRNU: 1 % of 1000 DN
    let vg = svar(&gain).sqrt() * 100.0;
    assert!(
        (r.prnu_percent.value - vg).abs() < 3.0 * r.prnu_percent.uncertainty + 0.02,
        "PRNU {} vs {vg}",
        r.prnu_percent.value
    );
    assert!((r.prnu_pixel_percent - vg).abs() < 0.05 * vg);
    assert_eq!(
        r.dsnu_histogram_e.counts.iter().sum::<u64>(),
        (m * n) as u64
    );
    assert_eq!(
        r.prnu_histogram_percent.counts.iter().sum::<u64>(),
        ((m - 4) * (n - 4)) as u64
    );
}

#[test]
fn adding_frames_together_gives_the_sums_of_adding_them_one_by_one() {
    // 3 × 2000 pixels: more than one 4096-pixel tile and a partial one; full-range values
    // (65535² is the largest square) so an overflow would show.
    let (m, n) = (3usize, 2000usize);
    let frames: Vec<Vec<u16>> = (0..5u64)
        .map(|f| {
            (0..(m * n) as u64)
                .map(|i| ((i * 2_654_435_761 + f * 40_503) % 65_536) as u16)
                .collect()
        })
        .collect();
    let mut one = StackAccumulator::new(m, n);
    for f in &frames {
        one.add(f).unwrap();
    }
    let mut together = StackAccumulator::new(m, n);
    let refs: Vec<&[u16]> = frames.iter().map(|f| f.as_slice()).collect();
    together.add_frames(&refs[..2]).unwrap();
    together.add_frames(&refs[2..]).unwrap();
    assert_eq!(together.frames, 5);
    assert_eq!(together.average(), one.average());
    assert_eq!(stack_stats(&together), stack_stats(&one));
    // The exact sums of one pixel from the frames themselves.
    let p = 4100;
    let sum: u64 = frames.iter().map(|f| f[p] as u64).sum();
    assert_eq!(together.average()[p], sum as f64 / 5.0);
    // The temporal variance from the squares, against a direct two-pass computation.
    let var_stack = (0..m * n)
        .map(|i| {
            let mu = frames.iter().map(|f| f[i] as f64).sum::<f64>() / 5.0;
            frames
                .iter()
                .map(|f| (f[i] as f64 - mu).powi(2))
                .sum::<f64>()
                / 4.0
        })
        .sum::<f64>()
        / (m * n) as f64;
    let got = stack_stats(&together).var_stack_dn2;
    assert!(
        (got - var_stack).abs() <= 1e-12 * var_stack,
        "{got} vs {var_stack}"
    );
    // A frame of the wrong size adds nothing.
    let short = vec![0u16; m * n - 1];
    assert!(together.add_frames(&[refs[0], &short]).is_err());
    assert_eq!(together.frames, 5);
    assert_eq!(stack_stats(&together), stack_stats(&one));
}
