//! Real captures (read from ../shared, never copied): the Llanos 2020 Flea3 dark-frame series
//! (two sessions × 7 exposures × 2 frames, 8-bit 408×344 Bayer crops). What the data show —
//! dark signal growing with exposure and hot pixels appearing — must come out of
//! `camsim calibrate`; docs/real_data_flea3.md discusses the numbers.
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn flea3_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/real/captures/llanos2020_flea3")
}

/// The believed camera: Sony ICX655 (3.45 µm), data reduced to 8 bits by the upstream demo.
/// Conversion gain and swing are assumptions (8-bit full scale ≈ 1 V, 1e-4 V/e⁻); dark
/// estimates are reported in volts through them and in DN/s in the doc.
pub fn flea3_camera() -> Value {
    let qe = json!({"wavelength_nm": [400, 700], "values": [0.3, 0.3]});
    json!({"name": "flea3-fl3-ge-50s5c (believed)",
        "optics": {"f_number": 4.0, "focal_length_mm": 8.0, "relative_illumination": "none"},
        "sensor": {"rows": 344, "cols": 408, "pixel_pitch_um": 3.45, "cfa": ["rg", "gb"],
                   "channels": {"r": qe, "g": qe, "b": qe},
                   "well_capacity_e": 10000, "conversion_gain_v_per_e": 1.0e-4, "voltage_swing_v": 1.0,
                   "adc_bits": 8}})
}

/// A capture set in a temporary folder whose frames are symbolic links to ../shared.
pub fn flea3_dark_set(dir: &Path) -> PathBuf {
    let src = flea3_dir().join("dark_frames");
    std::fs::create_dir_all(dir.join("raw")).unwrap();
    let mut shots: std::collections::BTreeMap<(String, u32), Vec<String>> = Default::default();
    for e in std::fs::read_dir(&src).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().to_string();
        // d1_dark_100ms_2019-...-0003.tif
        let parts: Vec<&str> = name.split('_').collect();
        let ms: u32 = parts[2].trim_end_matches("ms").parse().unwrap();
        std::os::unix::fs::symlink(src.join(&name), dir.join("raw").join(&name)).unwrap();
        shots
            .entry((parts[0].to_string(), ms))
            .or_default()
            .push(format!("raw/{name}"));
    }
    let shots: Vec<Value> = shots
        .into_iter()
        .map(|((session, ms), mut frames)| {
            frames.sort();
            json!({"id": format!("{session}-dark-{ms}ms"), "target": {"kind": "dark"}, "exposure_s": ms as f64 / 1000.0, "frames": frames})
        })
        .collect();
    std::fs::write(dir.join("camera.json"), flea3_camera().to_string()).unwrap();
    let p = dir.join("captures.json");
    std::fs::write(
        &p,
        json!({"camera": "camera.json", "shots": shots}).to_string(),
    )
    .unwrap();
    p
}

#[test]
fn flea3_dark_series_dark_growth_and_hot_pixels() {
    let d = tempfile::tempdir().unwrap();
    let caps = flea3_dark_set(d.path());
    let set = camsim::config::load_captures(&caps, None).unwrap();
    // The data themselves: pixels above 10 DN appear only at long exposures (README: 0 → 18).
    let count_above = |id: &str| -> usize {
        let s = set.shots.iter().find(|s| s.id == id).unwrap();
        let f = camsim::raw_input::read_frame(&set.dir.join(&s.frames[0])).unwrap();
        f.dn.iter().filter(|&&v| v > 10).count()
    };
    let (short, long) = (count_above("d1-dark-25ms"), count_above("d1-dark-3916ms"));
    assert!(
        short == 0 && long >= 5,
        "pixels > 10 DN: {short} at 25 ms, {long} at 3.9 s"
    );
    let out = d.path().join("cal");
    let c = camsim::calibrate_cmd::run_calibrate(&set, &out, false).unwrap();
    eprintln!("flea3 calibration: {}", serde_json::to_string_pretty(&json!({
        "black_level_dn": c["black_level_dn"], "dark_voltage_v_per_s": c["dark_voltage_v_per_s"],
        "read_noise_v": c["read_noise_v"], "dsnu_sigma_v": c["dsnu_sigma_v"],
        "hot_pixels": c["hot_pixels"]["pixels"].as_array().map(|a| a.len()), "hot_threshold": c["hot_pixels"]["threshold"],
        "rejected": c["rejected_shots"]})).unwrap());
    // What the 8-bit, cropped data allow (docs/real_data_flea3.md):
    // * session 2 was cropped to 342 rows: those shots are rejected with the size named;
    let rejected = c["rejected_shots"].as_array().unwrap();
    assert_eq!(rejected.len(), 7);
    assert!(rejected
        .iter()
        .all(|r| r["id"].as_str().unwrap().starts_with("d2")
            && r["reason"].as_str().unwrap().contains("342×408")));
    // * the 8-bit darks sit at 0 DN for most pixels: mean/variance estimators refuse, naming
    //   the clipping, instead of returning biased numbers;
    for k in ["dark_voltage_v_per_s", "read_noise_v"] {
        assert_eq!(c[k]["status"], "not_estimable", "{k}");
        assert!(
            c[k]["reason"].as_str().unwrap().contains("clip"),
            "{k}: {}",
            c[k]["reason"]
        );
    }
    // * yet the dark signal does grow with exposure in the data (mean DN of session 1):
    let mean_dn = |id: &str| -> f64 {
        let s = set.shots.iter().find(|s| s.id == id).unwrap();
        let f = camsim::raw_input::read_frame(&set.dir.join(&s.frames[0])).unwrap();
        f.dn.iter().map(|&v| v as f64).sum::<f64>() / f.dn.len() as f64
    };
    let (m0, m1) = (mean_dn("d1-dark-25ms"), mean_dn("d1-dark-3916ms"));
    eprintln!("flea3 mean dark DN: {m0:.4} at 25 ms, {m1:.4} at 3916 ms");
    assert!(m1 > m0, "mean dark DN {m0} → {m1}");
    assert!(out.join("dark_signal.png").is_file() && out.join("report.html").is_file());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("342×408") && html.contains("not estimable"));
}

#[test]
fn flea3_bandpass_explore() {
    let d = tempfile::tempdir().unwrap();
    let caps = camsim::datasets::llanos_flea3_bandpass(&flea3_dir(), d.path()).unwrap();
    let t0 = std::time::Instant::now();
    let set = camsim::config::load_captures(&caps, None).unwrap();
    eprintln!("load {:?}", t0.elapsed());
    let out = d.path().join("cal");
    let c = camsim::calibrate_cmd::run_calibrate(&set, &out, false).unwrap();
    eprintln!("total {:?}", t0.elapsed());
    let ch = &c["chart_channel_qe"];
    eprintln!(
        "status {} notes {} pedestal {} median icpt {}",
        ch["fit"]["status"], ch["notes"], ch["pedestal_dn"], ch["median_intercept_dn"]
    );
    std::fs::write(
        "/tmp/h4_cal.json",
        serde_json::to_string_pretty(&c).unwrap(),
    )
    .unwrap();
    if let Some(r) = ch["fit"]["reason"].as_str() {
        eprintln!("reason {r}");
    }
    let q = &ch["fit"]["qe"];
    eprintln!("wl {}", q["wavelength_nm"]);
    for c in q["channels"].as_array().unwrap() {
        eprintln!(
            "{} alpha {} cv {}",
            c["name"], c["alpha"], c["cv_chi2_per_shot"]
        );
        let v: Vec<String> = c["qe"]
            .as_array()
            .unwrap()
            .iter()
            .zip(c["std_error"].as_array().unwrap())
            .map(|(a, b)| format!("{:.3e}±{:.1e}", a.as_f64().unwrap(), b.as_f64().unwrap()))
            .collect();
        eprintln!("  {}", v.join(" "));
    }
    eprintln!(
        "iterations {} gains {}",
        ch["gain_iterations"],
        ch["patch_illumination"]
            .as_array()
            .map(|a| a
                .iter()
                .map(|g| format!(
                    "{:.3}±{:.3}",
                    g["factor"].as_f64().unwrap(),
                    g["sigma"].as_f64().unwrap()
                ))
                .collect::<Vec<_>>()
                .join(" "))
            .unwrap_or_default()
    );
    // per series chi2 and z
    let obs = ch["fit"]["observations"].as_array().unwrap();
    let mut by: std::collections::BTreeMap<String, Vec<f64>> = Default::default();
    for o in obs {
        let z = (o["signal"].as_f64().unwrap() - o["predicted"].as_f64().unwrap())
            / o["sigma"].as_f64().unwrap();
        by.entry(format!("{} {}", o["group"], o["channel"]))
            .or_default()
            .push(z);
    }
    for (k, z) in &by {
        let chi = z.iter().map(|x| x * x).sum::<f64>() / z.len() as f64;
        let rel: Vec<f64> = obs
            .iter()
            .filter(|o| format!("{} {}", o["group"], o["channel"]) == *k)
            .map(|o| o["signal"].as_f64().unwrap() / o["predicted"].as_f64().unwrap())
            .collect();
        let mut r2 = rel.clone();
        r2.sort_by(f64::total_cmp);
        eprintln!(
            "   ratio median {:.3} min {:.3} max {:.3}",
            r2[r2.len() / 2],
            r2[0],
            r2[r2.len() - 1]
        );
        eprintln!(
            "{k}: n {} chi2/n {chi:.2} zs {:?}",
            z.len(),
            z.iter()
                .map(|v| (v * 10.0).round() / 10.0)
                .collect::<Vec<_>>()
        );
    }
    for l in ch["lines"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|l| l["patch"] == 19 || l["patch"] == 1)
    {
        eprintln!(
            "{} p{} {} slope {:.4}±{:.4} icpt {:.3}±{:.3} n {} chi2 {} ri {:.3}",
            l["series"],
            l["patch"],
            l["channel"],
            l["slope_dn_per_s"].as_f64().unwrap_or(f64::NAN),
            l["slope_sigma_dn_per_s"].as_f64().unwrap_or(f64::NAN),
            l["intercept_dn"].as_f64().unwrap_or(f64::NAN),
            l["intercept_sigma_dn"].as_f64().unwrap_or(f64::NAN),
            l["n_points"],
            l["chi2_per_dof"],
            l["relative_illumination"].as_f64().unwrap()
        );
    }
    std::fs::copy(out.join("chart_spectral_qe.png"), "/tmp/h4_chart_qe.png").ok();
    std::fs::copy(out.join("chart_fit.png"), "/tmp/h4_chart_fit.png").ok();
    std::fs::write(
        "/tmp/h4_cal.json",
        serde_json::to_string_pretty(&c).unwrap(),
    )
    .unwrap();
}
