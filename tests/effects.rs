//! The effect blocks of effects.md (docs/effects.md) end to end: camera.json parsing and the
//! Serialize round trip, one-line errors, and every block's physics through `camsim simulate`'s
//! library path (scene → optics → sensor), each against a closed form or a direct computation.
use camsim_pipeline::config::{
    camera_file_json, load_camera, load_captures, read_camera_file, CaptureSet,
};
use camsim_pipeline::simulate::{shot_electron_rate, shot_irradiance, wavelength_grid};
use camsim_sensor::{electron_rate, expected_dn, ElectronRate, Shot};
use serde_json::{json, Value};
use std::f64::consts::PI;
use std::path::Path;

/// A monochrome camera, QE 0.5 on 400–700 nm, no blur, no fall-off.
fn mono_camera(rows: usize, cols: usize) -> Value {
    json!({
        "name": "fx",
        "optics": {"f_number": 2.0, "focal_length_mm": 4.0, "relative_illumination": "none",
                   "blur": {"kind": "none"}},
        "sensor": {"rows": rows, "cols": cols, "pixel_pitch_um": 2.0, "fill_factor": 0.5,
                   "cfa": ["m"],
                   "channels": {"m": {"wavelength_nm": [400, 700], "values": [0.5, 0.5]}},
                   "well_capacity_e": 1.0e6, "conversion_gain_v_per_e": 5.0e-5,
                   "voltage_swing_v": 1.0, "adc_bits": 12, "black_level_dn": 64.0,
                   "dark_voltage_v_per_s": 1.0e-3, "read_noise_v": 1.0e-3}
    })
}

/// A Bayer camera with every block (fitted or generator form as `generator` says).
fn camera_with_every_block(generator: bool) -> Value {
    let mut c = mono_camera(32, 48);
    c["sensor"]["cfa"] = json!(["gr", "bg"]);
    c["sensor"]["channels"] = json!({
        "r": {"wavelength_nm": [400, 580, 700], "values": [0.0, 0.1, 0.4]},
        "g": {"wavelength_nm": [400, 530, 700], "values": [0.05, 0.6, 0.05]},
        "b": {"wavelength_nm": [400, 460, 700], "values": [0.5, 0.4, 0.0]}
    });
    let o = &mut c["optics"];
    o["exposure_scale"] = json!({"factor": 1.07});
    o["veiling_glare"] = json!({"fraction": 0.02});
    if generator {
        o["relative_illumination"] = json!({"model": "cos4",
            "falloff": {"kind": "two_circle", "separation_at_h1": 0.5}});
        o["defocus"] = json!({"kind": "pillbox", "radius_um": 1.5});
        o["distortion"] = json!({"kind": "division", "k": 0.03});
        o["lateral_color"] = json!({"kind": "cauchy", "displacement_um": 1.5});
    } else {
        o["relative_illumination"] = json!({"model": "cos4",
            "falloff": {"kind": "polynomial", "coefficients": [-0.1, 0.02]}});
        o["defocus"] = json!({"kind": "gaussian", "sigma_um": 0.8});
        o["distortion"] = json!({"kind": "polynomial", "k1": -0.02, "k2": 0.005});
        o["lateral_color"] = json!({"kind": "linear", "displacement_um": 1.0});
    }
    let s = &mut c["sensor"];
    s["column_fpn"] = json!({"sigma_v": 2.0e-4});
    if generator {
        s["hot_pixels"] =
            json!({"fraction": 0.002, "dark_voltage_v_per_s": 0.05, "log_sigma": 0.4});
        s["nonlinearity"] = json!({"kind": "tanh", "saturation_v": 1.5});
        s["crosstalk"] = json!({"left": 0.01, "right": 0.02, "up": 0.005, "down": 0.0});
        s["ir_leakage"] = json!({"channels": {
            "r": {"wavelength_nm": [690, 800, 1000], "values": [0.0, 0.05, 0.02]}, "b": 0.01}});
    } else {
        s["hot_pixels"] = json!({"fraction": 0.002, "dark_voltage_v_per_s": 0.05});
        s["nonlinearity"] = json!({"kind": "quadratic", "coefficient_per_v": 0.05});
        s["crosstalk"] = json!({"fraction": 0.04});
        s["ir_leakage"] = json!({"channels": {"r": 0.03, "g": 0.02, "b": 0.02}});
    }
    s["qe_shift"] = json!({"shift_nm": {"r": 6.0, "b": -2.0}});
    c
}

fn write_json(path: &Path, v: &Value) {
    std::fs::write(path, serde_json::to_string_pretty(v).unwrap()).unwrap();
}

/// camera.json + captures.json (with `simulation` settings) in `dir`, loaded.
fn load(dir: &Path, camera: &Value, shots: Value, simulation: Option<Value>) -> CaptureSet {
    write_json(&dir.join("camera.json"), camera);
    let mut c = json!({"camera": "camera.json", "shots": shots});
    if let Some(s) = simulation {
        c["simulation"] = s;
    }
    write_json(&dir.join("captures.json"), &c);
    load_captures(&dir.join("captures.json"), None).unwrap()
}

fn rate(set: &CaptureSet, shot: usize) -> ElectronRate {
    shot_electron_rate(set, shot, &wavelength_grid(set)).unwrap()
}

/// The general (full-image) path even where the uniform fast path would apply.
fn general_rate(set: &CaptureSet, shot: usize) -> ElectronRate {
    let grid = wavelength_grid(set);
    electron_rate(
        &set.camera.sensor,
        &shot_irradiance(set, shot, &grid).unwrap(),
    )
}

fn uniform_shot(radiance: Value) -> Value {
    json!({"id": "flat", "exposure_s": 0.01, "frames": ["flat.png"],
           "target": {"kind": "uniform", "radiance": radiance, "radiance_unit": "photons"}})
}

// ---------------------------------------------------------------------------------------
// Parsing, round trip, errors

#[test]
fn every_block_parses_and_round_trips_through_serialize() {
    let dir = tempfile::tempdir().unwrap();
    for generator in [false, true] {
        let cam = camera_with_every_block(generator);
        let p = dir.path().join("camera.json");
        write_json(&p, &cam);
        let a = load_camera(&p).unwrap();
        let raw = read_camera_file(&p).unwrap();
        let text = camera_file_json(&raw).unwrap();
        // The written JSON is the input (same keys and values) …
        let back: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(
            numbers_as_f64(&back),
            numbers_as_f64(&cam),
            "generator {generator}"
        );
        // … and parses to the same camera.
        let q = dir.path().join("again.json");
        std::fs::write(&q, &text).unwrap();
        let b = load_camera(&q).unwrap();
        assert_eq!(a.optics, b.optics);
        assert_eq!(a.sensor, b.sensor);
        // Blocks landed in the models.
        assert!(a.optics.effects.defocus.is_some() && a.optics.effects.lateral_color.is_some());
        assert!(a.sensor.effects.crosstalk.is_some() && a.sensor.effects.qe_shift.is_some());
        // Editing the parsed file and writing it (what diagnose does) changes the camera.
        let mut edited = raw.clone();
        edited.sensor.conversion_gain_v_per_e *= 1.1;
        edited.optics.exposure_scale = None;
        camsim_pipeline::config::write_camera_file(&q, &edited).unwrap();
        let c = load_camera(&q).unwrap();
        assert!(c.optics.effects.exposure_scale.is_none());
        assert!(
            (c.sensor.conversion_gain_v_per_e / a.sensor.conversion_gain_v_per_e - 1.1).abs()
                < 1e-12
        );
    }
    // A camera without blocks round-trips to the same text keys (nothing added).
    let cam = mono_camera(8, 8);
    let p = dir.path().join("plain.json");
    write_json(&p, &cam);
    let back: Value =
        serde_json::from_str(&camera_file_json(&read_camera_file(&p).unwrap()).unwrap()).unwrap();
    assert_eq!(numbers_as_f64(&back), numbers_as_f64(&cam));
}

/// Every JSON number as an f64 (`400` and `400.0` are the same value in a camera file).
fn numbers_as_f64(v: &Value) -> Value {
    match v {
        Value::Number(n) => json!(n.as_f64().unwrap()),
        Value::Array(a) => Value::Array(a.iter().map(numbers_as_f64).collect()),
        Value::Object(m) => Value::Object(
            m.iter()
                .map(|(k, v)| (k.clone(), numbers_as_f64(v)))
                .collect(),
        ),
        other => other.clone(),
    }
}

#[test]
fn bad_blocks_give_one_line_errors_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases: Vec<(&str, &str, Value, &str)> = vec![
        (
            "sensor",
            "crosstalk",
            json!({"fraction": 1.5}),
            "sensor.crosstalk.fraction = 1.5: must be in [0, 1)",
        ),
        (
            "sensor",
            "crosstalk",
            json!({"fraction": 0.1, "left": 0.1}),
            "sensor.crosstalk.left",
        ),
        ("sensor", "crosstalk", json!({"fractoin": 0.1}), "fractoin"),
        (
            "sensor",
            "crosstalk",
            json!({"left": 0.5, "right": 0.6}),
            "must be < 1",
        ),
        (
            "sensor",
            "hot_pixels",
            json!({"fraction": 0.1}),
            "dark_voltage_v_per_s",
        ),
        (
            "sensor",
            "hot_pixels",
            json!({"fraction": 2.0, "dark_voltage_v_per_s": 1.0}),
            "sensor.hot_pixels.fraction = 2",
        ),
        (
            "sensor",
            "nonlinearity",
            json!({"kind": "quadratic", "coefficient_per_v": -1.0}),
            "sensor.nonlinearity.coefficient_per_v = -1",
        ),
        (
            "sensor",
            "nonlinearity",
            json!({"kind": "cubic", "a": 1.0}),
            "cubic",
        ),
        (
            "sensor",
            "ir_leakage",
            json!({"channels": {"x": 0.1}}),
            "sensor.ir_leakage.channels.x: no such channel",
        ),
        (
            "sensor",
            "ir_leakage",
            json!({"channels": {"m": -0.1}}),
            "sensor.ir_leakage.channels.m = -0.1",
        ),
        (
            "sensor",
            "qe_shift",
            json!({"shift_nm": {"q": 3.0}}),
            "sensor.qe_shift.shift_nm.q",
        ),
        ("sensor", "qe_shift", json!({"shift": {"m": 3.0}}), "shift"),
        (
            "optics",
            "exposure_scale",
            json!({"factor": 0.0}),
            "optics.exposure_scale.factor = 0",
        ),
        (
            "optics",
            "veiling_glare",
            json!({"fraction": -0.1}),
            "optics.veiling_glare.fraction = -0.1",
        ),
        (
            "optics",
            "defocus",
            json!({"kind": "gaussian", "sigma": 1.0}),
            "sigma",
        ),
        (
            "optics",
            "defocus",
            json!({"kind": "box", "radius_um": 1.0}),
            "box",
        ),
        (
            "optics",
            "defocus",
            json!({"kind": "pillbox", "radius_um": -2.0}),
            "optics.defocus.radius_um = -2",
        ),
        (
            "optics",
            "distortion",
            json!({"kind": "division", "k": 1.5}),
            "optics.distortion.k = 1.5",
        ),
        (
            "optics",
            "lateral_color",
            json!({"kind": "linear"}),
            "displacement_um",
        ),
        (
            "optics",
            "relative_illumination",
            json!({"modle": "cos4"}),
            "modle",
        ),
        (
            "optics",
            "relative_illumination",
            json!({"model": "cos4", "falloff": {"kind": "two_circle", "separation_at_h1": 3.0}}),
            "optics.relative_illumination.falloff.separation_at_h1 = 3",
        ),
        (
            "optics",
            "relative_illumination",
            json!({"model": "cos5"}),
            "cos5",
        ),
        (
            "optics",
            "exposure_scale",
            json!({"factor": 1.0, "extra": 1}),
            "extra",
        ),
    ];
    for (section, key, block, want) in cases {
        let mut cam = mono_camera(8, 8);
        cam[section][key] = block.clone();
        let p = dir.path().join("camera.json");
        write_json(&p, &cam);
        let e = load_camera(&p).expect_err(&format!("{section}.{key} = {block} accepted"));
        let msg = e.one_line();
        assert!(
            msg.contains(want) && msg.contains("camera.json"),
            "{section}.{key} = {block}: `{msg}` should name `{want}`"
        );
        assert!(!e.to_string().contains('\n'), "{msg}");
    }
    // The CLI exits non-zero with one line and writes nothing.
    let mut cam = mono_camera(8, 8);
    cam["sensor"]["crosstalk"] = json!({"fraction": 1.5});
    write_json(&dir.path().join("camera.json"), &cam);
    write_json(
        &dir.path().join("captures.json"),
        &json!({"camera": "camera.json", "shots": [uniform_shot(json!(1e18))]}),
    );
    let out = crate::util::camsim()
        .args(["simulate", "captures.json", "--out", "out"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("sensor.crosstalk.fraction = 1.5"), "{err}");
    assert!(!dir.path().join("out").exists());
}

// ---------------------------------------------------------------------------------------
// Optics blocks

#[test]
fn exposure_scale_scales_the_mean_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let shots = json!([
        uniform_shot(json!({"wavelength_nm": [400, 700], "values": [1e18, 2e18]})),
        {"id": "chart", "exposure_s": 0.01, "frames": ["c.png"],
         "target": {"kind": "macbeth", "illuminant": "D65", "patch_fraction": 0.7}}
    ]);
    let mut cam = mono_camera(24, 36);
    cam["optics"]["relative_illumination"] = json!("cos4");
    let base = load(dir.path(), &cam, shots.clone(), None);
    cam["optics"]["exposure_scale"] = json!({"factor": 1.07});
    let scaled = load(dir.path(), &cam, shots, None);
    for shot in 0..2 {
        let (a, b) = (rate(&base, shot), rate(&scaled, shot));
        for (x, y) in a.electrons_per_s.iter().zip(&b.electrons_per_s) {
            assert!(
                (*y as f64 - 1.07 * *x as f64).abs() <= 1e-6 * *y as f64 + 1e-30,
                "shot {shot}: {y} vs 1.07·{x}"
            );
        }
    }
}

/// Field height of pixel (r, c) (centre / half-diagonal).
fn h_of(rows: usize, cols: usize, r: usize, c: usize) -> f64 {
    let (y, x) = (
        r as f64 - (rows as f64 - 1.0) / 2.0,
        c as f64 - (cols as f64 - 1.0) / 2.0,
    );
    x.hypot(y) / (0.5 * ((rows * rows + cols * cols) as f64).sqrt())
}

#[test]
fn relative_illumination_falloff_matches_the_analytic_vignetting() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (24, 32);
    let shots = json!([uniform_shot(json!(1e18))]);
    let mut cam = mono_camera(rows, cols);
    cam["optics"]["relative_illumination"] = json!("cos4");
    let base = load(dir.path(), &cam, shots.clone(), None);
    let s = 0.7;
    cam["optics"]["relative_illumination"] = json!({"model": "cos4",
        "falloff": {"kind": "two_circle", "separation_at_h1": s}});
    let vig = load(dir.path(), &cam, shots.clone(), None);
    // Mechanical vignetting: the lens-shaped overlap of two unit circles d = s·h apart,
    // A = 2 acos(d/2) − (d/2)√(4 − d²), F = A / π.
    let lens_area = |d: f64| 2.0 * (d / 2.0).acos() - (d / 2.0) * (4.0 - d * d).sqrt();
    for (a, b) in [
        (rate(&base, 0), rate(&vig, 0)),
        (general_rate(&base, 0), general_rate(&vig, 0)),
    ] {
        for r in 0..rows {
            for c in 0..cols {
                let i = r * cols + c;
                let want = lens_area(s * h_of(rows, cols, r, c)) / PI;
                let got = b.electrons_per_s[i] as f64 / a.electrons_per_s[i] as f64;
                assert!((got - want).abs() < 1e-5, "({r},{c}): {got} vs {want}");
            }
        }
    }
    // Fitted polynomial form: 1 + a1 h² + a2 h⁴.
    cam["optics"]["relative_illumination"] = json!({"model": "none",
        "falloff": {"kind": "polynomial", "coefficients": [-0.3, 0.1]}});
    cam["optics"]["exposure_scale"] = json!({"factor": 0.9});
    let poly = load(dir.path(), &cam, shots.clone(), None);
    cam["optics"]["relative_illumination"] = json!("none");
    cam["optics"]
        .as_object_mut()
        .unwrap()
        .remove("exposure_scale");
    let none = load(dir.path(), &cam, shots, None);
    let (a, b) = (rate(&none, 0), rate(&poly, 0));
    let h = h_of(rows, cols, 0, 0);
    let want = 0.9 * (1.0 - 0.3 * h * h + 0.1 * h.powi(4));
    assert!((b.electrons_per_s[0] as f64 / a.electrons_per_s[0] as f64 - want).abs() < 1e-5);
    // The magnitude 1 − F(1).
    let f = poly.camera.optics.effects.falloff.as_ref().unwrap();
    assert!((f.magnitude() - 0.2).abs() < 1e-12);
}

#[test]
fn veiling_glare_adds_exactly_f_times_the_mean() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (24, 32);
    let shots = json!([
        {"id": "edge", "exposure_s": 0.01, "frames": ["e.png"],
         "target": {"kind": "slanted_edge", "dark": 1e17, "light": 2e18, "angle_deg": 8.0,
                    "radiance_unit": "photons"}},
        uniform_shot(json!(1e18))
    ]);
    let mut cam = mono_camera(rows, cols);
    cam["optics"]["relative_illumination"] = json!("cos4");
    cam["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 1.0});
    let base = load(dir.path(), &cam, shots.clone(), None);
    let f = 0.05;
    cam["optics"]["veiling_glare"] = json!({"fraction": f});
    let glare = load(dir.path(), &cam, shots.clone(), None);
    // Mono sensor: the added rate is f × the mean rate over the sensor, the same at every
    // pixel (blurred edge and cos⁴ included).
    let (a, b) = (rate(&base, 0), rate(&glare, 0));
    let mean = a.electrons_per_s.iter().map(|&v| v as f64).sum::<f64>() / (rows * cols) as f64;
    for (x, y) in a.electrons_per_s.iter().zip(&b.electrons_per_s) {
        let add = *y as f64 - *x as f64;
        assert!(
            (add - f * mean).abs() < 2e-5 * mean,
            "{add} vs {}",
            f * mean
        );
    }
    // Uniform target, fast path and general path agree.
    cam["optics"]["blur"] = json!({"kind": "none"});
    let fast = load(dir.path(), &cam, shots, None);
    let (x, y) = (rate(&fast, 1), general_rate(&fast, 1));
    for (p, q) in x.electrons_per_s.iter().zip(&y.electrons_per_s) {
        assert!((p / q - 1.0).abs() < 1e-5, "{p} vs {q}");
    }
}

/// MTF of the edge spread in `rate` at `freqs` (cycles/pixel): pixels projected on the edge
/// normal in 1/4-pixel bins (|d| < 14 px, rows away from the border), differentiated, and
/// Fourier transformed directly (ISO 12233-style slanted edge).
fn edge_mtf(rate: &ElectronRate, angle_deg: f64, freqs: &[f64]) -> Vec<f64> {
    let (rows, cols) = (rate.rows, rate.cols);
    let a = angle_deg.to_radians();
    let (bin, half) = (0.25, 14.0);
    let nb = (2.0 * half / bin) as usize;
    let (mut sum, mut cnt) = (vec![0.0; nb], vec![0usize; nb]);
    for r in 6..rows - 6 {
        for c in 0..cols {
            let y = r as f64 - (rows as f64 - 1.0) / 2.0;
            let x = c as f64 - (cols as f64 - 1.0) / 2.0;
            let d = x * a.cos() + y * a.sin();
            if d.abs() < half {
                let k = ((d + half) / bin) as usize;
                sum[k] += rate.electrons_per_s[r * cols + c] as f64;
                cnt[k] += 1;
            }
        }
    }
    let esf: Vec<f64> = sum
        .iter()
        .zip(&cnt)
        .map(|(s, &n)| s / n.max(1) as f64)
        .collect();
    assert!(cnt.iter().all(|&n| n > 0), "empty ESF bin");
    let lsf: Vec<f64> = esf.windows(2).map(|w| w[1] - w[0]).collect();
    let total: f64 = lsf.iter().sum();
    freqs
        .iter()
        .map(|&f| {
            let (mut re, mut im) = (0.0, 0.0);
            for (k, v) in lsf.iter().enumerate() {
                let ph = 2.0 * PI * f * k as f64 * bin;
                re += v * ph.cos();
                im += v * ph.sin();
            }
            re.hypot(im) / total
        })
        .collect()
}

fn edge_set(dir: &Path, cam: &Value, angle: f64) -> CaptureSet {
    let shots = json!([{"id": "edge", "exposure_s": 0.01, "frames": ["e.png"],
        "target": {"kind": "slanted_edge", "dark": 1e16, "light": 1e18, "angle_deg": angle,
                   "radiance_unit": "photons"}}]);
    load(dir, cam, shots, Some(json!({"oversample": 8})))
}

#[test]
fn defocus_mtf_on_a_slanted_edge_matches_gaussian_and_disk_closed_forms() {
    let dir = tempfile::tempdir().unwrap();
    let angle = 5.0;
    let mut cam = mono_camera(64, 64);
    let base = rate(&edge_set(dir.path(), &cam, angle), 0);
    let freqs: Vec<f64> = (1..=10).map(|k| 0.05 * k as f64).collect(); // cycles/pixel
    let m0 = edge_mtf(&base, angle, &freqs);
    let p_um = 2.0;
    // Fitted form: MTF ratio = exp(−2π²σ²f²).
    let sigma = 1.6;
    cam["optics"]["defocus"] = json!({"kind": "gaussian", "sigma_um": sigma});
    let m1 = edge_mtf(&rate(&edge_set(dir.path(), &cam, angle), 0), angle, &freqs);
    for ((f, a), b) in freqs.iter().zip(&m0).zip(&m1) {
        let fu = f / p_um;
        let want = (-2.0 * PI * PI * sigma * sigma * fu * fu).exp();
        assert!(
            (b / a - want).abs() < 0.015,
            "gaussian f={f}: {} vs {want}",
            b / a
        );
    }
    // Generator form: MTF ratio = 2 J1(2πrf)/(2πrf) (J1 by its integral representation).
    let r = 2.5;
    cam["optics"]["defocus"] = json!({"kind": "pillbox", "radius_um": r});
    let m2 = edge_mtf(&rate(&edge_set(dir.path(), &cam, angle), 0), angle, &freqs);
    let j1 = |x: f64| -> f64 {
        let n = 2000;
        (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * PI / n as f64;
                (t - x * t.sin()).cos()
            })
            .sum::<f64>()
            / n as f64
    };
    for ((f, a), b) in freqs.iter().zip(&m0).zip(&m2) {
        let x = 2.0 * PI * r * f / p_um;
        // The edge MTF is a modulus: |2 J1(x)/x| (negative beyond the first zero, x = 3.83).
        let want = (2.0 * j1(x) / x).abs();
        assert!(
            (b / a - want).abs() < 0.02,
            "pillbox f={f}: {} vs {want}",
            b / a
        );
    }
    // The magnitude: σ of the least-squares Gaussian of the disk (between the small-disk
    // moment match r/2 and r).
    let set = edge_set(dir.path(), &cam, angle);
    let d = set.camera.optics.effects.defocus.unwrap();
    let s = d.equivalent_sigma_um(p_um);
    assert!(s > 0.5 * r && s < r, "{s}");
}

/// Intensity centroids (x, y in pixels from the sensor centre) of the points of `rate` within
/// `win` pixels of the predicted positions.
fn centroid_near(rate: &ElectronRate, x0: f64, y0: f64, win: f64) -> (f64, f64) {
    let (rows, cols) = (rate.rows, rate.cols);
    let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for r in 0..rows {
        for c in 0..cols {
            let y = r as f64 - (rows as f64 - 1.0) / 2.0;
            let x = c as f64 - (cols as f64 - 1.0) / 2.0;
            if (x - x0).abs() <= win && (y - y0).abs() <= win {
                let v = rate.electrons_per_s[r * cols + c] as f64;
                s += v;
                sx += v * x;
                sy += v * y;
            }
        }
    }
    (sx / s, sy / s)
}

/// Points of 1 pixel on a 15-pixel grid, seen through `cam` plus a 1-pixel Gaussian blur
/// (so that pixel-grid centroids are exact: the blurred spot has no power at 1 cycle/pixel).
fn point_set(dir: &Path, cam: &Value, radiance: Value) -> CaptureSet {
    let mut cam = cam.clone();
    cam["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 2.0});
    let cam = &cam;
    let shots = json!([{"id": "points", "exposure_s": 0.01, "frames": ["p.png"],
        "target": {"kind": "point_array", "radiance": radiance, "background": 0.0,
                   "spacing_px": 15, "point_size_px": 1, "radiance_unit": "photons"}}]);
    load(dir, cam, shots, Some(json!({"oversample": 4})))
}

#[test]
fn distortion_moves_a_point_to_h_times_d_of_h() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (96, 128);
    let half_diag = 0.5 * ((rows * rows + cols * cols) as f64).sqrt(); // 80 px
    let mut cam = mono_camera(rows, cols);
    for (block, d_of_h) in [
        (
            json!({"kind": "division", "k": 0.12}),
            Box::new(|h: f64| 1.0 / (1.0 - 0.12 * h * h)) as Box<dyn Fn(f64) -> f64>,
        ),
        (
            json!({"kind": "polynomial", "k1": -0.08, "k2": 0.01}),
            Box::new(|h: f64| 1.0 - 0.08 * h * h + 0.01 * h.powi(4)),
        ),
    ] {
        cam["optics"]["distortion"] = block.clone();
        let set = point_set(dir.path(), &cam, json!(1e18));
        let rt = rate(&set, 0);
        // Scene points at multiples of 15 px from the axis (the central point on the axis).
        for (xs, ys) in [
            (45.0, 30.0),
            (-45.0, -30.0),
            (30.0, -15.0),
            (-45.0, 15.0),
            (0.0, 0.0),
        ] {
            let h: f64 = f64::hypot(xs, ys) / half_diag;
            let d = d_of_h(h);
            let (xi, yi) = (xs * d, ys * d);
            let (cx, cy) = centroid_near(&rt, xi, yi, 5.0);
            // Tolerance 0.02 px (displacements here: 0–2.6 px): bilinear resampling of the sharp
            // 1-pixel square on the 1/4-pixel scene grid moves its centroid by < 0.01 px.
            assert!(
                (cx - xi).abs() < 0.02 && (cy - yi).abs() < 0.02,
                "{block} point ({xs},{ys}) h={h:.3}: centroid ({cx:.3},{cy:.3}) vs h·D(h) → ({xi:.3},{yi:.3})"
            );
        }
        let fx = &set.camera.optics.effects;
        assert!((fx.distortion.unwrap().magnitude() - (d_of_h(1.0) - 1.0)).abs() < 1e-12);
    }
}

#[test]
fn lateral_color_displaces_650_nm_against_450_nm_by_d_at_the_corner() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (96, 128);
    let half_diag = 0.5 * ((rows * rows + cols * cols) as f64).sqrt();
    let p_um = 2.0;
    let narrow =
        |l: f64| json!({"wavelength_nm": [l - 10.0, l, l + 10.0], "values": [0.0, 1e18, 0.0]});
    for (kind, d_um) in [("linear", 3.0), ("cauchy", -4.0)] {
        let mut cam = mono_camera(rows, cols);
        cam["optics"]["lateral_color"] = json!({"kind": kind, "displacement_um": d_um});
        let red = rate(&point_set(dir.path(), &cam, narrow(650.0)), 0);
        let blue = rate(&point_set(dir.path(), &cam, narrow(450.0)), 0);
        // Points at h = 0.68 and 0.53 (the displacement is h·d: d at the corner, h = 1).
        for (xs, ys) in [(45.0, 30.0), (-45.0, -30.0), (-30.0, 30.0)] {
            let r = f64::hypot(xs, ys);
            let h = r / half_diag;
            let (rx, ry) = centroid_near(&red, xs, ys, 5.0);
            let (bx, by) = centroid_near(&blue, xs, ys, 5.0);
            // Radial component of the 650 − 450 displacement (µm) = h·d; no tangential part.
            let (ux, uy) = (xs / r, ys / r);
            let radial = ((rx - bx) * ux + (ry - by) * uy) * p_um;
            let tangential = ((rx - bx) * -uy + (ry - by) * ux) * p_um;
            assert!(
                (radial - h * d_um).abs() < 0.04,
                "{kind} ({xs},{ys}) h={h:.3}: {radial:.4} µm vs h·d = {:.4}",
                h * d_um
            );
            assert!(tangential.abs() < 0.04, "{tangential}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// Sensor blocks through the camera file

#[test]
fn qe_shift_via_camera_json_equals_shifted_curves() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera_with_every_block(false);
    for k in [
        "exposure_scale",
        "veiling_glare",
        "defocus",
        "distortion",
        "lateral_color",
    ] {
        cam["optics"].as_object_mut().unwrap().remove(k);
    }
    for k in [
        "hot_pixels",
        "nonlinearity",
        "crosstalk",
        "ir_leakage",
        "qe_shift",
    ] {
        cam["sensor"].as_object_mut().unwrap().remove(k);
    }
    cam["optics"]["relative_illumination"] = json!("none");
    let shots = json!([{"id": "chart", "exposure_s": 0.01, "frames": ["c.png"],
        "target": {"kind": "macbeth", "illuminant": "D65", "patch_fraction": 0.8}}]);
    let mut shifted = cam.clone();
    shifted["sensor"]["qe_shift"] = json!({"shift_nm": {"r": 6.0, "b": -3.0}});
    let mut moved = cam.clone();
    moved["sensor"]["channels"]["r"]["wavelength_nm"] = json!([406, 586, 706]);
    moved["sensor"]["channels"]["b"]["wavelength_nm"] = json!([397, 457, 697]);
    let a = rate(&load(dir.path(), &shifted, shots.clone(), None), 0);
    let b = rate(&load(dir.path(), &moved, shots.clone(), None), 0);
    let c = rate(&load(dir.path(), &cam, shots, None), 0);
    let mut changed = 0;
    for ((x, y), z) in a
        .electrons_per_s
        .iter()
        .zip(&b.electrons_per_s)
        .zip(&c.electrons_per_s)
    {
        assert!((x - y).abs() <= 1e-5 * y.abs() + 1e-3, "{x} vs {y}");
        if (x - z).abs() > 1e-3 * z.abs() {
            changed += 1;
        }
    }
    assert!(changed > 100, "the shift changes the red and blue pixels");
}

#[test]
fn ir_leakage_via_camera_json_adds_the_closed_form_and_extends_the_grid() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = mono_camera(8, 8);
    // Photon radiance L = 1e18 from 400 to 1100 nm; no fall-off, T = 1.
    let l = 1e18;
    let shots = json!([uniform_shot(
        json!({"wavelength_nm": [400, 1100], "values": [l, l]})
    )]);
    let base = load(dir.path(), &cam, shots.clone(), None);
    let v = 0.03;
    cam["sensor"]["ir_leakage"] = json!({"channels": {"m": v}});
    let ir = load(dir.path(), &cam, shots, None);
    let (a, b) = (rate(&base, 0), rate(&ir, 0));
    // Δe/s = p² · FF · π/(4N²) · L · v · 301 nm (plateau 300 nm + two 1 nm ramps).
    let want = 4e-12 * 0.5 * PI / 16.0 * l * v * 301.0;
    let got = (b.electrons_per_s[27] - a.electrons_per_s[27]) as f64;
    assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
    let g = wavelength_grid(&ir);
    assert!(*g.wavelength_nm.last().unwrap() >= 1000.0);
    assert!(
        (ir.camera
            .sensor
            .effects
            .ir_leakage
            .as_ref()
            .unwrap()
            .magnitude()
            - v)
            .abs()
            < 1e-12
    );
}

#[test]
fn crosstalk_via_camera_json_flat_field_interior_unchanged_corner_loses() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = mono_camera(8, 8);
    let shots = json!([uniform_shot(json!(1e18))]);
    let a = rate(&load(dir.path(), &cam, shots.clone(), None), 0);
    cam["sensor"]["crosstalk"] = json!({"fraction": 0.08});
    let b = rate(&load(dir.path(), &cam, shots, None), 0);
    assert!((b.electrons_per_s[27] / a.electrons_per_s[27] - 1.0).abs() < 1e-6);
    assert!((b.electrons_per_s[0] / a.electrons_per_s[0] - 0.96).abs() < 1e-6);
    assert!((b.electrons_per_s[1] / a.electrons_per_s[1] - 0.98).abs() < 1e-6);
}

/// Mean of an `--expected` EXR written by `camsim simulate`.
fn read_expected(path: &Path) -> Vec<f32> {
    let (_, _, chans, _) = camsim_core::exr_io::read_channels(path).unwrap();
    chans.into_iter().find(|c| c.0 == "Y").unwrap().1
}

#[test]
fn expected_images_reflect_every_mean_effect_and_omit_hot_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let (rows, cols) = (24, 32);
    let shots = json!([
        {"id": "chart", "exposure_s": 0.004, "frames": ["c.png"],
         "target": {"kind": "macbeth", "illuminant": "D65", "patch_fraction": 0.7,
                    "mean_luminance_cd_m2": 300.0}},
        {"id": "nir", "exposure_s": 0.004, "frames": ["n.png"],
         "target": {"kind": "uniform", "radiance_unit": "photons",
                    "radiance": {"wavelength_nm": [400, 1100], "values": [1e16, 1e16]}}}
    ]);
    let mut base = mono_camera(rows, cols);
    base["sensor"]["cfa"] = json!(["gr", "bg"]);
    base["sensor"]["channels"] = json!({
        "r": {"wavelength_nm": [400, 580, 700], "values": [0.0, 0.1, 0.4]},
        "g": {"wavelength_nm": [400, 530, 700], "values": [0.05, 0.6, 0.05]},
        "b": {"wavelength_nm": [400, 460, 700], "values": [0.5, 0.4, 0.0]}
    });
    base["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 1.0});
    let run = |cam: &Value, name: &str| -> Vec<Vec<f32>> {
        let d = dir.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        let set = load(&d, cam, shots.clone(), None);
        camsim_pipeline::simulate::simulate(
            &set,
            &camsim_pipeline::simulate::SimulateOptions {
                out_dir: d.join("out"),
                seed: 1,
                expected: true,
                progress: false,
            },
        )
        .unwrap();
        ["chart", "nir"]
            .iter()
            .map(|s| read_expected(&d.join(format!("out/{s}.exr"))))
            .collect()
    };
    let reference = run(&base, "base");
    let mean_blocks: Vec<(&str, &str, Value)> = vec![
        ("optics", "exposure_scale", json!({"factor": 1.05})),
        (
            "optics",
            "relative_illumination",
            json!({"model": "none", "falloff": {"kind": "polynomial", "coefficients": [-0.2]}}),
        ),
        ("optics", "veiling_glare", json!({"fraction": 0.03})),
        (
            "optics",
            "defocus",
            json!({"kind": "gaussian", "sigma_um": 2.0}),
        ),
        (
            "optics",
            "distortion",
            json!({"kind": "division", "k": 0.05}),
        ),
        (
            "optics",
            "lateral_color",
            json!({"kind": "linear", "displacement_um": 3.0}),
        ),
        ("sensor", "crosstalk", json!({"fraction": 0.05})),
        ("sensor", "ir_leakage", json!({"channels": {"r": 0.05}})),
        ("sensor", "qe_shift", json!({"shift_nm": {"g": 5.0}})),
        (
            "sensor",
            "nonlinearity",
            json!({"kind": "quadratic", "coefficient_per_v": 0.2}),
        ),
    ];
    for (section, key, block) in mean_blocks {
        let mut cam = base.clone();
        cam[section][key] = block;
        let out = run(&cam, key);
        let max_diff = out
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
            .fold(0f32, f32::max);
        assert!(
            max_diff > 0.5,
            "{key}: --expected unchanged (max |Δ| {max_diff} DN)"
        );
    }
    // Fixed patterns are not part of the expected image.
    for (key, block) in [
        (
            "hot_pixels",
            json!({"fraction": 0.05, "dark_voltage_v_per_s": 1.0}),
        ),
        ("column_fpn", json!({"sigma_v": 0.01})),
    ] {
        let mut cam = base.clone();
        cam["sensor"][key] = block;
        assert_eq!(run(&cam, key), reference, "{key}");
    }
}

#[test]
fn nonlinearity_and_hot_pixels_in_simulated_frames() {
    // Frames with every random term off: DN = round(expected) except at hot pixels, which
    // carry t·V_hot more volts; the nonlinearity compresses exactly as v − a v².
    let dir = tempfile::tempdir().unwrap();
    let mut cam = mono_camera(16, 16);
    cam["sensor"]["noise"] =
        json!({"shot": false, "dark": false, "read": false, "dsnu": false, "prnu": false});
    cam["sensor"]["dark_voltage_v_per_s"] = json!(0.0);
    let a = 0.3;
    cam["sensor"]["nonlinearity"] = json!({"kind": "quadratic", "coefficient_per_v": a});
    cam["sensor"]["hot_pixels"] = json!({"fraction": 0.05, "dark_voltage_v_per_s": 2.0});
    let shots = json!([uniform_shot(json!(1e16))]);
    let set = load(dir.path(), &cam, shots, None);
    let s = &set.camera.sensor;
    let rt = rate(&set, 0);
    let t = 0.01;
    let e = expected_dn(s, &rt, &Shot::new(s, t));
    let v = rt.electrons_per_s[0] as f64 * t * 5e-5;
    assert!((e[0] as f64 - (64.0 + 4095.0 * (v - a * v * v))).abs() < 1e-3);
    camsim_pipeline::simulate::simulate(
        &set,
        &camsim_pipeline::simulate::SimulateOptions {
            out_dir: dir.path().join("out"),
            seed: 9,
            expected: false,
            progress: false,
        },
    )
    .unwrap();
    let img = image::open(dir.path().join("out/flat.png"))
        .unwrap()
        .to_luma16();
    let hot = camsim_sensor::hot_pixel_map(s, 9);
    assert_eq!(hot.len(), 13); // round(0.05 · 256)
    for (i, px) in img.pixels().enumerate() {
        let (r, c) = (i / 16, i % 16);
        let is_hot = hot
            .iter()
            .any(|h| h.row as usize == r && h.col as usize == c);
        let n_v = rt.electrons_per_s[i] as f64 * t * 5e-5 + if is_hot { t * 2.0 } else { 0.0 };
        let want = (64.0 + 4095.0 * (n_v - a * n_v * n_v)).round();
        assert_eq!(px.0[0] as f64, want, "pixel ({r},{c}) hot={is_hot}");
    }
}

// ---------------------------------------------------------------------------------------
// The concealed-effect generator (`camsim demo diagnose`)

use camsim_pipeline::demo::{generate_capture_set, Concealment, DemoSpec, EFFECT_IDS};

fn demo_spec(effects: &[(&str, f64)], concealment: Concealment, seed: u64) -> DemoSpec {
    DemoSpec {
        effects: effects.iter().map(|(i, m)| (i.to_string(), *m)).collect(),
        concealment,
        rows: 32,
        cols: 48,
        seed,
    }
}

/// A requested magnitude per effect id (effects.md units).
fn demo_magnitude(id: &str) -> f64 {
    match id {
        "exposure_scale" => 1.08,
        "conversion_gain" => 0.9,
        "black_level" => 6.5,
        "dark_current" => 0.02,
        "read_noise" => 2.0e-3,
        "dsnu" => 2.0e-3,
        "prnu" => 2.0,
        "column_fpn" => 1.0e-3,
        "hot_pixels" => 0.004,
        "nonlinearity" => 0.06,
        "full_well" => 7000.0,
        "relative_illumination" => 0.25,
        "veiling_glare" => 0.03,
        "defocus" => 1.5,
        "crosstalk" => 0.05,
        "ir_leakage" => 0.03,
        "qe_shift" => -6.0,
        "distortion" => -0.04,
        "lateral_color" => 2.5,
        "row_noise" => 4.0e-4,
        "rtn" => 0.006,
        "black_level_drift" => 6.0,
        "dark_temperature" => 6.0,
        _ => unreachable!(),
    }
}

fn read_truth(dir: &Path) -> Vec<(String, f64)> {
    let v: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["effect"].as_str().unwrap().to_string(),
                e["magnitude"].as_f64().unwrap(),
            )
        })
        .collect()
}

#[test]
fn demo_generates_every_effect_with_its_true_magnitude() {
    let root = tempfile::tempdir().unwrap();
    for id in EFFECT_IDS {
        let m = demo_magnitude(id);
        let dir = root.path().join(id);
        let truth = generate_capture_set(&demo_spec(&[(id, m)], Concealment::None, 3), &dir)
            .unwrap_or_else(|e| panic!("{id}: {e}"));
        assert_eq!(truth.captures_json, dir.join("captures.json"));
        // truth.json holds what the function returned.
        let file = read_truth(&dir);
        assert_eq!(file.len(), 1);
        assert_eq!(file[0].0, id);
        // (serde_json's default float parsing may differ in the last bit)
        assert!((file[0].1 - truth.effects[0].magnitude).abs() <= 1e-14 * file[0].1.abs());
        let got = truth.effects[0].magnitude;
        // Solved generator parameters reproduce the request; drawn patterns are realised
        // values (hot and RTN pixels: round(f·N)/N; column offsets: sample σ of 48 columns).
        let tol = match id {
            "hot_pixels" | "rtn" => 0.5 / (32.0 * 48.0),
            "column_fpn" => 0.35 * m,
            _ => 1e-6 * m.abs(),
        };
        assert!((got - m).abs() <= tol, "{id}: truth {got} vs requested {m}");
        // The set parses, its camera is the believed one (no effect blocks), and every frame
        // is there with the sensor's size.
        let set = load_captures(&truth.captures_json, None).unwrap();
        assert!(set.camera.optics.effects.is_empty() && set.camera.sensor.effects.is_empty());
        assert_eq!(set.camera.sensor.channel_names, ["b", "g", "r"]);
        for shot in &set.shots {
            for f in &shot.frames {
                let img = image::open(dir.join(f)).unwrap().to_luma16();
                assert_eq!((img.height(), img.width()), (32, 48), "{id} {f}");
            }
        }
        // No staging or true-camera file is left behind.
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .collect();
        assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
    }
}

#[test]
fn demo_null_set_is_the_believed_camera_exactly_and_effects_change_the_frames() {
    let root = tempfile::tempdir().unwrap();
    let null = root.path().join("null");
    let t = generate_capture_set(&demo_spec(&[], Concealment::None, 7), &null).unwrap();
    assert!(t.effects.is_empty() && read_truth(&null).is_empty());
    // Re-simulating the set with its own (believed) camera and seed gives the same frames.
    let set = load_captures(&t.captures_json, None).unwrap();
    let again = root.path().join("again");
    camsim_pipeline::simulate::simulate(
        &set,
        &camsim_pipeline::simulate::SimulateOptions {
            out_dir: again.clone(),
            seed: 7,
            expected: false,
            progress: false,
        },
    )
    .unwrap();
    for shot in &set.shots {
        for f in &shot.frames {
            assert_eq!(
                std::fs::read(null.join(f)).unwrap(),
                std::fs::read(again.join(f)).unwrap(),
                "{f}"
            );
        }
    }
    // Deterministic in the seed; another seed gives other frames.
    let same = root.path().join("same");
    generate_capture_set(&demo_spec(&[], Concealment::None, 7), &same).unwrap();
    let other = root.path().join("other");
    generate_capture_set(&demo_spec(&[], Concealment::None, 8), &other).unwrap();
    let f = &set.shots[3].frames[0];
    assert_eq!(
        std::fs::read(null.join(f)).unwrap(),
        std::fs::read(same.join(f)).unwrap()
    );
    assert_ne!(
        std::fs::read(null.join(f)).unwrap(),
        std::fs::read(other.join(f)).unwrap()
    );
    // With exposure_scale = 1.1 the flats' mean signal above black rises by 1.1 (same seed:
    // the noise is common; tolerance from the shot noise of ~1500 pixels).
    let fx = root.path().join("fx");
    generate_capture_set(
        &demo_spec(&[("exposure_scale", 1.1)], Concealment::None, 7),
        &fx,
    )
    .unwrap();
    let mean = |p: &Path| -> f64 {
        let img = image::open(p).unwrap().to_luma16();
        img.pixels().map(|p| p.0[0] as f64 - 64.0).sum::<f64>() / (32.0 * 48.0)
    };
    let flat = "raw/flat-50-0.png";
    let ratio = mean(&fx.join(flat)) / mean(&null.join(flat));
    assert!((ratio - 1.1).abs() < 0.01, "{ratio}");
}

#[test]
fn demo_concealment_variants_shape_the_capture_set() {
    let root = tempfile::tempdir().unwrap();
    let shots = |c: Concealment, fx: &[(&str, f64)]| -> Vec<(String, Value, usize)> {
        let dir = root.path().join(format!("{c:?}-{}", fx.len()));
        let t = generate_capture_set(&demo_spec(fx, c, 5), &dir).unwrap();
        let v: Value =
            serde_json::from_str(&std::fs::read_to_string(&t.captures_json).unwrap()).unwrap();
        load_captures(&t.captures_json, None).unwrap(); // parses (image targets included)
        v["shots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| {
                (
                    s["id"].as_str().unwrap().to_string(),
                    s["target"].clone(),
                    s["frames"].as_array().unwrap().len(),
                )
            })
            .collect()
    };
    let count = |s: &[(String, Value, usize)], kind: &str| -> usize {
        s.iter().filter(|x| x.1["kind"] == kind).map(|x| x.2).sum()
    };
    let none = shots(Concealment::None, &[("prnu", 1.0)]);
    // Default: darks at 3 exposures with repeats, ≥ 5 flat levels × 2, two charts, edge, points.
    assert!(count(&none, "dark") >= 9 && count(&none, "uniform") >= 10);
    assert_eq!(count(&none, "macbeth"), 2);
    assert!(count(&none, "slanted_edge") >= 1 && count(&none, "point_array") >= 1);
    // Below noise: more repeats of everything.
    let below = shots(Concealment::BelowNoise, &[("prnu", 0.2)]);
    assert!(count(&below, "uniform") >= 2 * count(&none, "uniform"));
    assert!(count(&below, "dark") >= 2 * count(&none, "dark"));
    // Under the scene: no flat field.
    let under = shots(Concealment::UnderScene, &[("relative_illumination", 0.2)]);
    assert_eq!(count(&under, "uniform"), 0);
    assert!(count(&under, "macbeth") >= 4);
    // Mimicked conversion gain: an exposure series of flats with ≥ 4 repeats per level,
    // no charts (their means would scale alike too).
    let mim = shots(Concealment::Mimicked, &[("conversion_gain", 1.1)]);
    let flats: Vec<&(String, Value, usize)> =
        mim.iter().filter(|x| x.1["kind"] == "uniform").collect();
    assert!(flats.len() >= 5 && flats.iter().all(|x| x.2 >= 4));
    assert_eq!(count(&mim, "macbeth"), 0);
    // Mimicked vignetting: a scene whose own radiance falls off radially, no flat field.
    let mim = shots(
        Concealment::Mimicked,
        &[("relative_illumination", 0.2), ("prnu", 1.0)],
    );
    assert!(count(&mim, "image") >= 1);
    // Charts (the 12 MP benchmark's set): the default dark and flat series, three charts
    // (two illuminants, two levels), no edge or points.
    let ch = shots(Concealment::Charts, &[]);
    assert_eq!(count(&ch, "dark"), count(&none, "dark"));
    assert_eq!(count(&ch, "uniform"), count(&none, "uniform"));
    assert_eq!(count(&ch, "macbeth"), 3);
    assert_eq!(count(&ch, "slanted_edge") + count(&ch, "point_array"), 0);
    let ids: Vec<&str> = ch.iter().map(|x| x.0.as_str()).collect();
    for id in ["chart-d65-35", "chart-d65-70", "chart-a-70"] {
        assert!(ids.contains(&id), "{id} missing from {ids:?}");
    }
}

#[test]
fn demo_cli_writes_the_set_and_rejects_bad_effects_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = crate::util::camsim()
        .args([
            "demo",
            "diagnose",
            "--effect",
            "veiling_glare=0.02",
            "--conceal",
            "under-scene",
            "--rows",
            "24",
            "--cols",
            "32",
            "--seed",
            "4",
            "--out",
            "set",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        read_truth(&dir.path().join("set")),
        [("veiling_glare".to_string(), 0.02)]
    );
    // The set simulates with `camsim simulate --expected`.
    let out = crate::util::camsim()
        .args([
            "simulate",
            "set/captures.json",
            "--expected",
            "--out",
            "exp",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (args, want) in [
        (vec!["--effect", "vignette=0.2"], "unknown effect id"),
        (vec!["--effect", "crosstalk=lots"], "not a number"),
        (vec!["--effect", "crosstalk"], "ID=MAGNITUDE"),
        (vec!["--effect", "crosstalk=1.5"], "crosstalk=1.5"),
    ] {
        let mut a = vec!["demo", "diagnose", "--out", "bad"];
        a.extend(args);
        let out = crate::util::camsim()
            .args(&a)
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(want), "{a:?}: {err}");
        assert!(!dir.path().join("bad").exists());
    }
}
