//! Phase-detection autofocus with a dual-pixel sensor (issue 21): the disparity between the
//! left and right half-photodiode images of a region is, in thin-lens geometry, affine in
//! the defocus, `d = α (1/z − 1/D)` (Garg et al., "Learning single camera depth estimation
//! using dual-pixels", ICCV 2019; `camsim_optics::dual_pixel`), so one measurement tells the
//! direction and the size of the lens move: `1/D ← 1/D + d/α`.
//!
//! * **Measurement** ([`measure_disparity`]): the scene through the camera focused at D
//!   ([`crate::chain::dual_pixel_rates`]), the two half-photodiode frames (noise-free
//!   expected frames, or one noisy readout), black level removed, and the edge disparity of
//!   the region ([`camsim_metrics::dual_pixel::edge_disparity_px`], per CFA phase).
//! * **Calibration** ([`calibrate_slope`]): as a factory calibration on a chart at a known
//!   distance Z, the disparity is measured at several focus distances and α is the
//!   least-squares slope through the origin of d against `1/Z − 1/D`.
//! * **Loop** ([`phase_detection_autofocus`]): from the camera's focus, measure, stop when
//!   `|d|` is below the tolerance, else move the focus by the calibrated slope; α changes
//!   slightly with the focus (the sensor distance v), which the iteration absorbs.
//!   The focus is kept beyond the focal length (vergence clamped to `[0, 0.99/f]`).
//!
//! * **Real lens** (`blur.kind = "lens"`, issue 21): the half-pupil images are the lens's
//!   traced half-pupil PSFs ([`crate::chain::dual_pixel_irradiance`]) and each focus move
//!   refocuses the lens by its focus model ([`focused_at`]: the whole lens, or its focusing
//!   group); vergences are measured from the lens's paraxial entrance pupil.
//!
//! The depth of focus the loop must land in is the thin-lens one for an acceptable circle of
//! confusion one pixel pitch `p` across: `|1/D − 1/z| ≤ (p/2) / (A v)` ([`depth_of_focus_per_m`]).
use crate::chain::{dual_pixel_rates, expected_dual_pixel_frames};
use crate::config::Camera;
use crate::error::CliError;
use camsim_core::image::SceneRadiance;
use camsim_core::spectrum::WavelengthGrid;
use camsim_core::stats::Rect;
use camsim_metrics::dual_pixel::{edge_disparity_px, EdgeDisparity};
use camsim_sensor::Shot;
use std::path::Path;

/// Which frames the disparity is measured on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DisparityFrames {
    /// The noise-free expected frames.
    Expected,
    /// One noisy readout of the half-photodiodes (temporal noise from `seed`, stream `[k]`
    /// for the k-th measurement).
    Noisy {
        /// Seed.
        seed: u64,
    },
}

/// Where and how the disparity is measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisparityOptions {
    /// Region of the sensor (pixels) holding one near-vertical edge.
    pub region: Rect,
    /// Columns at each side of every sub-row used as the edge's reference levels.
    pub ref_cols: usize,
    /// Frames measured.
    pub frames: DisparityFrames,
}

/// The real lens of a camera (`blur.kind = "lens"` built from a prescription): its blur and
/// the lens as the focus model focused it (`None` for a thin-lens camera).
pub(crate) fn real_lens(
    cam: &Camera,
) -> Option<(&camsim_optics::LensBlur, &camsim_lens::FocusedLens)> {
    match &cam.optics.blur {
        camsim_optics::Blur::Lens(lb) => lb.focus.as_deref().map(|f| (lb, f)),
        _ => None,
    }
}

/// Paraxial first-order data of a focused lens the loop needs: entrance-pupil position and
/// radius (mm), effective focal length (mm) and the image-side scale (mm of paraxial image per
/// unit tan θ of the object).
pub(crate) struct LensFirstOrder {
    pub(crate) entrance_pupil_z_mm: f64,
    pub(crate) entrance_pupil_radius_mm: f64,
    pub(crate) efl_mm: f64,
    pub(crate) per_tan_mm: f64,
}

pub(crate) fn lens_first_order(
    f: &camsim_lens::FocusedLens,
) -> Result<LensFirstOrder, camsim_lens::LensError> {
    let l = &f.lens;
    let fo = l.first_order(l.primary_nm)?;
    Ok(LensFirstOrder {
        entrance_pupil_z_mm: fo.entrance_pupil_z_mm,
        entrance_pupil_radius_mm: 0.5 * fo.entrance_pupil_diameter_mm,
        efl_mm: fo.efl_mm,
        per_tan_mm: l.paraxial_image_mm_per_tan(l.primary_nm)?,
    })
}

/// The camera focused at the vergence `vergence_per_m` (1/m from the lens's entrance pupil
/// for a real lens; 0 = infinity): the thin lens's focus distance, or the real lens refocused
/// by the focus model with the camera's method (criterion and motion: the whole lens, or its
/// focusing group from its infinity position). A real lens's distortion and relative
/// illumination stay those of the camera's own focus (second order for a focus move).
pub fn focused_at(
    cam: &Camera,
    camera_path: &Path,
    vergence_per_m: f64,
) -> Result<Camera, CliError> {
    let mut c = cam.clone();
    let Some((lb, f)) = real_lens(cam) else {
        c.thin_lens_focus_m = (vergence_per_m > 0.0).then(|| 1.0 / vergence_per_m);
        return Ok(c);
    };
    let lens_err =
        |e: &dyn std::fmt::Display| CliError::input(camera_path, format!("optics.blur: {e}"));
    let fo = lens_first_order(f).map_err(|e| lens_err(&e))?;
    let distance_mm = if vergence_per_m > 0.0 {
        let d = 1e3 / vergence_per_m - fo.entrance_pupil_z_mm;
        if !(d > 0.0) {
            return Err(lens_err(&format!(
                "focus vergence {vergence_per_m} 1/m lies behind the lens's first vertex"
            )));
        }
        Some(d)
    } else {
        None
    };
    // the prescription at its own gaps: undo the focusing group's shift
    let base = match f.motion {
        camsim_lens::FocusMotion::Group {
            first_surface,
            last_surface,
        } => f
            .lens
            .with_group_shift(first_surface, last_surface, -f.group_shift_mm)
            .map_err(|e| lens_err(&e))?,
        camsim_lens::FocusMotion::Unit => f.lens.clone(),
    };
    let refocused = base
        .focus(&camsim_lens::FocusSpec {
            focus_distance_mm: distance_mm,
            method: f.method.clone(),
        })
        .map_err(|e| lens_err(&e))?;
    let mut blur = lb.clone();
    blur.focus = Some(std::sync::Arc::new(refocused));
    c.optics.blur = camsim_optics::Blur::Lens(blur);
    Ok(c)
}

/// The vergence (1/m) of the camera's focus (0 = infinity): the thin lens's, or the real
/// lens's focus distance measured from its entrance pupil.
pub fn focus_vergence_per_m(cam: &Camera) -> f64 {
    match real_lens(cam) {
        Some((_, f)) => match (f.focus_distance_mm, lens_first_order(f)) {
            (Some(d), Ok(fo)) => 1e3 / (d + fo.entrance_pupil_z_mm),
            _ => 0.0,
        },
        None => cam.thin_lens_focus_m.map_or(0.0, |d| 1.0 / d),
    }
}

/// Depth of focus as a vergence half-width (1/m): the defocus `|1/z − 1/D|` at which the
/// circle of confusion (its radius grows linearly with the defocus,
/// [`crate::chain::dual_pixel_expected_disparity_px`]'s law) reaches a diameter of one pixel
/// pitch, for the camera's focus. For a real lens the same paraxial law with the entrance-pupil
/// radius A and the image-side scale H (mm per unit tan θ): radius `A |Δ(1/z)| H`.
pub fn depth_of_focus_per_m(cam: &Camera, camera_path: &Path) -> Result<f64, CliError> {
    if let Some((_, f)) = real_lens(cam) {
        let fo = lens_first_order(f)
            .map_err(|e| CliError::input(camera_path, format!("optics.blur: {e}")))?;
        let r1_mm = camsim_lens::paraxial::paraxial_blur_radius_mm(
            fo.entrance_pupil_radius_mm,
            fo.per_tan_mm,
            1.0,
            0.0,
        );
        return Ok(0.5 * cam.sensor.pixel_pitch_m * 1e3 / r1_mm);
    }
    let t = crate::chain::camera_thin_lens(cam, camera_path, cam.sensor.pixel_pitch_m)?;
    // radius (px) at a defocus of 1/m
    let r1 = crate::chain::signed_coc_radius_px(&t, focus_vergence_per_m(cam) + 1.0);
    Ok(0.5 / r1)
}

/// The largest focus vergence (1/m) the loop may set: 0.99 over the focal length.
fn max_focus_vergence_per_m(cam: &Camera) -> f64 {
    match real_lens(cam).map(|(_, f)| lens_first_order(f)) {
        Some(Ok(fo)) => 0.99e3 / fo.efl_mm.abs(),
        _ => 0.99 / cam.optics.focal_length_m,
    }
}

/// The disparity (pixels, right − left) of `scene` through `cam` as it is focused, on the
/// region of `opts` (`k` numbers the measurement's noise stream). Errors when the region
/// holds no edge.
pub fn measure_disparity(
    cam: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
    shot: &Shot,
    opts: &DisparityOptions,
    k: u64,
) -> Result<EdgeDisparity, CliError> {
    let rates = dual_pixel_rates(cam, camera_path, scene, grid)?;
    let black = cam.sensor.black_level_dn;
    let (left, right): (Vec<f64>, Vec<f64>) = match opts.frames {
        DisparityFrames::Expected => {
            let e = expected_dual_pixel_frames(cam, &rates, shot).expect("dual pixel checked");
            (
                e.left_dn.iter().map(|v| *v as f64 - black).collect(),
                e.right_dn.iter().map(|v| *v as f64 - black).collect(),
            )
        }
        DisparityFrames::Noisy { seed } => {
            let dp = cam.dual_pixel.expect("dual pixel checked");
            let f =
                camsim_sensor::expose_dual_pixel(&cam.sensor, &dp, &rates, shot, seed, seed, &[k]);
            (
                f.left.dn.iter().map(|v| *v as f64 - black).collect(),
                f.right.dn.iter().map(|v| *v as f64 - black).collect(),
            )
        }
    };
    let period = cam.sensor.cfa.tile_cols().max(cam.sensor.cfa.tile_rows());
    edge_disparity_px(
        &left,
        &right,
        cam.sensor.cols,
        opts.region,
        period,
        opts.ref_cols,
    )
    .ok_or_else(|| {
        CliError::input(
            camera_path,
            "dual pixel: the disparity region holds no edge (flat left and right images)",
        )
    })
}

/// A calibrated disparity slope.
#[derive(Debug, Clone, PartialEq)]
pub struct SlopeCalibration {
    /// α (pixels per 1/m of defocus vergence `1/z − 1/D`).
    pub slope_px_m: f64,
    /// The calibration measurements: (defocus vergence `1/Z − 1/D` in 1/m, disparity px).
    pub points: Vec<(f64, f64)>,
}

/// Calibrate α on `chart` (an edge at the known distance `chart_distance_m`): the disparity
/// at each focus vergence of `focus_vergences_per_m` (1/m), α the least-squares slope through
/// the origin of d against `1/Z − 1/D`.
#[allow(clippy::too_many_arguments)]
pub fn calibrate_slope(
    cam: &Camera,
    camera_path: &Path,
    chart: &SceneRadiance,
    chart_distance_m: f64,
    grid: &WavelengthGrid,
    shot: &Shot,
    opts: &DisparityOptions,
    focus_vergences_per_m: &[f64],
) -> Result<SlopeCalibration, CliError> {
    let mut points = Vec::new();
    for (k, &u) in focus_vergences_per_m.iter().enumerate() {
        let d = measure_disparity(
            &focused_at(cam, camera_path, u)?,
            camera_path,
            chart,
            grid,
            shot,
            opts,
            1000 + k as u64,
        )?;
        points.push((1.0 / chart_distance_m - u, d.disparity_px));
    }
    let sxx: f64 = points.iter().map(|(x, _)| x * x).sum();
    let sxy: f64 = points.iter().map(|(x, y)| x * y).sum();
    if !(sxx > 0.0) {
        return Err(CliError::input(
            camera_path,
            "dual pixel: the calibration focus distances must differ from the chart distance",
        ));
    }
    Ok(SlopeCalibration {
        slope_px_m: sxy / sxx,
        points,
    })
}

/// One step of the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdafStep {
    /// Focus vergence at which the disparity was measured (1/m; 0 = infinity).
    pub focus_vergence_per_m: f64,
    /// The measured disparity (pixels).
    pub disparity_px: f64,
    /// Its standard error (pixels; 0 on expected frames).
    pub std_error_px: f64,
}

/// What the loop does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdafOptions {
    /// Measurement.
    pub disparity: DisparityOptions,
    /// Calibrated slope α (px·m).
    pub slope_px_m: f64,
    /// Stop when `|d|` is below this (pixels).
    pub tolerance_px: f64,
    /// Measurements at most.
    pub max_iterations: usize,
}

/// The result of [`phase_detection_autofocus`].
#[derive(Debug, Clone, PartialEq)]
pub struct Pdaf {
    /// Every measurement, in order (the last one at the final focus).
    pub steps: Vec<PdafStep>,
    /// The final focus vergence (1/m).
    pub final_focus_vergence_per_m: f64,
    /// Whether `|d|` fell below the tolerance.
    pub converged: bool,
}

/// Focus `cam` (thin lens, or a real lens moved by its focus model, [`focused_at`]) on the edge in the region of `scene` by phase detection (module
/// docs).
pub fn phase_detection_autofocus(
    cam: &Camera,
    camera_path: &Path,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
    shot: &Shot,
    opts: &PdafOptions,
) -> Result<Pdaf, CliError> {
    if !(opts.slope_px_m.is_finite() && opts.slope_px_m != 0.0) {
        return Err(CliError::input(
            camera_path,
            format!(
                "dual pixel: the calibrated slope must be finite and non-zero, got {}",
                opts.slope_px_m
            ),
        ));
    }
    let max_vergence = max_focus_vergence_per_m(cam);
    let mut u = focus_vergence_per_m(cam);
    let mut steps = Vec::new();
    for k in 0..opts.max_iterations.max(1) {
        let d = measure_disparity(
            &focused_at(cam, camera_path, u)?,
            camera_path,
            scene,
            grid,
            shot,
            &opts.disparity,
            k as u64,
        )?;
        steps.push(PdafStep {
            focus_vergence_per_m: u,
            disparity_px: d.disparity_px,
            std_error_px: d.std_error_px,
        });
        if d.disparity_px.abs() < opts.tolerance_px {
            return Ok(Pdaf {
                steps,
                final_focus_vergence_per_m: u,
                converged: true,
            });
        }
        u = (u + d.disparity_px / opts.slope_px_m).clamp(0.0, max_vergence);
    }
    Ok(Pdaf {
        final_focus_vergence_per_m: steps.last().map_or(u, |s| s.focus_vergence_per_m),
        steps,
        converged: false,
    })
}
