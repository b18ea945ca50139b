//! Shot targets of kind `gltf` (a camsim extension of the capture format; docs/config.md
//! "glTF scenes as targets"): a glTF 2.0 scene path-traced on the shot's scene sampling grid
//! by the one function that renders `camsim run`'s scenes too
//! ([`crate::chain::render_gltf_on_grid`]: radiance with planar depth, the same render camera
//! policy), so that the one chain's optics stage ([`crate::chain::irradiance_and_blur_of`])
//! forms its image depth-aware. Renders are cached per (scene file, render settings, sampling
//! grid) within one `simulate` ([`RenderCache`]): shots of the same scene render once.
use crate::config::CaptureSet;
use crate::error::CliError;
use camsim_core::image::SceneRadiance;
use camsim_core::scene::SamplingGrid;
use camsim_core::spectrum::WavelengthGrid;
use serde_json::{Map, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Keys of a `gltf` target (besides `kind`, `radiance_unit` and `mean_luminance_cd_m2`).
pub const GLTF_KEYS: &[&str] = &[
    "file",
    "camera_name",
    "spp",
    "seed",
    "bands",
    "max_depth",
    "depth_optics",
    "field_of_view",
];

/// The largest `spp` a target may ask for (the work budget then bounds spp × samples).
pub const MAX_SPP: f64 = 1e6;

/// A glTF scene as a shot's target and how to render it.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfTarget {
    /// The glTF 2.0 file (.gltf or .glb), resolved against the capture file's folder.
    pub file: PathBuf,
    /// The render cache's identity of the scene: the file's canonical path (its relative
    /// buffers and textures resolve against its folder), size and modification time.
    pub file_identity: String,
    /// The glTF camera (node or camera name; None: the first).
    pub camera_name: Option<String>,
    /// Path-tracing samples per scene sample (default 16, as `camsim run`).
    pub spp: u32,
    /// Seed of the render (default 0; the sensor noise uses `simulate --seed`).
    pub seed: u64,
    /// Render bands (band centres; None: the simulation's wavelength grid). The render is
    /// resampled onto the simulation grid.
    pub bands: Option<WavelengthGrid>,
    /// Longest path (Mitsuba's convention, −1 = unlimited; default −1).
    pub max_depth: i32,
    /// Keep the render's depth so the optics stage defocuses by depth (default true; the
    /// camera needs `optics.focus_distance_m` or `blur.kind = "lens"` for it to act).
    pub depth_optics: bool,
    /// The field the sensor sees (`"camera"`, default: the glTF camera's; `"optics"`: the
    /// field the camera's lens images onto the sensor).
    pub field_of_view: crate::chain::FieldOfView,
}

/// Parse the keys of a `gltf` target (`m`, already checked for unknown keys). Errors start
/// with the key below `target` (".spp: …").
pub fn gltf_target(m: &Map<String, Value>, dir: &Path) -> Result<GltfTarget, String> {
    for k in ["fov_deg", "distance_m", "swap_illuminant"] {
        if m.contains_key(k) {
            return Err(format!(
                ".{k}: not for a gltf target (the glTF camera sets the view and the scene its \
                 distances and lights)"
            ));
        }
    }
    if m.contains_key("radiance_unit") {
        return Err(".radiance_unit: not for a gltf target (the render is in W/(sr·m²·nm))".into());
    }
    let f = m
        .get("file")
        .and_then(Value::as_str)
        .filter(|s| !s.is_empty())
        .ok_or(".file: required (a .gltf or .glb path, relative to the capture file)")?;
    let file = dir.join(f);
    crate::staging::protect_input(&file);
    let limit = crate::budget::memory_limit().bytes;
    let meta = std::fs::metadata(&file)
        .map_err(|e| format!(".file: {}: cannot read: {e}", file.display()))?;
    if !meta.is_file() {
        return Err(format!(".file: {}: not a file", file.display()));
    }
    if meta.len() > limit {
        return Err(format!(
            ".file: {}: {} is over the memory limit of {} (docs/limits.md)",
            file.display(),
            crate::budget::human_bytes(meta.len() as f64),
            crate::budget::human_bytes(limit as f64)
        ));
    }
    let canonical = std::fs::canonicalize(&file)
        .map_err(|e| format!(".file: {}: cannot read: {e}", file.display()))?;
    let modified_ns = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    let file_identity = format!("{}|{}|{modified_ns}", canonical.display(), meta.len());
    let num = |k: &str| -> Result<Option<f64>, String> {
        match m.get(k) {
            None => Ok(None),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .map(Some)
                .ok_or_else(|| format!(".{k}: must be a number")),
        }
    };
    let spp = match num("spp")? {
        None => 16,
        Some(v) if v >= 1.0 && v <= MAX_SPP && v.fract() == 0.0 => v as u32,
        Some(v) => {
            return Err(format!(
                ".spp: must be a whole number of samples from 1 to {MAX_SPP:e}, got {v}"
            ))
        }
    };
    let seed = match num("seed")? {
        None => 0,
        Some(v) if v >= 0.0 && v.fract() == 0.0 && v < 2f64.powi(53) => v as u64,
        Some(v) => return Err(format!(".seed: must be a non-negative integer, got {v}")),
    };
    let max_depth = match num("max_depth")? {
        None => -1,
        Some(v) if v >= -1.0 && v <= 1e4 && v.fract() == 0.0 => v as i32,
        Some(v) => {
            return Err(format!(
                ".max_depth: must be −1 (unlimited) or a path length up to 10000, got {v}"
            ))
        }
    };
    let camera_name = match m.get("camera_name") {
        None => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(_) => return Err(".camera_name: must be a string".into()),
    };
    let depth_optics = match m.get("depth_optics") {
        None => true,
        Some(Value::Bool(b)) => *b,
        Some(_) => return Err(".depth_optics: must be true or false".into()),
    };
    let field_of_view = match m.get("field_of_view") {
        None => crate::chain::FieldOfView::Camera,
        Some(Value::String(v)) => {
            crate::chain::FieldOfView::parse(v).map_err(|e| format!(".field_of_view: {e}"))?
        }
        Some(v) => {
            return Err(format!(
                ".field_of_view: {v}: expected \"camera\" or \"optics\""
            ))
        }
    };
    let bands = match m.get("bands") {
        None => None,
        Some(v) => {
            let g: crate::config::GridFile = serde_json::from_value(v.clone()).map_err(|e| {
                format!(".bands: {e} (expected {{\"start_nm\", \"stop_nm\", \"step_nm\"}})")
            })?;
            let grid = WavelengthGrid::regular(g.start_nm, g.stop_nm, g.step_nm)
                .map_err(|e| format!(".bands: {e}"))?;
            if grid.len() < 2 || grid.len() > 1000 {
                return Err(format!(".bands: needs 2 to 1000 bands, got {}", grid.len()));
            }
            Some(grid)
        }
    };
    Ok(GltfTarget {
        file,
        file_identity,
        camera_name,
        spp,
        seed,
        bands,
        max_depth,
        depth_optics,
        field_of_view,
    })
}

impl GltfTarget {
    /// The render's bands (band centres): [`GltfTarget::bands`] or the simulation grid.
    pub fn render_grid<'a>(&'a self, sim: &'a WavelengthGrid) -> &'a WavelengthGrid {
        self.bands.as_ref().unwrap_or(sim)
    }

    /// The render cache's key: the scene file's identity and every setting that changes the
    /// render, with the grid it is rendered on (the grid's size and pitch fix the
    /// oversampling and margin; one cache serves one capture set, so one camera).
    fn cache_key(&self, g: &SamplingGrid, sim: &WavelengthGrid) -> String {
        let r = self.render_grid(sim);
        format!(
            "{}|{:?}|{}|{}|{}|{}|{:?}|{:?}|{:?}|{}x{}|{:e}",
            self.file_identity,
            self.camera_name,
            self.spp,
            self.seed,
            self.max_depth,
            self.depth_optics,
            self.field_of_view,
            r.wavelength_nm,
            sim.wavelength_nm,
            g.rows,
            g.cols,
            g.pitch_m
        )
    }
}

/// Renders of glTF targets kept for one `simulate` (keyed by scene content, render settings
/// and sampling grid).
#[derive(Debug, Default)]
pub struct RenderCache {
    renders: Mutex<HashMap<String, Arc<SceneRadiance>>>,
    count: Mutex<usize>,
}

impl RenderCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }
    /// How many renders were made through this cache.
    pub fn renders(&self) -> usize {
        *self.count.lock().expect("render count")
    }
}

/// The path-traced samples (rows × cols × spp) of `t` on `set`'s grid, refused over the work
/// budget ([`crate::budget::check_work`]) with the shot's key.
pub fn check_render_work(set: &CaptureSet, key: &str, t: &GltfTarget) -> Result<(), CliError> {
    let grid = crate::simulate::wavelength_grid(set);
    let s = &set.camera.sensor;
    let (os, margin) =
        crate::chain::sampling_for(&set.camera.optics, s, &grid, set.simulation.oversample);
    let g = SamplingGrid::for_sensor(s.rows, s.cols, s.pixel_pitch_m, os, margin);
    let samples = g.rows as f64 * g.cols as f64;
    crate::budget::check_work(
        Some(&set.path),
        &format!("{key}.target.spp"),
        samples * t.spp as f64,
        &format!(
            "{}×{} scene samples (sensor + {margin} px margin, {os}×{os} per pixel) × {} paths",
            g.cols, g.rows, t.spp
        ),
    )
}

/// The scene radiance (with planar depth unless `depth_optics` is false) of the glTF target
/// `t` of shot `shot_id` on the sampling grid `g` of `set`'s camera, on the simulation
/// wavelengths `sim`: [`crate::chain::render_gltf_on_grid`], the render of `camsim run`
/// (same camera policy). With a `cache`, a render of the same scene file and settings is
/// made once. Errors name the capture file, the shot and the key.
pub fn render_gltf_target(
    set: &CaptureSet,
    shot_id: &str,
    t: &GltfTarget,
    g: &SamplingGrid,
    sim: &WavelengthGrid,
    cache: Option<&RenderCache>,
) -> Result<SceneRadiance, CliError> {
    let key = t.cache_key(g, sim);
    if let Some(c) = cache {
        if let Some(r) = c.renders.lock().expect("render cache").get(&key) {
            return Ok((**r).clone());
        }
    }
    let err = |e: CliError| {
        CliError::input(
            &set.path,
            format!("shot {shot_id}: target.file: {}", e.one_line()),
        )
    };
    let mut scene = crate::chain::render_gltf_on_grid(
        set,
        &crate::chain::GltfOnGrid {
            scene: &t.file,
            camera_name: t.camera_name.clone(),
            camera: None,
            spp: t.spp,
            max_depth: t.max_depth,
            seed: t.seed,
            bands: t.bands.as_ref(),
            field_of_view: t.field_of_view,
        },
        sim,
    )
    .map_err(err)?;
    if scene.radiance.rows != g.rows || scene.radiance.cols != g.cols {
        return Err(CliError::input(
            &set.path,
            format!(
                "shot {shot_id}: target.file: the render is {}×{} samples, the grid {}×{}",
                scene.radiance.rows, scene.radiance.cols, g.rows, g.cols
            ),
        ));
    }
    if !t.depth_optics {
        scene.depth_m = None;
    }
    if let Some(c) = cache {
        c.renders
            .lock()
            .expect("render cache")
            .insert(key, Arc::new(scene.clone()));
        *c.count.lock().expect("render count") += 1;
    }
    Ok(scene)
}
