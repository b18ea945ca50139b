//! `camsim validate` (library API `camsim_pipeline::validate_cmd::run_validate`): a capture set recorded
//! with `camsim simulate` is validated against the camera that made it (agreement) and against
//! a camera whose conversion gain is 20 % off (the mismatch is found); the figures are real;
//! a recording of the wrong size is one clear error and nothing is written.
use crate::cli::{camera, write_set};
use crate::util::{camsim, camsim_ok};
use camsim_pipeline::config::load_captures;
use camsim_pipeline::validate_cmd::run_validate;
use serde_json::{json, Value};
use std::path::Path;

const ROWS: usize = 192;
const COLS: usize = 288;
/// Seed of the recording (`camsim simulate`).
const RECORD_SEED: u64 = 3;
/// Seed of the validation's simulated frames (not the recording's: agreement is statistical).
const VALIDATE_SEED: u64 = 11;

/// tests/cli.rs camera with three distinct (Gaussian) channel QEs, so that a 3×3 colour
/// correction can be fitted.
fn colour_camera() -> Value {
    let mut cam = camera(ROWS, COLS);
    let wl: Vec<f64> = (0..=30).map(|i| 400.0 + 10.0 * i as f64).collect();
    let gauss = |peak: f64, sigma: f64| -> Value {
        let v: Vec<f64> = wl
            .iter()
            .map(|w| 0.5 * (-0.5 * ((w - peak) / sigma).powi(2)).exp())
            .collect();
        json!({"wavelength_nm": wl, "values": v})
    };
    cam["sensor"]["channels"] =
        json!({"r": gauss(610.0, 35.0), "g": gauss(540.0, 35.0), "b": gauss(460.0, 30.0)});
    cam
}

fn captures() -> Value {
    json!({"camera": "camera.json", "shots": [
        {"id": "macbeth", "exposure_s": 0.08,
         "target": {"kind": "macbeth", "illuminant": "tungsten", "mean_luminance_cd_m2": 61, "patch_fraction": 0.8},
         "frames": ["raw/macbeth-0.png", "raw/macbeth-1.png"]},
        {"id": "dark", "target": {"kind": "dark"}, "exposure_s": 0.01, "frames": ["raw/dark-0.png"]},
        {"id": "flat", "exposure_s": 0.1,
         "target": {"kind": "uniform", "radiance": {"wavelength_nm": [400, 700], "values": [0.002, 0.002]}},
         "frames": ["raw/flat-0.png", "raw/flat-1.png"]}
    ]})
}

/// Writes the set and records it with `camsim simulate --seed RECORD_SEED`.
fn recorded_set(dir: &Path) {
    write_set(dir, &colour_camera(), &captures());
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--out", "."])
            .args(["--seed", &RECORD_SEED.to_string()])
            .current_dir(dir),
    );
}

/// Mean DN of channel `ch` of the flat shot of [`captures`] on [`colour_camera`], written out
/// independently of camsim's code (paper Eq. 1–3):
/// * sensor irradiance `E(λ) = L(λ) · T · π / (4 N²) · cos⁴θ` (object at infinity, m = 0),
///   `cos⁴θ = (f² / (f² + r²))²` at each pixel centre;
/// * electrons `n = t · p² · FF · ∫ QE_c(λ) E(λ) λ / (h c) dλ` with the channel's QE linear
///   between its 10 nm samples (integrated exactly: QE·λ is quadratic on each interval,
///   Simpson's rule is exact);
/// * DN `= black + (n · g + V_dark · t) · (2^bits − 1) / V_swing` (unit analog gain, no offset;
///   the mean of the zero-mean read noise, DSNU and PRNU patterns is 0 and 1).
fn flat_mean_dn_closed_form(ch: &str) -> f64 {
    let cam = colour_camera();
    let s = &cam["sensor"];
    let o = &cam["optics"];
    let (h, c_light) = (6.626_070_15e-34, 299_792_458.0);
    let (radiance, t_s) = (0.002, 0.1); // the flat shot of `captures()`
    let n_f = f(&o["f_number"]);
    let focal_m = f(&o["focal_length_mm"]) * 1e-3;
    let pitch_m = f(&s["pixel_pitch_um"]) * 1e-6;
    let (rows, cols) = (ROWS, COLS);
    let wl: Vec<f64> = s["channels"][ch]["wavelength_nm"]
        .as_array()
        .unwrap()
        .iter()
        .map(f)
        .collect();
    let qe: Vec<f64> = s["channels"][ch]["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(f)
        .collect();
    // ∫ QE(λ) λ dλ over the samples (nm · m), Simpson per linear piece.
    let mut qe_lambda = 0.0;
    for i in 0..wl.len() - 1 {
        let (a, b) = (wl[i], wl[i + 1]);
        let m = 0.5 * (a + b);
        let q = |x: f64| qe[i] + (qe[i + 1] - qe[i]) * (x - a) / (b - a);
        qe_lambda += (b - a) / 6.0 * (q(a) * a + 4.0 * q(m) * m + q(b) * b) * 1e-9;
    }
    let photons_axis = radiance * f(&o["transmittance"]) * std::f64::consts::PI / (4.0 * n_f * n_f)
        * qe_lambda
        / (h * c_light);
    // CFA gb/rg: g at (even, even) and (odd, odd), b at (even, odd), r at (odd, even).
    let (mut cos4_sum, mut n_px) = (0.0, 0.0);
    for r in 0..rows {
        for c in 0..cols {
            let here = match (r % 2, c % 2) {
                (0, 0) | (1, 1) => "g",
                (0, 1) => "b",
                _ => "r",
            };
            if here != ch {
                continue;
            }
            let y = (r as f64 - (rows as f64 - 1.0) / 2.0) * pitch_m;
            let x = (c as f64 - (cols as f64 - 1.0) / 2.0) * pitch_m;
            let c2 = focal_m * focal_m / (focal_m * focal_m + x * x + y * y);
            cos4_sum += c2 * c2;
            n_px += 1.0;
        }
    }
    let electrons = t_s * pitch_m * pitch_m * f(&s["fill_factor"]) * photons_axis * cos4_sum / n_px;
    let volts = electrons * f(&s["conversion_gain_v_per_e"]) + f(&s["dark_voltage_v_per_s"]) * t_s;
    let dn_per_v = (2f64.powf(f(&s["adc_bits"])) - 1.0) / f(&s["voltage_swing_v"]);
    f(&s["black_level_dn"]) + volts * dn_per_v
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn shot<'a>(v: &'a Value, id: &str) -> &'a Value {
    v["shots"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .unwrap_or_else(|| panic!("no shot {id}"))
}

#[test]
fn same_camera_agrees_and_figures_are_real() {
    let d = tempfile::tempdir().unwrap();
    recorded_set(d.path());
    let set = load_captures(&d.path().join("captures.json"), None).unwrap();
    let out = d.path().join("val");
    let v = run_validate(&set, &out, VALIDATE_SEED, false).unwrap().json;
    // what is returned is what is written (up to float printing)
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("validation.json")).unwrap())
            .unwrap();
    assert_eq!(written["figures"], v["figures"]);
    assert_eq!(written["shots"].as_array().unwrap().len(), 3);
    let w = f(&written["summary"]["max_abs_normalised_residual"]);
    assert!((w - f(&v["summary"]["max_abs_normalised_residual"])).abs() < 1e-9);

    // per shot and channel: measured and simulated means agree, normalised residual ~ N(0, 1),
    // χ² per pixel ≈ 1 (the noise model explains the scatter of the frame-averaged pixels)
    for id in ["macbeth", "flat"] {
        let s = shot(&v, id);
        for ch in ["r", "g", "b"] {
            let c = &s["channels"][ch];
            let (m, sim) = (f(&c["measured_mean_dn"]), f(&c["simulated_mean_dn"]));
            assert!((sim / m - 1.0).abs() < 0.01, "{id}/{ch}: {m} vs {sim}");
            assert!(f(&c["relative_mismatch"]).abs() < 0.01, "{id}/{ch}: {c}");
            assert!(f(&c["normalised_residual"]).abs() < 4.0, "{id}/{ch}: {c}");
            assert!(
                f(&c["simulated_normalised_residual"]).abs() < 4.0,
                "{id}/{ch}: {c}"
            );
            let chi2 = f(&c["chi2_per_pixel"]);
            assert!((chi2 - 1.0).abs() < 0.1, "{id}/{ch}: χ² {chi2}");
        }
    }
    // The recording and the validation share camsim's forward model, so their agreement alone
    // cannot catch an error common to both. An independent path: the flat shot's channel means
    // from the camera equation, written out here (flat_mean_dn_closed_form).
    let flat = shot(&v, "flat");
    for ch in ["r", "g", "b"] {
        let c = &flat["channels"][ch];
        let reference = flat_mean_dn_closed_form(ch);
        let (measured, expected, sigma) = (
            f(&c["measured_mean_dn"]),
            f(&c["expected_mean_dn"]),
            f(&c["sigma_model_dn"]),
        );
        eprintln!(
            "flat/{ch}: camera equation {reference:.4} DN, recorded {measured:.4} ± {sigma:.4}, \
             validate's expectation {expected:.4}"
        );
        // The expectation is the same integral in f32 planes: 10⁻⁵ relative.
        assert!(
            (expected - reference).abs() <= 1e-5 * (reference - 64.0),
            "flat/{ch}: validate's expected mean {expected} DN vs camera equation {reference} DN"
        );
        // The recording: its mean scatters by the model's standard error of the mean (shot,
        // read, DSNU, PRNU, quantisation); 4.5σ two-sided (false-failure rate 7·10⁻⁶ per
        // channel) plus the f32 allowance above.
        assert!(
            (measured - reference).abs() <= 4.5 * sigma + 1e-5 * (reference - 64.0),
            "flat/{ch}: recorded mean {measured} DN vs camera equation {reference} DN (σ {sigma})"
        );
    }

    // the dark shot: no signal above black to form a ratio, residual still ~ 0
    let dark = &shot(&v, "dark")["all_pixels"];
    assert!(dark["relative_mismatch"].is_null(), "{dark}");
    assert!(f(&dark["normalised_residual"]).abs() < 4.0, "{dark}");

    // per patch (paper Figs. 3–4): means within a few % (or 4 combined σ for the darkest),
    // patch residuals ~ 0 on average, SNR measured ≈ simulated
    let patches = &shot(&v, "macbeth")["patches"];
    let mut z_sum = 0.0;
    let mut snr_diff = 0.0;
    let mut n = 0.0;
    for ch in ["r", "g", "b"] {
        let list = patches[ch].as_array().unwrap();
        assert_eq!(list.len(), 24);
        for (i, p) in list.iter().enumerate() {
            let black = 64.0;
            let m = f(&p["measured_mean_dn"]) - black;
            let s = f(&p["simulated_mean_dn"]) - black;
            let sigma = f(&p["sigma_model_dn"]);
            assert!(
                (s - m).abs() < 0.03 * m.abs() || (s - m).abs() < 4.0 * 2f64.sqrt() * sigma,
                "patch {i} {ch}: measured {m}, simulated {s} (σ {sigma})"
            );
            let z = f(&p["normalised_residual"]);
            assert!(z.abs() < 4.5, "patch {i} {ch}: z = {z}");
            z_sum += z;
            n += 1.0;
            // SNR from the spatial σ of ~130–260 pixels per frame: σ's own sampling error is
            // ≈ 1/√(2n) relative, i.e. 8.7/√(2n) dB per chart; allow 4σ of the difference
            let (snr_m, snr_s) = (f(&p["measured_snr_db"]), f(&p["simulated_snr_db"]));
            let tol = 4.0 * 2f64.sqrt() * 8.69 / (2.0 * f(&p["pixels"])).sqrt();
            assert!(
                (snr_m - snr_s).abs() < tol,
                "patch {i} {ch}: SNR {snr_m} vs {snr_s} dB (tolerance {tol})"
            );
            snr_diff += snr_m - snr_s;
        }
    }
    // 72 patch residuals: their mean has σ ≈ 1/√72 ≈ 0.12
    assert!((z_sum / n).abs() < 0.5, "mean patch residual {}", z_sum / n);
    // on average over the 72 patches the SNRs agree to a fraction of a dB
    assert!(
        (snr_diff / n).abs() < 0.3,
        "mean SNR difference {} dB",
        snr_diff / n
    );

    // colour (Figs. 5–6): both charts corrected comparably well
    let col = &shot(&v, "macbeth")["colour"];
    let (dm, ds) = (
        f(&col["delta_e_2000_measured"]["mean"]),
        f(&col["delta_e_2000_simulated"]["mean"]),
    );
    assert!(dm < 10.0 && ds < 10.0, "{col}");
    assert!(
        (dm - ds).abs() < 0.5,
        "ΔE2000 measured {dm} vs simulated {ds}"
    );
    assert!(f(&col["delta_e_2000_measured_vs_simulated"]["mean"]) < 1.0);
    assert!(v["summary"]["max_abs_relative_mismatch"].as_f64().unwrap() < 0.01);

    // figures: every one listed exists, shows something and is in the report
    let figs: Vec<&str> = v["figures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    for want in [
        "shot_means.png",
        "patch_means_macbeth.png",
        "patch_snr_macbeth.png",
        "delta_e_measured_macbeth.png",
        "delta_e_simulated_macbeth.png",
        "residual_macbeth.png",
        "residual_dark.png",
        "residual_flat.png",
    ] {
        assert!(figs.contains(&want), "{want} not in {figs:?}");
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    for fig in &figs {
        let k = camsim_pipeline::plots::check_figure(&out.join(fig)).unwrap();
        assert!(
            k.distinct_colours > 8 && k.non_white_per_mille > 10,
            "{fig}: {k:?}"
        );
        assert!(html.contains(fig), "{fig} not in the report");
    }
    let res = camsim_pipeline::plots::check_figure(&out.join("residual_macbeth.png")).unwrap();
    assert_eq!((res.width, res.height), (COLS as u32, ROWS as u32));

    // with the recording's own seed the simulation reproduces the recording exactly
    let v3 = run_validate(&set, &d.path().join("val3"), RECORD_SEED, false)
        .unwrap()
        .json;
    for id in ["macbeth", "dark", "flat"] {
        let a = &shot(&v3, id)["all_pixels"];
        assert_eq!(a["measured_mean_dn"], a["simulated_mean_dn"], "{id}");
    }
}

#[test]
fn conversion_gain_20_percent_off_is_detected() {
    let d = tempfile::tempdir().unwrap();
    recorded_set(d.path());
    let mut cam = colour_camera();
    cam["sensor"]["conversion_gain_v_per_e"] = json!(5.0e-5 * 1.2);
    std::fs::write(
        d.path().join("camera_g12.json"),
        serde_json::to_string_pretty(&cam).unwrap(),
    )
    .unwrap();
    let set = load_captures(
        &d.path().join("captures.json"),
        Some(&d.path().join("camera_g12.json")),
    )
    .unwrap();
    let v = run_validate(&set, &d.path().join("val"), VALIDATE_SEED, false)
        .unwrap()
        .json;
    // the believed camera gives 20 % more signal above black than was recorded
    for id in ["macbeth", "flat"] {
        let s = shot(&v, id);
        for ch in ["r", "g", "b"] {
            let c = &s["channels"][ch];
            let rel = f(&c["relative_mismatch"]);
            assert!(
                (rel - 0.2).abs() < 0.02,
                "{id}/{ch}: relative mismatch {rel}"
            );
            let sim_rel = f(&c["simulated_relative_mismatch"]);
            assert!(
                (sim_rel - 0.2).abs() < 0.02,
                "{id}/{ch}: simulated {sim_rel}"
            );
            assert!(
                f(&c["normalised_residual"]) < -20.0,
                "{id}/{ch}: a 20 % error is many σ: {c}"
            );
            assert!(f(&c["chi2_per_pixel"]) > 5.0, "{id}/{ch}: {c}");
        }
    }
    let worst = f(&v["summary"]["max_abs_relative_mismatch"]);
    assert!((worst - 0.2).abs() < 0.03, "summary: {worst}");
    // patch by patch too (Fig. 3): simulated / measured above black ≈ 1.2 on the bright patches
    for p in shot(&v, "macbeth")["patches"]["g"].as_array().unwrap() {
        let m = f(&p["measured_mean_dn"]) - 64.0;
        let s = f(&p["simulated_mean_dn"]) - 64.0;
        if m > 200.0 {
            assert!((s / m - 1.2).abs() < 0.05, "patch: {m} vs {s}");
        }
    }
}

#[test]
fn recording_of_the_wrong_size_is_one_clear_error_and_writes_nothing() {
    let d = tempfile::tempdir().unwrap();
    recorded_set(d.path());
    let wrong = camsim_core::RawFrame {
        rows: 4,
        cols: 8,
        adc_bits: 12,
        dn: vec![100; 32],
        layout: None,
    };
    camsim_pipeline::frames::write_png16(&d.path().join("raw/flat-1.png"), &wrong).unwrap();
    let set = load_captures(&d.path().join("captures.json"), None).unwrap();
    let out = d.path().join("val");
    let e = run_validate(&set, &out, VALIDATE_SEED, false).unwrap_err();
    let msg = e.to_string();
    assert!(!msg.contains('\n'), "one line: {msg}");
    for needle in ["flat-1.png", "4×8", &format!("{ROWS}×{COLS}")] {
        assert!(msg.contains(needle), "'{needle}' not in: {msg}");
    }
    assert!(!out.exists(), "nothing may be written on error");
    // an existing output folder is left as it was
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("keep.txt"), "x").unwrap();
    assert!(run_validate(&set, &out, VALIDATE_SEED, false).is_err());
    let names: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names, vec!["keep.txt".to_string()]);
}
