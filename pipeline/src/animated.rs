//! Animated glTF scenes as the scene of a shot: the scene file, its render settings and the
//! time step of the time nodes, and the path-traced scene radiance on the sensor's sampling
//! grid at one instant ([`render_on_grid_at`]). The per-row time integration of a rolling (or
//! global) shutter over these renders is in the one chain
//! ([`crate::chain::animated_shot_rate`]).
//!
//! Why a render per time node and not one render moved by a projected velocity: the glTF
//! animation moves objects (and the camera) independently, so the image is not one rigid
//! translation (a bar sliding over a still wall, parallax between depths, occlusion); a
//! render at each node is exact at the node whatever the motion, and between nodes the rate
//! is interpolated linearly in time ([`camsim_sensor::temporal_nodes`]).
use crate::config::CaptureSet;
use crate::error::CliError;
use camsim_core::spectrum::WavelengthGrid;
use camsim_core::SceneRadiance;
use camsim_render::job::{prepare_at_time, CameraChoice, RenderJob};
use std::path::PathBuf;

/// An animated glTF scene and how to render it.
#[derive(Debug, Clone, PartialEq)]
pub struct AnimatedScene {
    /// The glTF 2.0 file (its animations move nodes; [`camsim_render::animation`]).
    pub gltf: PathBuf,
    /// Camera node/camera name (None: the first camera).
    pub camera_name: Option<String>,
    /// Path-tracing samples per scene sample.
    pub spp: u32,
    /// Spacing of the time nodes (s).
    pub time_step_s: f64,
}

/// What a render on the scene sampling grid needs besides the scene file.
#[derive(Debug, Clone)]
pub struct GridRender<'a> {
    /// The glTF camera (node or camera name; None: the first).
    pub camera_name: Option<String>,
    /// The render camera (pinhole for the depth-aware optics).
    pub camera: CameraChoice,
    /// The sensor whose grid is sampled.
    pub sensor: &'a camsim_sensor::SensorModel,
    /// Scene samples per pixel side.
    pub oversample: usize,
    /// Border (pixels) around the sensor for the blur's reach.
    pub margin_px: usize,
    /// Path-tracing samples per scene sample (≥ 1).
    pub spp: u32,
    /// Longest path (Mitsuba's convention, −1 = unlimited).
    pub max_depth: i32,
    /// Vertical field of view (rad) of the render; `None`: the glTF camera's
    /// ([`crate::chain::FieldOfView`]).
    pub yfov_rad: Option<f64>,
}

/// The render job of `gltf` on the scene sampling grid of `g` ((rows + 2·margin)·os ×
/// (cols + 2·margin)·os samples of pitch pixel_pitch/os; the vertical field of view of
/// [`GridRender::yfov_rad`], else the glTF camera's, spans the grid's height), bands centred on the simulation wavelengths `grid`.
pub fn grid_render_job(
    gltf: &std::path::Path,
    g: &GridRender,
    seed: u64,
    grid: &WavelengthGrid,
) -> Result<RenderJob, CliError> {
    let step = grid
        .step_nm()
        .ok_or_else(|| CliError::input(gltf, "render: the wavelength grid must be regular"))?;
    let (w0, wn) = (grid.wavelength_nm[0], grid.wavelength_nm[grid.len() - 1]);
    let bands = camsim_render::Bands::new(w0 - step / 2.0, wn + step / 2.0, step)
        .map_err(|e| CliError::input(gltf, format!("render bands: {e}")))?;
    if g.spp == 0 {
        return Err(CliError::input(
            gltf,
            "spp = 0: need at least one sample per scene sample",
        ));
    }
    let (os, margin, sensor) = (g.oversample, g.margin_px, g.sensor);
    Ok(RenderJob {
        scene: gltf.to_path_buf(),
        camera_name: g.camera_name.clone(),
        camera: g.camera.clone(),
        width: ((sensor.cols + 2 * margin) * os) as u32,
        height: Some(((sensor.rows + 2 * margin) * os) as u32),
        aperture_radius_m: None,
        focus_distance_m: None,
        yfov_rad: g.yfov_rad,
        settings: camsim_render::RenderSettings {
            spp: g.spp,
            seed,
            bands,
            max_depth: g.max_depth,
            rr_depth: camsim_render::RenderSettings::default().rr_depth,
            variance: false,
            depth_spp: 0,
            environment: None,
        },
    })
}

/// The scene radiance (with planar depth) of a grid render job at `time_s` (None: the
/// animations ignored), samples of pitch `pitch_m`, on the simulation wavelengths `grid`.
/// Refuses a camera that does not give radiance (the optics stage forms the image).
pub fn render_job_radiance(
    job: &RenderJob,
    time_s: Option<f64>,
    pitch_m: f64,
    grid: &WavelengthGrid,
) -> Result<SceneRadiance, CliError> {
    let err = |e: camsim_render::RenderError| CliError::input(&job.scene, e.to_string());
    let p = prepare_at_time(job, time_s).map_err(err)?;
    if p.camera.output_quantity() != camsim_render::camera::OutputQuantity::Radiance {
        return Err(CliError::input(
            &job.scene,
            "render.camera: the scene must be rendered as radiance (pinhole or thinlens); the optics stage forms the image",
        ));
    }
    let out = camsim_render::render(
        &p.scene,
        p.camera.as_ref(),
        p.camera_to_world,
        &job.settings,
        None,
    );
    let mut sr = camsim_render::output::scene_radiance(&out, pitch_m, None).map_err(err)?;
    // the band-centre cube onto the simulation grid (same wavelengths)
    sr.radiance = sr.radiance.to_bands(grid);
    Ok(sr)
}

/// The render job of `scene` on `set`'s scene sampling grid ([`grid_render_job`], pinhole,
/// unlimited path depth) and the grid's oversampling.
pub fn grid_job(
    set: &CaptureSet,
    scene: &AnimatedScene,
    seed: u64,
    grid: &WavelengthGrid,
) -> Result<(RenderJob, usize), CliError> {
    let cam = &set.camera;
    let (os, margin) =
        crate::chain::sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
    let g = GridRender {
        camera_name: scene.camera_name.clone(),
        camera: CameraChoice::Pinhole,
        sensor: &cam.sensor,
        oversample: os,
        margin_px: margin,
        spp: scene.spp,
        max_depth: -1,
        yfov_rad: None,
    };
    Ok((grid_render_job(&scene.gltf, &g, seed, grid)?, os))
}

/// The scene radiance of `scene` at time `time_s` on `set`'s sampling grid (with depth), on
/// the simulation wavelengths.
pub fn render_on_grid_at(
    set: &CaptureSet,
    scene: &AnimatedScene,
    seed: u64,
    grid: &WavelengthGrid,
    time_s: f64,
) -> Result<SceneRadiance, CliError> {
    let (job, os) = grid_job(set, scene, seed, grid)?;
    let pitch_m = set.camera.sensor.pixel_pitch_m / os as f64;
    render_job_radiance(&job, Some(time_s), pitch_m, grid)
}

/// The image velocity (sensor pixels per second, `[x, y]`, x along columns, y down the rows)
/// of node `node` of `scene` at time `time_s`: the difference of its pinhole projections
/// ([`camsim_render::job::node_film_position_px`]) at `time_s ± h/2` over h, divided by the
/// render's oversampling. Exact for a LINEAR translation parallel to the image plane within
/// one keyframe interval (the projection is then linear in time).
pub fn node_image_velocity_px_per_s(
    set: &CaptureSet,
    scene: &AnimatedScene,
    node: &str,
    time_s: f64,
    h_s: f64,
) -> Result<[f64; 2], CliError> {
    let grid = crate::chain::wavelength_grid(set);
    let (job, os) = grid_job(set, scene, 0, &grid)?;
    let err = |e: camsim_render::RenderError| CliError::input(&scene.gltf, e.to_string());
    let a =
        camsim_render::job::node_film_position_px(&job, node, time_s - h_s / 2.0).map_err(err)?;
    let b =
        camsim_render::job::node_film_position_px(&job, node, time_s + h_s / 2.0).map_err(err)?;
    Ok([
        (b[0] - a[0]) / h_s / os as f64,
        (b[1] - a[1]) / h_s / os as f64,
    ])
}
