//! Time within the exposure through the pipeline: the rolling-shutter study
//! (examples/study_rolling_shutter/spec_edge_ci.json: skew of a moving edge and LED flicker band
//! period measured on simulated frames against `v · row_time` and `(1/f)/row_time`), the
//! camera and shot keys (one-line errors), and the dark-current temperature law through
//! `camera.json`.
use crate::util::{camsim, camsim_ok, num, repo, study_rows};
use camsim_pipeline::config::{camera_from_file, CameraFile};
use serde_json::{json, Value};
use std::path::Path;

#[test]
fn rolling_shutter_study_measures_skew_and_flicker_period() {
    let dir = tempfile::tempdir().unwrap();
    let spec = repo().join("examples/study_rolling_shutter/spec_edge_ci.json");
    let rows = &study_rows(&spec, dir.path());
    assert_eq!(rows.len(), 2, "two exposure times");
    for r in rows {
        // Skew: v · row_time · (rows − 1) = 2000 px/s · 20 µs · 199.
        let (m, e, tol) = (
            num(r, "skew_px_measured"),
            num(r, "skew_px_expected"),
            num(r, "skew_px_tolerance"),
        );
        assert!((e - 2000.0 * 20e-6 * 199.0).abs() < 1e-9, "{e}");
        // The tolerance is 5 standard errors from the noise plus the model's PWM bias; it must
        // be small enough to tell the skew from none.
        assert!(tol < 0.1 * e, "skew tolerance {tol} too loose for {e}");
        assert!(
            (m - e).abs() <= tol,
            "skew measured {m} expected {e} ± {tol}"
        );
        // Flicker: (1/1000 Hz) / 20 µs = 50 rows.
        let (m, e, tol) = (
            num(r, "flicker_period_rows_measured"),
            num(r, "flicker_period_rows_expected"),
            num(r, "flicker_period_rows_tolerance"),
        );
        assert!((e - 50.0).abs() < 1e-9, "{e}");
        assert!(tol < 0.05 * e, "period tolerance {tol} too loose for {e}");
        assert!(
            (m - e).abs() <= tol,
            "period measured {m} expected {e} ± {tol}"
        );
    }
    // Band visibility from the closed form: 0.3 ms = 0.3 periods > D = 0.2: (0.2 − 0.0)/(0.2);
    // 2.5 ms = 2.5 periods: (0.6 − 0.4)/(0.6 + 0.4).
    assert!((num(&rows[0], "flicker_visibility_expected") - 1.0).abs() < 1e-12);
    assert!((num(&rows[1], "flicker_visibility_expected") - 0.2).abs() < 1e-12);
}

#[test]
fn rolling_shutter_study_on_a_moving_gltf_bar() {
    let dir = tempfile::tempdir().unwrap();
    let spec = repo().join("examples/study_rolling_shutter/spec_ci.json");
    let t0 = std::time::Instant::now();
    let rows = &study_rows(&spec, dir.path());
    eprintln!("study: {:.1} s", t0.elapsed().as_secs_f64());
    assert_eq!(rows.len(), 2, "two exposure times");
    // Closed form of the bar's image velocity: a pinhole camera whose 30° vertical field spans
    // the 200 rows (blur none: no margin, one sample per pixel): f_px = 100 / tan 15°; the bar
    // moves at 8 m/s in the plane 2 m away: v = 8 · f_px / 2 px/s.
    let v = 8.0 * (100.0 / 15f64.to_radians().tan()) / 2.0;
    let row_time = 20e-6;
    for r in rows {
        assert!(
            (num(r, "image_velocity_px_per_s") - v).abs() < 1e-3 * v,
            "{r}"
        );
        let (m, e, tol) = (
            num(r, "skew_px_measured"),
            num(r, "skew_px_expected"),
            num(r, "skew_px_tolerance"),
        );
        assert!((e - v * row_time * 199.0).abs() < 1e-2, "{e}");
        assert!(tol < 0.1 * e, "skew tolerance {tol} too loose for {e}");
        assert!(
            (m - e).abs() <= tol,
            "skew measured {m} expected {e} ± {tol}"
        );
        let (m, e, tol) = (
            num(r, "flicker_period_rows_measured"),
            num(r, "flicker_period_rows_expected"),
            num(r, "flicker_period_rows_tolerance"),
        );
        assert!((e - 50.0).abs() < 1e-9, "{e}");
        assert!(tol < 0.05 * e, "period tolerance {tol} too loose for {e}");
        assert!(
            (m - e).abs() <= tol,
            "period measured {m} expected {e} ± {tol}"
        );
        // video, 240 Hz: the bar advances v/240 px per frame
        let (m, e, tol) = (
            num(r, "bar_advance_px_per_frame_measured"),
            num(r, "bar_advance_px_per_frame_expected"),
            num(r, "bar_advance_px_per_frame_tolerance"),
        );
        assert!((e - v / 240.0).abs() < 1e-4 * e, "{e}"); // v from an f32 projection
        assert!(tol < 0.1 * e, "advance tolerance {tol} too loose for {e}");
        assert!(
            (m - e).abs() <= tol,
            "advance measured {m} expected {e} ± {tol}"
        );
        // the bands drift by ((1/240 s) mod 1 ms) / 20 µs = 8.33 rows per frame
        let (m, e, tol) = (
            num(r, "band_drift_rows_measured"),
            num(r, "band_drift_rows_expected"),
            num(r, "band_drift_rows_tolerance"),
        );
        assert!((e - (1.0 / 240.0 - 4e-3) / row_time).abs() < 1e-6, "{e}");
        assert!(tol < 0.1 * 50.0, "drift tolerance {tol} too loose");
        let d = (m - e).rem_euclid(50.0);
        assert!(
            d.min(50.0 - d) <= tol,
            "drift measured {m} expected {e} ± {tol}"
        );
    }
    // the numbered frames of each point
    let points: Vec<_> = std::fs::read_dir(dir.path().join("points"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(points.len(), 2);
    for p in points {
        for f in ["frame_000.png", "frame_001.png"] {
            assert!(p.join(f).is_file(), "{} missing in {}", f, p.display());
        }
    }
}

fn camera(sensor_extra: Value) -> Value {
    let mut c = json!({
        "name": "t",
        "optics": {"f_number": 2.0, "focal_length_mm": 4.0, "relative_illumination": "none",
                   "blur": {"kind": "none"}},
        "sensor": {"rows": 8, "cols": 8, "pixel_pitch_um": 2.0, "cfa": ["m"],
                   "channels": {"m": 0.5}, "well_capacity_e": 1e4,
                   "conversion_gain_v_per_e": 1e-4, "voltage_swing_v": 1.0, "adc_bits": 12,
                   "dark_voltage_v_per_s": 2e-3}
    });
    for (k, v) in sensor_extra.as_object().unwrap() {
        c["sensor"][k] = v.clone();
    }
    c
}

fn load(c: Value) -> Result<camsim_pipeline::config::Camera, String> {
    let f: CameraFile = serde_json::from_value(c).map_err(|e| e.to_string())?;
    camera_from_file(Path::new("camera.json"), f).map_err(|e| e.one_line())
}

#[test]
fn dark_current_follows_the_doubling_temperature_through_camera_json() {
    let base = load(camera(json!({}))).unwrap().sensor.dark_voltage_v_per_s;
    for (t, factor) in [(25.0, 1.0), (31.0, 2.0), (43.0, 8.0), (19.0, 0.5)] {
        let s = load(camera(
            json!({"temperature_c": t, "dark_reference_temperature_c": 25.0,
                                   "dark_doubling_temperature_c": 6.0}),
        ))
        .unwrap()
        .sensor;
        assert!(
            (s.dark_voltage_v_per_s - factor * base).abs() < 1e-15,
            "T = {t}: {} vs {}",
            s.dark_voltage_v_per_s,
            factor * base
        );
    }
    let e = load(camera(json!({"temperature_c": 30.0}))).unwrap_err();
    assert!(e.contains("sensor.temperature_c"), "{e}");
    let e = load(camera(
        json!({"temperature_c": 30.0, "dark_reference_temperature_c": 25.0,
                               "dark_doubling_temperature_c": 0.0}),
    ))
    .unwrap_err();
    assert!(e.contains("dark_doubling_temperature_c"), "{e}");
}

#[test]
fn readout_and_shot_time_keys_are_checked() {
    let c = load(camera(
        json!({"readout": {"mode": "rolling", "row_time_us": 15}}),
    ))
    .unwrap();
    assert_eq!(c.readout.mode, camsim_sensor::ShutterMode::Rolling);
    assert!((c.readout.row_time_s - 15e-6).abs() < 1e-18);
    assert_eq!(
        load(camera(json!({}))).unwrap().readout,
        camsim_sensor::Readout::default()
    );
    let e = load(camera(json!({"readout": {"mode": "diagonal"}}))).unwrap_err();
    assert!(
        e.contains("sensor.readout.mode") && e.contains("diagonal"),
        "{e}"
    );
    let e = load(camera(json!({"readout": {"mode": "rolling"}}))).unwrap_err();
    assert!(e.contains("sensor.readout.row_time_us"), "{e}");
    // Shot keys: a duty cycle of 0 is named with its shot.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("camera.json"),
        camera(json!({})).to_string(),
    )
    .unwrap();
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "a", "exposure_s": 0.01, "frames": ["a.png"], "target": {"kind": "dark"},
         "light_modulation": {"frequency_hz": 100, "duty_cycle": 0.0}}]});
    let p = dir.path().join("captures.json");
    std::fs::write(&p, caps.to_string()).unwrap();
    let e = camsim_pipeline::config::load_captures(&p, None)
        .unwrap_err()
        .one_line();
    assert!(
        e.contains("shots[0] (a)") && e.contains("duty_cycle"),
        "{e}"
    );
}

/// Row-major DN of a single-channel 16-bit PNG.
fn read_gray16(p: &Path) -> (usize, usize, Vec<f64>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
    let v = buf[..info.buffer_size()]
        .chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]) as f64)
        .collect();
    (info.height as usize, info.width as usize, v)
}

#[test]
fn simulate_writes_a_video_whose_bands_drift_and_edge_advances() {
    use camsim_metrics::rolling_shutter::{edge_skew_fit, phase_at_period, row_edge_positions_px};
    use camsim_sensor::{PwmLight, Readout, ShutterMode, TimeModel};
    // the edge study's camera at 200 × 96, a 240 Hz video of three frames
    let dir = tempfile::tempdir().unwrap();
    let mut cam: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_rolling_shutter/camera.json"))
            .unwrap(),
    )
    .unwrap();
    cam["sensor"]["rows"] = json!(200);
    cam["sensor"]["cols"] = json!(96);
    std::fs::write(dir.path().join("camera.json"), cam.to_string()).unwrap();
    let (f_led, duty, fr, v, row_time, exposure) = (1000.0, 0.2, 240.0, 2000.0, 20e-6, 3e-4);
    let frames: Vec<String> = (0..3).map(|k| format!("video/f{k:03}.png")).collect();
    let caps = json!({"camera": "camera.json", "shots": [{
        "id": "video", "exposure_s": exposure, "frames": frames, "frame_rate_hz": fr,
        "target": {"kind": "slanted_edge", "dark": 3e15, "light": 3e16, "angle_deg": 0.0,
                   "radiance_unit": "photons"},
        "light_modulation": {"frequency_hz": f_led, "duty_cycle": duty, "phase": 0.0},
        "motion": {"velocity_px_per_s": [v, 0.0]}}]});
    let p = dir.path().join("captures.json");
    std::fs::write(&p, caps.to_string()).unwrap();
    let out = dir.path().join("out");
    camsim_ok(camsim().args([
        "simulate",
        p.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]));
    let black = 64.0;
    let period = (1.0 / f_led) / row_time; // 50 rows
    let (rows, cols) = (200, 96);
    let k = 12; // reference columns each side
    let r_mid = (rows - 1) as f64 / 2.0;
    let model = |frame: usize| TimeModel {
        readout: Readout {
            mode: ShutterMode::Rolling,
            row_time_s: row_time,
        },
        light: Some(PwmLight {
            frequency_hz: f_led,
            duty_cycle: duty,
            phase: (-f_led * frame as f64 / fr).rem_euclid(1.0),
        }),
        motion: None,
    };
    let mut phases = Vec::new();
    let mut centres = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let (h, w, dn) = read_gray16(&out.join(f));
        assert_eq!((h, w), (rows, cols));
        let x: Vec<f64> = dn.iter().map(|d| d - black).collect();
        // bands: row means of the light (right) side; their noise from the spread within rows
        let (mut means, mut var) = (Vec::new(), 0.0);
        for r in 0..rows {
            let s = &x[r * cols + cols - k..(r + 1) * cols];
            let m = s.iter().sum::<f64>() / k as f64;
            var += s.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (k as f64 - 1.0) / k as f64;
            means.push(m);
        }
        var /= rows as f64;
        let mean = means.iter().sum::<f64>() / rows as f64;
        // amplitude of the fundamental: 2 |DTFT at the band frequency| / N
        let (mut re, mut im) = (0.0, 0.0);
        for (r, m) in means.iter().enumerate() {
            let a = 2.0 * std::f64::consts::PI * r as f64 / period;
            re += (m - mean) * a.cos();
            im -= (m - mean) * a.sin();
        }
        let amp = 2.0 * (re * re + im * im).sqrt() / rows as f64;
        phases.push((phase_at_period(&means, period), var, amp));
        // edge: centre at the middle row from the line fit, and the model's (light-weighted
        // mean time of each row used, the frame starting at i/fr)
        let pos = row_edge_positions_px(&x, rows, cols, k, 0.25);
        let fit = edge_skew_fit(&pos);
        let used: Vec<f64> = (0..rows)
            .map(|r| {
                if pos[r].is_finite() {
                    v * (i as f64 / fr + model(i).row_mean_time_s(r, exposure))
                } else {
                    f64::NAN
                }
            })
            .collect();
        let mfit = edge_skew_fit(&used);
        let n = pos.iter().filter(|p| p.is_finite()).count() as f64;
        centres.push((
            fit.intercept + fit.slope * r_mid,
            mfit.intercept + mfit.slope * r_mid,
            // standard error of the fitted value near the rows' mean: ≈ residual σ / √n
            fit.slope_std_error * (n * (n * n - 1.0) / 12.0).sqrt() / n.sqrt(),
        ));
    }
    // drift per frame: ((1/240 s) mod 1 ms) / 20 µs = 8.33 rows; phase σ² = 2σ²/(N A²)
    let drift_expected = (1.0 / fr).rem_euclid(1.0 / f_led) / row_time;
    assert!((drift_expected - 8.0 - 1.0 / 3.0).abs() < 1e-9);
    for i in 0..2 {
        let d = ((phases[i + 1].0 - phases[i].0) / (2.0 * std::f64::consts::PI) * period)
            .rem_euclid(period);
        let sig = |(_, var, amp): (f64, f64, f64)| (2.0 * var / (rows as f64 * amp * amp)).sqrt();
        let se = (sig(phases[i]).powi(2) + sig(phases[i + 1]).powi(2)).sqrt()
            / (2.0 * std::f64::consts::PI)
            * period;
        // + 0.1 row: the fundamental's leakage bias over 4 periods (the study's noise-free
        // frames at this size: ≤ 0.03 rows)
        let tol = 5.0 * se + 0.1;
        assert!(tol < 1.0, "drift tolerance {tol}");
        assert!(
            (d - drift_expected).abs() <= tol,
            "frames {i}→{}: drift {d} rows, expected {drift_expected} ± {tol}",
            i + 1
        );
        // the edge advances v/fr = 8.33 px (the model's light-weighted times give the small
        // difference between frames whose light phases differ)
        let adv = centres[i + 1].0 - centres[i].0;
        let adv_model = centres[i + 1].1 - centres[i].1;
        let tol = 5.0 * (centres[i].2.powi(2) + centres[i + 1].2.powi(2)).sqrt()
            + (adv_model - v / fr).abs();
        assert!(tol < 0.1 * v / fr, "advance tolerance {tol}");
        assert!(
            (adv - v / fr).abs() <= tol,
            "frames {i}→{}: advance {adv} px, expected {} ± {tol}",
            i + 1,
            v / fr
        );
    }
    // a bad frame rate is one line naming the shot and the key
    let mut bad = caps.clone();
    bad["shots"][0]["frame_rate_hz"] = json!(0.0);
    std::fs::write(&p, bad.to_string()).unwrap();
    let e = camsim_pipeline::config::load_captures(&p, None)
        .unwrap_err()
        .one_line();
    assert!(
        e.contains("shots[0] (video)") && e.contains("frame_rate_hz"),
        "{e}"
    );
}
