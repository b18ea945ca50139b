//! HDR readouts (split pixel: LPD/SPD × HCG/LCG) simulated by [`expose_hdr`] against the
//! shot-plus-read model of each readout ([`HdrReadoutModel::estimate_variance`]): z-tests of
//! the mean and of the variance (its standard error from the sample fourth moment) of each
//! readout's estimate of the exposure on flat fields, at both conversion gains of both
//! photodiodes, and of the shared shot noise (covariance of two readouts of one photodiode).
//! Fixed seeds; every z-test at |z| < 4.5 (two-sided 7e-6 per test).
use camsim_sensor::*;

const T_S: f64 = 0.01;
const Z_MAX: f64 = 4.5;

fn setup(h_e: f64) -> (SensorModel, HdrModel, ElectronRate, Shot) {
    let s = SensorModel::mono_test(128, 128);
    let rate = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![(h_e / T_S) as f32; s.rows * s.cols],
    };
    let shot = Shot::new(&s, T_S);
    (s, HdrModel::split_pixel_test(), rate, shot)
}

/// Sample mean, variance (n − 1) and fourth central moment.
fn moments(x: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|a| (a - m).powi(2)).sum::<f64>() / (n - 1.0);
    let m4 = x.iter().map(|a| (a - m).powi(4)).sum::<f64>() / n;
    (m, v, m4)
}

fn estimates(frame: &HdrFrame, model: &HdrReadoutModel, i: usize) -> Vec<f64> {
    frame.readouts[i]
        .dn
        .iter()
        .map(|&d| model.estimate_h_e(d as f64))
        .collect()
}

#[test]
fn split_pixel_readouts_follow_the_shot_plus_read_model_at_both_gains() {
    // Exposures (photo-electrons of the camera's pixel) per readout: low and high within its
    // usable range, at least 7 σ from its saturation threshold; LCG levels where the noise is
    // several DN (the 1/12 DN² quantisation model holds).
    let levels: [(usize, &[f64]); 4] = [
        (0, &[5.0, 100.0, 3000.0]),
        (1, &[2000.0, 30000.0]),
        (2, &[20000.0, 300000.0]),
        (3, &[300000.0, 1.5e6]),
    ];
    let mut seed = 11;
    for (i, hs) in levels {
        for &h in hs {
            let (s, hdr, rate, shot) = setup(h);
            let models = hdr.readout_models(&s, &shot);
            let m = &models[i];
            assert!(m.usable_at(m.mean_e(h)), "{} at {h}", m.name);
            let frame = expose_hdr(&s, &hdr, &rate, &shot, seed, &[0, 0]);
            seed += 1;
            let x = estimates(&frame, m, i);
            let n = x.len() as f64;
            let (mean, var, m4) = moments(&x);
            let model_var = m.estimate_variance(h);
            let z_mean = (mean - h) / (var / n).sqrt();
            let z_var = (var - model_var) / ((m4 - var * var) / n).sqrt();
            assert!(
                z_mean.abs() < Z_MAX && z_var.abs() < Z_MAX,
                "{} at H = {h}: mean {mean} (z {z_mean:.2}), variance {var} vs model {model_var} (z {z_var:.2})",
                m.name
            );
            // The readout's SNR (H/√var) is the model's: the two z-tests above are its test.
            assert!((m.snr(h) - h / model_var.sqrt()).abs() < 1e-12 * m.snr(h));
        }
    }
}

#[test]
fn readouts_of_one_photodiode_share_its_shot_noise() {
    // Cov(x_HCG, x_LCG) = (s H + d)/s² (the photodiode's Poisson charge read twice; read
    // noises independent); the standard error of the sample covariance of (x, y) is
    // √((Var x Var y + Cov²)/n) for jointly normal data.
    let h = 3000.0;
    let (s, hdr, rate, shot) = setup(h);
    let models = hdr.readout_models(&s, &shot);
    let frame = expose_hdr(&s, &hdr, &rate, &shot, 5, &[0, 0]);
    let x = estimates(&frame, &models[0], 0);
    let y = estimates(&frame, &models[1], 1);
    let n = x.len() as f64;
    let (mx, vx, _) = moments(&x);
    let (my, vy, _) = moments(&y);
    let cov = x
        .iter()
        .zip(&y)
        .map(|(a, b)| (a - mx) * (b - my))
        .sum::<f64>()
        / (n - 1.0);
    let m = &models[0];
    let expected = m.mean_e(h) / m.gain_over_pixel.powi(2);
    let z = (cov - expected) / ((vx * vy + cov * cov) / n).sqrt();
    assert!(z.abs() < Z_MAX, "cov {cov} vs {expected} (z {z:.2})");
    // Readouts of different photodiodes are independent.
    let w = estimates(&frame, &models[2], 2);
    let (mw, vw, _) = moments(&w);
    let cov_xw = x
        .iter()
        .zip(&w)
        .map(|(a, b)| (a - mx) * (b - mw))
        .sum::<f64>()
        / (n - 1.0);
    let z = cov_xw / (vx * vw / n).sqrt();
    assert!(z.abs() < Z_MAX, "LPD/SPD covariance {cov_xw} (z {z:.2})");
}

#[test]
fn saturated_readouts_clip_where_the_model_says() {
    // Beyond its clipping signal a readout stays at its clip level; the model's saturation
    // is the smallest of the well, the swing and the ADC full scale.
    let h = 60000.0; // LPD: 54 000 e⁻ > 40 000 e⁻ well; LCG clips at the ADC (39 374 e⁻).
    let (s, hdr, rate, shot) = setup(h);
    let models = hdr.readout_models(&s, &shot);
    let frame = expose_hdr(&s, &hdr, &rate, &shot, 9, &[0, 0]);
    for i in 0..2 {
        let m = &models[i];
        assert!(!m.usable_at(m.mean_e(h)));
        let top = frame.readouts[i].dn.iter().copied().max().unwrap() as f64;
        assert!(
            (m.electrons_of_dn(top) - m.saturation_e).abs() <= 1.0 / m.dn_per_e,
            "{}",
            m.name
        );
        assert!(
            frame.readouts[i].dn.iter().all(|&d| d as f64 == top),
            "{} not clipped",
            m.name
        );
    }
    assert!((models[1].saturation_e - (4095.0 - 64.0) / (2.5e-5 * 4095.0)).abs() < 1e-6);
    // Same seed, same frames; another stream, other frames.
    let again = expose_hdr(&s, &hdr, &rate, &shot, 9, &[0, 0]);
    assert_eq!(frame, again);
    let other = expose_hdr(&s, &hdr, &rate, &shot, 9, &[0, 1]);
    assert_ne!(frame.readouts[3].dn, other.readouts[3].dn);
}
