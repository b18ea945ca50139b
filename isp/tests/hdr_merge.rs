//! The HDR merge of a split pixel (LPD/SPD × HCG/LCG, [`HdrModel::split_pixel_test`]) on
//! simulated flat fields against the closed form of the merged variance
//! ([`camsim_isp::merged_variance`] with the merge's weights at the true exposure): z-tests
//! of the mean and variance on both sides of every crossover, and of the SNR drop at the
//! LPD → SPD crossover against its closed form. Fixed seeds; |z| < 4.5 per test.
use camsim_isp::{hdr_merge, merge_weights, merged_variance};
use camsim_sensor::*;

const T_S: f64 = 0.01;
const Z_MAX: f64 = 4.5;

struct Measured {
    mean: f64,
    var: f64,
    /// Standard error of the sample variance (fourth moment).
    var_se: f64,
    n: f64,
}

fn merged_at(h_e: f64, seed: u64) -> (Measured, Vec<HdrReadoutModel>) {
    let s = SensorModel::mono_test(128, 128);
    let hdr = HdrModel::split_pixel_test();
    let rate = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![(h_e / T_S) as f32; s.rows * s.cols],
    };
    let shot = Shot::new(&s, T_S);
    let models = hdr.readout_models(&s, &shot);
    let frame = expose_hdr(&s, &hdr, &rate, &shot, seed, &[0, 0]);
    let merged = hdr_merge(&frame, &models).unwrap();
    let x: Vec<f64> = merged.data.iter().map(|&v| v as f64).collect();
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let m4 = x.iter().map(|a| (a - mean).powi(4)).sum::<f64>() / n;
    (
        Measured {
            mean,
            var,
            var_se: ((m4 - var * var) / n).sqrt(),
            n,
        },
        models,
    )
}

/// Closed-form variance of the merged estimate at `h_e`: readouts usable at their expected
/// signal, inverse-variance weights at `h_e`.
fn model_variance(models: &[HdrReadoutModel], h_e: f64) -> f64 {
    let usable: Vec<bool> = models.iter().map(|m| m.usable_at(m.mean_e(h_e))).collect();
    merged_variance(models, &merge_weights(models, &usable, h_e), h_e)
}

fn crossovers() -> Vec<f64> {
    let s = SensorModel::mono_test(1, 1);
    HdrModel::split_pixel_test()
        .readout_models(&s, &Shot::new(&s, T_S))
        .iter()
        .map(HdrReadoutModel::last_usable_h_e)
        .collect()
}

#[test]
fn merged_split_pixel_follows_the_closed_form_on_both_sides_of_each_crossover() {
    let hc = crossovers();
    // LPD-HCG, LPD-LCG, SPD-HCG stop being used at ≈ 5.2e3, 4.2e4, 5.2e5 e⁻ (LPD-LCG's
    // threshold is 20 σ of shot noise from 0.96·H_c).
    let levels = [
        30.0,
        1000.0,
        0.9 * hc[0],
        1.1 * hc[0],
        0.96 * hc[1],
        1.04 * hc[1],
        0.9 * hc[2],
        1.1 * hc[2],
        0.7 * hc[3],
    ];
    for (k, &h) in levels.iter().enumerate() {
        let (m, models) = merged_at(h, 100 + k as u64);
        let v = model_variance(&models, h);
        let z_mean = (m.mean - h) / (m.var / m.n).sqrt();
        let z_var = (m.var - v) / m.var_se;
        assert!(
            z_mean.abs() < Z_MAX && z_var.abs() < Z_MAX,
            "H = {h}: mean {} (z {z_mean:.2}), variance {} vs {v} (z {z_var:.2})",
            m.mean,
            m.var
        );
    }
}

#[test]
fn snr_drop_at_the_lpd_to_spd_crossover_matches_its_closed_form() {
    // Just below H_c the LPD's low-gain readout carries the signal; just above only the SPD
    // readouts do. Measured drop 20 log₁₀(SNR₋/SNR₊) against the closed form at the same two
    // exposures; its standard error by the delta method: Var(ln SNR) ≈ Var(s²)/(4 s⁴) + 1/SNR²/n.
    let hc = crossovers()[1];
    let (lo, hi) = (0.96 * hc, 1.04 * hc);
    let (a, models) = merged_at(lo, 7);
    let (b, _) = merged_at(hi, 8);
    let snr = |m: &Measured| m.mean / m.var.sqrt();
    let measured_db = 20.0 * (snr(&a) / snr(&b)).log10();
    let model_db = 20.0
        * ((lo / model_variance(&models, lo).sqrt()) / (hi / model_variance(&models, hi).sqrt()))
            .log10();
    let var_ln = |m: &Measured| (m.var_se / m.var).powi(2) / 4.0 + m.var / (m.mean * m.mean * m.n);
    let se_db = 20.0 / std::f64::consts::LN_10 * (var_ln(&a) + var_ln(&b)).sqrt();
    let z = (measured_db - model_db) / se_db;
    assert!(
        model_db > 15.0,
        "a split pixel has a deep hole here: {model_db} dB"
    );
    assert!(
        z.abs() < Z_MAX,
        "SNR drop measured {measured_db:.3} dB vs closed form {model_db:.3} dB (se {se_db:.3}, z {z:.2})"
    );
}

#[test]
fn merge_rejects_mismatched_readouts() {
    let s = SensorModel::mono_test(4, 4);
    let hdr = HdrModel::split_pixel_test();
    let shot = Shot::new(&s, T_S);
    let rate = ElectronRate {
        rows: 4,
        cols: 4,
        electrons_per_s: vec![1e5; 16],
    };
    let mut frame = expose_hdr(&s, &hdr, &rate, &shot, 1, &[0]);
    let models = hdr.readout_models(&s, &shot);
    frame.readouts.pop();
    let e = hdr_merge(&frame, &models).unwrap_err().to_string();
    assert!(e.contains("3 readout frames for 4"), "{e}");
}
