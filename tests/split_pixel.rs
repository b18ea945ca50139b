//! HDR pixels through the pipeline: the split-pixel study (examples/study_split_pixel/
//! spec_ci.json: a standard pixel and an IMX490-style split pixel on simulated flat fields;
//! merged SNR, dynamic range and the SNR hole against their closed forms, report with SNR
//! plots) and the `sensor.hdr` camera keys (one-line errors).
use crate::util::{num, repo, study_rows};
use camsim_pipeline::config::{camera_from_file, CameraFile};
use serde_json::{json, Value};
use std::path::Path;

#[test]
fn split_pixel_study_reports_snr_curves_and_dynamic_range() {
    let dir = tempfile::tempdir().unwrap();
    let spec = repo().join("examples/study_split_pixel/spec_ci.json");
    let rows = &study_rows(&spec, dir.path());
    assert_eq!(rows.len(), 14, "2 pixels × 7 exposures");
    // Standard pixel (camera.json): one readout, g = 50 µV/e⁻, σ = 150 µV (3 e⁻), 12 bits
    // over 1 V with black 64 DN: clips at (4095 − 64)/(4095 · 5e-5) e⁻; dark 1 mV/s · 10 ms
    // / 50 µV/e⁻ = 0.2 e⁻. Dynamic range 20 log₁₀(H_max/H₀) with H_max = 0.95 · clip − d and
    // H₀ = (1 + √(1 + 4(d + σ² + q²)))/2 (SNR = 1), q² = 1/(12 k²) the quantisation.
    let k: f64 = 4095.0 * 5e-5;
    let clip = (4095.0 - 64.0) / k;
    let d = 0.2;
    let c = d + 9.0 + 1.0 / (12.0 * k * k);
    let dr_standard = 20.0 * ((0.95 * clip - d) / ((1.0 + (1.0 + 4.0 * c).sqrt()) / 2.0)).log10();
    let mut checked = 0;
    for r in rows {
        let pixel = r["pixel"].as_str().unwrap_or_default().to_string();
        let dr = num(r, "dynamic_range_db");
        if pixel == "standard" {
            assert!((dr - dr_standard).abs() < 1e-6, "{dr} vs {dr_standard}");
            assert!(r["snr_hole_max_db"].is_null());
        } else {
            // The split pixel reaches ≥ 40 dB further, with a deep hole where the large
            // photodiode hands over to the small one (100× less charge: ≈ 20 dB).
            assert!(dr > dr_standard + 40.0, "{dr}");
            assert!(num(r, "snr_hole_max_db") > 15.0);
            let z = num(r, "snr_hole_z");
            assert!(
                z.abs() < 4.5,
                "SNR hole measured {} vs closed form {} (z {z})",
                num(r, "snr_hole_measured_db"),
                num(r, "snr_hole_model_db")
            );
            assert_eq!(num(r, "crossovers"), 3.0);
        }
        // Merged SNR of the simulated field against the closed form (away from the knees).
        if let Some(z) = r["snr_z"].as_f64() {
            assert!(
                z.abs() < 4.5,
                "{pixel} at H = {}: z {z} ({r})",
                num(r, "exposure_e")
            );
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} levels compared");
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(
        html.contains("dynamic_range_db"),
        "report table lacks dynamic_range_db"
    );
    let figs: Vec<_> = std::fs::read_dir(dir.path().join("figures"))
        .unwrap()
        .filter_map(|e| e.ok())
        .collect();
    assert!(figs.len() >= 3, "{} figures", figs.len());
    for f in figs {
        let k = camsim_pipeline::plots::check_figure(&f.path()).unwrap();
        assert!(k.distinct_colours > 3, "{} is blank", f.path().display());
    }
}

fn camera(hdr: Value) -> Value {
    let mut c: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_split_pixel/camera.json")).unwrap(),
    )
    .unwrap();
    c["sensor"]["hdr"] = hdr;
    c
}

fn load(c: Value) -> Result<camsim_pipeline::config::Camera, String> {
    let f: CameraFile = serde_json::from_value(c).map_err(|e| e.to_string())?;
    camera_from_file(Path::new("camera.json"), f).map_err(|e| e.one_line())
}

#[test]
fn hdr_keys_are_checked_and_default_to_the_standard_pixel() {
    assert!(load(camera(Value::Null)).unwrap().hdr.is_none());
    let split: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_split_pixel/split_pixel.json"))
            .unwrap(),
    )
    .unwrap();
    let c = load(camera(split.clone())).unwrap();
    let h = c.hdr.unwrap();
    assert_eq!(h.readouts[2].packet, 1, "spd_hcg reads spd");
    // Defaults: the sensor's well and read noise.
    let c = load(camera(
        json!({"photodiodes": [{"name": "a", "sensitivity": 1}],
        "readouts": [{"name": "r", "photodiode": "a", "conversion_gain_v_per_e": 1e-4}]}),
    ))
    .unwrap();
    let h = c.hdr.unwrap();
    assert_eq!(h.packets[0].well_capacity_e, 40000.0);
    assert_eq!(h.readouts[0].read_noise_v, 1.5e-4);
    let mut bad = split.clone();
    bad["readouts"][1]["photodiode"] = json!("mpd");
    let e = load(camera(bad)).unwrap_err();
    assert!(
        e.contains("sensor.hdr.readouts[1].photodiode") && e.contains("mpd"),
        "{e}"
    );
    let mut bad = split.clone();
    bad["photodiodes"][1]["sensitivity"] = json!(0.0);
    let e = load(camera(bad)).unwrap_err();
    assert!(
        e.contains("sensor.hdr.photodiodes[1].sensitivity") && e.contains('0'),
        "{e}"
    );
    let mut bad = split;
    bad["readouts"][3]["name"] = json!("lpd_hcg");
    let e = load(camera(bad)).unwrap_err();
    assert!(
        e.contains("sensor.hdr.readouts[3].name") && e.contains("twice"),
        "{e}"
    );
}
