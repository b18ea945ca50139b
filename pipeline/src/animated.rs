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

/// The render job of `scene` on `set`'s scene sampling grid ((rows + 2·margin)·os ×
/// (cols + 2·margin)·os samples of pitch pixel_pitch/os; the glTF camera's vertical field of
/// view spans the grid's height), pinhole, bands centred on the simulation wavelengths.
pub fn grid_job(
    set: &CaptureSet,
    scene: &AnimatedScene,
    seed: u64,
    grid: &WavelengthGrid,
) -> Result<(RenderJob, usize), CliError> {
    let cam = &set.camera;
    let sensor = &cam.sensor;
    let (os, margin) =
        crate::chain::sampling_for(&cam.optics, sensor, grid, set.simulation.oversample);
    let step = grid.step_nm().ok_or_else(|| {
        CliError::input(
            &scene.gltf,
            "the wavelength grid must be regular to render a scene",
        )
    })?;
    let (w0, wn) = (grid.wavelength_nm[0], grid.wavelength_nm[grid.len() - 1]);
    let bands = camsim_render::Bands::new(w0 - step / 2.0, wn + step / 2.0, step)
        .map_err(|e| CliError::input(&scene.gltf, format!("render bands: {e}")))?;
    if scene.spp == 0 {
        return Err(CliError::input(
            &scene.gltf,
            "spp = 0: need at least one sample per scene sample",
        ));
    }
    Ok((
        RenderJob {
            scene: scene.gltf.clone(),
            camera_name: scene.camera_name.clone(),
            camera: CameraChoice::Pinhole,
            width: ((sensor.cols + 2 * margin) * os) as u32,
            height: Some(((sensor.rows + 2 * margin) * os) as u32),
            aperture_radius_m: None,
            focus_distance_m: None,
            settings: camsim_render::RenderSettings {
                spp: scene.spp,
                seed,
                bands,
                max_depth: -1,
                rr_depth: camsim_render::RenderSettings::default().rr_depth,
                variance: false,
                depth_spp: 0,
            },
        },
        os,
    ))
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
    let err = |e: camsim_render::RenderError| CliError::input(&scene.gltf, e.to_string());
    let p = prepare_at_time(&job, Some(time_s)).map_err(err)?;
    let out = camsim_render::render(
        &p.scene,
        p.camera.as_ref(),
        p.camera_to_world,
        &job.settings,
        None,
    );
    let pitch_m = set.camera.sensor.pixel_pitch_m / os as f64;
    let mut sr = camsim_render::output::scene_radiance(&out, pitch_m, None).map_err(err)?;
    sr.radiance = sr.radiance.to_bands(grid);
    Ok(sr)
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
