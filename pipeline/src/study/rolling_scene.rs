//! The `"rolling_shutter"` study point on an animated glTF scene: a vertical bar moved by the
//! file's animation, path-traced at time nodes and integrated over each row's window by the
//! one chain ([`crate::chain::animated_shot_rate`]), under a PWM light; optionally a video of
//! `frames` frames at `frame_rate_hz` (frame k starts at k / frame_rate_hz; the animation and
//! the light's phase carry on), written as numbered raw frames `frame_000.png`, ….
//!
//! Metrics (one row of the study table; frame 0 unless said otherwise):
//! * `skew_px_measured`: slope of the OLS line through the bar centre of every row
//!   ([`camsim_metrics::rolling_shutter::row_bar_centres_px`]; rows whose bar signal is at
//!   least a quarter of the largest) times rows − 1;
//! * `skew_px_expected` = `v · row_time · (rows − 1)` with v the bar's image velocity
//!   (px/s), the pinhole projection of its animated node through the glTF camera
//!   ([`crate::animated::node_image_velocity_px_per_s`]: `v_m·f_px / Z` for a bar moving
//!   parallel to the image plane);
//! * `skew_px_tolerance`: 5 standard errors of the fitted skew + the PWM model bias (the bar
//!   centre follows the light-weighted mean time of each window,
//!   [`camsim_sensor::TimeModel::row_mean_time_s`]) + the same fit's error on the noise-free
//!   frame against that model (the time interpolation and the render's sampling);
//! * `flicker_period_rows_measured` / `_expected` / `_tolerance`: the dominant period of the
//!   row means over all columns (the bar's share of a row is the same wherever it is, so
//!   only the light modulates them) against `(1/f) / row_time`; the noise of each row mean
//!   from the noisy minus the noise-free frame;
//! * `flicker_visibility_expected`, `image_velocity_px_per_s`, `renders`;
//! * with `frames` > 1: `bar_advance_px_per_frame_measured` (bar centre at the middle row,
//!   from the line fits of the first and last frames, divided by frames − 1) against
//!   `_expected` = `v / frame_rate`, and `band_drift_rows_measured` (the phase change of the
//!   flicker bands' fundamental from frame to frame,
//!   [`camsim_metrics::rolling_shutter::phase_at_period`], averaged over frame pairs, as rows
//!   in [0, P)) against `_expected` = `((1/frame_rate) mod (1/f)) / row_time`, each with a
//!   `_tolerance` (5 standard errors + the bias of the same measurement on the noise-free
//!   frames).
use super::output::PointOutput;
use crate::animated::AnimatedScene;
use crate::config::{CaptureSet, Exposure};
use crate::error::CliError;
use camsim_metrics::rolling_shutter::{
    dominant_period, edge_skew_fit, phase_at_period, row_bar_centres_px,
};
use camsim_sensor::{PatternSource, TimeModel};
use serde_json::json;
use std::f64::consts::PI;
use std::path::Path;

/// Rows whose bar signal is below this fraction of the largest are left out of the fits.
const MIN_SIGNAL_FRACTION: f64 = 0.25;

/// One simulated frame: noisy and noise-free values (DN above black).
struct FramePair {
    noisy: Vec<f64>,
    clean: Vec<f64>,
}

/// Row means over all columns and the variance of each mean from the noise (noisy − clean).
fn row_means(f: &FramePair, rows: usize, cols: usize) -> (Vec<f64>, Vec<f64>, f64) {
    let mut noisy = Vec::with_capacity(rows);
    let mut clean = Vec::with_capacity(rows);
    let mut var = 0.0;
    for r in 0..rows {
        let (a, b) = (
            &f.noisy[r * cols..(r + 1) * cols],
            &f.clean[r * cols..(r + 1) * cols],
        );
        let n = cols as f64;
        noisy.push(a.iter().sum::<f64>() / n);
        clean.push(b.iter().sum::<f64>() / n);
        var += a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n / n;
    }
    (noisy, clean, var / rows as f64)
}

/// The bar centre fit of one plane: (slope px/row, its std error, centre at row `r_mid`, its
/// std error, the rows used).
fn bar_fit(
    plane: &[f64],
    rows: usize,
    cols: usize,
    k: usize,
    r_mid: f64,
) -> (f64, f64, f64, f64, Vec<bool>) {
    let pos = row_bar_centres_px(plane, rows, cols, k, MIN_SIGNAL_FRACTION);
    let fit = edge_skew_fit(&pos);
    let used: Vec<bool> = pos.iter().map(|p| p.is_finite()).collect();
    let x: Vec<f64> = (0..rows).filter(|&r| used[r]).map(|r| r as f64).collect();
    let n = x.len() as f64;
    let mx = x.iter().sum::<f64>() / n;
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    // standard error of the fitted value at r_mid from the slope's: s² = se_b²·Sxx
    let s2 = fit.slope_std_error.powi(2) * sxx;
    let se_mid = (s2 * (1.0 / n + (r_mid - mx).powi(2) / sxx)).sqrt();
    (
        fit.slope,
        fit.slope_std_error,
        fit.intercept + fit.slope * r_mid,
        se_mid,
        used,
    )
}

/// Line fit through the model positions `v · (F + t̄_r)` of the rows used.
fn model_fit(
    model: &TimeModel,
    exposure_s: f64,
    frame_start_s: f64,
    v: f64,
    used: &[bool],
    r_mid: f64,
) -> (f64, f64) {
    let shifted = TimeModel {
        light: model.light.map(|l| camsim_sensor::PwmLight {
            phase: (l.phase - l.frequency_hz * frame_start_s).rem_euclid(1.0),
            ..l
        }),
        ..*model
    };
    let pos: Vec<f64> = (0..used.len())
        .map(|r| {
            if used[r] {
                v * (frame_start_s + shifted.row_mean_time_s(r, exposure_s))
            } else {
                f64::NAN
            }
        })
        .collect();
    let f = edge_skew_fit(&pos);
    (f.slope, f.intercept + f.slope * r_mid)
}

/// Wrap `x` into [0, p).
fn wrap(x: f64, p: f64) -> f64 {
    x.rem_euclid(p)
}

/// Signed difference of two drifts on a circle of circumference p, in (−p/2, p/2].
fn circ_diff(a: f64, b: f64, p: f64) -> f64 {
    let d = (a - b).rem_euclid(p);
    if d > p / 2.0 {
        d - p
    } else {
        d
    }
}

/// Evaluate a rolling-shutter point on an animated glTF scene (module documentation).
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    set: &CaptureSet,
    frac: f64,
    scene: &AnimatedScene,
    node: &str,
    frames: usize,
    frame_rate_hz: Option<f64>,
    seed: u64,
    dir: &Path,
) -> Result<PointOutput, CliError> {
    let sensor = &set.camera.sensor;
    let (rows, cols) = (sensor.rows, sensor.cols);
    let black = sensor.black_level_dn;
    let exposure_s = match set.shots[0].exposure {
        Exposure::Fixed(t) => t,
        Exposure::Auto(_) => unreachable!("exposure_s is fixed"),
    };
    let sh = camsim_sensor::Shot {
        exposure_s,
        analog_gain: set.shots[0].analog_gain,
    };
    let model = crate::chain::shot_time_model(set, 0);
    let readout = set.camera.readout;
    let light = set.shots[0].light.expect("checked");
    let frame_period_s = frame_rate_hz.map_or(0.0, |f| 1.0 / f);
    let span = (rows - 1) as f64;
    let r_mid = span / 2.0;
    let k = ((cols as f64 * frac).round() as usize).max(1);

    // image velocity of the bar at the middle of the first frame
    let (t0, t1) = camsim_sensor::frame_span_s(&model, rows, exposure_s, 0.0);
    let v = crate::animated::node_image_velocity_px_per_s(set, scene, node, 0.5 * (t0 + t1), 1e-3)?;

    let mut pairs = Vec::with_capacity(frames);
    let mut renders = 0;
    let mut images = Vec::new();
    for f in 0..frames {
        let start = f as f64 * frame_period_s;
        let (rate, n) = crate::chain::animated_shot_rate(set, 0, scene, &sh, start, seed)?;
        renders += n;
        let raw = crate::chain::simulate_frame(
            sensor,
            &rate,
            &sh,
            PatternSource::Seeded(seed),
            seed,
            &[0, f as u64],
        );
        let clean = crate::chain::expected_frame(sensor, &rate, &sh);
        let name = format!("frame_{f:03}.png");
        crate::frames::write_png16(&dir.join(&name), &raw)?;
        images.push((name, format!("raw frame {f} (t = {start} s)")));
        pairs.push(FramePair {
            noisy: raw.dn.iter().map(|&x| x as f64 - black).collect(),
            clean: clean.data.iter().map(|&x| x as f64 - black).collect(),
        });
    }

    // skew on frame 0
    let (slope, slope_se, _, _, used) = bar_fit(&pairs[0].noisy, rows, cols, k, r_mid);
    let (clean_slope, ..) = bar_fit(&pairs[0].clean, rows, cols, k, r_mid);
    let skew_expected = v[0] * readout.row_time_s * span;
    let (model_slope, _) = model_fit(&model, exposure_s, 0.0, v[0], &used, r_mid);
    let skew_tol = 5.0 * slope_se * span
        + ((model_slope * span) - skew_expected).abs()
        + ((clean_slope - model_slope) * span).abs();

    // flicker on frame 0
    let (noisy_means, clean_means, noise_var) = row_means(&pairs[0], rows, cols);
    let period_expected = camsim_sensor::flicker_period_rows(&light, &readout);
    let measured = dominant_period(&noisy_means, noise_var);
    let noise_free = dominant_period(&clean_means, 0.0);
    let period_tol = match (measured, noise_free) {
        (Some(m), Some(c)) => {
            Some(5.0 * m.period_std_error_rows + (c.period_rows - period_expected).abs())
        }
        _ => None,
    };

    let mut out = super::rolling::skew_and_flicker_columns(
        [slope * span, skew_expected, skew_tol],
        measured.map(|m| m.period_rows),
        period_expected,
        period_tol,
        light.band_visibility(exposure_s),
    );
    out.put("image_velocity_px_per_s", v[0]);
    out.put("renders", renders as f64);
    let mut detail = json!({
        "skew_px_std_error": slope_se * span,
        "skew_px_model": model_slope * span,
        "skew_px_noise_free": clean_slope * span,
        "skew_rows_used": used.iter().filter(|u| **u).count(),
        "flicker_period_rows_noise_free": noise_free.map(|p| p.period_rows),
        "row_mean_noise_variance_dn2": noise_var,
        "flicker_row_means_dn": noisy_means,
    });

    if frames > 1 {
        let fr = frame_rate_hz.expect("checked with frames > 1");
        let n = (frames - 1) as f64;
        // bar advance: centre at the middle row, first vs last frame
        let first = bar_fit(&pairs[0].noisy, rows, cols, k, r_mid);
        let last = bar_fit(&pairs[frames - 1].noisy, rows, cols, k, r_mid);
        let adv = (last.2 - first.2) / n;
        let adv_se = (first.3.powi(2) + last.3.powi(2)).sqrt() / n;
        let adv_expected = v[0] / fr;
        let m_first = model_fit(&model, exposure_s, 0.0, v[0], &first.4, r_mid).1;
        let m_last = model_fit(&model, exposure_s, n * frame_period_s, v[0], &last.4, r_mid).1;
        let c_first = bar_fit(&pairs[0].clean, rows, cols, k, r_mid).2;
        let c_last = bar_fit(&pairs[frames - 1].clean, rows, cols, k, r_mid).2;
        let adv_model = (m_last - m_first) / n;
        let adv_tol = 5.0 * adv_se
            + (adv_model - adv_expected).abs()
            + ((c_last - c_first) / n - adv_model).abs();
        out.put("bar_advance_px_per_frame_measured", adv);
        out.put("bar_advance_px_per_frame_expected", adv_expected);
        out.put("bar_advance_px_per_frame_tolerance", adv_tol);

        // band drift: phase of the fundamental at the expected period, frame to frame
        let p = period_expected;
        let drift_expected = wrap(frame_period_s, 1.0 / light.frequency_hz) / readout.row_time_s;
        let drift_of = |which: &dyn Fn(usize) -> Vec<f64>| -> f64 {
            // mean of the pairwise drifts on the circle, around the first pair's
            let drifts: Vec<f64> = (0..frames - 1)
                .map(|i| {
                    let d = phase_at_period(&which(i + 1), p) - phase_at_period(&which(i), p);
                    wrap(d / (2.0 * PI) * p, p)
                })
                .collect();
            let d0 = drifts[0];
            wrap(
                d0 + drifts.iter().map(|d| circ_diff(*d, d0, p)).sum::<f64>() / drifts.len() as f64,
                p,
            )
        };
        let noisy_rows = |i: usize| row_means(&pairs[i], rows, cols).0;
        let clean_rows = |i: usize| row_means(&pairs[i], rows, cols).1;
        let drift = drift_of(&noisy_rows);
        let drift_clean = drift_of(&clean_rows);
        // phase noise of one frame: σ_φ² = 2σ²/(N A²) (least-squares phase of a sinusoid of
        // known frequency; Rife & Boorstyn 1974), a difference of two frames: ×2, averaged
        // over the pairs (adjacent pairs share frames: not reduced by more than √pairs)
        let amp = measured.map_or(f64::NAN, |m| m.amplitude);
        let sigma_phi = (2.0 * noise_var / (rows as f64 * amp * amp)).sqrt();
        let drift_se = (2.0f64).sqrt() * sigma_phi / (2.0 * PI) * p;
        let drift_tol = 5.0 * drift_se + circ_diff(drift_clean, drift_expected, p).abs();
        out.put("band_drift_rows_measured", drift);
        out.put("band_drift_rows_expected", drift_expected);
        out.put("band_drift_rows_tolerance", drift_tol);
        detail["band_drift_rows_noise_free"] = json!(drift_clean);
        detail["bar_advance_px_per_frame_model"] = json!(adv_model);
        detail["frame_rate_hz"] = json!(fr);
    }
    detail["frames"] = json!(frames);
    out.images = images;
    out.detail = detail;
    Ok(out)
}
