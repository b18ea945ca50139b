//! The `"dual_pixel"` study point: a vertical edge on a plane at one object distance through
//! a dual-pixel camera with a thin lens ([`crate::chain::dual_pixel_irradiance`]): the
//! disparity between the left and right half-photodiode images against the thin-lens closed
//! form `d = (2s − 1) · 8r/(3π)` (r the signed circle of confusion; `camsim_optics::dual_pixel`),
//! and a phase-detection autofocus loop ([`crate::pdaf`]) from the camera's focus onto the
//! edge, with the slope calibrated on a chart at a known distance.
//!
//! | key | default | meaning |
//! |---|---|---|
//! | `camera` | required | camera.json content with `sensor.dual_pixel` and the thin lens's `optics.focus_distance_m` |
//! | `target` | required | a captures.json target holding one vertical edge (`slanted_edge` with `angle_deg` 0); its `distance_m` is replaced by the object distance |
//! | `object_vergence_per_m` | required | 1 / object distance (1/m, > 0) |
//! | `exposure_s` | required | exposure time (s) |
//! | `reference_fraction` | 0.125 | fraction of the columns at each side used as the edge's reference levels |
//! | `pdaf` | `{}` | `tolerance_px` (0.05), `max_iterations` (8), `calibration_distance_m` (the camera's focus distance), `calibration_offsets_per_m` ([−0.5, 0.5]: focus vergences of the calibration relative to the chart's) |
//! | `simulation` | absent | captures.json `simulation` block |
//! | `lens` | absent | a real lens (prescription) in place of the thin lens: the camera's `optics.blur` is then `{"kind": "lens", "focus_distance_m": …}` (m from the first vertex; focus keys as in camera.json, no `lens_file`); vergences are from the lens's entrance pupil, the disparity is formed by its traced half-pupil PSFs and the loop refocuses it by its focus model (docs/study.md) |
//!
//! Metrics (one row of the study table):
//! * `object_distance_m`, `defocus_per_m` (`1/Z − 1/D`), `coc_radius_px` (signed);
//! * `disparity_px_expected` (closed form, [`crate::chain::dual_pixel_expected_disparity_px`]),
//!   `disparity_px_measured` (on the noise-free expected frames), `disparity_px_sampled` (the
//!   x-centroid difference of the two sampled half-disc kernels the chain applies, at the
//!   scene's sample pitch: each sample cell's sub-samples count at the cell's centre, so the
//!   column through the disc's centre puts half its light at x = 0 instead of ±¼ sample, a
//!   bias of the order of 1/(π r) samples that vanishes as r grows), `disparity_px_tolerance`
//!   (0.02 px + 2 % of the closed form + the kernel's sampling bias `|sampled − expected|`);
//! * `disparity_px_noisy`, `disparity_px_noisy_std_error` (one noisy readout; the standard
//!   error from the row-to-row scatter);
//! * `slope_px_m_calibrated`, `slope_px_m_expected` (α = d / (1/Z − 1/D) at the calibration
//!   focus, closed form);
//! * `pdaf_iterations` (measurements), `pdaf_final_focus_m`, `pdaf_focus_error_per_m`
//!   (`|1/D_final − 1/Z|`), `depth_of_focus_per_m` (thin lens, circle of confusion one pixel
//!   across, [`crate::pdaf::depth_of_focus_per_m`]), `pdaf_within_depth_of_focus` (1/0).
use super::output::PointOutput;
use crate::config::{camera_from_file, captures_with_camera, CameraFile, CaptureSet, CapturesFile};
use crate::error::CliError;
use crate::pdaf::{
    calibrate_slope, depth_of_focus_per_m, focus_vergence_per_m, focused_at, measure_disparity,
    phase_detection_autofocus, DisparityFrames, DisparityOptions, PdafOptions,
};
use camsim_core::stats::Rect;
use serde::Deserialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct DualPixelDoc {
    #[allow(dead_code)]
    kind: String,
    camera: Value,
    target: Value,
    object_vergence_per_m: f64,
    exposure_s: f64,
    #[serde(default)]
    reference_fraction: Option<f64>,
    #[serde(default)]
    pdaf: Option<PdafDoc>,
    #[serde(default)]
    simulation: Option<Value>,
    /// A real lens (prescription) in place of the thin lens.
    #[serde(default)]
    lens: Option<Value>,
    /// Added by the study planner (hashed with the point).
    #[allow(dead_code)]
    #[serde(default)]
    camsim_version: Option<String>,
    /// Per-point seed override ([`super::point::seed_of`]).
    #[allow(dead_code)]
    #[serde(default)]
    seed: Option<u64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct PdafDoc {
    #[serde(default)]
    tolerance_px: Option<f64>,
    #[serde(default)]
    max_iterations: Option<usize>,
    #[serde(default)]
    calibration_distance_m: Option<f64>,
    #[serde(default)]
    calibration_offsets_per_m: Option<Vec<f64>>,
}

/// The validated point.
struct Point {
    /// The object's capture set (one shot).
    set: CaptureSet,
    /// The calibration chart's capture set (the same target at the calibration distance).
    chart: CaptureSet,
    object_distance_m: f64,
    chart_distance_m: f64,
    ref_fraction: f64,
    tolerance_px: f64,
    max_iterations: usize,
    calibration_offsets_per_m: Vec<f64>,
    /// The real lens and how to build its blur (installed by [`evaluate`]: the field model is
    /// not built by [`validate`]).
    lens: Option<(
        camsim_lens::LensPrescription,
        camsim_optics::LensBlurOptions,
    )>,
}

/// The point's real lens: the prescription `lens` with the camera's `optics.blur` focus keys
/// (`focus_distance_m` from the first vertex, required; `focus_criterion`,
/// `focus_frequency_cyc_per_mm`, `focus_group_surfaces`), and the camera with blur "none" in
/// its place. Returns the camera file, the lens and its blur options and the focus vergence
/// (1/m from the entrance pupil) and effective focal length (m).
#[allow(clippy::type_complexity)]
fn lens_point(
    camera: &Value,
    lens: &Value,
) -> Result<
    (
        CameraFile,
        camsim_lens::LensPrescription,
        camsim_optics::LensBlurOptions,
        f64,
        f64,
    ),
    String,
> {
    let mut cam = camera.clone();
    let blur = cam["optics"]["blur"].clone();
    match blur["kind"].as_str() {
        Some("lens") => {}
        k => {
            return Err(format!(
                "camera.optics.blur.kind: {k:?} but the point has a lens; use \"lens\" with focus_distance_m"
            ))
        }
    }
    let b: crate::config::BlurFile =
        serde_json::from_value(blur).map_err(|e| format!("camera.optics.blur: {e}"))?;
    if b.lens_file.is_some() {
        return Err("camera.optics.blur.lens_file: in a study the lens is the point's \"lens\" (e.g. {\"$file\": \"lens.json\"})".into());
    }
    let fd = match b.focus_distance_m {
        Some(d) if d.is_finite() && d > 0.0 => d,
        d => {
            return Err(format!(
                "camera.optics.blur.focus_distance_m: required by a dual_pixel point with a lens (m from the first vertex, > 0), got {d:?}"
            ))
        }
    };
    let method = camsim_lens::FocusMethod::from_keys(
        b.focus_criterion.as_deref(),
        b.focus_frequency_cyc_per_mm,
        b.focus_group_surfaces,
    )
    .map_err(|m| format!("camera.optics.blur.{m}"))?;
    if let Some(o) = cam.get_mut("optics").and_then(Value::as_object_mut) {
        o.insert("blur".into(), json!({"kind": "none"}));
        o.remove("focus_distance_m");
    }
    let f: CameraFile = serde_json::from_value(cam).map_err(|e| format!("camera: {e}"))?;
    let prescription = camsim_lens::LensPrescription::from_json_str(
        &lens.to_string(),
        &camsim_lens::GlassCatalog::bundled(),
    )
    .map_err(|e| format!("lens: {e}"))?;
    let fo = prescription
        .first_order(prescription.primary_nm)
        .map_err(|e| format!("lens: {e}"))?;
    let mut opts = camsim_optics::LensBlurOptions::covering(1.0);
    opts.focus = camsim_optics::LensFocus::At(Some(fd * 1e3));
    opts.focus_method = method;
    // distortion and relative illumination only (the dual-pixel PSFs are traced per half)
    opts.kind = Some(camsim_lens::PsfKind::Geometric);
    // the lens's own wavelengths (each band uses the nearest), few field heights: a study
    // point's sensor is small
    opts.wavelengths_nm = prescription.wavelengths_nm.clone();
    opts.n_dense_fields = 9;
    Ok((
        f,
        prescription,
        opts,
        1e3 / (fd * 1e3 + fo.entrance_pupil_z_mm),
        fo.efl_mm * 1e-3,
    ))
}

fn capture_set(
    d: &DualPixelDoc,
    cam: &crate::config::Camera,
    distance_m: f64,
) -> Result<CaptureSet, String> {
    let mut target = d.target.clone();
    if !target.is_object() {
        return Err("target: a captures.json target object".into());
    }
    target["distance_m"] = json!(distance_m);
    let mut captures = json!({
        "camera": "camera.json",
        "shots": [{
            "id": "frame",
            "target": target,
            "exposure_s": d.exposure_s,
            "frames": ["frame.png"],
        }],
    });
    if let Some(s) = &d.simulation {
        captures["simulation"] = s.clone();
    }
    let raw: CapturesFile = serde_json::from_value(captures).map_err(|e| e.to_string())?;
    captures_with_camera(
        Path::new("point"),
        raw,
        cam.clone(),
        PathBuf::from("camera"),
    )
    .map_err(|e| e.one_line())
}

fn point(doc: &Value) -> Result<Point, String> {
    let d: DualPixelDoc = serde_json::from_value(doc.clone()).map_err(|e| e.to_string())?;
    let (f, lens, lens_focus) = match &d.lens {
        None => (
            serde_json::from_value(d.camera.clone()).map_err(|e| format!("camera: {e}"))?,
            None,
            None,
        ),
        Some(l) => {
            let (f, pr, opts, u_focus, efl_m) = lens_point(&d.camera, l)?;
            (f, Some((pr, opts)), Some((u_focus, efl_m)))
        }
    };
    let cam = camera_from_file(Path::new("camera"), f).map_err(|e| e.one_line())?;
    match cam.dual_pixel {
        None => {
            return Err("camera.sensor.dual_pixel: required by a dual_pixel point (e.g. {})".into())
        }
        // s = ½: both half-photodiodes see the whole pupil, so there is no disparity to
        // measure and no phase detection to focus with.
        Some(dp) if dp.separation <= 0.5 => {
            return Err(format!(
                "camera.sensor.dual_pixel.separation: {} gives no disparity (both halves see the whole pupil); a dual_pixel point needs 0.5 < separation <= 1",
                dp.separation
            ))
        }
        Some(_) => {}
    }
    let (focus_m, f_m) = match lens_focus {
        Some((u_focus, efl_m)) => (1.0 / u_focus, efl_m),
        None => {
            let Some(focus_m) = cam.thin_lens_focus_m else {
                return Err(
                    "camera.optics.focus_distance_m: required by a dual_pixel point (the thin lens's focus)"
                        .into(),
                );
            };
            (focus_m, cam.optics.focal_length_m)
        }
    };
    // the sensor's half-diagonal, as camera.json's blur kind "lens" covers it; merit
    // frequency default half the pixel Nyquist
    let lens = lens.map(|(pr, mut o)| {
        let s = &cam.sensor;
        o.max_image_height_mm = (0.5 * s.pixel_pitch_m * (s.rows as f64).hypot(s.cols as f64))
            .max(s.pixel_pitch_m)
            * 1e3;
        o.focus_method.frequency_cyc_per_mm = o
            .focus_method
            .frequency_cyc_per_mm
            .or(Some(0.25 / (s.pixel_pitch_m * 1e3)));
        (pr, o)
    });
    let u = d.object_vergence_per_m;
    if !(u.is_finite() && u > 0.0 && 1.0 / u > f_m) {
        return Err(format!(
            "object_vergence_per_m: must be > 0 with 1/value beyond the focal length ({f_m} m), got {u}"
        ));
    }
    let frac = d.reference_fraction.unwrap_or(0.125);
    if !(frac > 0.0 && frac <= 0.5) {
        return Err(format!(
            "reference_fraction: must be in (0, 0.5], got {frac}"
        ));
    }
    let pd = d.pdaf.clone().unwrap_or_default();
    let tolerance_px = pd.tolerance_px.unwrap_or(0.05);
    if !(tolerance_px.is_finite() && tolerance_px > 0.0) {
        return Err(format!(
            "pdaf.tolerance_px: must be > 0, got {tolerance_px}"
        ));
    }
    let max_iterations = pd.max_iterations.unwrap_or(8);
    if !(1..=100).contains(&max_iterations) {
        return Err(format!(
            "pdaf.max_iterations: must be 1 to 100, got {max_iterations}"
        ));
    }
    let chart_distance_m = pd.calibration_distance_m.unwrap_or(focus_m);
    if !(chart_distance_m.is_finite() && chart_distance_m > f_m) {
        return Err(format!(
            "pdaf.calibration_distance_m: must be finite and beyond the focal length ({f_m} m), got {chart_distance_m}"
        ));
    }
    let offsets = pd
        .calibration_offsets_per_m
        .unwrap_or_else(|| vec![-0.5, 0.5]);
    let chart_u = 1.0 / chart_distance_m;
    if offsets.is_empty()
        || offsets
            .iter()
            .any(|o| !(o.is_finite() && *o != 0.0 && chart_u + o >= 0.0 && chart_u + o < 1.0 / f_m))
    {
        return Err(format!(
            "pdaf.calibration_offsets_per_m: non-zero focus vergences relative to the chart's ({chart_u} 1/m) that keep the focus between infinity and the focal length, got {offsets:?}"
        ));
    }
    let set = capture_set(&d, &cam, 1.0 / u)?;
    let chart = capture_set(&d, &cam, chart_distance_m)?;
    Ok(Point {
        set,
        chart,
        object_distance_m: 1.0 / u,
        chart_distance_m,
        ref_fraction: frac,
        tolerance_px,
        max_iterations,
        calibration_offsets_per_m: offsets,
        lens,
    })
}

/// Cheap validation of a dual-pixel document.
pub fn validate(doc: &Value) -> Result<(), String> {
    point(doc).map(|_| ())
}

/// Evaluate a dual-pixel point (see the module documentation).
pub fn evaluate(doc: &Value, seed: u64, _dir: &Path) -> Result<PointOutput, CliError> {
    let mut p = point(doc).map_err(CliError::Other)?;
    if let Some((lens, opts)) = &p.lens {
        let blur = camsim_optics::LensBlur::from_prescription(lens, opts)
            .map_err(|e| CliError::Other(format!("lens: {e}")))?;
        p.set.camera.optics.blur = camsim_optics::Blur::Lens(blur.clone());
        p.chart.camera.optics.blur = camsim_optics::Blur::Lens(blur);
    }
    let cam = &p.set.camera;
    let path = &p.set.camera_path;
    let grid = crate::chain::wavelength_grid(&p.set);
    let scene = crate::chain::shot_scene(&p.set, 0, &grid)?;
    let chart = crate::chain::shot_scene(&p.chart, 0, &grid)?;
    // The shot's exposure from the normal pixel's light; a real lens's PSFs are left out
    // there (a normalised PSF does not change the light level the exposure depends on).
    let mut exposure_set = p.set.clone();
    if let camsim_optics::Blur::Lens(l) = &mut exposure_set.camera.optics.blur {
        l.apply_psf = false;
    }
    let rate = camsim_sensor::electron_rate(
        &cam.sensor,
        &crate::chain::irradiance_of(&exposure_set, &scene, &grid)?,
    );
    let shot = crate::chain::shot_exposure(&p.set, 0, &rate);
    let s = &cam.sensor;
    let region = Rect {
        row0: 0,
        row1: s.rows,
        col0: 0,
        col1: s.cols,
    };
    let ref_cols = ((s.cols as f64 * p.ref_fraction).round() as usize).max(1);
    let expected_opts = DisparityOptions {
        region,
        ref_cols,
        frames: DisparityFrames::Expected,
    };
    let z = p.object_distance_m;
    let u_focus = focus_vergence_per_m(cam);

    // Disparity against the closed form.
    let expected = crate::chain::dual_pixel_expected_disparity_px(cam, path, Some(z))?;
    let separation = cam.dual_pixel.expect("checked").separation;
    let coc_px = expected / camsim_optics::dual_pixel_disparity_m(1.0, separation);
    let measured = measure_disparity(cam, path, &scene, &grid, &shot, &expected_opts, 0)?;
    let noisy_opts = DisparityOptions {
        frames: DisparityFrames::Noisy { seed },
        ..expected_opts
    };
    let noisy = measure_disparity(cam, path, &scene, &grid, &shot, &noisy_opts, 0)?;

    // Slope calibration on the chart, then the loop from the camera's focus.
    let chart_u = 1.0 / p.chart_distance_m;
    let cal_focus: Vec<f64> = p
        .calibration_offsets_per_m
        .iter()
        .map(|o| chart_u + o)
        .collect();
    let cal = calibrate_slope(
        cam,
        path,
        &chart,
        p.chart_distance_m,
        &grid,
        &shot,
        &expected_opts,
        &cal_focus,
    )?;
    let slope_expected = {
        let c = focused_at(cam, path, chart_u)?;
        // α = d / (1/Z − 1/D) at unit defocus, closed form
        crate::chain::dual_pixel_expected_disparity_px(&c, path, Some(1.0 / (chart_u + 1.0)))?
    };
    let pdaf = phase_detection_autofocus(
        cam,
        path,
        &scene,
        &grid,
        &shot,
        &PdafOptions {
            disparity: expected_opts,
            slope_px_m: cal.slope_px_m,
            tolerance_px: p.tolerance_px,
            max_iterations: p.max_iterations,
        },
    )?;
    let final_u = pdaf.final_focus_vergence_per_m;
    let at_final = focused_at(cam, path, final_u)?;
    let dof = depth_of_focus_per_m(&at_final, path)?;
    let focus_error = (final_u - 1.0 / z).abs();

    let mut out = PointOutput::default();
    out.put("object_distance_m", z);
    out.put("defocus_per_m", 1.0 / z - u_focus);
    out.put("coc_radius_px", coc_px);
    out.put("disparity_px_expected", expected);
    out.put("disparity_px_measured", measured.disparity_px);
    let sampled = match crate::pdaf::real_lens(cam) {
        None => sampled_kernel_disparity_px(cam, scene.sample_pitch_m, coc_px, separation),
        Some((lb, f)) => {
            lens_kernel_disparity_px(cam, lb, f, scene.sample_pitch_m, 1.0 / z, separation)?
        }
    };
    out.put("disparity_px_sampled", sampled);
    out.put(
        "disparity_px_tolerance",
        0.02 + 0.02 * expected.abs() + (sampled - expected).abs(),
    );
    out.put("disparity_px_noisy", noisy.disparity_px);
    out.put("disparity_px_noisy_std_error", noisy.std_error_px);
    out.put("slope_px_m_calibrated", cal.slope_px_m);
    out.put("slope_px_m_expected", slope_expected);
    out.put("pdaf_iterations", pdaf.steps.len() as f64);
    out.put_opt("pdaf_final_focus_m", (final_u > 0.0).then(|| 1.0 / final_u));
    out.put("pdaf_focus_error_per_m", focus_error);
    out.put("depth_of_focus_per_m", dof);
    out.put(
        "pdaf_within_depth_of_focus",
        if pdaf.converged && focus_error <= dof {
            1.0
        } else {
            0.0
        },
    );
    out.detail = json!({
        "pdaf_converged": pdaf.converged,
        "pdaf_steps": pdaf.steps.iter().map(|s| json!({
            "focus_vergence_per_m": s.focus_vergence_per_m,
            "disparity_px": s.disparity_px,
        })).collect::<Vec<_>>(),
        "calibration": cal.points.iter().map(|(x, d)| json!({"defocus_per_m": x, "disparity_px": d})).collect::<Vec<_>>(),
        "rows_used": measured.rows_used,
    });
    Ok(out)
}

/// The disparity (pixels) implied by the sampled half-disc kernels the chain applies for the
/// signed circle of confusion `coc_px` (pixels) at the scene sample pitch `dx_m`: the
/// difference of their x-centroids (cell centres), times `2s − 1`.
fn sampled_kernel_disparity_px(
    cam: &crate::config::Camera,
    dx_m: f64,
    coc_px: f64,
    separation: f64,
) -> f64 {
    use camsim_optics::{half_pupil_psf, PupilHalf};
    let p = cam.sensor.pixel_pitch_m;
    let centroid_m = |half| {
        let k = half_pupil_psf(coc_px * p, dx_m, half);
        let n = k.cols();
        k.data
            .iter()
            .enumerate()
            .map(|(i, v)| v * ((i % n) as f64 - k.half_cols as f64) * dx_m)
            .sum::<f64>()
            / k.sum()
    };
    (2.0 * separation - 1.0) * (centroid_m(PupilHalf::Right) - centroid_m(PupilHalf::Left)) / p
}

/// The disparity (pixels) implied by the traced half-pupil kernels of the real lens the chain
/// applies ([`camsim_render::depth_path::LensDualPixelDefocus`]) at inverse depth `inv_z`
/// (1/m) and the scene sample pitch `dx_m`: the difference of their x-centroids averaged over
/// the tabulated wavelengths, times `2s − 1`.
fn lens_kernel_disparity_px(
    cam: &crate::config::Camera,
    lb: &camsim_optics::LensBlur,
    f: &camsim_lens::FocusedLens,
    dx_m: f64,
    inv_z: f64,
    separation: f64,
) -> Result<f64, CliError> {
    let dp = camsim_render::depth_path::LensDualPixelDefocus::new(
        f,
        dx_m * 1e3,
        &lb.model.wavelengths_nm,
        32,
        &[inv_z],
    )
    .map_err(|e| CliError::Other(format!("lens: {e}")))?;
    let cx = |k: &camsim_render::depth_path::Kernel| {
        let n = 2 * k.radius + 1;
        k.values
            .iter()
            .enumerate()
            .map(|(i, v)| *v as f64 * ((i % n) as f64 - k.radius as f64))
            .sum::<f64>()
            / k.values.iter().map(|v| *v as f64).sum::<f64>()
    };
    let n = dp.wavelengths_nm.len();
    let mean_samples = (0..n)
        .map(|w| {
            let (l, r) = dp.kernels(w, inv_z);
            cx(&r) - cx(&l)
        })
        .sum::<f64>()
        / n as f64;
    Ok((2.0 * separation - 1.0) * mean_samples * dx_m / cam.sensor.pixel_pitch_m)
}
