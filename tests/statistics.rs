//! Simulated frames agree statistically with the baseline model over a 1-megapixel flat
//! field: mean within 0.5 %, variance within 3 % of the model's (spec acceptance 3).
use crate::cli::{camera, captures, write_set};
use camsim_pipeline::config::load_captures;
use camsim_pipeline::simulate::{shot_electron_rate, wavelength_grid};
use camsim_sensor::{expected_dn, expose, fixed_pattern, Shot};

#[test]
fn flat_field_frames_match_expected_mean_and_model_variance() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(1000, 1000);
    cam["optics"]["relative_illumination"] = serde_json::json!("none");
    let (l, t) = (0.002, 0.02);
    write_set(dir.path(), &cam, &captures(l, t));
    let set = load_captures(&dir.path().join("captures.json"), None).unwrap();
    let grid = wavelength_grid(&set);
    let rate = shot_electron_rate(&set, 1, &grid).unwrap();
    let s = &set.camera.sensor;
    let shot = Shot {
        exposure_s: t,
        analog_gain: 1.0,
    };
    let expected = expected_dn(s, &rate, &shot);
    let mean_exp = expected.iter().map(|v| *v as f64).sum::<f64>() / expected.len() as f64;
    // Model variance of one frame over pixels (DN²), spec steps 4–7:
    // electrons: Poisson(e(1+P)+d) → var = e + d + e²σ_P²; volts add σ_D² + σ_r²; quantisation 1/12.
    let e = rate.electrons_per_s[0] as f64 * t;
    let d = t * s.dark_voltage_v_per_s / s.conversion_gain_v_per_e;
    let g = s.conversion_gain_v_per_e;
    let k = (2f64.powi(s.adc_bits as i32) - 1.0) / s.voltage_swing_v; // DN per output volt
    let sp = s.prnu_sigma_percent / 100.0;
    let var_v = g * g * (e + d + e * e * sp * sp) + s.dsnu_sigma_v.powi(2) + s.read_noise_v.powi(2);
    let var_model = k * k * var_v + 1.0 / 12.0;
    assert!(
        mean_exp > 500.0 && mean_exp < 3500.0,
        "operating point in range: {mean_exp}"
    );
    let fixed = fixed_pattern(s, 11);
    for frame_index in 0..2u64 {
        let f = expose(s, &rate, &shot, &fixed, 11, &[1, frame_index]);
        let n = f.dn.len() as f64;
        let mean = f.dn.iter().map(|v| *v as f64).sum::<f64>() / n;
        let var = f.dn.iter().map(|v| (*v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
        assert!(
            (mean / mean_exp - 1.0).abs() < 0.005,
            "mean {mean} vs expected {mean_exp}"
        );
        assert!(
            (var / var_model - 1.0).abs() < 0.03,
            "variance {var} vs model {var_model}"
        );
    }
}
