//! Shot targets of kind `gltf` (a camsim extension of the capture format; docs/config.md
//! "glTF scenes as targets"): a glTF 2.0 scene path-traced on the shot's scene sampling grid
//! by the same render job as `camsim run` ([`crate::animated::grid_render_job`], a pinhole
//! render of radiance with planar depth), so that the one chain's optics stage
//! ([`crate::chain::irradiance_and_blur_of`]) forms its image depth-aware. Renders are cached
//! per (scene file content, render settings, sampling grid) within one `simulate`
//! ([`RenderCache`]): shots of the same scene render once.
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
];

/// The largest `spp` a target may ask for (the work budget then bounds spp × samples).
pub const MAX_SPP: f64 = 1e6;

/// A glTF scene as a shot's target and how to render it.
#[derive(Debug, Clone, PartialEq)]
pub struct GltfTarget {
    /// The glTF 2.0 file (.gltf or .glb), resolved against the capture file's folder.
    pub file: PathBuf,
    /// FNV-1a 64-bit hash of the file's bytes (the render cache's identity of the scene).
    pub file_hash: u64,
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
}

/// FNV-1a, 64 bit (Fowler, Noll & Vo; the published offset basis and prime).
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= *b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
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
    let bytes =
        std::fs::read(&file).map_err(|e| format!(".file: {}: cannot read: {e}", file.display()))?;
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
        file_hash: fnv1a64(&bytes),
        camera_name,
        spp,
        seed,
        bands,
        max_depth,
        depth_optics,
    })
}

impl GltfTarget {
    /// The render's bands (band centres): [`GltfTarget::bands`] or the simulation grid.
    pub fn render_grid<'a>(&'a self, sim: &'a WavelengthGrid) -> &'a WavelengthGrid {
        self.bands.as_ref().unwrap_or(sim)
    }

    /// The render cache's key: the scene's content and every setting that changes the
    /// render, with the grid it is rendered on.
    fn cache_key(
        &self,
        g: &SamplingGrid,
        os: usize,
        margin: usize,
        sim: &WavelengthGrid,
    ) -> String {
        let r = self.render_grid(sim);
        format!(
            "{:016x}|{:?}|{}|{}|{}|{}|{:?}|{:?}|{}x{}|{}|{}|{:e}",
            self.file_hash,
            self.camera_name,
            self.spp,
            self.seed,
            self.max_depth,
            self.depth_optics,
            r.wavelength_nm,
            sim.wavelength_nm,
            g.rows,
            g.cols,
            os,
            margin,
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
    let side = |n: usize| (n as f64 + 2.0 * margin as f64) * os as f64;
    let samples = side(s.rows) * side(s.cols);
    crate::budget::check_work(
        Some(&set.path),
        &format!("{key}.target.spp"),
        samples * t.spp as f64,
        &format!(
            "{:.0}×{:.0} scene samples (sensor + {margin} px margin, {os}×{os} per pixel) × {} \
             paths",
            side(s.cols),
            side(s.rows),
            t.spp
        ),
    )
}

/// The scene radiance (with planar depth unless `depth_optics` is false) of the glTF target
/// `t` of shot `shot_id` on the sampling grid `g` (`os` samples per pixel side, `margin`
/// pixels around the sensor), on the simulation wavelengths `sim`: the render job of
/// `camsim run` ([`crate::animated::grid_render_job`], pinhole camera,
/// [`crate::animated::render_job_radiance`]). With a `cache`, a render of the same scene
/// content and settings is made once. Errors name the capture file, the shot and the key.
#[allow(clippy::too_many_arguments)]
pub fn render_gltf_target(
    set: &CaptureSet,
    shot_id: &str,
    t: &GltfTarget,
    g: &SamplingGrid,
    os: usize,
    margin: usize,
    sim: &WavelengthGrid,
    cache: Option<&RenderCache>,
) -> Result<SceneRadiance, CliError> {
    let key = t.cache_key(g, os, margin, sim);
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
    let job = crate::animated::grid_render_job(
        &t.file,
        &crate::animated::GridRender {
            camera_name: t.camera_name.clone(),
            camera: camsim_render::job::CameraChoice::Pinhole,
            sensor: &set.camera.sensor,
            oversample: os,
            margin_px: margin,
            spp: t.spp,
            max_depth: t.max_depth,
        },
        t.seed,
        t.render_grid(sim),
    )
    .map_err(err)?;
    let mut scene = crate::guard::guarded(&t.file, || {
        crate::animated::render_job_radiance(&job, None, g.pitch_m, t.render_grid(sim))
    })
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
    if t.bands.is_some() {
        scene.radiance = scene.radiance.to_bands(sim);
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
