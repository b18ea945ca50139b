//! The `"rolling_shutter"` study point: one shot of a moving edge under a PWM light through a
//! rolling-shutter camera, simulated by the one chain ([`crate::simulate::simulate_each`]),
//! then measured on the frame: the skew of the edge from row to row and the period of the
//! flicker bands along the rows, each beside its closed form.
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `camera` | required | camera.json content; `sensor.readout` must be `"rolling"` |
//! | `target` | one of `target`, `scene` | a captures.json target holding one near-vertical edge (`slanted_edge` with `angle_deg` 0), moved by `motion` |
//! | `scene` | one of `target`, `scene` | an animated glTF scene holding a vertical bar: `{"gltf": PATH, "node": NAME, "camera", "spp" (4), "time_step_s" (1e-4)}` ([`super::rolling_scene`]) |
//! | `frames`, `frame_rate_hz` | 1, absent | with a `scene`: a video of `frames` frames, frame k starting at k / frame_rate_hz |
//! | `exposure_s` | required | exposure time (s) |
//! | `light_modulation` | required | `{"frequency_hz", "duty_cycle", "phase"}` as in captures.json |
//! | `motion` | with a `target` | `{"velocity_px_per_s": [v_x, v_y]}` as in captures.json |
//! | `reference_fraction` | 0.125 | fraction of the columns at each side used as the edge's reference levels (the light side's also give the flicker row means) |
//! | `simulation` | absent | captures.json `simulation` block |
//!
//! Metrics (one row of the study table): `skew_px_measured` (slope of the OLS line through
//! the edge position of every row whose edge contrast is at least a quarter of the largest, times rows − 1: the edge's displacement from the first to
//! the last row), `skew_px_expected` = `v_x · row_time · (rows − 1)`, `skew_px_tolerance`
//! (5 standard errors of the fitted skew plus the model bias: under a PWM light the edge
//! centroid follows the light-weighted mean time of each window, not its middle; the bias is
//! the skew of the exact model positions minus the closed form),
//! `flicker_period_rows_measured` (dominant period of the light side's row means,
//! [`camsim_metrics::rolling_shutter::dominant_period`]), `flicker_period_rows_expected` =
//! `(1/f) / row_time`, `flicker_period_rows_tolerance` (5 Cramér–Rao standard errors from the
//! measured row-mean noise plus the estimator's bias on the noise-free frame),
//! `flicker_visibility_expected` ([`camsim_sensor::PwmLight::band_visibility`]).
use super::output::PointOutput;
use crate::config::{camera_from_file, captures_with_camera, CameraFile, CapturesFile};
use crate::error::CliError;
use crate::simulate::SimOutput;
use camsim_metrics::rolling_shutter::{dominant_period, edge_skew_fit, row_edge_positions_px};
use camsim_sensor::ShutterMode;
use serde::Deserialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Rows whose edge contrast is below this fraction of the largest (rows that caught little
/// of the flickering light) are left out of the skew fit.
const MIN_CONTRAST_FRACTION: f64 = 0.25;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct RollingDoc {
    #[allow(dead_code)]
    kind: String,
    camera: Value,
    #[serde(default)]
    target: Option<Value>,
    #[serde(default)]
    scene: Option<SceneDoc>,
    exposure_s: f64,
    light_modulation: Value,
    #[serde(default)]
    motion: Option<Value>,
    #[serde(default)]
    frames: Option<usize>,
    #[serde(default)]
    frame_rate_hz: Option<f64>,
    #[serde(default)]
    reference_fraction: Option<f64>,
    #[serde(default)]
    simulation: Option<Value>,
    /// Added by the study planner (hashed with the point).
    #[allow(dead_code)]
    #[serde(default)]
    camsim_version: Option<String>,
    /// Per-point seed override ([`super::point::seed_of`]).
    #[allow(dead_code)]
    #[serde(default)]
    seed: Option<u64>,
}

/// `scene`: an animated glTF scene holding a vertical bar.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneDoc {
    /// The glTF file (absolute, or relative to the working folder; a spec writes
    /// `{"$path": "…"}` to give it relative to the spec).
    gltf: String,
    /// The animated node whose image velocity gives the expected skew.
    node: String,
    #[serde(default)]
    camera: Option<String>,
    #[serde(default)]
    spp: Option<u32>,
    #[serde(default)]
    time_step_s: Option<f64>,
}

/// The animated scene of a document with a `scene`, and the video settings.
struct ScenePoint {
    scene: crate::animated::AnimatedScene,
    node: String,
    frames: usize,
    frame_rate_hz: Option<f64>,
}

/// The table columns both rolling-shutter evaluators report: skew (measured, expected,
/// tolerance; px over the frame) and flicker period (rows) with the band visibility expected.
pub(super) fn skew_and_flicker_columns(
    [skew_measured, skew_expected, skew_tol]: [f64; 3],
    period_measured: Option<f64>,
    period_expected: f64,
    period_tol: Option<f64>,
    visibility_expected: f64,
) -> PointOutput {
    let mut out = PointOutput::default();
    out.put("skew_px_measured", skew_measured);
    out.put("skew_px_expected", skew_expected);
    out.put("skew_px_tolerance", skew_tol);
    out.put_opt("flicker_period_rows_measured", period_measured);
    out.put("flicker_period_rows_expected", period_expected);
    out.put_opt("flicker_period_rows_tolerance", period_tol);
    out.put("flicker_visibility_expected", visibility_expected);
    out
}

fn scene_point(d: &RollingDoc) -> Result<Option<ScenePoint>, String> {
    let Some(sd) = &d.scene else {
        if d.frames.is_some() || d.frame_rate_hz.is_some() {
            return Err("frames, frame_rate_hz: video needs a glTF \"scene\"".into());
        }
        return Ok(None);
    };
    let time_step_s = sd.time_step_s.unwrap_or(1e-4);
    if !(time_step_s.is_finite() && time_step_s > 0.0) {
        return Err(format!(
            "scene.time_step_s: must be a positive number of seconds, got {time_step_s}"
        ));
    }
    let spp = sd.spp.unwrap_or(4);
    if spp == 0 || spp > 4096 {
        return Err(format!("scene.spp: must be 1–4096, got {spp}"));
    }
    let frames = d.frames.unwrap_or(1);
    if frames == 0 || frames > 1000 {
        return Err(format!("frames: must be 1–1000, got {frames}"));
    }
    match d.frame_rate_hz {
        Some(f) if !(f.is_finite() && f > 0.0) => {
            return Err(format!("frame_rate_hz: must be a positive number, got {f}"))
        }
        None if frames > 1 => return Err("frame_rate_hz: required with frames > 1".into()),
        _ => {}
    }
    Ok(Some(ScenePoint {
        scene: crate::animated::AnimatedScene {
            gltf: PathBuf::from(&sd.gltf),
            camera_name: sd.camera.clone(),
            spp,
            time_step_s,
        },
        node: sd.node.clone(),
        frames,
        frame_rate_hz: d.frame_rate_hz,
    }))
}

/// The capture set of the point (one shot, one frame) from the document.
fn capture_set(doc: &Value) -> Result<(crate::config::CaptureSet, f64), String> {
    capture_set_and_scene(doc).map(|(s, f, _)| (s, f))
}

/// [`capture_set`] and the animated scene when the document has one.
fn capture_set_and_scene(
    doc: &Value,
) -> Result<(crate::config::CaptureSet, f64, Option<ScenePoint>), String> {
    let d: RollingDoc = serde_json::from_value(doc.clone()).map_err(|e| e.to_string())?;
    let scene = scene_point(&d)?;
    let target = match (&d.target, &scene, &d.motion) {
        (Some(t), None, Some(_)) => t.clone(),
        (None, Some(_), None) => json!({"kind": "dark"}),
        (Some(_), Some(_), _) => return Err("target, scene: give one of them".into()),
        (None, None, _) => return Err("target or scene: one of them is required".into()),
        (_, Some(_), Some(_)) => {
            return Err("motion: not with a glTF scene (its animation moves it)".into())
        }
        (Some(_), None, None) => return Err("light_modulation and motion: both required".into()),
    };
    let f: CameraFile =
        serde_json::from_value(d.camera.clone()).map_err(|e| format!("camera: {e}"))?;
    let cam = camera_from_file(Path::new("camera"), f).map_err(|e| e.one_line())?;
    if cam.readout.mode != ShutterMode::Rolling {
        return Err("camera.sensor.readout: a rolling_shutter point needs {\"mode\": \"rolling\", \"row_time_us\": …}".into());
    }
    let frac = d.reference_fraction.unwrap_or(0.125);
    if !(frac > 0.0 && frac <= 0.5) {
        return Err(format!(
            "reference_fraction: must be in (0, 0.5], got {frac}"
        ));
    }
    let mut captures = json!({
        "camera": "camera.json",
        "shots": [{
            "id": "frame",
            "target": target,
            "exposure_s": d.exposure_s,
            "frames": ["frame.png"],
            "light_modulation": d.light_modulation,
        }],
    });
    if let Some(m) = &d.motion {
        captures["shots"][0]["motion"] = m.clone();
    }
    if let Some(s) = d.simulation {
        captures["simulation"] = s;
    }
    let raw: CapturesFile = serde_json::from_value(captures).map_err(|e| e.to_string())?;
    let set = captures_with_camera(Path::new("point"), raw, cam, PathBuf::from("camera"))
        .map_err(|e| e.one_line())?;
    if set.shots[0].light.is_none() {
        return Err("light_modulation: required".into());
    }
    Ok((set, frac, scene))
}

/// Cheap validation of a rolling-shutter document.
pub fn validate(doc: &Value) -> Result<(), String> {
    capture_set(doc).map(|_| ())
}

/// Evaluate a rolling-shutter point (see the module documentation).
pub fn evaluate(doc: &Value, seed: u64, dir: &Path) -> Result<PointOutput, CliError> {
    let (set, frac, scene) = capture_set_and_scene(doc).map_err(CliError::Other)?;
    if let Some(sp) = scene {
        return super::rolling_scene::evaluate(
            &set,
            frac,
            &sp.scene,
            &sp.node,
            sp.frames,
            sp.frame_rate_hz,
            seed,
            dir,
        );
    }
    let sensor = &set.camera.sensor;
    let (rows, cols) = (sensor.rows, sensor.cols);
    let black = sensor.black_level_dn;
    let mut noisy: Vec<f64> = Vec::new();
    let mut clean: Vec<f64> = Vec::new();
    for expected in [false, true] {
        crate::simulate::simulate_each(&set, seed, expected, &mut |_, _| {}, &mut |o| {
            match o {
                SimOutput::Frame { raw, .. } => {
                    noisy = raw.dn.iter().map(|&v| v as f64 - black).collect()
                }
                SimOutput::Expected { dn, .. } => {
                    clean = dn.data.iter().map(|&v| v as f64 - black).collect()
                }
            }
            Ok(())
        })?;
    }
    let k = ((cols as f64 * frac).round() as usize).max(1);
    let readout = set.camera.readout;
    let model = crate::chain::shot_time_model(&set, 0);
    let light = set.shots[0].light.expect("checked");
    let v = set.shots[0].motion.expect("checked").velocity_px_per_s;
    let exposure_s = match set.shots[0].exposure {
        crate::config::Exposure::Fixed(t) => t,
        crate::config::Exposure::Auto(_) => unreachable!("exposure_s is fixed"),
    };
    let span = (rows - 1) as f64;

    // Skew: the edge position of every row.
    let positions = row_edge_positions_px(&noisy, rows, cols, k, MIN_CONTRAST_FRACTION);
    let fit = edge_skew_fit(&positions);
    let skew_expected = v[0] * readout.row_time_s * span;
    // Exact model positions on the same rows.
    let model_pos: Vec<f64> = (0..rows)
        .map(|r| {
            if positions[r].is_finite() {
                v[0] * model.row_mean_time_s(r, exposure_s)
            } else {
                f64::NAN
            }
        })
        .collect();
    let skew_model = edge_skew_fit(&model_pos).slope * span;
    let skew_tol = 5.0 * fit.slope_std_error * span + (skew_model - skew_expected).abs();

    // Flicker: row means of the light side (the side with the larger reference level).
    let side_mean = |data: &[f64], left: bool| -> f64 {
        let (lo, hi) = if left { (0, k) } else { (cols - k, cols) };
        (0..rows)
            .map(|r| data[r * cols + lo..r * cols + hi].iter().sum::<f64>())
            .sum()
    };
    let left = side_mean(&clean, true) > side_mean(&clean, false);
    let (c0, c1) = if left { (0, k) } else { (cols - k, cols) };
    let row_stats = |data: &[f64]| -> (Vec<f64>, f64) {
        let mut means = Vec::with_capacity(rows);
        let mut var_of_mean = 0.0;
        for r in 0..rows {
            let s = &data[r * cols + c0..r * cols + c1];
            let n = s.len() as f64;
            let m = s.iter().sum::<f64>() / n;
            let var = s.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
            means.push(m);
            var_of_mean += var / n;
        }
        (means, var_of_mean / rows as f64)
    };
    let (noisy_means, noise_var) = row_stats(&noisy);
    let (clean_means, _) = row_stats(&clean);
    let period_expected = camsim_sensor::flicker_period_rows(&light, &readout);
    let measured = dominant_period(&noisy_means, noise_var);
    let noise_free = dominant_period(&clean_means, 0.0);
    let estimator_bias = noise_free.map(|p| (p.period_rows - period_expected).abs());
    let period_tol = match (measured, estimator_bias) {
        (Some(m), Some(b)) => Some(5.0 * m.period_std_error_rows + b),
        _ => None,
    };

    let mut out = skew_and_flicker_columns(
        [fit.slope * span, skew_expected, skew_tol],
        measured.map(|m| m.period_rows),
        period_expected,
        period_tol,
        light.band_visibility(exposure_s),
    );
    out.detail = json!({
        "skew_px_std_error": fit.slope_std_error * span,
        "skew_px_model": skew_model,
        "skew_rows_used": positions.iter().filter(|p| p.is_finite()).count(),
        "flicker_period_rows_std_error": measured.map(|m| m.period_std_error_rows),
        "flicker_period_rows_noise_free": noise_free.map(|p| p.period_rows),
        "row_mean_noise_variance_dn2": noise_var,
        "flicker_row_means_dn": noisy_means,
    });
    Ok(out)
}
