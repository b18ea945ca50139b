//! The sensor effect blocks (docs/effects.md) against closed forms and direct computations:
//! crosstalk, QE shift, IR leakage, nonlinearity (and its magnitude), hot pixels.
use camsim_core::{SensorIrradiance, SpectralImage, Spectrum};
use camsim_sensor::*;

fn mono(rows: usize, cols: usize) -> SensorModel {
    let mut s = SensorModel::mono_test(rows, cols);
    s.fill_factor = 0.5;
    s.well_capacity_e = 20000.0;
    s.conversion_gain_v_per_e = 5e-5;
    s.dsnu_sigma_v = 0.0;
    s.prnu_sigma_percent = 0.0;
    s
}

/// A Bayer sensor (g r / b g) with sampled QE curves on 400–700 nm.
fn bayer(rows: usize, cols: usize) -> SensorModel {
    let mut s = mono(rows, cols);
    s.cfa = Cfa {
        tile: vec![vec![1, 2], vec![0, 1]],
    };
    s.channel_names = vec!["b".into(), "g".into(), "r".into()];
    s.channel_qe = vec![
        Spectrum::sampled(vec![400.0, 450.0, 520.0, 700.0], vec![0.3, 0.5, 0.1, 0.0]).unwrap(),
        Spectrum::sampled(vec![400.0, 530.0, 620.0, 700.0], vec![0.05, 0.6, 0.2, 0.02]).unwrap(),
        Spectrum::sampled(vec![400.0, 560.0, 610.0, 700.0], vec![0.0, 0.05, 0.5, 0.3]).unwrap(),
    ];
    s
}

/// A uniform irradiance image (one sample) with spectrum `e` (photons/(s·m²·nm)).
fn uniform(e: Spectrum) -> SensorIrradiance {
    SensorIrradiance {
        irradiance: SpectralImage::from_single_spectrum(1, 1, e, vec![1.0]),
        sample_pitch_m: 1.0,
    }
}

fn flat_rate(s: &SensorModel, r: f32) -> ElectronRate {
    ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![r; s.rows * s.cols],
    }
}

#[test]
fn crosstalk_moves_exactly_the_fraction_and_conserves_charge() {
    let s = mono(9, 11);
    let ct = Crosstalk {
        left: 0.01,
        right: 0.03,
        up: 0.02,
        down: 0.04,
    };
    // Single bright pixel: each neighbour receives exactly its fraction, the pixel keeps the
    // rest, nothing else changes, and the total is conserved away from the border.
    let mut rate = flat_rate(&s, 0.0);
    let (r0, c0) = (4, 5);
    rate.electrons_per_s[r0 * 11 + c0] = 1000.0;
    apply_crosstalk(&ct, &mut rate);
    let at = |r: usize, c: usize| rate.electrons_per_s[r * 11 + c] as f64;
    assert!((at(r0, c0) - 900.0).abs() < 1e-3);
    assert!((at(r0, c0 - 1) - 10.0).abs() < 1e-4, "left");
    assert!((at(r0, c0 + 1) - 30.0).abs() < 1e-4, "right");
    assert!((at(r0 - 1, c0) - 20.0).abs() < 1e-4, "up");
    assert!((at(r0 + 1, c0) - 40.0).abs() < 1e-4, "down");
    let total: f64 = rate.electrons_per_s.iter().map(|&v| v as f64).sum();
    assert!((total - 1000.0).abs() < 1e-3);
    let nonzero = rate.electrons_per_s.iter().filter(|&&v| v != 0.0).count();
    assert_eq!(nonzero, 5);
    // Flat field: interior pixels unchanged (gain = loss); a corner pixel loses the charge it
    // sends off the array (left and up at the top-left corner), and the array's total loss
    // is the charge crossing the border.
    let mut flat = flat_rate(&s, 100.0);
    apply_crosstalk(&ct, &mut flat);
    let f = |r: usize, c: usize| flat.electrons_per_s[r * 11 + c] as f64;
    assert!((f(4, 5) - 100.0).abs() < 1e-4);
    // Top-left (0,0): keeps 90, receives left·e from (0,1) and up·e from (1,0).
    assert!((f(0, 0) - (90.0 + 1.0 + 2.0)).abs() < 1e-4, "{}", f(0, 0));
    let total: f64 = flat.electrons_per_s.iter().map(|&v| v as f64).sum();
    let lost = 100.0 * (9.0 * (0.01 + 0.03) + 11.0 * (0.02 + 0.04));
    assert!((total - (9.0 * 11.0 * 100.0 - lost)).abs() < 1e-2);
    // The symmetric (fitted) form and its magnitude.
    let sym = Crosstalk::symmetric(0.08);
    assert_eq!(sym.left, 0.02);
    assert!((sym.total() - 0.08).abs() < 1e-15);
}

#[test]
fn crosstalk_acts_in_electron_rate_on_photo_charge_only() {
    // Via the SensorModel: electron_rate applies it; the expected image of a dark frame is
    // unchanged (dark charge is not shared).
    let mut s = mono(6, 6);
    let irr = uniform(Spectrum::sampled(vec![400.0, 700.0], vec![1e15, 1e15]).unwrap());
    let base = electron_rate(&s, &irr);
    s.effects.crosstalk = Some(Crosstalk::symmetric(0.1));
    let with = electron_rate(&s, &irr);
    let (b, w) = (
        base.electrons_per_s[2 * 6 + 2],
        with.electrons_per_s[2 * 6 + 2],
    );
    assert!(
        (w / b - 1.0).abs() < 1e-6,
        "interior of a flat field: {w} vs {b}"
    );
    let (b, w) = (base.electrons_per_s[0], with.electrons_per_s[0]);
    assert!(
        (w as f64 / b as f64 - 0.95).abs() < 1e-6,
        "corner loses 2 × f/4"
    );
    let dark = flat_rate(&s, 0.0);
    let shot = Shot::new(&s, 1.0);
    let mut s0 = s.clone();
    s0.effects = Default::default();
    assert_eq!(
        expected_dn(&s, &dark, &shot),
        expected_dn(&s0, &dark, &shot)
    );
}

#[test]
fn qe_shift_equals_simulating_with_shifted_curves() {
    let s0 = bayer(4, 4);
    let irr = uniform(
        Spectrum::sampled(
            vec![380.0, 450.0, 520.0, 600.0, 720.0],
            vec![1e15, 3e15, 2e15, 2.5e15, 1e15],
        )
        .unwrap(),
    );
    let shifts = [-4.0, 2.5, 6.0]; // b, g, r
    let mut s = s0.clone();
    s.effects.qe_shift = Some(QeShift {
        shift_nm: shifts.to_vec(),
    });
    // Independent construction: the curves themselves moved by s_c.
    let mut moved = s0.clone();
    for (q, sh) in moved.channel_qe.iter_mut().zip(shifts) {
        if let Spectrum::Sampled {
            wavelength_nm,
            values,
        } = q.clone()
        {
            *q = Spectrum::sampled(wavelength_nm.iter().map(|w| w + sh).collect(), values).unwrap();
        }
    }
    let a = electron_rate(&s, &irr);
    let b = electron_rate(&moved, &irr);
    let c = electron_rate(&s0, &irr);
    for i in 0..16 {
        let (x, y) = (a.electrons_per_s[i] as f64, b.electrons_per_s[i] as f64);
        assert!((x / y - 1.0).abs() < 1e-6, "pixel {i}: {x} vs {y}");
    }
    // And it changes the signal (the test is not vacuous).
    assert!((a.electrons_per_s[1] / c.electrons_per_s[1] - 1.0).abs() > 1e-3);
    // Effective QE at a wavelength: QE_c(λ − s_c).
    assert!((s.effective_qe_at(2, 616.0) - s0.channel_qe[2].eval(610.0)).abs() < 1e-12);
    // Magnitude: the shift of largest |s|, signed.
    assert_eq!(s.effects.qe_shift.as_ref().unwrap().magnitude(), 6.0);
    let neg = QeShift {
        shift_nm: vec![1.0, -7.0, 3.0],
    };
    assert_eq!(neg.magnitude(), -7.0);
}

#[test]
fn ir_leakage_adds_the_expected_electrons_for_a_known_nir_radiance() {
    let mut s = bayer(2, 2);
    // Irradiance: 2e15 photons/(s·m²·nm) from 400 to 1100 nm.
    let e0 = 2e15;
    let irr = uniform(Spectrum::sampled(vec![400.0, 1100.0], vec![e0, e0]).unwrap());
    let base = electron_rate(&s, &irr);
    let v_r = 0.03;
    let mut channels = vec![None; 3];
    channels[2] = Some(IrLeakage::band(v_r)); // r: fitted form
                                              // b: a generator spectrum, 0.02 at 800 nm falling linearly to 0 at 1000 nm.
    channels[0] =
        Some(Spectrum::sampled(vec![700.0, 800.0, 1000.0], vec![0.0, 0.02, 0.0]).unwrap());
    s.effects.ir_leakage = Some(IrLeakage { channels });
    let with = electron_rate(&s, &irr);
    let area = s.pixel_pitch_m * s.pixel_pitch_m * s.fill_factor;
    // r pixel (row 0, col 1): + area · E · v · (300 nm + two 1 nm ramps of mean v/2).
    let want_r = area * e0 * v_r * 301.0;
    let got_r = (with.electrons_per_s[1] - base.electrons_per_s[1]) as f64;
    assert!((got_r / want_r - 1.0).abs() < 1e-5, "{got_r} vs {want_r}");
    // b pixel (row 1, col 0): + area · E · (triangle areas 1 + 2 nm·QE).
    let want_b = area * e0 * (0.5 * 100.0 * 0.02 + 0.5 * 200.0 * 0.02);
    let got_b = (with.electrons_per_s[2] - base.electrons_per_s[2]) as f64;
    assert!((got_b / want_b - 1.0).abs() < 1e-5, "{got_b} vs {want_b}");
    // g untouched.
    assert_eq!(with.electrons_per_s[0], base.electrons_per_s[0]);
    // A radiance given only to 700 nm gets nothing from the band (zero beyond its range).
    let vis = uniform(Spectrum::sampled(vec![400.0, 699.0], vec![e0, e0]).unwrap());
    let s0 = bayer(2, 2);
    assert_eq!(
        electron_rate(&s, &vis).electrons_per_s[1],
        electron_rate(&s0, &vis).electrons_per_s[1]
    );
    // Magnitude: largest channel mean over 700–1000 nm (r: 0.03; b: 0.03·... = 3/300 · 1).
    let ir = s.effects.ir_leakage.as_ref().unwrap();
    assert!((ir.band_mean(2) - 0.03).abs() < 1e-12);
    assert!((ir.band_mean(0) - 0.5 * 300.0 * 0.02 / 300.0).abs() < 1e-12);
    assert!((ir.magnitude() - 0.03).abs() < 1e-12);
    // The simulation must cover 1000 nm: the effective support says so.
    assert_eq!(s.effective_qe_support_nm(), (400.0, 1001.0));
}

#[test]
fn nonlinearity_expected_path_and_magnitude_closed_forms() {
    let mut s = mono(2, 2);
    s.dark_voltage_v_per_s = 0.0;
    s.well_capacity_e = 1e6; // no well clip below the swing
    let k = s.dn_per_output_v(); // DN per volt at gain 1
    let fs = s.max_dn() - s.black_level_dn;
    let v80 = 0.8 * fs / k;
    // Without the block: 0 (no clipping below 80 % of full scale).
    assert!(nonlinearity_magnitude(&s, 1.0).abs() < 1e-9);
    // Quadratic: signal K(v − a v²) against the line K v → magnitude a·v80.
    let a = 0.1;
    s.effects.nonlinearity = Some(Nonlinearity::Quadratic {
        coefficient_per_v: a,
    });
    let m = nonlinearity_magnitude(&s, 1.0);
    assert!((m - a * v80).abs() < 1e-6, "{m} vs {}", a * v80);
    // Expected image: v' = v − a v².
    let rate = flat_rate(&s, 8000.0);
    let e = expected_dn(&s, &rate, &Shot::new(&s, 1.0));
    let v = 8000.0 * 5e-5;
    assert!((e[0] as f64 - (64.0 + k * (v - a * v * v))).abs() < 1e-2);
    // Beyond the vertex the response is flat at 1/(4a).
    assert_eq!(
        Nonlinearity::Quadratic {
            coefficient_per_v: 2.0
        }
        .apply(0.4),
        0.125
    );
    // Tanh: 1 − S tanh(v80/S)/v80.
    let sat = 1.2;
    s.effects.nonlinearity = Some(Nonlinearity::Tanh { saturation_v: sat });
    let m = nonlinearity_magnitude(&s, 1.0);
    let want = 1.0 - sat * (v80 / sat).tanh() / v80;
    assert!((m - want).abs() < 1e-6, "{m} vs {want}");
    // Analog gain 2 halves the voltage at 80 % of full scale.
    let m2 = nonlinearity_magnitude(&s, 2.0);
    let v80g = v80 / 2.0;
    assert!((m2 - (1.0 - sat * (v80g / sat).tanh() / v80g)).abs() < 1e-6);
}

#[test]
fn nonlinearity_magnitude_matches_a_direct_noisy_simulation() {
    // Direct: frames at a low and at the 80 % exposure; the line through the low-signal mean,
    // extrapolated, against the measured mean. Means of 128×128 pixels.
    let mut s = mono(128, 128);
    s.dark_voltage_v_per_s = 0.0;
    s.well_capacity_e = 1e6;
    s.effects.nonlinearity = Some(Nonlinearity::Tanh { saturation_v: 1.5 });
    let fixed = fixed_pattern(&s, 3);
    let rate = flat_rate(&s, 1e5);
    let mean_signal = |t: f64, id: u64| -> f64 {
        let f = expose(&s, &rate, &Shot::new(&s, t), &fixed, 3, &[id, 0]);
        f.dn.iter().map(|&d| d as f64).sum::<f64>() / f.dn.len() as f64 - s.black_level_dn
    };
    let t_low = 0.004; // 400 e → 0.02 V: compression (v/S)²/3 = 6e-5 (negligible)
    let slope = mean_signal(t_low, 0) / t_low; // DN per second of exposure
    let fs = s.max_dn() - s.black_level_dn;
    let t80 = 0.8 * fs / slope;
    let direct = 1.0 - mean_signal(t80, 1) / (0.8 * fs);
    let formula = nonlinearity_magnitude(&s, 1.0);
    // Noise: σ(mean at low signal) ≈ 4.4 DN/√16384 = 0.035 DN on 82 DN ⇒ 4e-4 relative
    // slope error ⇒ ≈ 4e-4 on the magnitude; tolerance 2e-3 (5σ) on a magnitude ≈ 0.07.
    assert!(formula > 0.05);
    assert!((direct - formula).abs() < 2e-3, "{direct} vs {formula}");
}

#[test]
fn hot_pixel_fraction_and_rate_recovered_from_a_dark_frame() {
    let mut s = mono(128, 128);
    s.dark_voltage_v_per_s = 1e-3;
    s.read_noise_v = 5e-4;
    let (f, v_hot) = (0.004, 0.05);
    s.effects.hot_pixels = Some(HotPixels {
        fraction: f,
        dark_voltage_v_per_s: v_hot,
        log_sigma: 0.0,
    });
    let n = 128 * 128;
    assert_eq!(hot_pixel_count(&s), (f * n as f64).round() as usize);
    let fixed = fixed_pattern(&s, 11);
    assert_eq!(fixed.hot_pixels, hot_pixel_map(&s, 11));
    assert_eq!(fixed.hot_pixels.len(), 66);
    // Dark frame, t = 2 s: hot pixels carry 0.1 V ≈ 409 DN extra; the others 2 mV ± noise.
    let t = 2.0;
    let dark = flat_rate(&s, 0.0);
    let frame = expose(&s, &dark, &Shot::new(&s, t), &fixed, 11, &[0, 0]);
    let k = s.dn_per_output_v();
    let base = s.black_level_dn + k * t * s.dark_voltage_v_per_s;
    let threshold = base + 0.5 * k * t * v_hot;
    let hot: Vec<usize> = (0..n).filter(|&i| frame.dn[i] as f64 > threshold).collect();
    // Fraction: exactly the drawn positions.
    let want: Vec<usize> = fixed
        .hot_pixels
        .iter()
        .map(|h| h.row as usize * 128 + h.col as usize)
        .collect();
    assert_eq!(hot, want);
    // Rate: mean excess (DN) / (t · K) against V; σ per pixel: shot noise of
    // t(V+V0)/g = 2100 e ⇒ 46 e ⇒ 0.19 DN... plus read noise; z-test at 4σ.
    let excess: Vec<f64> = hot.iter().map(|&i| frame.dn[i] as f64 - base).collect();
    let m = excess.iter().sum::<f64>() / excess.len() as f64;
    let var = excess.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (excess.len() - 1) as f64;
    let v_est = m / (k * t);
    let se = (var / excess.len() as f64).sqrt() / (k * t);
    assert!(
        (v_est - v_hot).abs() < 4.0 * se + 1e-6,
        "{v_est} vs {v_hot} (se {se})"
    );
    // The expected image does not contain them (fixed pattern, like DSNU/PRNU).
    let mut s0 = s.clone();
    s0.effects = Default::default();
    assert_eq!(
        expected_dn(&s, &dark, &Shot::new(&s, t)),
        expected_dn(&s0, &dark, &Shot::new(&s0, t))
    );
    // Seeded and map sources give the same frame.
    let f2 = expose_with(
        &s,
        &dark,
        &Shot::new(&s, t),
        PatternSource::Seeded(11),
        11,
        &[0, 0],
    );
    assert_eq!(f2.dn, frame.dn);
}

#[test]
fn hot_pixel_lognormal_rates() {
    let mut s = mono(200, 200);
    let (v, sig) = (0.02, 0.5);
    s.effects.hot_pixels = Some(HotPixels {
        fraction: 0.05,
        dark_voltage_v_per_s: v,
        log_sigma: sig,
    });
    let map = hot_pixel_map(&s, 5);
    assert_eq!(map.len(), 2000);
    // Positions are distinct and sorted.
    assert!(map
        .windows(2)
        .all(|w| (w[0].row, w[0].col) < (w[1].row, w[1].col)));
    let logs: Vec<f64> = map
        .iter()
        .map(|h| (h.dark_voltage_v_per_s as f64).ln())
        .collect();
    let n = logs.len() as f64;
    let m = logs.iter().sum::<f64>() / n;
    let sd = (logs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(
        (m - v.ln()).abs() < 4.0 * sig / n.sqrt(),
        "{m} vs {}",
        v.ln()
    );
    assert!((sd / sig - 1.0).abs() < 4.0 * (0.5 / n).sqrt(), "{sd}");
    // Positions are uniform: rows of the hot pixels have mean ≈ (rows − 1)/2.
    let mr = map.iter().map(|h| h.row as f64).sum::<f64>() / n;
    let se = (200.0f64 * 200.0 / 12.0).sqrt() / n.sqrt();
    assert!((mr - 99.5).abs() < 4.0 * se);
    // Deterministic in the seed, different for another seed.
    assert_eq!(map, hot_pixel_map(&s, 5));
    assert_ne!(map, hot_pixel_map(&s, 6));
}

#[test]
fn blocks_absent_leave_frames_bit_identical() {
    // The effect machinery must not change anything when no block is present.
    let s = mono(16, 16);
    let rate = flat_rate(&s, 3e4);
    let fixed = fixed_pattern(&s, 2);
    assert!(fixed.hot_pixels.is_empty());
    let a = expose(&s, &rate, &Shot::new(&s, 0.01), &fixed, 2, &[0, 0]);
    let mut s1 = s.clone();
    s1.effects.hot_pixels = Some(HotPixels {
        fraction: 0.0,
        dark_voltage_v_per_s: 1.0,
        log_sigma: 0.0,
    });
    let b = expose(
        &s1,
        &rate,
        &Shot::new(&s1, 0.01),
        &fixed_pattern(&s1, 2),
        2,
        &[0, 0],
    );
    assert_eq!(a.dn, b.dn);
}

#[test]
fn validation_names_the_block() {
    let mut s = mono(4, 4);
    s.effects.crosstalk = Some(Crosstalk::symmetric(1.2));
    assert!(s.validate().unwrap_err().to_string().contains("crosstalk"));
    let mut s = mono(4, 4);
    s.effects.nonlinearity = Some(Nonlinearity::Tanh { saturation_v: 0.0 });
    assert!(s
        .validate()
        .unwrap_err()
        .to_string()
        .contains("nonlinearity.saturation_v"));
    let mut s = mono(4, 4);
    s.effects.qe_shift = Some(QeShift {
        shift_nm: vec![1.0, 2.0],
    });
    assert!(s.validate().unwrap_err().to_string().contains("qe_shift"));
}
