//! Dynamic range and SNR holes of HDR pixels ([`camsim_metrics::hdr_snr`]) against closed
//! forms, and the noise floor of a split pixel against simulated frames (z-test, fixed seed).
use camsim_metrics::hdr_snr::*;
use camsim_sensor::*;

const T_S: f64 = 0.01;

fn models(hdr: &HdrModel) -> Vec<HdrReadoutModel> {
    let s = SensorModel::mono_test(1, 1);
    hdr.readout_models(&s, &Shot::new(&s, T_S))
}

#[test]
fn standard_pixel_dynamic_range_is_the_closed_form() {
    // One readout: SNR(H) = H/√(H + d + σ²) = 1 at H₀ = (1 + √(1 + 4(d + σ²)))/2; the largest
    // usable signal is (0.95 · saturation − d)/1.
    let s = SensorModel::mono_test(1, 1);
    let m = models(&HdrModel::standard(&s));
    let c = m[0].dark_e + m[0].read_variance_e2;
    let floor = (1.0 + (1.0 + 4.0 * c).sqrt()) / 2.0;
    let h_max = 0.95 * m[0].saturation_e - m[0].dark_e;
    let dr = dynamic_range(&m);
    assert!(
        (dr.noise_floor_e - floor).abs() < 1e-9 * floor,
        "{} vs {floor}",
        dr.noise_floor_e
    );
    assert!((dr.max_signal_e - h_max).abs() < 1e-9 * h_max);
    assert!((dr.dynamic_range_db - 20.0 * (h_max / floor).log10()).abs() < 1e-9);
    // No second readout: no crossover.
    assert!(snr_holes(&m).is_empty());
}

#[test]
fn dual_gain_hole_is_the_closed_form() {
    // DCG: one photodiode read at HCG and LCG. Above the HCG's last usable exposure only the
    // LCG remains: SNR₊ = sH/√(sH + d + σ_L²). Below, both readouts of the same charge with
    // weights w ∝ 1/σ_i² (the shared shot noise cannot be averaged away):
    // var = (sH + d)/s² + 1/(s²(1/σ_H² + 1/σ_L²)).
    let mut hdr = HdrModel::split_pixel_test();
    hdr.packets.truncate(1);
    hdr.readouts.truncate(2);
    let m = models(&hdr);
    let holes = snr_holes(&m);
    assert_eq!(holes.len(), 1);
    let (hi, lo) = (&m[0], &m[1]);
    let h = hi.last_usable_h_e();
    assert_eq!(holes[0].readout, "lpd_hcg");
    assert!((holes[0].crossover_e - h).abs() < 1e-9 * h);
    let (s, d) = (hi.gain_over_pixel, hi.dark_e);
    let e = s * h + d;
    let above = s * h / (e + lo.read_variance_e2).sqrt();
    let var_below =
        e / (s * s) + 1.0 / (s * s * (1.0 / hi.read_variance_e2 + 1.0 / lo.read_variance_e2));
    let below = h / var_below.sqrt();
    let drop = 20.0 * (below / above).log10();
    assert!(
        (holes[0].drop_db - drop).abs() < 1e-9,
        "{} vs {drop}",
        holes[0].drop_db
    );
    assert!(drop > 0.0);
}

#[test]
fn split_pixel_range_holes_and_noise_floor() {
    let hdr = HdrModel::split_pixel_test();
    let m = models(&hdr);
    let dr = dynamic_range(&m);
    // Largest signal: SPD-LCG (20 000 e⁻ well) up to 95 %.
    let h_max = (0.95 * 20000.0 - m[3].dark_e) / 0.009;
    assert!((dr.max_signal_e - h_max).abs() < 1e-6 * h_max);
    // Three crossovers in order of exposure: LPD-HCG, LPD-LCG, SPD-HCG.
    let holes = snr_holes(&m);
    let names: Vec<&str> = holes.iter().map(|h| h.readout.as_str()).collect();
    assert_eq!(names, ["lpd_hcg", "lpd_lcg", "spd_hcg"]);
    // The LPD → SPD hole: 20 log₁₀ √(s_L/s_S) in the shot-noise limit (100× less charge);
    // the read noise of the SPD deepens it a little.
    let shot_limit = 10.0 * (0.9f64 / 0.009).log10();
    assert!(
        holes[1].drop_db > shot_limit - 1.0 && holes[1].drop_db < shot_limit + 1.0,
        "{}",
        holes[1].drop_db
    );
    // Curves: the merged SNR is never below a usable readout's (the merge is the best linear
    // unbiased combination).
    let hs: Vec<f64> = (0..=70).map(|k| 10f64.powf(k as f64 / 10.0)).collect();
    let c = snr_curves(&m, &hs);
    for (j, &h) in hs.iter().enumerate() {
        for r in &c.readout_snr_db {
            assert!(
                c.merged_snr_db[j] >= r[j] - 1e-9 || !r[j].is_finite(),
                "at {h}"
            );
        }
    }

    // Simulated: the merged SNR at the closed-form noise floor is 1 (z-test on the variance,
    // 256×256 flat field).
    let s = SensorModel::mono_test(256, 256);
    let h = dr.noise_floor_e;
    let rate = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![(h / T_S) as f32; s.rows * s.cols],
    };
    let shot = Shot::new(&s, T_S);
    let frame = expose_hdr(&s, &hdr, &rate, &shot, 3, &[0, 0]);
    let x: Vec<f64> = camsim_isp::hdr_merge(&frame, &m)
        .unwrap()
        .data
        .iter()
        .map(|&v| v as f64)
        .collect();
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let m4 = x.iter().map(|a| (a - mean).powi(4)).sum::<f64>() / n;
    // At the floor the variance is H² (SNR = 1).
    let z = (var - h * h) / ((m4 - var * var) / n).sqrt();
    assert!(
        z.abs() < 4.5,
        "variance at the floor {var} vs H² = {} (z {z:.2}), H = {h}",
        h * h
    );
    assert!(
        dr.dynamic_range_db > 115.0 && dr.dynamic_range_db < 130.0,
        "{}",
        dr.dynamic_range_db
    );
}
