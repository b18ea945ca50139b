//! `camsim simulate`: the baseline forward model of ../spec/capture-format.md applied to every
//! shot of a capture set: target → SceneRadiance → optics → SensorIrradiance → sensor →
//! frames (or, with `--expected`, the noise-free expected image per shot).
use crate::config::CaptureSet;
use crate::error::CliError;
use crate::frames;
use camsim_core::constants::SI;
use camsim_core::exr_io::write_single_channel_exr;
use camsim_core::image::{Plane, SceneRadiance, SensorIrradiance};
use camsim_core::sample_aperture::SampleAperture;
use camsim_core::scene::{scale_to_mean_luminance, SamplingGrid};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_optics::{form_image, Blur, OpticsModel};
use camsim_sensor::{
    electron_rate, fixed_pattern, ElectronRate, FixedPattern, PatternSource, SensorModel,
};
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Options of one `simulate` run.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    /// Output folder.
    pub out_dir: PathBuf,
    /// Seed of every random term.
    pub seed: u64,
    /// Write expected images instead of frames.
    pub expected: bool,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
}

/// What a run produced.
#[derive(Debug, Clone, Default)]
pub struct SimulateSummary {
    /// Files written (relative to the output folder).
    pub files: Vec<PathBuf>,
    /// Exposure used per shot (s).
    pub exposures_s: Vec<(String, f64)>,
}

/// Wavelength grid for wavelength-dependent optics: the configured one, or 10 nm steps over
/// the channels' spectral support (effective QE: the qe_shift and ir_leakage blocks move and
/// extend it) clipped to 350–1100 nm (400–700 nm if unbounded).
pub fn wavelength_grid(set: &CaptureSet) -> WavelengthGrid {
    if let Some(g) = &set.simulation.wavelength_nm {
        return WavelengthGrid::regular(g.start_nm, g.stop_nm, g.step_nm).expect("validated");
    }
    // The effective QE (qe_shift and ir_leakage blocks included) sets the range.
    let (lo, hi) = set.camera.sensor.effective_qe_support_nm();
    if !lo.is_finite() || !hi.is_finite() {
        return WavelengthGrid::default_visible();
    }
    let lo = (lo.max(350.0) / 10.0).floor() * 10.0;
    let hi = (hi.min(1100.0) / 10.0).ceil() * 10.0;
    WavelengthGrid::regular(lo, hi.max(lo + 10.0), 10.0).expect("valid grid")
}

/// Scene samples per pixel side and margin (pixels) needed by the optics' blur.
pub fn sampling_for(
    optics: &OpticsModel,
    sensor: &SensorModel,
    grid: &WavelengthGrid,
    oversample: Option<usize>,
) -> (usize, usize) {
    let p_um = sensor.pixel_pitch_m * 1e6;
    let lmin_um = grid.wavelength_nm[0] * 1e-3;
    let lmax_um = grid.wavelength_nm[grid.len() - 1] * 1e-3;
    let n = optics.f_number;
    let diffraction_os = (p_um / (0.5 * lmin_um * n)).ceil() as usize;
    // Float-to-usize casts saturate and the sums below saturate: an absurd blur gives a huge
    // margin that the budget (check_budget) refuses, never an overflow.
    let diffraction_margin = ((5.0 * lmax_um * n / p_um).ceil() as usize).saturating_add(2);
    let (os, mut margin) = match &optics.blur {
        Blur::None => (1, 0),
        Blur::Gaussian { sigma_um } => (
            (p_um / sigma_um.max(1e-9)).ceil() as usize,
            ((4.0 * sigma_um / p_um).ceil() as usize).saturating_add(1),
        ),
        Blur::Pillbox { width_um } => (
            (2.0 * p_um / width_um).ceil() as usize,
            ((0.5 * width_um / p_um).ceil() as usize).saturating_add(1),
        ),
        Blur::Diffraction | Blur::Psf(_) => (diffraction_os, diffraction_margin),
        Blur::Wavefront { defocus_um, .. } => (
            diffraction_os,
            diffraction_margin.saturating_add((16.0 * defocus_um.abs() * n / p_um).ceil() as usize),
        ),
        Blur::Pupil(wp) => {
            let aperture_m = optics.focal_length_m / n;
            let reach_um = wp
                .reach_m(&grid.wavelength_nm, n, aperture_m)
                .unwrap_or(0.0)
                * 1e6;
            (
                diffraction_os,
                ((reach_um / p_um).ceil() as usize).saturating_add(2),
            )
        }
        // Resolve the field model's PSF detail; margin = PSF half-width + the inward shift of
        // the corner by (barrel) distortion, capped at the sensor's size.
        Blur::Lens(l) => {
            let half_diag_m = 0.5
                * sensor.pixel_pitch_m
                * ((sensor.rows as f64).powi(2) + (sensor.cols as f64).powi(2)).sqrt();
            let margin = ((l.margin_m(half_diag_m) * 1e6 / p_um).ceil() as usize).saturating_add(2);
            (
                (p_um / l.detail_um(lmin_um * 1e3)).ceil() as usize,
                margin.min(sensor.rows.max(sensor.cols)),
            )
        }
    };
    if let Some(d) = &optics.diffuser {
        margin =
            margin.saturating_add(((2.0 * d.fwhm_um / p_um).ceil() as usize).saturating_add(1));
    }
    // Effect blocks: the defocus blur's detail and reach, and the scene the distortion /
    // lateral-colour warp samples beyond the blurred region (the target continues there).
    let fx = &optics.effects;
    let os = os.max(fx.oversample_hint(sensor.pixel_pitch_m));
    if fx.defocus.is_some() || fx.has_warp() {
        margin += fx.extra_margin_px(
            sensor.pixel_pitch_m,
            sensor.rows,
            sensor.cols,
            margin,
            &grid.wavelength_nm,
        );
    }
    (oversample.unwrap_or(os.clamp(1, 4)), margin)
}

/// What the scene's samples stand for ([`camsim_core::sample_aperture`]): the cubic B-spline
/// filter of the cell pitch when the blur is band-limited within the grid's Nyquist frequency
/// (diffraction or a wavefront pupil, cutoff `1/(λ_min N)` ≤ `os/(2p)`, edge-replicated
/// padding, no warp block), so that the optics return exact cell averages of the blurred
/// irradiance up to an aliasing residue ~30× below the cell average's (issue 17 §5); else cell
/// averages. `simulation.sample_aperture = "cell"` forces cell averages.
pub fn sample_aperture_for(
    optics: &OpticsModel,
    sensor: &SensorModel,
    grid: &WavelengthGrid,
    os: usize,
    choice: Option<crate::config::SampleApertureChoice>,
) -> SampleAperture {
    if choice == Some(crate::config::SampleApertureChoice::Cell) {
        return SampleAperture::Cell;
    }
    let band_limited = matches!(
        optics.blur,
        Blur::Diffraction | Blur::Wavefront { .. } | Blur::Pupil(_)
    ) && optics.padding == camsim_optics::Padding::Replicate
        && !optics.effects.has_warp();
    // The OTF cutoff 1/(λ N) (the working f-number N(1+|m|) only lowers it) must lie within
    // the grid's Nyquist frequency os/(2p).
    let d_m = sensor.pixel_pitch_m / os as f64;
    let cutoff_ok = d_m <= 0.5 * grid.wavelength_nm[0] * 1e-9 * optics.f_number * (1.0 + 1e-9);
    if band_limited && cutoff_ok {
        SampleAperture::CubicBSpline
    } else {
        SampleAperture::Cell
    }
}

/// The memory one shot of `set` needs (docs/limits.md), bytes: the scene and the sensor
/// irradiance as f32 planes of `((rows + 2·margin)·os) × ((cols + 2·margin)·os)` samples ×
/// bands, one more such plane set as the blur's working copy, and ~48 bytes per sensor pixel
/// (electron rates, electrons and noise in f64, fixed patterns, DN).
pub fn shot_memory_bytes(set: &CaptureSet, grid: &WavelengthGrid) -> f64 {
    let s = &set.camera.sensor;
    let (os, margin) = sampling_for(&set.camera.optics, s, grid, set.simulation.oversample);
    let side = |n: usize| (n as f64 + 2.0 * margin as f64) * os as f64;
    let samples = side(s.rows) * side(s.cols);
    // A picture or cube keeps its own basis on the sampling grid (one plane per band of a
    // cube) until the optics expand it to the simulation's bands.
    let planes = set
        .shots
        .iter()
        .map(|sh| match (&sh.target.target, &sh.target.gltf) {
            (camsim_core::scene::Target::Image { radiance }, _) => radiance.terms(),
            // the render's bands, its depth plane and the compositing's working planes
            (_, Some(t)) => t.render_grid(grid).len().max(grid.len()) * 2 + 2,
            _ => 0,
        })
        .max()
        .unwrap_or(0)
        .max(grid.len());
    crate::budget::f32_bytes(samples * planes as f64, 3.0) + s.rows as f64 * s.cols as f64 * 48.0
}

/// Refuse a capture set whose shots need more memory than the budget allows
/// ([`shot_memory_bytes`], [`crate::budget::check_memory`]).
pub fn check_budget(set: &CaptureSet) -> Result<(), CliError> {
    for (i, shot) in set.shots.iter().enumerate() {
        if let Some(t) = &shot.target.gltf {
            crate::gltf_target::check_render_work(set, &format!("shots[{i}] ({})", shot.id), t)?;
        }
    }
    let grid = wavelength_grid(set);
    let s = &set.camera.sensor;
    let (os, margin) = sampling_for(&set.camera.optics, s, &grid, set.simulation.oversample);
    crate::budget::check_memory(
        Some(&set.camera_path),
        "sensor.rows/cols, optics.blur and simulation",
        shot_memory_bytes(set, &grid),
        &format!(
            "{}×{} pixels + {margin} px blur margin, {os}×{os} samples per pixel, {} bands",
            s.rows,
            s.cols,
            grid.len()
        ),
    )
}

/// A shot's target rendered on `g`, with its illuminant, scaled to its mean luminance over
/// the sensor when the target asks for one.
///
/// Scenes from the world (docs/config.md): with `fov_deg` the target covers
/// `W = 2 s′ tan(F/2)` of the image plane ([`camsim_core::scene_view`]; `s′` the thin-lens
/// image distance of the optics' focal length for the target's `distance_m`, `f` at
/// infinity) instead of filling the sensor, and its mean luminance is then taken over that
/// extent (the part of it the grid samples); `distance_m` is the scene's object distance (the
/// camera equation's magnification); with `swap_illuminant` the scene is rendered under its
/// own illuminant and swapped keeping reflectance and mean luminance
/// ([`camsim_core::illuminant::swap_illuminant`]).
fn scene_on_grid(
    set: &CaptureSet,
    shot: &crate::config::Shot,
    g: &SamplingGrid,
) -> Result<(SceneRadiance, f64), CliError> {
    let mut scene = scene_rows_unscaled(set, shot, g, 0..g.rows)?;
    let world = &shot.target.world;
    if let (Some(_), Some(new)) = (&world.swapped_from, &shot.target.illuminant) {
        camsim_core::illuminant::swap_illuminant(&mut scene, new, true, &SI).map_err(|e| {
            CliError::input(&set.path, format!("shot {}: swap_illuminant: {e}", shot.id))
        })?;
    }
    let mut k = 1.0;
    if let Some(l) = shot.target.mean_luminance_cd_m2 {
        k = scale_to_mean_luminance(&mut scene, l, Some(luminance_window_m(set, shot, g)), &SI);
    }
    Ok((scene, k))
}

/// The window over which a shot's scene is scaled to its mean luminance: the target's
/// image-plane extent, or the sensor.
fn luminance_window_m(
    set: &CaptureSet,
    shot: &crate::config::Shot,
    g: &SamplingGrid,
) -> (f64, f64) {
    target_extent_m(set, shot).unwrap_or((g.sensor_width_m, g.sensor_height_m))
}

/// The grid rows `rows` of a shot's target rendered on `g` with its illuminant, before any
/// illuminant swap or luminance scaling ([`scene_on_grid`]'s first step).
fn scene_rows_unscaled(
    set: &CaptureSet,
    shot: &crate::config::Shot,
    g: &SamplingGrid,
    rows: std::ops::Range<usize>,
) -> Result<SceneRadiance, CliError> {
    let world = &shot.target.world;
    check_target_distance(set, shot)?;
    let extent = target_extent_m(set, shot);
    let radiance =
        camsim_core::scene_view::render_target_in_view_rows(&shot.target.target, g, extent, rows)
            .map_err(|e| CliError::input(&set.path, format!("shot {}: {e}", shot.id)))?;
    Ok(SceneRadiance {
        radiance,
        sample_pitch_m: g.pitch_m,
        object_distance_m: world.distance_m,
        illuminant: world
            .swapped_from
            .clone()
            .or_else(|| shot.target.illuminant.clone()),
        depth_m: None,
        sample_aperture: camsim_core::scene::rendered_aperture(&shot.target.target, g),
    })
}

/// Refuses a target nearer than the focal length (no real image).
fn check_target_distance(set: &CaptureSet, shot: &crate::config::Shot) -> Result<(), CliError> {
    let f_m = set.camera.optics.focal_length_m;
    if let Some(d) = shot.target.world.distance_m {
        if !(d > f_m) {
            return Err(CliError::input(
                &set.path,
                format!(
                    "shot {}: target.distance_m = {d} must exceed the focal length ({f_m} m) to \
                     form a real image",
                    shot.id
                ),
            ));
        }
    }
    Ok(())
}

/// A shot's scene rows projected onto planes ([`shot_scene_projected_rows`]): plane j is
/// `Σ_k w_jk L_k(x)` of the scene's basis terms, on the scene's sampling.
#[derive(Debug, Clone)]
pub struct ProjectedScene {
    /// One row-major `rows × cols` plane per row of weights.
    pub planes: Vec<Vec<f32>>,
    /// Grid rows rendered.
    pub rows: usize,
    /// Grid columns.
    pub cols: usize,
    /// Sample spacing in the image plane (m).
    pub sample_pitch_m: f64,
    /// Object distance (m; None = infinity), as the scene's.
    pub object_distance_m: Option<f64>,
    /// What each sample stands for, as the scene's.
    pub sample_aperture: camsim_core::sample_aperture::SampleAperture,
}

/// The grid rows `rows` of [`shot_scene_rows`] (luminance factor `factor`) projected onto the
/// weights `weights_of` gives for the target's basis ([`camsim_core::scene::target_basis`]):
/// plane j = `Σ_k weights[j][k] · plane_k`, bit for bit [`camsim_core::SpectralImage::combine`]
/// of each row of weights on those rows, without the scene's basis-term planes
/// ([`camsim_core::scene_view::render_target_in_view_projected_rows`]: a 12 MP chart is 25
/// dense planes of 48 M samples, its channel planes 3–4). Only for [`shot_scene_by_rows`]
/// shots.
pub fn shot_scene_projected_rows(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    rows: std::ops::Range<usize>,
    factor: f64,
    weights_of: impl FnOnce(&camsim_core::SpectralBasis) -> Vec<Vec<f64>>,
) -> Result<ProjectedScene, CliError> {
    refuse_unless_by_rows(set, shot_index)?;
    let g = shot_sampling_grid(set, grid);
    projected_rows_on(set, shot_index, &g, rows, factor, weights_of)
}

/// [`shot_scene_projected_rows`] on the sampling grid `g`.
fn projected_rows_on(
    set: &CaptureSet,
    shot_index: usize,
    g: &SamplingGrid,
    rows: std::ops::Range<usize>,
    factor: f64,
    weights_of: impl FnOnce(&camsim_core::SpectralBasis) -> Vec<Vec<f64>>,
) -> Result<ProjectedScene, CliError> {
    let shot = &set.shots[shot_index];
    let err =
        |e: camsim_core::CoreError| CliError::input(&set.path, format!("shot {}: {e}", shot.id));
    check_target_distance(set, shot)?;
    let target = &shot.target.target;
    let basis = camsim_core::scene::target_basis(target).map_err(err)?;
    let proj = camsim_core::scene::PlaneProjection {
        weights: weights_of(&basis),
        term_scale: factor,
    };
    let n = rows.len();
    let planes = camsim_core::scene_view::render_target_in_view_projected_rows(
        target,
        g,
        target_extent_m(set, shot),
        rows,
        &proj,
    )
    .map_err(err)?;
    Ok(ProjectedScene {
        planes,
        rows: n,
        cols: g.cols,
        sample_pitch_m: g.pitch_m,
        object_distance_m: shot.target.world.distance_m,
        sample_aperture: camsim_core::scene::rendered_aperture(target, g),
    })
}

/// Refuses (one line naming the shot) a shot whose scene cannot be rendered by row windows
/// ([`shot_scene_by_rows`]).
fn refuse_unless_by_rows(set: &CaptureSet, shot_index: usize) -> Result<(), CliError> {
    if shot_scene_by_rows(set, shot_index) {
        return Ok(());
    }
    Err(CliError::input(
        &set.path,
        format!(
            "shot {}: its scene cannot be rendered by row windows",
            set.shots[shot_index].id
        ),
    ))
}

/// Whether shot `shot_index`'s scene can be rendered by row windows ([`shot_scene_rows`]): a
/// target sampled on the grid (not a glTF render) without an illuminant swap (which keeps the
/// whole scene's mean luminance).
pub fn shot_scene_by_rows(set: &CaptureSet, shot_index: usize) -> bool {
    let shot = &set.shots[shot_index];
    shot.target.gltf.is_none() && shot.target.world.swapped_from.is_none()
}

/// What the luminance factor of shot `shot_index`'s scene ([`shot_scene_luminance_factor`])
/// depends on besides the target: the sampling grid `g` without its size when the mean is
/// taken over the sensor (every margin of one oversampling and aperture samples the sensor
/// with the same cells, bit for bit: [`camsim_core::scene::SamplingGrid::for_sensor`] centres
/// the grid), the whole grid when a field of view sets the window, and the focal length.
pub fn shot_scene_factor_key(set: &CaptureSet, shot_index: usize, g: &SamplingGrid) -> String {
    let shot = &set.shots[shot_index];
    let grid = match target_extent_m(set, shot) {
        None => SamplingGrid {
            rows: 0,
            cols: 0,
            ..*g
        },
        Some(_) => *g,
    };
    format!("{grid:?} f {}", set.camera.optics.focal_length_m)
}

/// The factor [`shot_scene`] scales shot `shot_index`'s scene by (to its mean luminance; 1
/// without one or for a black scene), computed from the scene rendered by row strips of about
/// [`FACTOR_STRIP_SAMPLES`] samples each in the whole scene's summation order
/// ([`camsim_core::scene::LuminanceSum`]), each strip rendered straight onto its luminance
/// plane ([`shot_scene_projected_rows`]): the same bits as the whole render's without the
/// whole scene in memory. Only for [`shot_scene_by_rows`] shots.
pub fn shot_scene_luminance_factor(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<f64, CliError> {
    let shot = &set.shots[shot_index];
    let Some(l) = shot.target.mean_luminance_cd_m2 else {
        return Ok(1.0);
    };
    refuse_unless_by_rows(set, shot_index)?;
    let g = shot_sampling_grid(set, grid);
    let window = luminance_window_m(set, shot, &g);
    let strip = (FACTOR_STRIP_SAMPLES / g.cols.max(1)).max(1);
    // rows whose centres lie in the window (the others add nothing to the sum)
    let inside =
        |r: usize| ((r as f64 + 0.5 - g.rows as f64 / 2.0) * g.pitch_m).abs() <= window.1 / 2.0;
    let mut sum = camsim_core::scene::LuminanceSum::default();
    let lw = camsim_core::colorimetry::luminance_weight_for_photons(&SI);
    let mut r0 = 0;
    while r0 < g.rows {
        let r1 = (r0 + strip).min(g.rows);
        if (r0..r1).any(inside) {
            // the strip's luminance plane, projected (not its basis-term planes)
            let part = projected_rows_on(set, shot_index, &g, r0..r1, 1.0, |b| {
                vec![b.term_integrals(&lw)]
            })?;
            sum.add_luminance_rows(&part.planes[0], g.cols, r0, g.rows, g.pitch_m, Some(window));
        }
        r0 = r1;
    }
    let now = sum.mean();
    Ok(if now <= 0.0 { 1.0 } else { l / now })
}

/// Samples per row strip of [`shot_scene_luminance_factor`] (one luminance plane: 4 MB).
pub const FACTOR_STRIP_SAMPLES: usize = 1 << 20;

/// The grid rows `rows` of [`shot_scene`] by themselves, bit for bit
/// ([`camsim_core::scene::render_target_rows`]), given the scene's luminance factor
/// `factor` ([`shot_scene_luminance_factor`], or the one [`shot_scene_and_factor`] applied on
/// a grid of the same [`shot_scene_factor_key`]). Only for [`shot_scene_by_rows`] shots.
pub fn shot_scene_rows(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    rows: std::ops::Range<usize>,
    factor: f64,
) -> Result<SceneRadiance, CliError> {
    let shot = &set.shots[shot_index];
    refuse_unless_by_rows(set, shot_index)?;
    let g = shot_sampling_grid(set, grid);
    let mut scene = scene_rows_unscaled(set, shot, &g, rows)?;
    if factor != 1.0 {
        scene.scale(factor);
    }
    Ok(scene)
}

/// [`shot_scene`] and the luminance factor it applied (1 when none; see
/// [`shot_scene_luminance_factor`]).
pub fn shot_scene_and_factor(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<(SceneRadiance, f64), CliError> {
    let shot = &set.shots[shot_index];
    if shot.target.gltf.is_some() {
        return Ok((shot_scene(set, shot_index, grid)?, 1.0));
    }
    scene_on_grid(set, shot, &shot_sampling_grid(set, grid))
}

/// The scene radiance of one shot's target, sampled for the camera's optics (with margin).
/// A `gltf` target is path-traced on that grid ([`crate::gltf_target::render_gltf_target`],
/// with depth).
pub fn shot_scene(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<SceneRadiance, CliError> {
    shot_scene_cached(set, shot_index, grid, None)
}

/// [`shot_scene`] with the renders of `gltf` targets kept in `cache` (one render per scene
/// content and render settings).
pub fn shot_scene_cached(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    cache: Option<&crate::gltf_target::RenderCache>,
) -> Result<SceneRadiance, CliError> {
    let shot = &set.shots[shot_index];
    let g = shot_sampling_grid(set, grid);
    if let Some(t) = &shot.target.gltf {
        let mut scene = crate::gltf_target::render_gltf_target(set, &shot.id, t, &g, grid, cache)?;
        if let Some(l) = shot.target.mean_luminance_cd_m2 {
            scale_to_mean_luminance(
                &mut scene,
                l,
                Some((g.sensor_width_m, g.sensor_height_m)),
                &SI,
            );
        }
        return Ok(scene);
    }
    scene_on_grid(set, shot, &g).map(|(scene, _)| scene)
}

/// The grid on which [`shot_scene`] samples every shot's scene for the capture set's camera
/// (its oversampling, blur margin and sample aperture): two cameras with the same grid, focal
/// length and wavelength grid give the same scene of a target.
pub fn shot_sampling_grid(set: &CaptureSet, grid: &WavelengthGrid) -> SamplingGrid {
    let cam = &set.camera;
    let s = &cam.sensor;
    let (os, margin) = sampling_for(&cam.optics, s, grid, set.simulation.oversample);
    let ap = sample_aperture_for(&cam.optics, s, grid, os, set.simulation.sample_aperture);
    SamplingGrid::for_sensor(s.rows, s.cols, s.pixel_pitch_m, os, margin).with_aperture(ap)
}

/// Sensor irradiance of one shot (scene → optics stage).
pub fn shot_irradiance(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<SensorIrradiance, CliError> {
    shot_irradiance_cached(set, shot_index, grid, None)
}

/// [`shot_irradiance`] with a render cache ([`shot_scene_cached`]). A scene with depth (a
/// `gltf` target) goes through the depth-aware optics stage
/// ([`crate::chain::irradiance_and_blur_of`]), as in `camsim run`.
pub fn shot_irradiance_cached(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    cache: Option<&crate::gltf_target::RenderCache>,
) -> Result<SensorIrradiance, CliError> {
    let scene = shot_scene_cached(set, shot_index, grid, cache)?;
    shot_irradiance_of_scene(set, shot_index, &scene, grid)
}

/// The optics stage of [`shot_irradiance`] on the shot's scene (from [`shot_scene`], which
/// may be kept across cameras with one [`shot_sampling_grid`]).
pub fn shot_irradiance_of_scene(
    set: &CaptureSet,
    shot_index: usize,
    scene: &SceneRadiance,
    grid: &WavelengthGrid,
) -> Result<SensorIrradiance, CliError> {
    if scene.depth_m.is_some() {
        return crate::chain::irradiance_of(set, scene, grid);
    }
    let shot = &set.shots[shot_index];
    let extent = target_extent_m(set, shot);
    crate::chain::optical_image(set, scene, grid, extent)
}

/// Image-plane extent (W, H) of a shot's target with a field of view (`None`: the target
/// fills the sensor), as [`camsim_core::scene_view::extent_in_image_plane_m`] with the optics'
/// image distance; an image target keeps its own aspect, others the sensor's.
fn target_extent_m(set: &CaptureSet, shot: &crate::config::Shot) -> Option<(f64, f64)> {
    let world = &shot.target.world;
    let f_m = set.camera.optics.focal_length_m;
    let s = &set.camera.sensor;
    world.fov_deg.map(|fov| {
        let image_distance_m = camsim_optics::thin_lens_image_distance_m(f_m, world.distance_m);
        let aspect = match &shot.target.target {
            camsim_core::scene::Target::Image { radiance } => {
                radiance.rows as f64 / radiance.cols as f64
            }
            _ => s.rows as f64 / s.cols as f64,
        };
        camsim_core::scene_view::extent_in_image_plane_m(fov, aspect, image_distance_m)
    })
}

/// Mean electron rate of every pixel for one target (optics + pixel integration + pixel
/// optics, [`crate::chain::apply_pixel_optics`]).
pub fn shot_electron_rate(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<ElectronRate, CliError> {
    shot_electron_rate_cached(set, shot_index, grid, None)
}

/// [`shot_electron_rate`] with a render cache ([`shot_scene_cached`]).
pub fn shot_electron_rate_cached(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
    cache: Option<&crate::gltf_target::RenderCache>,
) -> Result<ElectronRate, CliError> {
    let mut rate = match uniform_electron_rate(set, shot_index, grid)? {
        Some(rate) => rate,
        None => electron_rate(
            &set.camera.sensor,
            &shot_irradiance_cached(set, shot_index, grid, cache)?,
        ),
    };
    crate::chain::apply_pixel_optics(&set.camera, &mut rate);
    Ok(rate)
}

/// Fast path of [`shot_electron_rate`] for a uniform (or dark) target seen without blur,
/// diffuser or oversampling: the irradiance is then one spectrum times the relative
/// illumination R(x), so the rate of pixel (i, j) of channel c is `K_c · R(x_ij)` with
/// `K_c = p² · FF · ∫ QE_c(λ) E_axis(λ) dλ`. `E_axis` comes from the ordinary scene and optics
/// stages run on a single sample on the axis (R = 1 there), with the same luminance scaling;
/// R is evaluated at the pixel centres, as the general path does for one sample per pixel
/// (whose box average over its own cell is that sample). No full-size planes are built.
/// Returns None when the fast path does not apply.
fn uniform_electron_rate(
    set: &CaptureSet,
    shot_index: usize,
    grid: &WavelengthGrid,
) -> Result<Option<ElectronRate>, CliError> {
    use camsim_core::scene::Target;
    use camsim_optics::RelativeIllumination;
    let cam = &set.camera;
    let s = &cam.sensor;
    let shot = &set.shots[shot_index];
    if !matches!(shot.target.target, Target::Uniform { .. } | Target::Dark) {
        return Ok(None);
    }
    if !matches!(
        cam.optics.relative_illumination,
        RelativeIllumination::Cos4 | RelativeIllumination::None
    ) {
        return Ok(None);
    }
    if !matches!(cam.optics.blur, Blur::None)
        || cam.optics.diffuser.is_some()
        || cam.uncropped_optical_image
    {
        return Ok(None);
    }
    // Effect blocks the fast path folds in: exposure_scale, fall-off and veiling glare
    // (uniform target); not the warp or defocus.
    let fx = &cam.optics.effects;
    if fx.defocus.is_some() || fx.has_warp() {
        return Ok(None);
    }
    let (os, margin) = sampling_for(&cam.optics, s, grid, set.simulation.oversample);
    if (os, margin) != (1, 0) {
        return Ok(None);
    }
    // The scene on the sensor's grid, but only its sample on the axis (a uniform target has
    // the same value everywhere, and so the same mean luminance over the sensor).
    let full = SamplingGrid::for_sensor(s.rows, s.cols, s.pixel_pitch_m, os, margin);
    let g = SamplingGrid {
        rows: 1,
        cols: 1,
        ..full
    };
    let (scene, _) = scene_on_grid(set, shot, &g)?;
    // The axis sample without the glare block (added below from the mean over the sensor).
    let mut axis_optics = cam.optics.clone();
    axis_optics.effects.veiling_glare = None;
    let irr = form_image(&axis_optics, &scene, grid)
        .map_err(|e| CliError::input(&set.camera_path, format!("optics: {e}")))?;
    let img = &irr.irradiance;
    // Step 2 on the axis: K_c = p² · FF · Σ_k (∫ QE_c B_k dλ) a_k.
    let area = s.pixel_pitch_m * s.pixel_pitch_m * s.fill_factor;
    let k_c: Vec<f64> = (0..s.channel_qe.len())
        .map(|c| {
            area * camsim_sensor::channel_term_integrals(s, img, c)
                .iter()
                .zip(&img.planes)
                .map(|(w, p)| w * p[0] as f64)
                .sum::<f64>()
        })
        .collect();
    // R = cos⁴θ = (f² / (f² + r²))², tan θ = r / f (camsim_optics::relative_illumination_cos4),
    // at the pixel centres ((j − (cols−1)/2)·dx, (i − (rows−1)/2)·dx); R = 1 without fall-off.
    let cos4 = cam.optics.relative_illumination == RelativeIllumination::Cos4;
    let (f, dx) = (cam.optics.focal_length_m, irr.sample_pitch_m);
    let cos4_at = |r2_m2: f64| camsim_optics::relative_illumination_cos4_r2(r2_m2, f);
    let (yc, xc) = ((s.rows as f64 - 1.0) / 2.0, (s.cols as f64 - 1.0) / 2.0);
    let x2: Vec<f64> = (0..s.cols)
        .map(|c| ((c as f64 - xc) * dx).powi(2))
        .collect();
    // K of each column for every tile row.
    let k_rows: Vec<Vec<f64>> = s
        .cfa
        .tile
        .iter()
        .map(|t| (0..s.cols).map(|c| k_c[t[c % t.len()]]).collect())
        .collect();
    let mut out = vec![0f32; s.rows * s.cols];
    if fx.falloff.is_some() || fx.veiling_glare.is_some() {
        // Effect blocks: m(x) = R(x)·F(h) at the pixel centres, plus the veiling glare
        // f · mean over the sensor of m (the irradiance is E_axis(λ)·m(x): one spectrum).
        let hd = fx.half_diagonal_m();
        let factor = |r: usize, c: usize| -> f64 {
            let (y, x) = ((r as f64 - yc) * dx, (c as f64 - xc) * dx);
            let ri = if cos4 { cos4_at(x * x + y * y) } else { 1.0 };
            ri * fx
                .falloff
                .as_ref()
                .map_or(1.0, |f| f.factor(x.hypot(y) / hd))
        };
        let glare = match fx.veiling_glare {
            Some(g) if g > 0.0 => {
                // Row sums collected, then added in order: the same bits at any thread count.
                let sum: f64 = (0..s.rows)
                    .into_par_iter()
                    .map(|r| (0..s.cols).map(|c| factor(r, c)).sum::<f64>())
                    .collect::<Vec<f64>>()
                    .iter()
                    .sum();
                g * sum / (s.rows * s.cols) as f64
            }
            _ => 0.0,
        };
        out.par_chunks_mut(s.cols).enumerate().for_each(|(r, row)| {
            let k = &k_rows[r % k_rows.len()];
            for (c, (o, &k)) in row.iter_mut().zip(k).enumerate() {
                *o = (k * (factor(r, c) + glare)) as f32;
            }
        });
    } else {
        out.par_chunks_mut(s.cols).enumerate().for_each(|(r, row)| {
            let k = &k_rows[r % k_rows.len()];
            if cos4 {
                let y2 = ((r as f64 - yc) * dx).powi(2);
                // f² + y² once per row, and held in the returned function's locals: read
                // through this closure's capture, the focal length is re-loaded for every pixel
                // and the loop does not vectorise.
                let cos4_of_x2 = camsim_optics::relative_illumination_cos4_row(y2, f);
                for ((o, &k), &x2) in row.iter_mut().zip(k).zip(&x2) {
                    *o = (k * cos4_of_x2(x2)) as f32;
                }
            } else {
                for (o, &k) in row.iter_mut().zip(k) {
                    *o = k as f32;
                }
            }
        });
    }
    let mut rate = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: out,
    };
    // Crosstalk block (after pixel integration, as electron_rate does).
    if let Some(ct) = &s.effects.crosstalk {
        camsim_sensor::apply_crosstalk(ct, &mut rate);
    }
    Ok(Some(rate))
}

/// Run the simulation and write its outputs; on any error nothing is left in the output folder.
pub fn simulate(set: &CaptureSet, opts: &SimulateOptions) -> Result<SimulateSummary, CliError> {
    let sensor = &set.camera.sensor;
    // Recorded frames that exist must fit the sensor (spec: wrong size / bit depth is bad input).
    for shot in &set.shots {
        for f in &shot.frames {
            let p = set.dir.join(f);
            if p.extension()
                .map(|e| e.eq_ignore_ascii_case("png"))
                .unwrap_or(false)
                && p.exists()
            {
                frames::check_frame(&p, sensor.rows, sensor.cols)?;
            }
        }
    }
    let mut summary = SimulateSummary::default();
    crate::staging::with_staging(&opts.out_dir, |staging| {
        summary = run_into(set, opts, staging)?;
        Ok(summary.files.clone())
    })?;
    Ok(summary)
}

/// One product of [`simulate_each`].
#[derive(Debug)]
pub enum SimOutput {
    /// A simulated frame of shot `shot` (index into the capture set), frame `frame`.
    Frame {
        /// shot index
        shot: usize,
        /// frame index within the shot
        frame: usize,
        /// the frame (DN)
        raw: camsim_core::image::RawFrame,
    },
    /// The noise-free expected image of shot `shot` (DN, row-major, sensor size).
    Expected {
        /// shot index
        shot: usize,
        /// expected DN per pixel
        dn: Plane,
    },
}

/// The simulation loop of `camsim simulate` without any file output: every frame of every
/// shot (or, with `expected`, every shot's expected image) is handed to `sink` in order;
/// `progress(done, total)` is called after each. Returns the exposure used per shot (s).
/// `simulate` writes what this produces, so a caller of this function gets the CLI's numbers.
pub fn simulate_each(
    set: &CaptureSet,
    seed: u64,
    expected: bool,
    progress: &mut dyn FnMut(u64, u64),
    sink: &mut dyn FnMut(SimOutput) -> Result<(), CliError>,
) -> Result<Vec<(String, f64)>, CliError> {
    let sensor = &set.camera.sensor;
    let grid = wavelength_grid(set);
    let total: u64 = if expected {
        set.shots.len() as u64
    } else {
        set.shots.iter().map(|s| s.frames.len() as u64).sum()
    };
    let mut done = 0u64;
    let profile = std::env::var_os("CAMSIM_PROFILE").is_some();
    let mut tick = std::time::Instant::now();
    let mut lap = |what: &str| {
        if profile {
            eprintln!("camsim: {what}: {:.3} s", tick.elapsed().as_secs_f64());
            tick = std::time::Instant::now();
        }
    };
    // Fixed patterns: one frame draws them row by row inside the frame loop (same values,
    // no full-size maps); several frames share the maps, built once on first use.
    let total_frames: usize = if expected {
        0
    } else {
        set.shots.iter().map(|s| s.frames.len()).sum()
    };
    let mut fixed: Option<FixedPattern> = None;
    let mut cache: HashMap<&str, ElectronRate> = HashMap::new();
    // glTF targets: one render per scene content and render settings
    let renders = crate::gltf_target::RenderCache::new();
    let mut exposures_s = Vec::with_capacity(set.shots.len());
    for (si, shot) in set.shots.iter().enumerate() {
        if !cache.contains_key(shot.target_key.as_str()) {
            let rate = shot_electron_rate_cached(set, si, &grid, Some(&renders))?;
            lap("scene + optics + pixel integration");
            cache.insert(shot.target_key.as_str(), rate);
        }
        let rate = &cache[shot.target_key.as_str()];
        let sh = crate::chain::shot_exposure(set, si, rate);
        let base_rate = rate;
        let rate = &*crate::chain::shot_time_rate(set, si, rate, &sh);
        exposures_s.push((shot.id.clone(), sh.exposure_s));
        // The sensor during this shot (dark current at the shot's temperature).
        let shot_sensor = crate::chain::shot_sensor(set, si);
        if expected {
            let plane = crate::chain::expected_frame(&shot_sensor, rate, &sh);
            sink(SimOutput::Expected {
                shot: si,
                dn: plane,
            })?;
            done += 1;
            progress(done, total);
        } else {
            for fi in 0..shot.frames.len() {
                // a video: frame fi starts at fi / frame_rate (light phase and motion carry on)
                let video_rate = shot.frame_rate_hz.filter(|_| fi > 0).map(|f| {
                    crate::chain::shot_time_rate_from(set, si, base_rate, &sh, fi as f64 / f)
                });
                let rate = video_rate.as_deref().unwrap_or(rate);
                let pattern = if total_frames <= 1 {
                    PatternSource::Seeded(seed)
                } else {
                    if fixed.is_none() {
                        fixed = Some(fixed_pattern(sensor, seed));
                        lap("fixed pattern");
                    }
                    PatternSource::Maps(fixed.as_ref().expect("built above"))
                };
                let frame = crate::chain::simulate_frame_at(
                    &shot_sensor,
                    rate,
                    &sh,
                    pattern,
                    seed,
                    &[si as u64, fi as u64],
                    crate::chain::frame_index(set, si, fi),
                );
                lap("expose");
                sink(SimOutput::Frame {
                    shot: si,
                    frame: fi,
                    raw: frame,
                })?;
                lap("write");
                done += 1;
                progress(done, total);
            }
        }
    }
    Ok(exposures_s)
}

fn run_into(
    set: &CaptureSet,
    opts: &SimulateOptions,
    staging: &Path,
) -> Result<SimulateSummary, CliError> {
    let total: u64 = if opts.expected {
        set.shots.len() as u64
    } else {
        set.shots.iter().map(|s| s.frames.len() as u64).sum()
    };
    let bar = crate::progress::bar(
        opts.progress,
        total,
        "{spinner} simulate [{bar:40}] {pos}/{len} {msg} ({eta})",
    );
    let mut files = Vec::new();
    let mut sink = |out: SimOutput| -> Result<(), CliError> {
        match out {
            SimOutput::Expected { shot, dn } => {
                let rel = PathBuf::from(format!("{}.exr", set.shots[shot].id));
                write_single_channel_exr(&staging.join(&rel), "Y", &dn)
                    .map_err(|e| CliError::output(&rel, e))?;
                files.push(rel);
            }
            SimOutput::Frame { shot, frame, raw } => {
                let rel = PathBuf::from(&set.shots[shot].frames[frame]);
                let dst = staging.join(&rel);
                if let Some(parent) = dst.parent() {
                    camsim_core::cleanup::create_dir_all(parent)
                        .map_err(|e| CliError::output(parent, e))?;
                }
                frames::write_frame_with(&dst, &raw, set.raw_format.as_ref())?;
                files.push(rel);
            }
        }
        Ok(())
    };
    let exposures_s = simulate_each(
        set,
        opts.seed,
        opts.expected,
        &mut |done, _| bar.set_position(done),
        &mut sink,
    )?;
    bar.finish_and_clear();
    Ok(SimulateSummary { files, exposures_s })
}

/// Used by tests: the photon spectrum of a W spectrum with the baseline constants.
pub fn photons(s: &Spectrum) -> Spectrum {
    s.energy_to_photons(&SI)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn write(dir: &Path, optics: serde_json::Value, shots: serde_json::Value) -> CaptureSet {
        let camera = json!({
            "name": "t",
            "optics": optics,
            "sensor": {"rows": 37, "cols": 52, "pixel_pitch_um": 2.2, "fill_factor": 0.6, "cfa": ["gr", "bg"],
                       "channels": {"r": {"wavelength_nm": [400, 550, 700], "values": [0.05, 0.2, 0.6]},
                                    "g": {"wavelength_nm": [400, 520, 600, 700], "values": [0.1, 0.7, 0.3, 0.05]},
                                    "b": {"wavelength_nm": [400, 450, 700], "values": [0.6, 0.5, 0.02]}},
                       "well_capacity_e": 20000, "conversion_gain_v_per_e": 5.0e-5, "voltage_swing_v": 1.0,
                       "adc_bits": 12, "black_level_dn": 64.0, "dark_voltage_v_per_s": 1.0e-3,
                       "read_noise_v": 1.0e-3, "dsnu_sigma_v": 1.0e-3, "prnu_sigma_percent": 1.0}
        });
        std::fs::write(dir.join("camera.json"), camera.to_string()).unwrap();
        std::fs::write(
            dir.join("captures.json"),
            json!({"camera": "camera.json", "shots": shots}).to_string(),
        )
        .unwrap();
        crate::config::load_captures(&dir.join("captures.json"), None).unwrap()
    }

    #[test]
    fn uniform_fast_path_matches_general_path() {
        let dir = tempfile::tempdir().unwrap();
        let shots = json!([
            {"id": "a", "exposure_s": 0.01, "frames": ["a.png"],
             "target": {"kind": "uniform", "radiance": {"wavelength_nm": [400, 500, 700], "values": [0.002, 0.004, 0.001]}}},
            {"id": "b", "exposure_s": 0.01, "frames": ["b.png"],
             "target": {"kind": "uniform", "radiance": 0.003, "mean_luminance_cd_m2": 50.0}},
            {"id": "c", "exposure_s": 0.01, "frames": ["c.png"], "target": {"kind": "dark"}}
        ]);
        for ri in ["cos4", "none"] {
            // A short focal length makes the cos⁴ fall-off across this small sensor large.
            let optics = json!({"f_number": 2.8, "focal_length_mm": 0.05, "transmittance": 0.9,
                                "relative_illumination": ri, "blur": {"kind": "none"}});
            let set = write(dir.path(), optics, shots.clone());
            let grid = wavelength_grid(&set);
            for si in 0..3 {
                let fast = uniform_electron_rate(&set, si, &grid)
                    .unwrap()
                    .expect("fast path applies");
                let general = electron_rate(
                    &set.camera.sensor,
                    &shot_irradiance(&set, si, &grid).unwrap(),
                );
                assert_eq!((fast.rows, fast.cols), (general.rows, general.cols));
                let (lo, hi) = general
                    .electrons_per_s
                    .iter()
                    .fold((f32::MAX, 0f32), |(a, b), &v| (a.min(v), b.max(v)));
                if si < 2 && ri == "cos4" {
                    assert!(lo < 0.9 * hi, "fall-off visible: {lo} {hi}");
                }
                for (i, (a, b)) in fast
                    .electrons_per_s
                    .iter()
                    .zip(&general.electrons_per_s)
                    .enumerate()
                {
                    let (a, b) = (*a as f64, *b as f64);
                    assert!(
                        (a - b).abs() <= 1e-6 * b.abs(),
                        "{ri} shot {si} pixel {i}: {a} vs {b}"
                    );
                }
            }
        }
        // Not applicable with blur.
        let optics = json!({"f_number": 2.8, "focal_length_mm": 3.0, "relative_illumination": "cos4",
                            "blur": {"kind": "gaussian", "sigma_um": 1.0}});
        let set = write(dir.path(), optics, shots);
        assert!(uniform_electron_rate(&set, 0, &wavelength_grid(&set))
            .unwrap()
            .is_none());
    }
}
