//! The `"hdr"` study point: one pixel design (the camera's `sensor.hdr`, or its standard
//! pixel without it) at one exposure, simulated by the one chain
//! ([`crate::chain::simulate_hdr_frame`], [`crate::chain::merge_hdr`]) on a flat field of the
//! camera's size, beside the closed forms of [`camsim_metrics::hdr_snr`].
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `camera` | required | camera.json content (`sensor.hdr` optional: split pixel, DCG, bracketing) |
//! | `exposure_s` | required | exposure time t (s) of the shot |
//! | `log10_exposure_e` | required | log₁₀ of the exposure H: mean photo-electrons of the camera's pixel (the flat field's electron rate is H/t) |
//!
//! Metrics (one row of the study table): `exposure_e` (H), `snr_db` (merged signal of the
//! simulated frame: mean / standard deviation over the pixels; empty beyond the largest usable
//! exposure, where every readout clips), `snr_model_db` (closed form),
//! `snr_z` (z of the measured variance against the closed form, standard error from the
//! sample fourth moment; empty within 6 σ of a readout's saturation threshold, where the
//! readout in use is random and the closed form does not apply), `snr_<readout>_db` (each
//! readout alone, closed form; empty where it is saturated), `dynamic_range_db`,
//! `max_signal_e`, `noise_floor_e` (the pixel design's, [`camsim_metrics::hdr_snr::dynamic_range`]),
//! `crossovers` (readout hand-overs), `snr_hole_max_db` (deepest SNR drop, closed form at its
//! crossover), `snr_hole_measured_db` / `snr_hole_model_db` / `snr_hole_z` (that drop between
//! two simulated frames at `H_c(1 ∓ δ)`, δ putting each 8 σ of shot noise from the
//! threshold, against the closed form at the same exposures).
use super::output::PointOutput;
use crate::config::{camera_from_file, Camera, CameraFile};
use crate::error::CliError;
use camsim_metrics::hdr_snr::{db, dynamic_range, merged_snr, snr_holes};
use camsim_sensor::{ElectronRate, HdrReadoutModel, Shot};
use serde::Deserialize;
use serde_json::{json, Value};
use std::path::Path;

/// Distance (standard deviations of the packet's shot plus read noise) from a readout's
/// saturation threshold inside which a measured SNR is not compared with the closed form.
const KNEE_SIGMAS: f64 = 6.0;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct HdrDoc {
    #[allow(dead_code)]
    kind: String,
    camera: Value,
    exposure_s: f64,
    log10_exposure_e: f64,
    /// Added by the study planner (hashed with the point).
    #[allow(dead_code)]
    #[serde(default)]
    camsim_version: Option<String>,
    /// Per-point seed override ([`super::point::seed_of`]).
    #[allow(dead_code)]
    #[serde(default)]
    seed: Option<u64>,
}

fn parse(doc: &Value) -> Result<(Camera, f64, f64), String> {
    let d: HdrDoc = serde_json::from_value(doc.clone()).map_err(|e| e.to_string())?;
    let f: CameraFile =
        serde_json::from_value(d.camera.clone()).map_err(|e| format!("camera: {e}"))?;
    let cam = camera_from_file(Path::new("camera"), f).map_err(|e| e.one_line())?;
    if !(d.exposure_s.is_finite() && d.exposure_s > 0.0) {
        return Err(format!(
            "exposure_s: must be a positive number of seconds, got {}",
            d.exposure_s
        ));
    }
    if !(d.log10_exposure_e.is_finite() && (-3.0..=12.0).contains(&d.log10_exposure_e)) {
        return Err(format!(
            "log10_exposure_e: must be between -3 and 12, got {}",
            d.log10_exposure_e
        ));
    }
    Ok((cam, d.exposure_s, 10f64.powf(d.log10_exposure_e)))
}

/// Cheap validation of an HDR document.
pub fn validate(doc: &Value) -> Result<(), String> {
    parse(doc).map(|_| ())
}

/// Mean, variance (n − 1) and standard error of the variance (fourth moment) of `x`.
struct Moments {
    mean: f64,
    var: f64,
    var_se: f64,
    n: f64,
}

fn moments(x: &[f32]) -> Moments {
    let n = x.len() as f64;
    let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let m4 = x.iter().map(|&v| (v as f64 - mean).powi(4)).sum::<f64>() / n;
    Moments {
        mean,
        var,
        var_se: ((m4 - var * var) / n).max(0.0).sqrt(),
        n,
    }
}

/// The merged plane of one simulated flat field at exposure `h_e`.
fn merged_flat(
    cam: &Camera,
    models: &[HdrReadoutModel],
    shot: &Shot,
    h_e: f64,
    seed: u64,
    stream: u64,
) -> Result<Moments, CliError> {
    let s = &cam.sensor;
    let rate = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![(h_e / shot.exposure_s) as f32; s.rows * s.cols],
    };
    let frame = crate::chain::simulate_hdr_frame(cam, &rate, shot, seed, &[stream]);
    let merged = crate::chain::merge_hdr(Path::new("camera"), models, &frame)?;
    Ok(moments(&merged.data))
}

/// Whether exposure `h_e` is within [`KNEE_SIGMAS`] of some readout's saturation threshold.
fn near_knee(models: &[HdrReadoutModel], h_e: f64) -> bool {
    models.iter().any(|m| {
        let e = m.mean_e(h_e);
        let threshold = camsim_sensor::USABLE_FRACTION * m.saturation_e;
        (e - threshold).abs() < KNEE_SIGMAS * (e.max(0.0) + m.read_variance_e2).sqrt()
    })
}

/// Evaluate an HDR point (see the module documentation).
pub fn evaluate(doc: &Value, seed: u64, _dir: &Path) -> Result<PointOutput, CliError> {
    let (cam, exposure_s, h) = parse(doc).map_err(CliError::Other)?;
    let shot = Shot::new(&cam.sensor, exposure_s);
    let models = crate::chain::hdr_readout_models(&cam, &shot);
    let mut out = PointOutput::default();

    // The merged SNR at this exposure: simulated and closed form.
    let m = merged_flat(&cam, &models, &shot, h, seed, 0)?;
    let model_snr = merged_snr(&models, h);
    let model_var = (h / model_snr).powi(2);
    out.put("exposure_e", h);
    // Beyond the largest usable exposure every readout clips: no SNR to measure.
    out.put_opt(
        "snr_db",
        (model_snr > 0.0).then(|| db(m.mean / m.var.sqrt())),
    );
    out.put("snr_model_db", db(model_snr));
    out.put_opt(
        "snr_z",
        (model_snr > 0.0 && !near_knee(&models, h)).then(|| (m.var - model_var) / m.var_se),
    );
    for r in &models {
        out.put(&format!("snr_{}_db", r.name), db(r.snr(h)));
    }

    // The design's dynamic range and SNR holes (closed form).
    let dr = dynamic_range(&models);
    out.put("dynamic_range_db", dr.dynamic_range_db);
    out.put("max_signal_e", dr.max_signal_e);
    out.put("noise_floor_e", dr.noise_floor_e);
    let holes = snr_holes(&models);
    out.put("crossovers", holes.len() as f64);
    let deepest = holes
        .iter()
        .max_by(|a, b| a.drop_db.total_cmp(&b.drop_db))
        .cloned();
    out.put_opt("snr_hole_max_db", deepest.as_ref().map(|d| d.drop_db));
    // The deepest hole measured on two simulated frames either side of its crossover.
    let mut hole_detail = Value::Null;
    if let Some(d) = &deepest {
        let r = models
            .iter()
            .find(|m| m.name == d.readout)
            .expect("hole of a readout");
        let threshold = camsim_sensor::USABLE_FRACTION * r.saturation_e;
        let delta = (8.0 * (threshold + r.read_variance_e2).sqrt() / threshold).max(0.02);
        let (lo, hi) = (d.crossover_e * (1.0 - delta), d.crossover_e * (1.0 + delta));
        let a = merged_flat(&cam, &models, &shot, lo, seed, 1)?;
        let b = merged_flat(&cam, &models, &shot, hi, seed, 2)?;
        let measured = db((a.mean / a.var.sqrt()) / (b.mean / b.var.sqrt()));
        let model = db(merged_snr(&models, lo) / merged_snr(&models, hi));
        // Delta method: Var(ln SNR) ≈ Var(s²)/(4 s⁴) + s²/(mean² n).
        let var_ln =
            |m: &Moments| (m.var_se / m.var).powi(2) / 4.0 + m.var / (m.mean * m.mean * m.n);
        let se = 20.0 / std::f64::consts::LN_10 * (var_ln(&a) + var_ln(&b)).sqrt();
        out.put("snr_hole_measured_db", measured);
        out.put("snr_hole_model_db", model);
        out.put("snr_hole_z", (measured - model) / se);
        hole_detail = json!({"readout": d.readout, "exposure_below_e": lo, "exposure_above_e": hi,
                             "std_error_db": se});
    } else {
        out.put_opt("snr_hole_measured_db", None);
        out.put_opt("snr_hole_model_db", None);
        out.put_opt("snr_hole_z", None);
    }
    out.detail = json!({
        "readouts": models.iter().map(|r| json!({
            "name": r.name, "gain_over_pixel": r.gain_over_pixel, "saturation_e": r.saturation_e,
            "read_variance_e2": r.read_variance_e2, "dark_e": r.dark_e,
            "last_usable_exposure_e": r.last_usable_h_e()})).collect::<Vec<_>>(),
        "holes": holes.iter().map(|h| json!({"readout": h.readout, "crossover_e": h.crossover_e,
            "snr_below_db": h.snr_below_db, "snr_above_db": h.snr_above_db, "drop_db": h.drop_db}))
            .collect::<Vec<_>>(),
        "deepest_hole_measurement": hole_detail,
        "merged_mean_e": m.mean,
        "merged_variance_e2": m.var,
        "merged_variance_model_e2": model_var,
    });
    Ok(out)
}
