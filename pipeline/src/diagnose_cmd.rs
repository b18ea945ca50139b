//! `camsim diagnose CAPTURES.json --out DIR`: find the physics the camera model leaves out.
//!
//! The recording is reduced once (per shot: per-pixel frame mean, temporal variance, rail
//! counts); the believed camera's forward model (this crate's `simulate` stages, through the
//! [`Forward`] trait of `camsim_diagnose::mismatch`) gives the photo-electron rates, and the
//! diagnosis (fit check → locate → candidates → BIC selection) runs in camsim-diagnose.
//! Outputs, all or nothing: `DIR/report.json` (spec/effects.md), `DIR/fitted_camera.json`
//! (the camera format with the fitted effect blocks; `camsim simulate --camera` reproduces
//! the recording with it) and `DIR/report.html` with its figures.
mod figures;

use crate::chain::{
    optics_alike_at_every_wavelength, sampling_for, shot_irradiance_of_scene, wavelength_grid,
};
use crate::config::{camera_from_file, CameraFile, CaptureSet, Exposure};
use crate::error::CliError;
use crate::raw_input::read_frame_with;
use crate::staging::with_staging;
use camsim_core::scene::Target;
use camsim_diagnose::mismatch::{
    diagnose, DataSet, DiagnoseOptions, Diagnosis, Effect, Forward, ModelState, RateSpec,
    ShotAccumulator, TargetClass,
};
use camsim_sensor::PixelTermPlanes;
use rayon::prelude::*;
use serde_json::{json, Map, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Options of one `diagnose` run.
#[derive(Debug, Clone)]
pub struct DiagnoseCmdOptions {
    /// Accept a candidate when its ΔBIC is below −threshold.
    pub bic_threshold: f64,
    /// Restrict the candidates to these effect ids (empty: all).
    pub effects: Vec<String>,
    /// Show progress on a terminal.
    pub progress: bool,
}

impl Default for DiagnoseCmdOptions {
    fn default() -> Self {
        DiagnoseCmdOptions {
            bic_threshold: 10.0,
            effects: Vec::new(),
            progress: false,
        }
    }
}

/// The forward model of the believed camera with a [`RateSpec`] applied: the effect blocks
/// are set on the typed camera (as the camera file with those blocks would give), and the
/// one chain's scene → optics stages give each shot's irradiance.
///
/// The QE blocks (`qe_shift`, `ir_leakage`) change only the spectral weights of pixel
/// integration, not the irradiance, and the integration is linear in the irradiance's basis
/// terms. So the pixel-averaged term planes of the sensor crate
/// ([`camsim_sensor::pixel_term_planes`]) are kept per optics configuration ([`PlaneCache`])
/// and a candidate QE costs one weighted sum per pixel
/// ([`camsim_sensor::electron_rate_from_term_planes`]) instead of a re-render of every target.
struct SimForward {
    /// The capture set whose camera is replaced per call (behind a lock: calls are
    /// sequential, each internally parallel).
    set: Mutex<CaptureSet>,
    /// The believed camera, to which each call applies its [`RateSpec`].
    believed: crate::config::Camera,
    camera_path: PathBuf,
    /// Indices in the capture set of the data set's shots.
    shots: Vec<usize>,
    /// Pixel-averaged irradiance planes per optics configuration.
    planes: Mutex<PlaneCache>,
    /// Scene radiance per target and sampling grid ([`SceneCache`]).
    scenes: Mutex<SceneCache>,
    /// The veiling glare's whole-field sums per optics configuration (without the glare) and
    /// target, for the fit rows' bands ([`Forward::rates_rows`]).
    glare: Mutex<HashMap<String, Arc<camsim_optics::GlareSums>>>,
    /// The glare sums of candidate optics from a decimated whole field ([`GlareDecimation`]).
    glare_decimated: Mutex<GlareDecimation>,
    /// What the forward runs cost, by kind of work ([`ForwardWork`]).
    work: ForwardWork,
}

/// Counters of the forward model's work by kind (calls and wall seconds; with
/// `CAMSIM_PROFILE`, in the progress log and timing.json): where a large sensor's time goes.
#[derive(Default)]
struct ForwardWork {
    /// Whole scenes rendered ([`crate::chain::shot_scene`]) and their bytes.
    scene_renders: WorkCounter,
    scene_bytes: std::sync::atomic::AtomicU64,
    /// Whole scenes rendered straight onto the channel planes
    /// ([`crate::chain::shot_channel_scene_rows`]) and their bytes.
    channel_scene_renders: WorkCounter,
    channel_scene_bytes: std::sync::atomic::AtomicU64,
    /// Bands of a scene rendered by themselves ([`crate::chain::shot_scene_rows`]).
    scene_band_renders: WorkCounter,
    /// Luminance factors computed by row strips
    /// ([`crate::chain::shot_scene_luminance_factor`]: one whole scene's render, by strips).
    factor_passes: WorkCounter,
    /// Whole-sensor optics runs for the veiling glare's sums ([`crate::chain::shot_glare_sums`]).
    glare_sums: WorkCounter,
    /// Glare sums of candidate optics from a decimated whole field
    /// ([`SimForward::decimated_glare`]: the coarse render and optics, per target).
    glare_decimated: WorkCounter,
    /// Bands of rows through the optics ([`crate::chain::band_irradiance`]).
    band_optics: WorkCounter,
    /// Whole-sensor optics runs ([`Forward::rates`]: channel planes or basis-term planes).
    whole_optics: WorkCounter,
}

/// Calls and wall time of one kind of work.
#[derive(Default)]
struct WorkCounter {
    calls: std::sync::atomic::AtomicU64,
    nanos: std::sync::atomic::AtomicU64,
}

impl WorkCounter {
    /// Count one call that started at `t0`.
    fn add(&self, t0: std::time::Instant) {
        use std::sync::atomic::Ordering::Relaxed;
        self.calls.fetch_add(1, Relaxed);
        self.nanos
            .fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
    }

    /// (calls, seconds).
    fn get(&self) -> (u64, f64) {
        use std::sync::atomic::Ordering::Relaxed;
        (
            self.calls.load(Relaxed),
            self.nanos.load(Relaxed) as f64 * 1e-9,
        )
    }
}

impl ForwardWork {
    /// The counters as (stage name, calls, seconds).
    fn stages(&self) -> Vec<(String, u64, f64)> {
        let gb = self.scene_bytes.load(std::sync::atomic::Ordering::Relaxed) as f64 * 1e-9;
        let cgb = self
            .channel_scene_bytes
            .load(std::sync::atomic::Ordering::Relaxed) as f64
            * 1e-9;
        let one = |name: String, c: &WorkCounter| {
            let (n, s) = c.get();
            (name, n, s)
        };
        vec![
            one(
                format!("forward: whole scenes rendered ({gb:.1} GB in all)"),
                &self.scene_renders,
            ),
            one(
                format!("forward: whole channel scenes rendered ({cgb:.1} GB in all)"),
                &self.channel_scene_renders,
            ),
            one(
                "forward: scene bands rendered".into(),
                &self.scene_band_renders,
            ),
            one(
                "forward: luminance factors by row strips".into(),
                &self.factor_passes,
            ),
            one(
                "forward: whole-sensor optics for the glare sums".into(),
                &self.glare_sums,
            ),
            one(
                "forward: decimated whole fields for the glare sums".into(),
                &self.glare_decimated,
            ),
            one(
                "forward: bands through the optics".into(),
                &self.band_optics,
            ),
            one("forward: whole-sensor optics".into(), &self.whole_optics),
        ]
    }

    /// One line for the progress log.
    fn summary(&self) -> String {
        self.stages()
            .iter()
            .map(|(n, c, s)| format!("{}: {c} / {s:.1} s", n.trim_start_matches("forward: ")))
            .collect::<Vec<_>>()
            .join("; ")
    }
}

impl SimForward {
    /// The forward model of `set`'s camera (the believed one) on the shots `shots`, with empty
    /// caches.
    fn new(set: &CaptureSet, shots: Vec<usize>) -> Self {
        SimForward {
            set: Mutex::new(set.clone()),
            believed: set.camera.clone(),
            camera_path: set.camera_path.clone(),
            shots,
            planes: Mutex::new(PlaneCache::default()),
            scenes: Mutex::new(SceneCache::with_budget(scene_cache_budget())),
            glare: Mutex::new(HashMap::new()),
            glare_decimated: Mutex::new(GlareDecimation::default()),
            work: ForwardWork::default(),
        }
    }
}

/// Each target's scene radiance (the chain's [`crate::chain::shot_scene`]) by target and
/// sampling grid ([`crate::chain::shot_sampling_grid`]). The scene depends on the camera only
/// through that grid, the focal length and the wavelength grid, none of which the optics
/// candidates change except the grid's blur margin: a forward run of a candidate optics block
/// re-runs only the optics stage (the render and its luminance scaling were about half of a
/// run's time). Least recently used evicted first beyond [`scene_cache_budget`].
///
/// With the believed camera's QE blocks a chart's scene is kept on the sensor channels'
/// planes ([`SceneCache::channel_scene`], rendered straight onto them): 3–4 planes instead of
/// 25 basis terms, so a 12 MP chart (0.8 GB, not 4.8 GB) is kept between the fit check and
/// the confirmation.
///
/// A band of rows of a scene ([`SceneCache::scene_bands`]) is cut from the whole scene when
/// that is at hand, else rendered by itself ([`crate::chain::shot_scene_rows`], the same
/// bits) with the scene's luminance factor, which is kept per target and
/// [`crate::chain::shot_scene_factor_key`] (every blur margin of one oversampling shares it):
/// a new sampling grid then costs the bands' rows, not a whole 12 MP scene.
#[derive(Default)]
struct SceneCache {
    lru: LruBytes<Arc<camsim_core::image::SceneRadiance>, SCENE_CACHE_BYTES>,
    /// Luminance factor by target key and [`crate::chain::shot_scene_factor_key`].
    factors: HashMap<String, f64>,
}

/// The least memory for cached scenes ([`scene_cache_budget`]).
const SCENE_CACHE_BYTES: usize = 256 << 20;

/// Share of the memory limit the scene cache may hold ([`scene_cache_budget`]).
const SCENE_CACHE_SHARE: f64 = 0.2;

/// Memory for cached scenes: [`SCENE_CACHE_SHARE`] of the memory limit
/// ([`crate::budget::memory_limit`]: `--max-memory`, else ¾ of the available memory), at
/// least [`SCENE_CACHE_BYTES`] (docs/limits.md). At 12 MP a chart's channel scene is 0.8 GB
/// (4 planes × 48 M samples × 4 B) and a flat's or dark's 0.2 GB: a diagnosis with a 20 GB
/// limit keeps the 4 targets of the 12 MP benchmark set (2 GB of 4 GB).
fn scene_cache_budget() -> usize {
    let lim = crate::budget::memory_limit().bytes as f64 * SCENE_CACHE_SHARE;
    (lim.min(usize::MAX as f64) as usize).max(SCENE_CACHE_BYTES)
}

/// A map from keys to values that keeps its values' bytes within `BUDGET`, evicting the least
/// recently used first (the forward model's caches of scenes and pixel planes).
struct LruBytes<V, const BUDGET: usize> {
    /// Value, its last-use stamp and its bytes, by key.
    entries: HashMap<String, (u64, V, usize)>,
    bytes: usize,
    stamp: u64,
    /// The byte budget in force: `BUDGET` (tests lower it).
    budget: usize,
}

impl<V, const BUDGET: usize> Default for LruBytes<V, BUDGET> {
    fn default() -> Self {
        LruBytes {
            entries: HashMap::new(),
            bytes: 0,
            stamp: 0,
            budget: BUDGET,
        }
    }
}

impl<V: Clone, const BUDGET: usize> LruBytes<V, BUDGET> {
    /// The value of `key` (marked as used now), if kept.
    fn get(&mut self, key: &str) -> Option<V> {
        self.stamp += 1;
        let st = self.stamp;
        self.entries.get_mut(key).map(|e| {
            e.0 = st;
            e.1.clone()
        })
    }

    /// Keep `value` of `bytes` under `key` when it fits in the budget, evicting the least
    /// recently used values first.
    fn insert(&mut self, key: String, value: V, bytes: usize) {
        if bytes > self.budget {
            return;
        }
        if let Some((_, _, b)) = self.entries.remove(&key) {
            self.bytes -= b;
        }
        while self.bytes + bytes > self.budget && !self.entries.is_empty() {
            let oldest = self
                .entries
                .iter()
                .min_by_key(|(_, v)| v.0)
                .map(|(k, _)| k.clone())
                .expect("non-empty");
            if let Some((_, _, b)) = self.entries.remove(&oldest) {
                self.bytes -= b;
            }
        }
        self.stamp += 1;
        self.bytes += bytes;
        self.entries.insert(key, (self.stamp, value, bytes));
    }
}

fn scene_bytes(s: &camsim_core::image::SceneRadiance) -> usize {
    s.radiance.planes.iter().map(|x| x.len() * 4).sum::<usize>()
        + s.depth_m.as_ref().map_or(0, |d| d.data.len() * 4)
}

impl SceneCache {
    /// An empty cache holding at most `budget` bytes.
    fn with_budget(budget: usize) -> Self {
        let mut c = SceneCache::default();
        c.lru.budget = budget;
        c
    }

    /// What of the camera shapes a target's scene that a candidate can change: the sampling
    /// grid, the focal length and the wavelength grid. The rest (focus, sensor size, render
    /// settings) is the believed camera's, fixed for one [`SimForward`], which the cache
    /// belongs to.
    fn grid_key(set: &CaptureSet, grid: &camsim_core::WavelengthGrid) -> String {
        format!(
            "{:?} f {} λ {:?}",
            crate::chain::shot_sampling_grid(set, grid),
            set.camera.optics.focal_length_m,
            grid.wavelength_nm
        )
    }

    /// The scene of shot `si` of `set` (whose camera is the one of this call), from the cache
    /// or rendered (and kept when it fits); `grid_key` is [`SceneCache::grid_key`] of the
    /// call's camera. Renders are counted in `work`.
    fn scene(
        &mut self,
        set: &CaptureSet,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        grid_key: &str,
        work: &ForwardWork,
    ) -> Result<Arc<camsim_core::image::SceneRadiance>, String> {
        let key = format!("{} {grid_key}", set.shots[si].target_key);
        if let Some(scene) = self.lru.get(&key) {
            return Ok(scene);
        }
        let t0 = std::time::Instant::now();
        let (scene, factor) =
            crate::chain::shot_scene_and_factor(set, si, grid).map_err(|e| e.one_line())?;
        let scene = Arc::new(scene);
        work.scene_renders.add(t0);
        if crate::chain::shot_scene_by_rows(set, si) {
            self.factors.insert(Self::factor_key(set, si, grid), factor);
        }
        let bytes = scene_bytes(&scene);
        work.scene_bytes
            .fetch_add(bytes as u64, std::sync::atomic::Ordering::Relaxed);
        self.lru.insert(key, scene.clone(), bytes);
        Ok(scene)
    }

    /// The luminance factor of shot `si`'s scene (a [`crate::chain::shot_scene_by_rows`]
    /// shot): kept, or computed once by row strips.
    fn factor(
        &mut self,
        set: &CaptureSet,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        work: &ForwardWork,
    ) -> Result<f64, String> {
        let fkey = Self::factor_key(set, si, grid);
        if let Some(f) = self.factors.get(&fkey) {
            return Ok(*f);
        }
        let t0 = std::time::Instant::now();
        let f =
            crate::chain::shot_scene_luminance_factor(set, si, grid).map_err(|e| e.one_line())?;
        work.factor_passes.add(t0);
        self.factors.insert(fkey, f);
        Ok(f)
    }

    /// The scene of shot `si` on the sensor channels' planes ([`crate::chain::channel_scene`]
    /// of [`SceneCache::scene`], bit for bit), from the cache or rendered straight onto the
    /// planes ([`crate::chain::shot_channel_scene_rows`] with the scene's luminance factor;
    /// a shot that cannot be rendered by rows: from its whole scene). For the camera's QE
    /// blocks, which are the believed camera's whenever the channel path is taken
    /// ([`channel_path`]).
    fn channel_scene(
        &mut self,
        set: &CaptureSet,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        grid_key: &str,
        work: &ForwardWork,
    ) -> Result<Arc<camsim_core::image::SceneRadiance>, String> {
        let key = format!("{} {grid_key} channels", set.shots[si].target_key);
        if let Some(scene) = self.lru.get(&key) {
            return Ok(scene);
        }
        let scene = if crate::chain::shot_scene_by_rows(set, si) {
            let factor = self.factor(set, si, grid, work)?;
            let t0 = std::time::Instant::now();
            let rows = crate::chain::shot_sampling_grid(set, grid).rows;
            let (_, chs) = crate::chain::shot_channel_scene_rows(set, si, grid, 0..rows, factor)
                .map_err(|e| e.one_line())?;
            work.channel_scene_renders.add(t0);
            work.channel_scene_bytes.fetch_add(
                scene_bytes(&chs) as u64,
                std::sync::atomic::Ordering::Relaxed,
            );
            chs
        } else {
            let whole = self.scene(set, si, grid, grid_key, work)?;
            crate::chain::channel_scene(set, &whole)
                .map_err(|e| e.one_line())?
                .1
        };
        let scene = Arc::new(scene);
        self.lru.insert(key, scene.clone(), scene_bytes(&scene));
        Ok(scene)
    }

    /// Key of [`SceneCache::factors`].
    fn factor_key(set: &CaptureSet, si: usize, grid: &camsim_core::WavelengthGrid) -> String {
        let g = crate::chain::shot_sampling_grid(set, grid);
        format!(
            "{} {}",
            set.shots[si].target_key,
            crate::chain::shot_scene_factor_key(set, si, &g)
        )
    }

    /// Rows `r0..r1` of [`SceneCache::scene`] (with `channels`: of
    /// [`SceneCache::channel_scene`]) for each of `ranges`, kept by themselves: cut
    /// ([`crate::chain::scene_rows`]) from `whole` when the caller holds that scene already (of
    /// this `grid_key` and kind: the glare sums' render) or from the cached whole scene; else
    /// rendered by themselves ([`crate::chain::shot_scene_rows`], or straight onto the
    /// channel planes, [`crate::chain::shot_channel_scene_rows`], with the scene's luminance
    /// factor: kept, or computed once by row strips); a target that cannot be rendered by
    /// rows is rendered whole once and cut.
    #[allow(clippy::too_many_arguments)]
    fn scene_bands(
        &mut self,
        set: &CaptureSet,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        grid_key: &str,
        ranges: &[(usize, usize)],
        whole: Option<Arc<camsim_core::image::SceneRadiance>>,
        channels: bool,
        work: &ForwardWork,
    ) -> Result<Vec<Arc<camsim_core::image::SceneRadiance>>, String> {
        let kind = if channels { " channels" } else { "" };
        let key = |(r0, r1): (usize, usize)| {
            format!(
                "{} {grid_key}{kind} rows {r0}..{r1}",
                set.shots[si].target_key
            )
        };
        let mut whole = whole;
        let mut out = Vec::with_capacity(ranges.len());
        for &r in ranges {
            if let Some(scene) = self.lru.get(&key(r)) {
                out.push(scene);
                continue;
            }
            if whole.is_none() {
                let wkey = format!("{} {grid_key}{kind}", set.shots[si].target_key);
                whole = self.lru.get(&wkey);
            }
            if whole.is_none() && crate::chain::shot_scene_by_rows(set, si) {
                let factor = self.factor(set, si, grid, work)?;
                let t0 = std::time::Instant::now();
                let band = if channels {
                    crate::chain::shot_channel_scene_rows(set, si, grid, r.0..r.1, factor)
                        .map(|(_, chs)| chs)
                } else {
                    crate::chain::shot_scene_rows(set, si, grid, r.0..r.1, factor)
                }
                .map_err(|e| e.one_line())?;
                work.scene_band_renders.add(t0);
                let band = Arc::new(band);
                self.lru.insert(key(r), band.clone(), scene_bytes(&band));
                out.push(band);
                continue;
            }
            if whole.is_none() {
                whole = Some(if channels {
                    self.channel_scene(set, si, grid, grid_key, work)?
                } else {
                    self.scene(set, si, grid, grid_key, work)?
                });
            }
            let w = whole.as_ref().expect("rendered");
            let band = Arc::new(crate::chain::scene_rows(w, r.0, r.1));
            self.lru.insert(key(r), band.clone(), scene_bytes(&band));
            out.push(band);
        }
        Ok(out)
    }
}

/// The veiling glare's whole-field sums of candidate optics without a whole-field run per
/// candidate ([`SimForward::decimated_glare`]): each candidate's sums come from the
/// [`crate::chain::decimated_glare_field`] (the same physical sensor and optics on a grid `k`
/// times coarser per side, oversampling 1), scaled by the exact sums of a reference optics
/// setting — the believed optics, whose full-resolution sums the fit check stores
/// ([`Forward::rates`] → [`camsim_optics::glare_sums_of_image`]):
///
///   mean_j(θ) ≈ exact_mean_j(ref) · coarse_mean_j(θ) / coarse_mean_j(ref)
///
/// per plane j (the glare of plane j is `f · mean_j`, [`camsim_optics::GlareSums`]), when the
/// reference's planes are those of the candidate's run (same representation: the sensor
/// channels' planes or the scene's basis terms, and as many); else (a lateral-colour or QE
/// candidate's basis-term planes, split into wavelength bands or not, against the believed
/// run's channel planes) by one factor for every plane,
/// `Σ_j exact_mean_j(ref) / Σ_j coarse_mean_j(ref)` over the reference's planes. At the
/// reference itself the candidate's sums are the exact ones (a candidate at its null value
/// gives the baseline's rates); the decimation's error enters only through how the optics'
/// change moves the coarse field's mean differently from the full one's (test
/// `decimated_glare_sums_match_the_whole_field_sums`). The full-resolution confirmation
/// ([`Forward::rates`]) forms the whole image and its own glare: the accepted model is always
/// checked exactly.
#[derive(Default)]
struct GlareDecimation {
    /// Coarse scenes by target key and [`SceneCache::grid_key`] of the coarse set.
    scenes: LruBytes<Arc<camsim_core::image::SceneRadiance>, GLARE_COARSE_SCENE_BYTES>,
    /// Coarse sums of the reference (believed) optics by target key and representation.
    reference: HashMap<String, Arc<camsim_optics::GlareSums>>,
    /// Candidate sums by the key of [`SimForward::glare`] (optics without the glare, target,
    /// representation).
    sums: HashMap<String, Arc<camsim_optics::GlareSums>>,
    /// The decimation factor `k` of the last use (0: never used): for report.json.
    k: usize,
}

/// Memory for the decimated fields' scenes (a 12 MP chart's: 375 × 500 samples × 25 planes,
/// 19 MB).
const GLARE_COARSE_SCENE_BYTES: usize = 128 << 20;

/// Per plane j, `exact_mean_j · coarse_j / reference_j` (means: sums over counts), with
/// `exact`'s count, when `exact` (and `reference`, its coarse twin) has the planes of `coarse`
/// (`same_representation` and as many); else one factor for every plane
/// ([`GlareDecimation`]'s equation). A zero reference plane keeps the coarse mean.
fn scale_glare_sums(
    exact: &camsim_optics::GlareSums,
    reference: &camsim_optics::GlareSums,
    coarse: &camsim_optics::GlareSums,
    same_representation: bool,
) -> camsim_optics::GlareSums {
    let mean = |g: &camsim_optics::GlareSums, j: usize| g.sums[j] / g.count;
    let per_plane = same_representation
        && exact.sums.len() == reference.sums.len()
        && reference.sums.len() == coarse.sums.len();
    let common = {
        let e: f64 = (0..exact.sums.len()).map(|j| mean(exact, j)).sum();
        let r: f64 = (0..reference.sums.len()).map(|j| mean(reference, j)).sum();
        if r != 0.0 {
            e / r
        } else {
            1.0
        }
    };
    let sums = (0..coarse.sums.len())
        .map(|j| {
            let factor = if !per_plane {
                common
            } else if reference.sums[j] != 0.0 {
                mean(exact, j) / mean(reference, j)
            } else {
                1.0
            };
            factor * mean(coarse, j) * exact.count
        })
        .collect();
    camsim_optics::GlareSums {
        sums,
        count: exact.count,
    }
}

impl SimForward {
    /// The glare sums of `set`'s optics (its camera: a candidate's, with the glare block) for
    /// shot `si` from the decimated field ([`GlareDecimation`]), in the representation the
    /// bands will run: the channel planes when `channel_capable` and the target's scene has
    /// more basis terms than `used_channels`, else the basis terms. `None` when there is no
    /// decimated field ([`crate::chain::decimated_glare_field`]) or no exact sums of the
    /// believed optics for this target yet (the caller runs the whole field). Returns the
    /// sums and whether they are the channel planes'.
    fn decimated_glare(
        &self,
        set: &CaptureSet,
        spec: &RateSpec,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        channel_capable: bool,
        used_channels: usize,
    ) -> Result<Option<(Arc<camsim_optics::GlareSums>, bool)>, String> {
        fn lock_err<T>(_: T) -> String {
            "forward model lock poisoned".to_string()
        }
        let Some((coarse, k)) = crate::chain::decimated_glare_field(set) else {
            return Ok(None);
        };
        // the reference: the believed optics (with the candidate's glare block, which does
        // not change the sums) and its exact sums, stored by the fit check
        let ref_spec = RateSpec {
            glare_fraction: spec.glare_fraction,
            ..Default::default()
        };
        let mut ref_set = set.clone();
        ref_set.camera = self.camera_for(&ref_spec)?;
        let ref_grid = wavelength_grid(&ref_set);
        let key = &set.shots[si].target_key;
        let ref_key = format!(
            "{} target {key}",
            Self::optics_key(&ref_set, &RateSpec::default(), &ref_grid)
        );
        let (exact_ch, exact_te) = {
            let g = self.glare.lock().map_err(lock_err)?;
            (
                g.get(&format!("{ref_key} channels")).cloned(),
                g.get(&ref_key).cloned(),
            )
        };
        if exact_ch.is_none() && exact_te.is_none() {
            return Ok(None);
        }
        let t0 = std::time::Instant::now();
        let mut dec = self.glare_decimated.lock().map_err(lock_err)?;
        let scene_of = |dec: &mut GlareDecimation,
                        c: &CaptureSet,
                        g: &camsim_core::WavelengthGrid|
         -> Result<Arc<camsim_core::image::SceneRadiance>, String> {
            let skey = format!("{key} {}", SceneCache::grid_key(c, g));
            if let Some(s) = dec.scenes.get(&skey) {
                return Ok(s);
            }
            let s = Arc::new(crate::chain::shot_scene(c, si, g).map_err(|e| e.one_line())?);
            dec.scenes.insert(skey, s.clone(), scene_bytes(&s));
            Ok(s)
        };
        let scene = scene_of(&mut dec, &coarse, grid)?;
        let channel = channel_capable && scene.radiance.terms() > used_channels;
        let (coarse_sums, _) =
            crate::chain::decimated_glare_sums(&coarse, si, grid, channel, Some(scene))
                .map_err(|e| e.one_line())?;
        // the exact reference in the candidate's representation, else the other one
        let (exact, ref_channel) = match (channel, exact_ch, exact_te) {
            (true, Some(e), _) | (false, Some(e), None) => (e, true),
            (_, _, Some(e)) => (e, false),
            (_, None, None) => return Ok(None),
        };
        let rkey = format!("{key}{}", if ref_channel { " channels" } else { "" });
        let reference = match dec.reference.get(&rkey) {
            Some(r) => r.clone(),
            None => {
                let (ref_coarse, _) = crate::chain::decimated_glare_field(&ref_set)
                    .ok_or("the believed camera has no decimated field")?;
                let scene = scene_of(&mut dec, &ref_coarse, &ref_grid)?;
                let (r, _) = crate::chain::decimated_glare_sums(
                    &ref_coarse,
                    si,
                    &ref_grid,
                    ref_channel,
                    Some(scene),
                )
                .map_err(|e| e.one_line())?;
                let r = Arc::new(r);
                dec.reference.insert(rkey, r.clone());
                r
            }
        };
        dec.k = k;
        drop(dec);
        self.work.glare_decimated.add(t0);
        Ok(Some((
            Arc::new(scale_glare_sums(
                &exact,
                &reference,
                &coarse_sums,
                ref_channel == channel,
            )),
            channel,
        )))
    }
}

/// Pixel planes by optics key, then by target key; least recently used evicted first when
/// the planes exceed [`PLANE_CACHE_BYTES`].
type PlaneCache = LruBytes<HashMap<String, Arc<PixelTermPlanes>>, PLANE_CACHE_BYTES>;

/// Memory for cached pixel planes.
const PLANE_CACHE_BYTES: usize = 384 << 20;

fn planes_bytes(m: &HashMap<String, Arc<PixelTermPlanes>>) -> usize {
    m.values()
        .map(|p| p.planes.iter().map(|x| x.len() * 4).sum::<usize>())
        .sum()
}

impl SimForward {
    /// The capture set's camera with `spec` applied (crosstalk removed: the diagnosis applies
    /// it).
    fn camera_for(&self, spec: &RateSpec) -> Result<crate::config::Camera, String> {
        let mut cam = self.believed.clone();
        apply_rate_spec_typed(&mut cam, spec).map_err(|e| {
            format!(
                "{}: the camera with the candidate effect is invalid: {e}",
                self.camera_path.display()
            )
        })?;
        cam.sensor.effects.crosstalk = None;
        Ok(cam)
    }

    /// Whether shot `si`'s optics run on the sensor channels' planes: the camera may
    /// (`channel_capable`, [`channel_path`]) and its scene has more basis terms than the CFA
    /// has channels (`used`) and no depth. The terms are the target's
    /// ([`camsim_core::scene::target_basis`]) for a shot rendered by rows (nothing is
    /// rendered to tell), else its rendered scene's.
    fn channel_mode(
        &self,
        set: &CaptureSet,
        si: usize,
        grid: &camsim_core::WavelengthGrid,
        grid_key: &str,
        (channel_capable, used): (bool, usize),
    ) -> Result<bool, String> {
        if !channel_capable {
            return Ok(false);
        }
        if crate::chain::shot_scene_by_rows(set, si) {
            let basis = camsim_core::scene::target_basis(&set.shots[si].target.target)
                .map_err(|e| format!("{}: shot {}: {e}", set.path.display(), set.shots[si].id))?;
            return Ok(basis.len() > used);
        }
        let scene = self
            .scenes
            .lock()
            .map_err(|_| "forward model lock poisoned".to_string())?
            .scene(set, si, grid, grid_key, &self.work)?;
        Ok(scene.depth_m.is_none() && scene.radiance.terms() > used)
    }

    /// Key of everything but the QE blocks that shapes the pixel planes: the optics blocks,
    /// the scene sampling and, when the optics depend on wavelength (per-wavelength PSFs,
    /// warps) or the planes are wavelength bands, the wavelength grid.
    fn optics_key(set: &CaptureSet, spec: &RateSpec, grid: &camsim_core::WavelengthGrid) -> String {
        use camsim_optics::Blur;
        let optics_spec = RateSpec {
            ir_leakage: None,
            qe_shift_nm: None,
            ..spec.clone()
        };
        let cam = &set.camera;
        let (os, margin) = sampling_for(&cam.optics, &cam.sensor, grid, set.simulation.oversample);
        let grid_free = matches!(
            cam.optics.blur,
            Blur::None | Blur::Gaussian { .. } | Blur::Pillbox { .. }
        ) && !cam.optics.effects.has_warp();
        let g = if grid_free {
            String::new()
        } else {
            format!("{:?}", grid.wavelength_nm)
        };
        format!("{} os {os} margin {margin} {g}", optics_spec.key())
    }
}

/// Most of the scene sampling grid's rows the bands of a fit-row forward run may cover: more,
/// and the whole sensor is run (no dearer, and one entry in the caches).
const BAND_GRID_FRACTION: f64 = 0.5;

/// The row bands that hold pixel rows `rows` (ascending) for `set`'s camera: one per run of
/// consecutive rows, widened to whole CFA tiles, bands whose scene rows (with the optics'
/// margin, [`crate::chain::band_scene_rows`]) overlap merged. `None` when the camera cannot
/// run a band by itself ([`crate::chain::band_refusal`]) or the bands' scene rows exceed
/// [`BAND_GRID_FRACTION`] of the grid's. With the bands, each band's warp widening
/// ([`crate::chain::band_warp_widening`], computed once here for the whole forward run).
fn row_bands(
    set: &CaptureSet,
    grid: &camsim_core::WavelengthGrid,
    rows: &[usize],
) -> Option<(Vec<crate::chain::RowBand>, Vec<crate::chain::BandWidening>)> {
    use crate::chain::{band_refusal, band_scene_rows, RowBand};
    let s = &set.camera.sensor;
    let tile = s.cfa.tile_rows().max(1);
    let (os, margin) = sampling_for(&set.camera.optics, s, grid, set.simulation.oversample);
    let mut bands: Vec<RowBand> = Vec::new();
    for &r in rows {
        if r >= s.rows {
            return None;
        }
        let b = RowBand {
            start: r / tile * tile,
            end: ((r / tile + 1) * tile).min(s.rows),
        };
        match bands.last_mut() {
            // scene rows of the two overlap (or touch): one band
            Some(last) if b.start <= last.end + 2 * margin => last.end = last.end.max(b.end),
            _ => bands.push(b),
        }
    }
    if bands.is_empty() || bands.iter().any(|b| band_refusal(set, *b).is_some()) {
        return None;
    }
    let widen: Vec<_> = bands
        .iter()
        .map(|b| crate::chain::band_warp_widening(set, grid, *b))
        .collect();
    let scene_rows: usize = bands
        .iter()
        .zip(&widen)
        .map(|(b, w)| {
            let (r0, r1) = band_scene_rows(set, grid, *b, *w);
            r1 - r0
        })
        .sum();
    let grid_rows = (s.rows + 2 * margin) * os;
    (scene_rows as f64 <= BAND_GRID_FRACTION * grid_rows as f64).then_some((bands, widen))
}

impl Forward for SimForward {
    /// With the believed camera: whether the fit rows' bands ([`row_bands`]) cover less than
    /// [`BAND_GRID_FRACTION`] of the scene grid.
    fn row_window(&self, rows: &[usize]) -> bool {
        let Ok(set) = self.set.lock() else {
            return false;
        };
        let mut set = set.clone();
        set.camera = self.believed.clone();
        let grid = wavelength_grid(&set);
        row_bands(&set, &grid, rows).is_some()
    }

    /// The bands of [`row_bands`] through the chain by themselves
    /// ([`crate::chain::band_irradiance`] of the band's scene rows, the glare from the whole
    /// field's sums), each band's pixel planes kept as [`Forward::rates`] keeps the whole
    /// sensor's; rows outside the bands are 0. Every row when [`row_bands`] says no.
    fn rates_rows(&self, spec: &RateSpec, rows: &[usize]) -> Result<Vec<Arc<Vec<f32>>>, String> {
        let cam = self.camera_for(spec)?;
        fn lock_err<T>(_: T) -> String {
            "forward model lock poisoned".to_string()
        }
        let mut set = self.set.lock().map_err(lock_err)?;
        set.camera = cam;
        let grid = wavelength_grid(&set);
        let Some((bands, widen)) = row_bands(&set, &grid, rows) else {
            drop(set);
            return self.rates(spec);
        };
        // (on the channel planes the planes hold the believed QE: a key of their own)
        let (channel_capable, channels) = channel_path(&set, &self.believed);
        // Optics that depend on wavelength with the believed QE: each band's wavelength planes
        // projected onto the channels inside the optics, after the lateral-colour warp
        // ([`crate::chain::band_channel_irradiance`]); their planes are the channels' too.
        let projected = !channel_capable && believed_qe(&set, &self.believed);
        let okey = format!(
            "{} bands {bands:?}{}",
            Self::optics_key(&set, spec, &grid),
            if channel_capable || projected {
                " channels"
            } else {
                ""
            }
        );
        let cached = self.planes.lock().map_err(lock_err)?.get(&okey);
        let mut by_band: HashMap<String, Arc<PixelTermPlanes>> = cached.clone().unwrap_or_default();
        let (rows_n, cols) = (set.camera.sensor.rows, set.camera.sensor.cols);
        let glare_on = set
            .camera
            .optics
            .effects
            .veiling_glare
            .is_some_and(|f| f > 0.0);
        let glare_key = Self::optics_key(
            &set,
            &RateSpec {
                glare_fraction: None,
                ..spec.clone()
            },
            &grid,
        );
        let grid_key = std::cell::OnceCell::new();
        let mut rate_by_target: HashMap<String, Arc<Vec<f32>>> = HashMap::new();
        let mut out = Vec::with_capacity(self.shots.len());
        let used_channels = channels.len();
        for &si in &self.shots {
            let key = set.shots[si].target_key.clone();
            if let Some(r) = rate_by_target.get(&key) {
                out.push(r.clone());
                continue;
            }
            let gk: &String = grid_key.get_or_init(|| SceneCache::grid_key(&set, &grid));
            // The path of `rates`: the optics on the channel planes when they act alike at
            // every wavelength, the QE blocks are the believed ones and the target's scene has
            // more basis terms than the CFA has channels (`channel_rate`); else on the terms.
            let channel_mode_of =
                || self.channel_mode(&set, si, &grid, gk, (channel_capable, used_channels));
            let tkey = format!("{glare_key} target {key}");
            let ckey = format!("{tkey} channels");
            // The whole scene when the glare sums rendered it: the bands are cut from it.
            let mut whole_scene = None;
            let mut mode: Option<bool> = None;
            let glare = if glare_on {
                let (ch, te) = {
                    let g = self.glare.lock().map_err(lock_err)?;
                    (
                        g.get(&ckey).cloned().filter(|_| channel_capable),
                        g.get(&tkey).cloned(),
                    )
                };
                // without exact sums of these optics: the decimated field's (kept per key)
                let mut dec_hit = None;
                if ch.is_none() && te.is_none() {
                    let kept = {
                        let d = self.glare_decimated.lock().map_err(lock_err)?;
                        match d.sums.get(&ckey).filter(|_| channel_capable) {
                            Some(g) => Some((g.clone(), true)),
                            None => d.sums.get(&tkey).map(|g| (g.clone(), false)),
                        }
                    };
                    dec_hit = match kept {
                        Some(k) => Some(k),
                        None => {
                            let got = self.decimated_glare(
                                &set,
                                spec,
                                si,
                                &grid,
                                channel_capable,
                                used_channels,
                            )?;
                            if let Some((g, channel)) = &got {
                                let k = if *channel { &ckey } else { &tkey };
                                self.glare_decimated
                                    .lock()
                                    .map_err(lock_err)?
                                    .sums
                                    .insert(k.clone(), g.clone());
                            }
                            got
                        }
                    };
                }
                Some(match (ch, te) {
                    (Some(g), _) => {
                        mode = Some(true);
                        g
                    }
                    // (the terms' sums of these optics: the bands on the terms are exact too)
                    (None, Some(g)) => {
                        mode = Some(false);
                        g
                    }
                    // a decimated field's sums, scaled to the believed optics' exact sums
                    _ if dec_hit.is_some() => {
                        let (g, channel) = dec_hit.take().expect("checked");
                        mode = Some(channel);
                        g
                    }
                    _ => {
                        let channel = channel_mode_of()?;
                        mode = Some(channel);
                        // (on the channel planes: the whole scene rendered straight onto them)
                        let whole = {
                            let mut sc = self.scenes.lock().map_err(lock_err)?;
                            if channel {
                                sc.channel_scene(&set, si, &grid, gk, &self.work)?
                            } else {
                                sc.scene(&set, si, &grid, gk, &self.work)?
                            }
                        };
                        let t0 = std::time::Instant::now();
                        let g = crate::chain::shot_glare_sums(&set, &whole, &grid)
                            .map_err(|e| e.one_line())?
                            .ok_or("veiling glare without its sums")?;
                        self.work.glare_sums.add(t0);
                        whole_scene = Some(whole);
                        let g = Arc::new(g);
                        let k = if channel { &ckey } else { &tkey };
                        self.glare
                            .lock()
                            .map_err(lock_err)?
                            .insert(k.clone(), g.clone());
                        g
                    }
                })
            } else {
                None
            };
            // (a band's planes on the channel planes are kept under their own key)
            let bkey = |bi: usize, channel: bool| {
                format!("{key} band {bi}{}", if channel { " channels" } else { "" })
            };
            let missing: Vec<usize> = (0..bands.len())
                .filter(|&bi| {
                    !by_band.contains_key(&bkey(bi, false))
                        && !by_band.contains_key(&bkey(bi, true))
                })
                .collect();
            if !missing.is_empty() {
                let ranges: Vec<(usize, usize)> = missing
                    .iter()
                    .map(|&bi| crate::chain::band_scene_rows(&set, &grid, bands[bi], widen[bi]))
                    .collect();
                let channel = match mode {
                    Some(m) => m,
                    None => channel_mode_of()?,
                };
                // (on the channel planes: the bands rendered straight onto them)
                let scenes = self.scenes.lock().map_err(lock_err)?.scene_bands(
                    &set,
                    si,
                    &grid,
                    gk,
                    &ranges,
                    whole_scene,
                    channel,
                    &self.work,
                )?;
                for (&bi, scene) in missing.iter().zip(&scenes) {
                    let band = bands[bi];
                    let t0 = std::time::Instant::now();
                    let (irr, on_channels) = if !channel && projected {
                        let ch = crate::chain::band_channel_irradiance(
                            &set,
                            scene,
                            &grid,
                            band,
                            widen[bi],
                            glare.as_deref(),
                        )
                        .map_err(|e| e.one_line())?;
                        if ch.channels != channels {
                            return Err(format!(
                                "{}: band optics projected onto channels {:?}, the CFA's are {:?}",
                                self.camera_path.display(),
                                ch.channels,
                                channels
                            ));
                        }
                        (ch.irradiance, true)
                    } else {
                        let irr = crate::chain::band_irradiance(
                            &set,
                            scene,
                            &grid,
                            band,
                            widen[bi],
                            glare.as_deref(),
                        )
                        .map_err(|e| e.one_line())?;
                        (irr, channel)
                    };
                    self.work.band_optics.add(t0);
                    let sensor = crate::chain::band_sensor(&set, band);
                    let p = Arc::new(camsim_sensor::pixel_term_planes(&sensor, &irr));
                    by_band.insert(bkey(bi, on_channels), p);
                }
            }
            let mut rate = vec![0f32; rows_n * cols];
            for (bi, band) in bands.iter().enumerate() {
                let sensor = crate::chain::band_sensor(&set, *band);
                let r = match by_band.get(&bkey(bi, true)) {
                    Some(pp) => {
                        camsim_sensor::electron_rate_from_channel_planes(&sensor, &channels, pp)
                    }
                    None => camsim_sensor::electron_rate_from_term_planes(
                        &sensor,
                        &by_band[&bkey(bi, false)],
                    ),
                };
                rate[band.start * cols..band.end * cols].copy_from_slice(&r);
            }
            let r = Arc::new(rate);
            rate_by_target.insert(key, r.clone());
            out.push(r);
        }
        if cached.is_none() {
            let bytes = planes_bytes(&by_band);
            self.planes
                .lock()
                .map_err(lock_err)?
                .insert(okey, by_band, bytes);
        }
        Ok(out)
    }

    fn rates(&self, spec: &RateSpec) -> Result<Vec<Arc<Vec<f32>>>, String> {
        let cam = self.camera_for(spec)?;
        let mut set = self
            .set
            .lock()
            .map_err(|_| "forward model lock poisoned".to_string())?;
        set.camera = cam;
        let grid = wavelength_grid(&set);
        let okey = Self::optics_key(&set, spec, &grid);
        let cached = {
            let mut pc = self
                .planes
                .lock()
                .map_err(|_| "forward model lock poisoned".to_string())?;
            pc.get(&okey)
        };
        let mut by_target: HashMap<String, Arc<PixelTermPlanes>> =
            cached.clone().unwrap_or_default();
        let mut added = false;
        let mut rate_by_target: HashMap<String, Arc<Vec<f32>>> = HashMap::new();
        let mut out = Vec::with_capacity(self.shots.len());
        // (computed on the first render: the margin of a warp costs an inverse map)
        let grid_key = std::cell::OnceCell::new();
        // The QE blocks of the believed camera: the optics then act on the channel planes
        // (see `channel_rate`); a candidate QE reads the cached term planes instead.
        let (channel_capable, channels) = channel_path(&set, &self.believed);
        let glare_off = !set
            .camera
            .optics
            .effects
            .veiling_glare
            .is_some_and(|f| f > 0.0);
        for &si in &self.shots {
            let key = set.shots[si].target_key.clone();
            if let Some(r) = rate_by_target.get(&key) {
                out.push(r.clone());
                continue;
            }
            let scene_of = || -> Result<Arc<camsim_core::image::SceneRadiance>, String> {
                self.scenes
                    .lock()
                    .map_err(|_| "forward model lock poisoned".to_string())?
                    .scene(
                        &set,
                        si,
                        &grid,
                        grid_key.get_or_init(|| SceneCache::grid_key(&set, &grid)),
                        &self.work,
                    )
            };
            // The path is a function of the camera and the target alone (not of what is
            // cached), so a call's rates do not depend on the calls before it.
            let gk = grid_key.get_or_init(|| SceneCache::grid_key(&set, &grid));
            let channel =
                if self.channel_mode(&set, si, &grid, gk, (channel_capable, channels.len()))? {
                    // the scene rendered straight onto the channel planes (or kept)
                    let chs = self
                        .scenes
                        .lock()
                        .map_err(|_| "forward model lock poisoned".to_string())?
                        .channel_scene(&set, si, &grid, gk, &self.work)?;
                    let t0 = std::time::Instant::now();
                    let (r, sums) = channel_rate(&set, si, &chs, &channels, &grid)?;
                    self.work.whole_optics.add(t0);
                    // Without glare the channel image is the one before the glare: its sums are a
                    // glare spec's of these optics ([`Forward::rates_rows`]).
                    if glare_off {
                        let gkey = format!("{okey} target {key} channels");
                        if let Ok(mut g) = self.glare.lock() {
                            g.insert(gkey, Arc::new(sums));
                        }
                    }
                    Some(r)
                } else {
                    None
                };
            let r = match (channel, by_target.get(&key)) {
                (Some(r), _) => r,
                (None, Some(pp)) => {
                    camsim_sensor::electron_rate_from_term_planes(&set.camera.sensor, pp)
                }
                (None, None) => {
                    let sc = scene_of()?;
                    let t0 = std::time::Instant::now();
                    let irr =
                        shot_irradiance_of_scene(&set, si, &sc, &grid).map_err(|e| e.one_line())?;
                    self.work.whole_optics.add(t0);
                    // without glare: a glare spec's sums of these optics, as on the channels
                    if glare_off {
                        let sums = camsim_optics::glare_sums_of_image(&set.camera.optics, &irr);
                        if let Ok(mut g) = self.glare.lock() {
                            g.insert(format!("{okey} target {key}"), Arc::new(sums));
                        }
                    }
                    let pp = camsim_sensor::pixel_term_planes(&set.camera.sensor, &irr);
                    let r = camsim_sensor::electron_rate_from_term_planes(&set.camera.sensor, &pp);
                    by_target.insert(key.clone(), Arc::new(pp));
                    added = true;
                    r
                }
            };
            let r = Arc::new(r);
            rate_by_target.insert(key, r.clone());
            out.push(r);
        }
        // Keep the planes (when they fit in the cache's memory).
        let bytes = planes_bytes(&by_target);
        if added {
            self.planes
                .lock()
                .map_err(|_| "forward model lock poisoned".to_string())?
                .insert(okey, by_target, bytes);
        }
        Ok(out)
    }
}

/// The electron rates of shot `si` through the optics on the sensor channels' planes
/// (`channel_scene`: [`SceneCache::channel_scene`], plane j of channel `channels[j]`), the
/// optics stage of [`crate::chain::shot_channel_irradiance_of_scene`]: cheaper than the basis
/// terms' path and exact to f32 rounding when the optics act alike at every wavelength and
/// the scene has more basis terms than the CFA has channels (a colour chart: 25 terms, 3–4
/// channels; [`SimForward::channel_mode`]). The caller takes it only with the believed
/// camera's QE blocks: a QE candidate reuses the cached term planes of its optics instead
/// (one weighted sum per pixel). With the rates, the veiling-glare sums of the channel image
/// ([`camsim_optics::glare_sums_of_image`]: a glare spec's sums when the camera has no
/// glare).
fn channel_rate(
    set: &CaptureSet,
    si: usize,
    channel_scene: &camsim_core::image::SceneRadiance,
    channels: &[usize],
    grid: &camsim_core::WavelengthGrid,
) -> Result<(Vec<f32>, camsim_optics::GlareSums), String> {
    let sensor = &set.camera.sensor;
    let irradiance =
        shot_irradiance_of_scene(set, si, channel_scene, grid).map_err(|e| e.one_line())?;
    let pp = camsim_sensor::pixel_term_planes(sensor, &irradiance);
    let sums = camsim_optics::glare_sums_of_image(&set.camera.optics, &irradiance);
    Ok((
        camsim_sensor::electron_rate_from_channel_planes(sensor, channels, &pp),
        sums,
    ))
}

/// Whether the forward model of `set`'s camera may run the optics on the sensor channels'
/// planes ([`channel_rate`]; per target, when its scene has more basis terms than the CFA has
/// channels): the optics act alike at every wavelength and the QE blocks are the believed
/// camera's (a QE candidate reads the term planes of its optics instead). With the channels
/// used by the CFA, in [`camsim_sensor::channel_planes`]' order.
fn channel_path(set: &CaptureSet, believed: &crate::config::Camera) -> (bool, Vec<usize>) {
    let sensor = &set.camera.sensor;
    let believed_qe = believed_qe(set, believed);
    let channels = (0..sensor.channel_qe.len())
        .filter(|&c| sensor.cfa.tile.iter().flatten().any(|&t| t == c))
        .collect();
    (
        believed_qe && optics_alike_at_every_wavelength(&set.camera),
        channels,
    )
}

/// Whether `set`'s camera has the believed camera's QE blocks (QE shift, IR leakage): then
/// the channels' effective QE is the believed one, and planes projected onto it may be kept
/// under the optics' key (a QE candidate reads the term planes of its optics instead).
fn believed_qe(set: &CaptureSet, believed: &crate::config::Camera) -> bool {
    let sensor = &set.camera.sensor;
    sensor.effects.qe_shift == believed.sensor.effects.qe_shift
        && sensor.effects.ir_leakage == believed.sensor.effects.ir_leakage
}

/// Sets the blocks of `spec` on a validated camera, in their fitted forms (the typed twin of
/// [`apply_rate_spec`], which writes them into the camera file; `camera_from_file` of that
/// file gives the same camera). Values a camera file would refuse are refused.
fn apply_rate_spec_typed(cam: &mut crate::config::Camera, spec: &RateSpec) -> Result<(), String> {
    use camsim_optics::effects::{Defocus, Distortion, Falloff, LateralColor, LateralColorKind};
    use camsim_sensor::effects::{IrLeakage, QeShift};
    let fx = &mut cam.optics.effects;
    let finite = |k: &str, v: f64| {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(format!("{k} = {v} is not finite"))
        }
    };
    let at_least_0 = |k: &str, v: f64| {
        if v >= 0.0 {
            Ok(v)
        } else {
            Err(format!("{k} = {v}: must be ≥ 0"))
        }
    };
    if let Some(c) = &spec.falloff {
        for (i, a) in c.iter().enumerate() {
            finite(
                &format!("optics.relative_illumination.falloff.coefficients[{i}]"),
                *a,
            )?;
        }
        fx.falloff = Some(Falloff::Polynomial {
            coefficients: c.clone(),
        });
    }
    if let Some(f) = spec.glare_fraction {
        fx.veiling_glare = Some(at_least_0("optics.veiling_glare.fraction", f)?);
    }
    if let Some(s) = spec.defocus_sigma_um {
        fx.defocus = Some(Defocus::Gaussian {
            sigma_um: at_least_0("optics.defocus.sigma_um", s)?,
        });
    }
    if let Some([k1, k2]) = spec.distortion {
        fx.distortion = Some(Distortion::Polynomial {
            k1: finite("optics.distortion.k1", k1)?,
            k2: finite("optics.distortion.k2", k2)?,
        });
    }
    if let Some(d) = spec.lateral_color_um {
        fx.lateral_color = Some(LateralColor {
            kind: LateralColorKind::Linear,
            displacement_um: finite("optics.lateral_color.displacement_um", d)?,
        });
    }
    let sx = &mut cam.sensor.effects;
    if let Some(v) = &spec.ir_leakage {
        let mut channels = vec![None; v.len()];
        for (c, q) in v.iter().enumerate() {
            if *q != 0.0 {
                channels[c] = Some(IrLeakage::band(at_least_0("sensor.ir_leakage", *q)?));
            }
        }
        sx.ir_leakage = channels
            .iter()
            .any(Option::is_some)
            .then_some(IrLeakage { channels });
    }
    if let Some(v) = &spec.qe_shift_nm {
        for s in v {
            finite("sensor.qe_shift.shift_nm", *s)?;
        }
        sx.qe_shift = v.iter().any(|s| *s != 0.0).then(|| QeShift {
            shift_nm: v.clone(),
        });
    }
    Ok(())
}

/// Writes the blocks of `spec` into a camera file (JSON), in their fitted forms.
fn apply_rate_spec(cam: &mut Value, spec: &RateSpec, channel_names: &[String]) {
    let optics = &mut cam["optics"];
    if let Some(c) = &spec.falloff {
        let model = match &optics["relative_illumination"] {
            Value::String(m) => m.clone(),
            Value::Object(o) => o
                .get("model")
                .and_then(Value::as_str)
                .unwrap_or("cos4")
                .to_string(),
            _ => "cos4".to_string(),
        };
        optics["relative_illumination"] = json!({"model": model,
            "falloff": {"kind": "polynomial", "coefficients": c}});
    }
    if let Some(f) = spec.glare_fraction {
        optics["veiling_glare"] = json!({ "fraction": f });
    }
    if let Some(s) = spec.defocus_sigma_um {
        optics["defocus"] = json!({"kind": "gaussian", "sigma_um": s});
    }
    if let Some([k1, k2]) = spec.distortion {
        optics["distortion"] = json!({"kind": "polynomial", "k1": k1, "k2": k2});
    }
    if let Some(d) = spec.lateral_color_um {
        optics["lateral_color"] = json!({"kind": "linear", "displacement_um": d});
    }
    let sensor = &mut cam["sensor"];
    if let Some(v) = &spec.ir_leakage {
        let mut m = Map::new();
        for (c, q) in v.iter().enumerate() {
            if *q != 0.0 {
                if let Some(n) = channel_names.get(c) {
                    m.insert(n.clone(), json!(q));
                }
            }
        }
        if m.is_empty() {
            if let Some(o) = sensor.as_object_mut() {
                o.remove("ir_leakage");
            }
        } else {
            sensor["ir_leakage"] = json!({ "channels": m });
        }
    }
    if let Some(v) = &spec.qe_shift_nm {
        let mut m = Map::new();
        for (c, s) in v.iter().enumerate() {
            if *s != 0.0 {
                if let Some(n) = channel_names.get(c) {
                    m.insert(n.clone(), json!(s));
                }
            }
        }
        if m.is_empty() {
            if let Some(o) = sensor.as_object_mut() {
                o.remove("qe_shift");
            }
        } else {
            sensor["qe_shift"] = json!({ "shift_nm": m });
        }
    }
}

/// The believed camera file with every fitted parameter and block written in.
fn fitted_camera_json(
    believed_json: &Value,
    camera_dir: &Path,
    d: &Diagnosis,
    names: &[String],
) -> Value {
    let mut cam = believed_json.clone();
    // paths inside the camera stay valid from the output folder
    if let Some(blur) = cam["optics"]["blur"].as_object_mut() {
        for k in ["lens_file", "psf_file"] {
            if let Some(p) = blur.get(k).and_then(Value::as_str) {
                let abs = camera_dir.join(p);
                let abs = abs.canonicalize().unwrap_or(abs);
                blur.insert(k.into(), json!(abs.to_string_lossy()));
            }
        }
    }
    apply_rate_spec(&mut cam, &d.fitted.rates, names);
    let (b, f) = (&d.believed, &d.fitted);
    let (bs, fs) = (&b.sensor, &f.sensor);
    let s = &mut cam["sensor"];
    let mut set = |k: &str, old: f64, new: f64| {
        if old != new {
            s[k] = json!(new);
        }
    };
    set(
        "conversion_gain_v_per_e",
        bs.conversion_gain_v_per_e,
        fs.conversion_gain_v_per_e,
    );
    set("black_level_dn", bs.black_level_dn, fs.black_level_dn);
    set(
        "dark_voltage_v_per_s",
        bs.dark_voltage_v_per_s,
        fs.dark_voltage_v_per_s,
    );
    set("read_noise_v", bs.read_noise_v, fs.read_noise_v);
    set("dsnu_sigma_v", bs.dsnu_sigma_v, fs.dsnu_sigma_v);
    set(
        "prnu_sigma_percent",
        bs.prnu_sigma_percent,
        fs.prnu_sigma_percent,
    );
    set("well_capacity_e", bs.well_capacity_e, fs.well_capacity_e);
    if fs.column_fpn != bs.column_fpn {
        if let Some(c) = fs.column_fpn {
            s["column_fpn"] = json!({"sigma_v": c.offset_sigma_v});
        }
    }
    if fs.effects.hot_pixels != bs.effects.hot_pixels {
        if let Some(h) = fs.effects.hot_pixels {
            s["hot_pixels"] = json!({"fraction": h.fraction,
                "dark_voltage_v_per_s": h.dark_voltage_v_per_s, "log_sigma": h.log_sigma});
        }
    }
    if fs.effects.nonlinearity != bs.effects.nonlinearity {
        if let Some(camsim_sensor::Nonlinearity::Quadratic { coefficient_per_v }) =
            fs.effects.nonlinearity
        {
            s["nonlinearity"] =
                json!({"kind": "quadratic", "coefficient_per_v": coefficient_per_v});
        }
    }
    if fs.effects.crosstalk != bs.effects.crosstalk {
        if let Some(c) = fs.effects.crosstalk {
            s["crosstalk"] = json!({"fraction": c.total()});
        }
    }
    if fs.effects.row_noise != bs.effects.row_noise {
        if let Some(r) = fs.effects.row_noise {
            s["row_noise"] = json!({"sigma_v": r.sigma_v});
        }
    }
    if fs.effects.rtn != bs.effects.rtn {
        if let Some(r) = fs.effects.rtn {
            s["rtn"] = json!({"fraction": r.fraction, "amplitude_v": r.amplitude_v,
                              "p_up": r.p_up, "p_down": r.p_down});
        }
    }
    if fs.effects.black_level_drift != bs.effects.black_level_drift {
        if let Some(d) = fs.effects.black_level_drift {
            s["black_level_drift"] = json!({"dn_per_frame": d.dn_per_frame});
        }
    }
    if fs.effects.dark_temperature != bs.effects.dark_temperature {
        if let Some(t) = fs.effects.dark_temperature {
            // the dark voltage holds at the law's reference, the operating temperature
            s["temperature_c"] = json!(t.reference_temperature_c);
            s["dark_reference_temperature_c"] = json!(t.reference_temperature_c);
            s["dark_doubling_temperature_c"] = json!(t.doubling_temperature_c);
            s["dark_voltage_v_per_s"] = json!(fs.dark_voltage_v_per_s);
        }
    }
    if f.exposure_factor != b.exposure_factor {
        let old = cam["optics"]["exposure_scale"]["factor"]
            .as_f64()
            .unwrap_or(1.0);
        cam["optics"]["exposure_scale"] =
            json!({"factor": old * f.exposure_factor / b.exposure_factor});
    }
    cam
}

fn target_class(t: &Target) -> TargetClass {
    match t {
        Target::Dark => TargetClass::Dark,
        Target::Uniform { .. } => TargetClass::Uniform,
        Target::SlantedEdge { angle_deg, .. } => TargetClass::Edge {
            angle_deg: *angle_deg,
        },
        _ => TargetClass::Structured,
    }
}

/// Reads and reduces every frame of the shots with a known exposure time.
fn load_data(
    set: &CaptureSet,
    progress: bool,
) -> Result<(DataSet, Vec<usize>, Vec<String>), CliError> {
    let s = &set.camera.sensor;
    let (rows, cols) = (s.rows, s.cols);
    let max_dn = s.max_dn() as u16;
    let total: usize = set.shots.iter().map(|x| x.frames.len()).sum();
    let bar = crate::progress::bar(
        progress,
        total as u64,
        "{spinner} reading frames [{bar:30}] {pos}/{len}",
    );
    let mut shots = Vec::new();
    let mut used = Vec::new();
    let mut skipped = Vec::new();
    for (si, shot) in set.shots.iter().enumerate() {
        let exposure_s = match shot.exposure {
            Exposure::Fixed(t) => t,
            Exposure::Auto(_) => {
                skipped.push(format!(
                    "{}: auto_exposure gives no known exposure time; not used",
                    shot.id
                ));
                continue;
            }
        };
        if shot.frames.is_empty() {
            skipped.push(format!("{}: no frames; not used", shot.id));
            continue;
        }
        let mut acc = ShotAccumulator::new(rows, cols, max_dn);
        for chunk in shot.frames.chunks(8) {
            let frames: Vec<Result<(PathBuf, camsim_core::RawFrame), CliError>> = chunk
                .par_iter()
                .map(|f| {
                    let p = set.dir.join(f);
                    read_frame_with(&p, set.raw_format.as_ref()).map(|fr| (p, fr))
                })
                .collect();
            for r in frames {
                let (p, fr) = r?;
                if fr.rows != rows || fr.cols != cols {
                    return Err(CliError::input(
                        &p,
                        format!(
                            "frame is {}×{} (rows×cols) but the sensor is {rows}×{cols}",
                            fr.rows, fr.cols
                        ),
                    ));
                }
                acc.add(&fr.dn).map_err(|m| CliError::input(&p, m))?;
                bar.inc(1);
            }
        }
        let mut sd = acc.finish(
            shot.id.clone(),
            target_class(&shot.target.target),
            shot.target_key.clone(),
            exposure_s,
            shot.analog_gain,
        );
        sd.temperature_c = shot.temperature_c;
        sd.first_frame = crate::chain::frame_index(set, si, 0);
        shots.push(sd);
        used.push(si);
    }
    bar.finish_and_clear();
    if shots.is_empty() {
        return Err(CliError::input(
            &set.path,
            "no shot has both frames and a fixed exposure_s: nothing to diagnose",
        ));
    }
    let channel = (0..rows * cols)
        .map(|i| s.cfa.channel_at(i / cols, i % cols) as u8)
        .collect();
    Ok((
        DataSet {
            rows,
            cols,
            channel,
            channel_names: s.channel_names.clone(),
            max_dn: s.max_dn(),
            shots,
        },
        used,
        skipped,
    ))
}

/// Run the diagnosis and write its outputs into `out` (all or nothing). Returns report.json.
pub fn run_diagnose(
    set: &CaptureSet,
    out: &Path,
    opts: &DiagnoseCmdOptions,
) -> Result<DiagnoseSummary, CliError> {
    let camera_text = std::fs::read_to_string(&set.camera_path)
        .map_err(|e| CliError::input(&set.camera_path, format!("cannot read: {e}")))?;
    let camera_json: Value = serde_json::from_str(&camera_text)
        .map_err(|e| CliError::input(&set.camera_path, format!("invalid: {e}")))?;
    let mut effects = Vec::new();
    for id in &opts.effects {
        effects.push(Effect::from_id(id).ok_or_else(|| {
            CliError::Other(format!(
                "--effects: unknown effect id \"{id}\" (expected one of: {})",
                Effect::ALL.map(|e| e.id()).join(", ")
            ))
        })?);
    }
    if !(opts.bic_threshold.is_finite() && opts.bic_threshold >= 0.0) {
        return Err(CliError::Other(format!(
            "--bic-threshold must be ≥ 0, got {}",
            opts.bic_threshold
        )));
    }
    let t_load = std::time::Instant::now();
    let (data, used, skipped) = load_data(set, opts.progress)?;
    let load_s = t_load.elapsed().as_secs_f64();
    let forward = SimForward::new(set, used);
    let believed = ModelState {
        sensor: set.camera.sensor.clone(),
        exposure_factor: 1.0,
        rates: RateSpec::default(),
        frames_in_set: set.shots.iter().map(|s| s.frames.len() as u64).sum(),
    };
    let mut dopts = DiagnoseOptions::default();
    dopts.select.bic_threshold = opts.bic_threshold;
    if !effects.is_empty() {
        dopts.select.effects = effects;
    }
    let spinner = crate::progress::bar(opts.progress, 0, "{spinner} diagnose {msg} ({elapsed})");
    let profile = std::env::var_os("CAMSIM_PROFILE").is_some();
    let t0 = std::time::Instant::now();
    let progress = |m: &str| {
        if profile {
            eprintln!(
                "camsim: {:8.3} s  {m}  [{} likelihood evaluations so far; {}]",
                t0.elapsed().as_secs_f64(),
                camsim_diagnose::mismatch::prof::calls(),
                forward.work.summary()
            );
        }
        spinner.set_message(m.to_string())
    };
    let diag = diagnose(&data, &forward, &believed, &dopts, &progress)
        .map_err(|e| CliError::Other(format!("diagnose: {e}")))?;
    spinner.finish_and_clear();
    if profile {
        eprintln!(
            "camsim: profile: {}",
            camsim_diagnose::mismatch::prof::summary()
        );
    }
    let names = &set.camera.sensor.channel_names;
    let camera_dir = set.camera_path.parent().unwrap_or(Path::new("."));
    let fitted = fitted_camera_json(&camera_json, camera_dir, &diag, names);
    // The fitted camera must be one `camsim simulate` reads.
    let fitted_path = out.join("fitted_camera.json");
    let raw: CameraFile = serde_json::from_value(fitted.clone())
        .map_err(|e| CliError::Other(format!("internal: the fitted camera does not parse: {e}")))?;
    camera_from_file(&fitted_path, raw)?;
    let glare_k = forward.glare_decimated.lock().map_or(0, |d| d.k);
    let mut report = report_json(&diag, &data, &skipped, glare_k);
    if !profile {
        report["timing"] = Value::Null;
    }
    let files = with_staging(out, |st| {
        let mut files: Vec<PathBuf> = Vec::new();
        let p = st.join("fitted_camera.json");
        std::fs::write(&p, serde_json::to_string_pretty(&fitted).expect("json"))
            .map_err(|e| CliError::output(&p, e))?;
        files.push("fitted_camera.json".into());
        let p = st.join("report.json");
        std::fs::write(&p, serde_json::to_string_pretty(&report).expect("json"))
            .map_err(|e| CliError::output(&p, e))?;
        files.push("report.json".into());
        // Wall times differ from run to run: written only on request (CAMSIM_PROFILE), so that
        // the default outputs stay byte-identical for the same inputs and seed.
        if profile {
            let p = st.join("timing.json");
            std::fs::write(
                &p,
                serde_json::to_string_pretty(&timing_json(
                    &diag,
                    &data,
                    load_s,
                    &forward.work.stages(),
                ))
                .expect("json"),
            )
            .map_err(|e| CliError::output(&p, e))?;
            files.push("timing.json".into());
        }
        let figs = figures::write_figures(st, &diag, &data)?;
        for f in &figs {
            files.push(PathBuf::from(&f.file));
        }
        let p = st.join("report.html");
        std::fs::write(&p, figures::report_html(&report, &diag, &data, &figs))
            .map_err(|e| CliError::output(&p, e))?;
        files.push("report.html".into());
        Ok(files)
    })?;
    Ok(DiagnoseSummary {
        findings: diag
            .findings
            .iter()
            .map(|f| f.effect.id().to_string())
            .collect(),
        chi2_per_dof_before: diag.before.chi2_per_dof,
        chi2_per_dof_after: diag.after.chi2_per_dof,
        files,
        json: report,
    })
}

/// What `diagnose` reports: the effects found and the fit before and after, and report.json
/// as written.
#[derive(Debug, Clone)]
pub struct DiagnoseSummary {
    /// Effect ids found (spec/effects.md), in the order of the report.
    pub findings: Vec<String>,
    /// χ²/dof of the believed camera.
    pub chi2_per_dof_before: f64,
    /// χ²/dof of the fitted camera.
    pub chi2_per_dof_after: f64,
    /// Files written into `--out` (relative paths).
    pub files: Vec<PathBuf>,
    /// report.json as written.
    pub json: Value,
}

/// timing.json: wall time per stage (frames read and reduced, then the diagnosis's stages
/// and the likelihood/forward-model counters), and what was subsampled. Kept out of
/// report.json, which is byte-identical for the same inputs.
fn timing_json(
    d: &Diagnosis,
    data: &DataSet,
    load_s: f64,
    forward_work: &[(String, u64, f64)],
) -> Value {
    let mut stages = vec![json!({"stage": "read and reduce the frames", "seconds": load_s})];
    for t in &d.timing {
        let mut v = json!({"stage": t.stage, "seconds": t.seconds});
        if let Some(c) = t.calls {
            v["calls"] = json!(c);
        }
        stages.push(v);
    }
    for (stage, calls, seconds) in forward_work {
        stages.push(json!({"stage": stage, "seconds": seconds, "calls": calls}));
    }
    json!({
        "stages": stages,
        "note": "the first stages are sequential wall times; the counters (likelihood, forward model, identifiability, and the forward model's work by kind) are parts of them",
        "subsampled": {"fit_pixels": d.fit_pixels, "sensor_pixels": data.pixels(),
                       "rule": format!("{FIT_ROWS_RULE}; the reported fit (fit_before/fit_after, locate) uses every pixel")},
    })
}

/// Which rows the candidate fits read (`like::Ctx::new`, `like::fit_bands`,
/// `like::row_structure`), for report.json's and timing.json's `subsampled.rule`.
const FIT_ROWS_RULE: &str = "fits and selection use whole 2-row groups evenly spread over the sensor when it has more than fit_pixels pixels; when the fit rows are at most 1/8 of the rows and the forward model runs bands of rows by themselves, they are 5 contiguous bands of equal even length instead: the first at the top edge, the last at the bottom edge, and each inner band within half the even spacing, less its own length, of its evenly spaced start, on the rows with the most scene structure (the variance across columns of each row's per-pixel mean levels, per CFA channel, summed over the chart, edge and image shots; among equally structured starts the one nearest its evenly spaced start, then the upper one), evenly spaced when no shot has structure";

/// report.json `subsampled`: what the candidate fits read (the fit rows as runs of
/// consecutive rows, their pixels and pixel-shots) and the full-resolution confirmation (the
/// all-rows χ²/dof of the believed and the fitted camera, i.e. `fit_before`/`fit_after`), and,
/// when `glare_k` > 0, that candidate glare sums came from a `glare_k`× decimated field
/// ([`GlareDecimation`]).
fn subsampled_json(d: &Diagnosis, data: &DataSet, glare_k: usize) -> Value {
    // the fit rows as inclusive [first, last] runs
    let mut runs: Vec<[usize; 2]> = Vec::new();
    for &r in &d.fit_rows {
        match runs.last_mut() {
            Some(run) if run[1] + 1 == r => run[1] = r,
            _ => runs.push([r, r]),
        }
    }
    let shots = data.shots.len();
    let mut v = json!({"fit_pixels": d.fit_pixels, "sensor_pixels": data.pixels(),
           "fits_subsampled": d.fit_pixels < data.pixels(),
           "fit_rows": d.fit_rows.len(), "sensor_rows": data.rows,
           "fit_row_runs": runs,
           "fit_pixel_shots": d.fit_pixels * shots,
           "sensor_pixel_shots": data.pixels() * shots,
           "full_resolution": {"pixels": data.pixels(), "dof_believed": d.before.dof,
                               "chi2_per_dof_believed": r4(d.before.chi2_per_dof),
                               "chi2_per_dof_fitted": r4(d.after.chi2_per_dof)},
           "rule": format!("candidate {FIT_ROWS_RULE} (fit_row_runs, inclusive); the reported fit (fit_before/fit_after, repeated in full_resolution), locate, figures and the final fit check use every pixel")});
    if glare_k > 0 {
        v["candidate_glare_sums"] = json!({
            "decimation": glare_k,
            "rule": format!("the veiling glare's whole-field means of candidate optics (during the fits with veiling glare in the model) came from the whole field on a {glare_k}x coarser pixel grid (oversampling 1), scaled by the believed optics' full-resolution means over their coarse-grid means (per plane; by one common factor when the candidate's planes are basis terms and the believed run's the sensor channels'); the full-resolution confirmation forms the whole image and its own glare")
        });
    }
    v
}

fn r4(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// report.json (spec/effects.md) plus what the diagnosis could not decide or test, the
/// ranked candidates and the locate summaries.
/// `glare_k`: the decimation of the candidates' glare sums ([`GlareDecimation`]; 0: not used).
fn report_json(d: &Diagnosis, data: &DataSet, skipped: &[String], glare_k: usize) -> Value {
    let findings: Vec<Value> = d
        .findings
        .iter()
        .map(|f| {
            json!({
                "effect": f.effect.id(),
                "magnitude": r4(f.magnitude),
                "unit": f.effect.unit(),
                "where": f.where_,
                "explanation": f.explanation,
                "evidence": {
                    "delta_bic": r4(f.delta_bic),
                    "delta_log_likelihood": r4(f.delta_logl),
                    "parameters": f.k,
                    "chi2_per_dof_before": r4(f.chi2_before),
                    "next_best": f.alternatives.first().map(|(e, b)| json!({"effect": e.id(), "delta_bic": r4(*b)})),
                },
                "fit_after": {"chi2_per_dof": r4(f.chi2_after)},
            })
        })
        .collect();
    let undecided: Vec<Value> = d
        .selection
        .undecided
        .iter()
        .map(|u| {
            json!({
                "effects": u.effects.iter().map(|e| e.id()).collect::<Vec<_>>(),
                "delta_bic": u.delta_bic.iter().map(|x| r4(*x)).collect::<Vec<_>>(),
                "magnitudes": u.magnitudes.iter().map(|x| r4(*x)).collect::<Vec<_>>(),
                "kept_in_fitted_camera": u.effects[0].id(),
                "explanation": format!(
                    "the capture set cannot tell {} apart: each explains the residuals about equally well (ΔBIC within the margin)",
                    u.effects.iter().map(|e| e.id()).collect::<Vec<_>>().join(" and ")
                ),
                "would_separate": u.separated_by,
            })
        })
        .collect();
    let not_testable: Vec<Value> = d
        .selection
        .not_testable
        .iter()
        .map(|(e, why)| json!({"effect": e.id(), "reason": why}))
        .collect();
    let vif = |x: f64| {
        if x.is_finite() {
            json!(x)
        } else {
            json!("infinite")
        }
    };
    let cannot_tell: Vec<Value> = d
        .selection
        .identifiability
        .iter()
        .filter(|x| x.cannot_tell)
        .map(|x| {
            json!({
                "effect": x.effect.id(),
                "explanation": format!(
                    "cannot tell from these shots: a change of {} is {} along the baseline ({}); variance inflation {} > {}",
                    x.effect.id(),
                    if x.variance_inflation.is_finite() { "almost entirely" } else { "entirely" },
                    x.baseline.join(", "),
                    if x.variance_inflation.is_finite() { format!("{:.3e}", x.variance_inflation) } else { "∞".into() },
                    camsim_diagnose::mismatch::MAX_VARIANCE_INFLATION
                ),
                "variance_inflation": vif(x.variance_inflation),
                "would_separate": x.would_separate,
            })
        })
        .collect();
    let identifiability: Vec<Value> = d
        .selection
        .identifiability
        .iter()
        .map(|x| {
            json!({
                "effect": x.effect.id(),
                "parameters": x.parameters,
                "variance_inflation": vif(x.variance_inflation),
                "baseline": x.baseline,
                "most_alike": x.most_alike.map(|(e, r2)| json!({"effect": e.id(), "rho2": r4(r2)})),
                "cannot_tell": x.cannot_tell,
            })
        })
        .collect();
    let table = |rows: &[camsim_diagnose::mismatch::CandidateRow]| -> Vec<Value> {
        rows.iter()
            .filter(|r| r.not_testable.is_none())
            .map(|r| {
                json!({"effect": r.effect.id(), "delta_bic": r.delta_bic.map(r4),
                       "delta_log_likelihood": r4(r.delta_logl), "parameters": r.k,
                       "magnitude": r4(r.magnitude)})
            })
            .collect()
    };
    let rounds: Vec<Value> = d.selection.rounds.iter().map(|r| json!(table(r))).collect();
    let sc = |l: &camsim_diagnose::mismatch::Located| -> Vec<Value> {
        l.shot_channels
            .iter()
            .map(|x| {
                json!({"shot": data.shots[x.shot].id, "channel": data.channel_names[x.channel],
                       "chi2_per_dof": r4(x.chi2_per_dof), "dof": x.dof,
                       "data_mean_dn": r4(x.data_mean_dn), "model_mean_dn": r4(x.model_mean_dn),
                       "mean_residual_z": r4(x.mean_z),
                       "data_temporal_var_dn2": r4(x.data_temporal_var),
                       "model_temporal_var_dn2": r4(x.model_temporal_var),
                       "data_fixed_var_dn2": r4(x.data_fixed_var),
                       "model_fixed_var_dn2": r4(x.model_fixed_var),
                       "censored_pixel_shots": x.censored})
            })
            .collect()
    };
    json!({
        "fit_before": {"chi2_per_dof": r4(d.before.chi2_per_dof), "dof": d.before.dof},
        "findings": findings,
        "fit_after": {"chi2_per_dof": r4(d.after.chi2_per_dof), "dof": d.dof_after},
        "fitted_camera": "fitted_camera.json",
        "undecided": undecided,
        "not_testable": not_testable,
        "cannot_tell": cannot_tell,
        "identifiability": {"max_variance_inflation": camsim_diagnose::mismatch::MAX_VARIANCE_INFLATION,
                            "candidates": identifiability},
        "timing": "timing.json",
        "candidates": {"rounds": rounds},
        "locate": {"before": sc(&d.before), "after": sc(&d.after),
                   "hot_pixels_classified": {"before": d.before.hot_pixels, "after": d.after.hot_pixels}},
        "settings": {"fit_pixels": d.fit_pixels, "observations": d.selection.n_obs,
                     "bic_threshold": d.bic_threshold},
        "subsampled": subsampled_json(d, data, glare_k),
        "skipped_shots": skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chain::shot_electron_rate;
    use crate::demo::Concealment;

    /// The caches' LRU: within the byte budget, the least recently used evicted first, a
    /// value over the budget not kept, a replaced key's bytes not counted twice.
    #[test]
    fn lru_bytes_evicts_the_least_recently_used_within_its_budget() {
        let mut c: LruBytes<u32, 10> = LruBytes::default();
        c.insert("a".into(), 1, 4);
        c.insert("b".into(), 2, 4);
        assert_eq!(c.get("a"), Some(1)); // a is now more recent than b
        c.insert("c".into(), 3, 4); // 12 > 10: b goes
        assert_eq!(
            (c.get("a"), c.get("b"), c.get("c")),
            (Some(1), None, Some(3))
        );
        assert_eq!(c.bytes, 8);
        c.insert("d".into(), 4, 11); // over the budget: not kept, nothing evicted
        assert_eq!((c.get("d"), c.bytes), (None, 8));
        c.insert("c".into(), 5, 6); // replaced: 4 + 6 = 10 fits, a stays
        assert_eq!((c.get("a"), c.get("c"), c.bytes), (Some(1), Some(5), 10));
    }

    /// Optics that act alike at every wavelength run on the channel planes of a chart (25
    /// basis terms, 3 channels) and give `simulate`'s electron rates to f32 rounding, with
    /// every wavelength-independent optics block set; lateral colour (per wavelength) and a
    /// candidate QE take the basis terms' path.
    #[test]
    fn channel_plane_optics_equal_the_basis_term_optics() {
        let (_dir, set) = demo_set(
            vec![("veiling_glare".into(), 0.03)],
            Concealment::None,
            24,
            32,
        );
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        let nch = set.camera.sensor.channel_qe.len();
        let all_blocks = RateSpec {
            glare_fraction: Some(0.05),
            defocus_sigma_um: Some(3.0),
            distortion: Some([0.02, 0.01]),
            falloff: Some(vec![-0.1, 0.05]),
            ..Default::default()
        };
        let cases = [
            (RateSpec::default(), true),
            (all_blocks.clone(), true),
            (
                RateSpec {
                    lateral_color_um: Some(1.5),
                    ..all_blocks.clone()
                },
                false,
            ),
            (
                RateSpec {
                    qe_shift_nm: Some(vec![3.0; nch]),
                    ..all_blocks
                },
                false,
            ),
        ];
        let mut charts = 0;
        for (spec, channel_path) in &cases {
            let got = fw.rates(spec).unwrap();
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(spec).unwrap();
            let grid = wavelength_grid(&s2);
            // (whether the optics allow it: the QE candidate's rates take the terms' path)
            let capable = optics_alike_at_every_wavelength(&s2.camera);
            let channels = super::channel_path(&s2, &fw.believed).1;
            let gk = SceneCache::grid_key(&s2, &grid);
            for (si, g) in got.iter().enumerate() {
                let scene = crate::chain::shot_scene(&s2, si, &grid).unwrap();
                let via_channels = fw
                    .channel_mode(&s2, si, &grid, &gk, (capable, channels.len()))
                    .unwrap();
                let chart = scene.radiance.terms() > nch;
                charts += usize::from(chart);
                let alike = optics_alike_at_every_wavelength(&s2.camera);
                assert_eq!(via_channels, chart && alike, "{spec:?} shot {si}");
                assert_eq!(alike, *channel_path || spec.qe_shift_nm.is_some());
                let want = shot_electron_rate(&s2, si, &grid).unwrap().electrons_per_s;
                let (err, scale) = max_abs_diff(&want, g);
                assert!(
                    err <= 2e-6 * scale,
                    "{spec:?} shot {si}: max |Δ| {err} of {scale}"
                );
            }
        }
        assert!(charts > 0, "the set has no chart");
    }

    /// The forward model through cached scenes and pixel planes equals `simulate`'s per-shot
    /// electron rates of the same camera (QE blocks and optics blocks applied), also on a
    /// cache hit.
    #[test]
    fn plane_cache_rates_equal_the_simulator_rates() {
        let (_dir, set) = demo_set(
            vec![("qe_shift".into(), -6.0)],
            Concealment::Mimicked,
            16,
            24,
        );
        let camera_json: Value =
            serde_json::from_str(&std::fs::read_to_string(&set.camera_path).unwrap()).unwrap();
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        let (qe, ir) = test_colour_shifts(&set);
        let specs = [
            RateSpec::default(),
            RateSpec {
                glare_fraction: Some(0.05),
                ..Default::default()
            },
            RateSpec {
                qe_shift_nm: Some(qe.clone()),
                ..Default::default()
            },
            RateSpec {
                qe_shift_nm: Some(qe),
                ir_leakage: Some(ir),
                glare_fraction: Some(0.05),
                ..Default::default()
            },
            RateSpec {
                defocus_sigma_um: Some(6.0),
                ..Default::default()
            },
        ];
        let mut new_scenes = Vec::new();
        for spec in &specs {
            let scenes_before = fw.scenes.lock().unwrap().lru.entries.len();
            // The typed blocks are the ones the camera file with the blocks written in gives.
            let mut v = camera_json.clone();
            apply_rate_spec(&mut v, spec, &set.camera.sensor.channel_names);
            let mut from_file =
                camera_from_file(&set.camera_path, serde_json::from_value(v).unwrap()).unwrap();
            from_file.sensor.effects.crosstalk = None;
            let typed = fw.camera_for(spec).unwrap();
            assert_eq!(typed.optics.effects, from_file.optics.effects, "{spec:?}");
            assert_eq!(typed.sensor.effects, from_file.sensor.effects, "{spec:?}");
            for pass in 0..2 {
                let got = fw.rates(spec).unwrap();
                let mut s2 = set.clone();
                s2.camera = fw.camera_for(spec).unwrap();
                let grid = wavelength_grid(&s2);
                for (si, g) in got.iter().enumerate() {
                    let want = shot_electron_rate(&s2, si, &grid).unwrap().electrons_per_s;
                    let (err, scale) = max_abs_diff(&want, g);
                    assert!(
                        err <= 1e-5 * scale,
                        "{spec:?} pass {pass} shot {si}: max |Δ| {err} of {scale}"
                    );
                }
            }
            new_scenes.push(fw.scenes.lock().unwrap().lru.entries.len() - scenes_before);
        }
        // the QE candidates shared one optics entry, the two glare specs a second; the
        // defocus added a third
        assert_eq!(fw.planes.lock().unwrap().entries.len(), 3);
        // Scenes are rendered once per target and grid: the glare spec (same sampling and
        // wavelength grids as the believed camera) rendered none, the defocus (a wider blur
        // margin) one per target; the rates above, equal to the simulator's, used them.
        let targets: std::collections::HashSet<&str> =
            set.shots.iter().map(|s| s.target_key.as_str()).collect();
        assert_eq!(new_scenes[0], targets.len());
        assert_eq!(new_scenes[1], 0, "the glare spec re-rendered the scenes");
        assert_eq!(new_scenes[4], targets.len());
    }
}

/// A demo capture set written to a temporary directory (kept alive by the returned handle)
/// and loaded, for the forward model's tests.
#[cfg(test)]
fn demo_set(
    effects: Vec<(String, f64)>,
    concealment: crate::demo::Concealment,
    rows: usize,
    cols: usize,
) -> (tempfile::TempDir, CaptureSet) {
    let dir = tempfile::tempdir().unwrap();
    let spec = crate::demo::DemoSpec {
        effects,
        concealment,
        rows,
        cols,
        seed: 1,
    };
    let truth = crate::demo::generate_capture_set(&spec, dir.path()).unwrap();
    let set = crate::config::load_captures(&truth.captures_json, None).unwrap();
    (dir, set)
}

/// The largest |want − got| of two rate images and the largest |want| (at least 1e-30), for the
/// forward-model tests' relative tolerances.
#[cfg(test)]
fn max_abs_diff(want: &[f32], got: &[f32]) -> (f32, f32) {
    let scale = want.iter().fold(0f32, |m, &x| m.max(x.abs())).max(1e-30);
    let err = want
        .iter()
        .zip(got)
        .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
    (err, scale)
}

/// The forward-model tests' QE shifts (+4 nm on the first channel, −7 nm on the last) and IR
/// leakage (0.02 on the first channel) of `set`'s channels.
#[cfg(test)]
fn test_colour_shifts(set: &CaptureSet) -> (Vec<f64>, Vec<f64>) {
    let nch = set.camera.sensor.channel_qe.len();
    let mut qe = vec![0.0; nch];
    qe[0] = 4.0;
    qe[nch - 1] = -7.0;
    let mut ir = vec![0.0; nch];
    ir[0] = 0.02;
    (qe, ir)
}

#[cfg(test)]
mod band_tests {
    use super::*;
    use crate::demo::Concealment;

    /// The candidates that change the optics' sampling grid (fall-off keeps it; distortion
    /// both ways, lateral colour and defocus widen its margin), one each.
    fn sampling_grid_specs() -> [RateSpec; 5] {
        [
            RateSpec {
                falloff: Some(vec![-0.3, 0.1, 0.0]),
                ..Default::default()
            },
            RateSpec {
                distortion: Some([-0.08, 0.02]),
                ..Default::default()
            },
            RateSpec {
                distortion: Some([0.06, 0.0]),
                ..Default::default()
            },
            RateSpec {
                lateral_color_um: Some(1.5),
                ..Default::default()
            },
            RateSpec {
                defocus_sigma_um: Some(4.0),
                ..Default::default()
            },
        ]
    }

    /// A band through the optics projected onto the channels after the lateral-colour warp
    /// ([`crate::chain::band_channel_irradiance`], what [`Forward::rates_rows`] runs for a
    /// lateral-colour candidate with the believed QE) gives the electron rates of the band
    /// through the optics on every wavelength band's plane ([`crate::chain::band_irradiance`],
    /// the pixel integration per plane and the QE-weighted sum) within f32 rounding (1e-6 of
    /// the largest rate), with the believed Gaussian blur and cos⁴, lateral colour alone and
    /// with fall-off, defocus and veiling glare (the whole field's sums), on every band of fit
    /// rows at the top, middle and bottom of a chart, a flat and a dark shot; and
    /// [`Forward::rates_rows`] takes that path (its cached band planes are the channels').
    #[test]
    fn band_channel_irradiance_is_the_band_irradiance_projected() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 240, 320);
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        let rows: Vec<usize> = (0..4).chain(118..122).chain(236..240).collect();
        let specs = [
            RateSpec {
                lateral_color_um: Some(2.5),
                ..Default::default()
            },
            RateSpec {
                lateral_color_um: Some(-1.5),
                glare_fraction: Some(0.03),
                falloff: Some(vec![-0.2, 0.0, 0.0]),
                defocus_sigma_um: Some(2.0),
                ..Default::default()
            },
        ];
        let shots: Vec<usize> = ["chart", "flat", "dark"]
            .iter()
            .map(|k| {
                set.shots
                    .iter()
                    .position(|s| s.id.contains(k))
                    .unwrap_or_else(|| panic!("no {k} shot"))
            })
            .collect();
        for spec in &specs {
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(spec).unwrap();
            let grid = wavelength_grid(&s2);
            let (bands, widen) = row_bands(&s2, &grid, &rows).expect("run as bands");
            assert_eq!(bands.len(), 3);
            let (capable, channels) = channel_path(&s2, &fw.believed);
            assert!(!capable && believed_qe(&s2, &fw.believed));
            for &si in &shots {
                let scene = crate::chain::shot_scene(&s2, si, &grid).unwrap();
                let glare = crate::chain::shot_glare_sums(&s2, &scene, &grid).unwrap();
                for (band, w) in bands.iter().zip(&widen) {
                    let (r0, r1) = crate::chain::band_scene_rows(&s2, &grid, *band, *w);
                    let sb = crate::chain::scene_rows(&scene, r0, r1);
                    let sensor = crate::chain::band_sensor(&s2, *band);
                    let irr =
                        crate::chain::band_irradiance(&s2, &sb, &grid, *band, *w, glare.as_ref())
                            .unwrap();
                    let want = camsim_sensor::electron_rate_from_term_planes(
                        &sensor,
                        &camsim_sensor::pixel_term_planes(&sensor, &irr),
                    );
                    let ch = crate::chain::band_channel_irradiance(
                        &s2,
                        &sb,
                        &grid,
                        *band,
                        *w,
                        glare.as_ref(),
                    )
                    .unwrap();
                    assert_eq!(ch.channels, channels);
                    assert_eq!(ch.irradiance.irradiance.planes.len(), channels.len());
                    let got = camsim_sensor::electron_rate_from_channel_planes(
                        &sensor,
                        &ch.channels,
                        &camsim_sensor::pixel_term_planes(&sensor, &ch.irradiance),
                    );
                    let (err, scale) = max_abs_diff(&want, &got);
                    assert!(
                        err <= 1e-6 * scale,
                        "{spec:?} shot {} band {band:?}: max |Δ| {err} of {scale}",
                        set.shots[si].id
                    );
                }
            }
            // the forward model's bands went through the projection (channel planes cached)
            fw.rates_rows(spec, &rows).unwrap();
            let okey = format!(
                "{} bands {bands:?} channels",
                SimForward::optics_key(&s2, spec, &grid)
            );
            let kept = fw
                .planes
                .lock()
                .unwrap()
                .get(&okey)
                .expect("band planes kept");
            assert!(kept.values().all(|p| p.planes.len() == channels.len()));
        }
    }

    /// The forward model of fit-row bands ([`Forward::rates_rows`]: each band through the
    /// chain by itself, [`crate::chain::band_irradiance`]) equals the whole-sensor run
    /// ([`Forward::rates`]) on the requested rows within f32 rounding, for every block a
    /// candidate sets: the believed Gaussian blur alone, veiling glare (the whole field's
    /// mean), relative-illumination fall-off, distortion, lateral colour, defocus, QE shift,
    /// IR leakage, crosstalk (applied to both, compared on the rows whose neighbours the bands
    /// hold) and several at once; bands touching the sensor's top and bottom edges and one in
    /// the middle, on a charts set (chart shots, flats, darks).
    #[test]
    fn band_rates_equal_the_whole_sensor_rates() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 640, 24);
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        // fit rows 0..4, 318..322, 636..640 and their neighbours (what the diagnosis asks for)
        let fit: Vec<usize> = (0..4).chain(318..322).chain(636..640).collect();
        let mut rows: Vec<usize> = fit
            .iter()
            .flat_map(|&r| [r.saturating_sub(1), r, (r + 1).min(639)])
            .collect();
        rows.sort_unstable();
        rows.dedup();
        let (qe, ir) = test_colour_shifts(&set);
        let mut specs = vec![
            RateSpec::default(),
            RateSpec {
                glare_fraction: Some(0.05),
                ..Default::default()
            },
        ];
        specs.extend(sampling_grid_specs());
        specs.extend([
            RateSpec {
                qe_shift_nm: Some(qe.clone()),
                ..Default::default()
            },
            RateSpec {
                ir_leakage: Some(ir.clone()),
                ..Default::default()
            },
            RateSpec {
                glare_fraction: Some(0.03),
                falloff: Some(vec![-0.2, 0.0, 0.0]),
                distortion: Some([-0.05, 0.0]),
                lateral_color_um: Some(-1.0),
                defocus_sigma_um: Some(2.0),
                qe_shift_nm: Some(qe),
                ir_leakage: Some(ir),
            },
        ]);
        let ct = camsim_sensor::effects::Crosstalk {
            left: 0.01,
            right: 0.02,
            up: 0.015,
            down: 0.025,
        };
        let (r_n, cols) = (set.camera.sensor.rows, set.camera.sensor.cols);
        for spec in &specs {
            {
                // the bands are really run by themselves (not the whole-sensor fallback)
                let mut s2 = set.clone();
                s2.camera = fw.camera_for(spec).unwrap();
                let grid = wavelength_grid(&s2);
                let (os, margin) = sampling_for(
                    &s2.camera.optics,
                    &s2.camera.sensor,
                    &grid,
                    s2.simulation.oversample,
                );
                let why =
                    crate::chain::band_refusal(&s2, crate::chain::RowBand { start: 0, end: 6 });
                let (bands, _) = row_bands(&s2, &grid, &rows).unwrap_or_else(|| {
                    panic!("{spec:?}: not run as bands (os {os}, margin {margin}: {why:?})")
                });
                assert_eq!(bands.len(), 3, "{spec:?}: {bands:?}");
            }
            let whole = fw.rates(spec).unwrap();
            let band = fw.rates_rows(spec, &rows).unwrap();
            // single blocks: within 1e-6 of the shot's largest rate; all blocks at once
            // (65 wavelength planes warped, glare and defocus) measured 1.5e-6 with the bands'
            // optics on their pixel rows ± the whole margin, 4.4e-6 (shot 11) since they run on
            // the pixel rows ± the blur's reach (branch d12s): the same relative error on every
            // fit row of all three bands, alternating with the CFA row, so a per-channel factor,
            // not a windowing error at the band's edges; it depends on the band's window, as the
            // wavelength cells' spectral shapes of the lateral-colour split do (the image's mean
            // spectrum, `camsim_optics::split_into_bands`) — likely that, not proven. Far below
            // any σ.
            let blocks = [
                spec.falloff.is_some(),
                spec.glare_fraction.is_some(),
                spec.defocus_sigma_um.is_some(),
                spec.distortion.is_some(),
                spec.lateral_color_um.is_some(),
                spec.ir_leakage.is_some(),
                spec.qe_shift_nm.is_some(),
            ];
            let tol = if blocks.iter().filter(|b| **b).count() > 1 {
                1e-5
            } else {
                1e-6
            };
            for (si, (w, b)) in whole.iter().zip(&band).enumerate() {
                let scale = w.iter().fold(0f32, |m, &x| m.max(x.abs())).max(1e-30);
                let err = rows.iter().fold(0f32, |m, &r| {
                    (0..cols).fold(m, |m, c| m.max((w[r * cols + c] - b[r * cols + c]).abs()))
                });
                assert!(
                    err <= tol * scale,
                    "{spec:?} shot {si} ({}): max |Δ| {err} of {scale}",
                    set.shots[si].id
                );
                // crosstalk, applied by the diagnosis to the rates: right on the fit rows
                let xt = |v: &Vec<f32>| {
                    let mut r = camsim_sensor::ElectronRate {
                        rows: r_n,
                        cols,
                        electrons_per_s: v.clone(),
                    };
                    camsim_sensor::effects::apply_crosstalk(&ct, &mut r);
                    r.electrons_per_s
                };
                let (wx, bx) = (xt(w), xt(b));
                let err = fit.iter().fold(0f32, |m, &r| {
                    (0..cols).fold(m, |m, c| m.max((wx[r * cols + c] - bx[r * cols + c]).abs()))
                });
                assert!(
                    err <= tol * scale,
                    "{spec:?} + crosstalk, shot {si}: max |Δ| {err} of {scale}"
                );
            }
        }
    }

    /// Each band is widened by the warp displacement its own rows can have
    /// ([`crate::chain::band_warp_widening`]), not the whole field's: at large |k1| (the
    /// distortion fit's bracket reaches ±0.3; here barrel beyond ≈ −0.08 folds the grid's
    /// field over and is refused) on a 240 × 320 sensor with fit rows at both edges and the middle, barrel and pincushion distortion (and a k2 whose
    /// parabola turns inside the field, and lateral colour with it) still run as bands (with
    /// the whole field's widening, 0.3 · 200 px each side of every band, they exceeded
    /// [`BAND_GRID_FRACTION`] and ran the whole sensor), the middle band is widened less than
    /// the edge bands, pincushion's edge bands only towards the centre and barrel's only
    /// outwards; and the band rates equal the whole-sensor rates on the requested rows within
    /// f32 rounding (1e-6 of the shot's largest rate, as
    /// `band_rates_equal_the_whole_sensor_rates`).
    #[test]
    fn bands_are_widened_by_their_own_rows_warp() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 240, 320);
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        let rows: Vec<usize> = (0..4).chain(118..122).chain(236..240).collect();
        let specs = [[0.3, 0.0], [-0.07, 0.0], [0.3, -0.25], [-0.15, 0.1]].map(|d| RateSpec {
            distortion: Some(d),
            ..Default::default()
        });
        let mut specs = specs.to_vec();
        specs.push(RateSpec {
            distortion: Some([0.03, 0.0]),
            lateral_color_um: Some(3.0),
            ..Default::default()
        });
        let cols = set.camera.sensor.cols;
        for spec in &specs {
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(spec).unwrap();
            let grid = wavelength_grid(&s2);
            let (bands, widen) = row_bands(&s2, &grid, &rows)
                .unwrap_or_else(|| panic!("{spec:?}: not run as bands"));
            assert_eq!(bands.len(), 3, "{spec:?}: {bands:?}");
            let reach = |w: &crate::chain::BandWidening| w.above.max(w.below);
            assert!(
                reach(&widen[1]) < reach(&widen[0]) && reach(&widen[1]) < reach(&widen[2]),
                "{spec:?}: middle band widened {:?}, edges {:?} {:?}",
                widen[1],
                widen[0],
                widen[2]
            );
            let k1 = spec.distortion.unwrap()[0];
            if spec.lateral_color_um.is_none() && k1.abs() >= 0.07 {
                // top band: pincushion reads towards the centre (below), barrel above
                let (inward, outward) = (widen[0].below, widen[0].above);
                if k1 > 0.0 {
                    assert!(inward > 2 * outward.max(1), "{spec:?}: {:?}", widen[0]);
                } else {
                    assert!(outward > 2 * inward.max(1), "{spec:?}: {:?}", widen[0]);
                }
            }
            let whole = fw.rates(spec).unwrap_or_else(|e| panic!("{spec:?}: {e}"));
            let band = fw
                .rates_rows(spec, &rows)
                .unwrap_or_else(|e| panic!("{spec:?}: {e}"));
            for (si, (w, b)) in whole.iter().zip(&band).enumerate() {
                let scale = w.iter().fold(0f32, |m, &x| m.max(x.abs())).max(1e-30);
                let err = rows.iter().fold(0f32, |m, &r| {
                    (0..cols).fold(m, |m, c| m.max((w[r * cols + c] - b[r * cols + c]).abs()))
                });
                assert!(
                    err <= 1e-6 * scale,
                    "{spec:?} shot {si} ({}): max |Δ| {err} of {scale} (widening {widen:?})",
                    set.shots[si].id
                );
            }
        }
    }

    /// Without the whole scene at hand (a 12 MP chart does not fit the scene cache), the
    /// bands' scene rows are rendered by themselves ([`crate::chain::shot_scene_rows`]) with
    /// the target's luminance factor, computed once by row strips and shared by every blur
    /// margin of one oversampling: the rates are bit for bit those of the bands cut from the
    /// cached whole scenes, for the believed camera and candidates that change the sampling
    /// grid's margin (defocus, distortion both ways, lateral colour) or not (fall-off), and no
    /// whole scene is rendered.
    #[test]
    fn band_scenes_rendered_by_rows_equal_the_whole_scenes_rows() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 640, 24);
        let rows: Vec<usize> = (0..6).chain(317..323).chain(634..640).collect();
        let mut specs = vec![RateSpec::default()];
        specs.extend(sampling_grid_specs());
        let cached = SimForward::new(&set, (0..set.shots.len()).collect());
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        // no scene fits the cache (as a whole 12 MP chart does not)
        fw.scenes.lock().unwrap().lru.budget = 0;
        let mut margins = std::collections::HashSet::new();
        for spec in &specs {
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(spec).unwrap();
            let grid = wavelength_grid(&s2);
            assert!(
                row_bands(&s2, &grid, &rows).is_some(),
                "{spec:?}: not run as bands"
            );
            let (os, margin) = sampling_for(
                &s2.camera.optics,
                &s2.camera.sensor,
                &grid,
                s2.simulation.oversample,
            );
            margins.insert((os, margin));
            let want = cached.rates_rows(spec, &rows).unwrap();
            let got = fw.rates_rows(spec, &rows).unwrap();
            for (si, (a, b)) in want.iter().zip(&got).enumerate() {
                assert!(
                    a.iter()
                        .zip(b.iter())
                        .all(|(x, y)| x.to_bits() == y.to_bits()),
                    "{spec:?} shot {si} ({}): rates differ from the whole scenes' rows",
                    set.shots[si].id
                );
            }
        }
        assert!(
            margins.len() >= 4,
            "the specs change the margin: {margins:?}"
        );
        assert_eq!(
            fw.work.scene_renders.get().0 + fw.work.channel_scene_renders.get().0,
            0,
            "a whole scene was rendered"
        );
        assert!(fw.work.scene_band_renders.get().0 > 0);
        // one strip pass per target and oversampling, not per margin
        let targets: std::collections::HashSet<&str> =
            set.shots.iter().map(|s| s.target_key.as_str()).collect();
        let oversamplings: std::collections::HashSet<usize> = margins.iter().map(|m| m.0).collect();
        assert_eq!(
            fw.work.factor_passes.get().0,
            (targets.len() * oversamplings.len()) as u64,
            "{margins:?}"
        );
    }

    /// A shot's scene rendered straight onto the channel planes (whole, and grid-row windows
    /// with the luminance factor computed by row strips on the luminance plane) is bit for
    /// bit [`crate::chain::channel_scene`] of its term render, for every target of a chart
    /// set (two charts under two illuminants, a flat, a dark); and the forward model's kept
    /// channel scene is that.
    #[test]
    fn channel_scenes_rendered_straight_equal_the_term_scenes_channel_planes() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 40, 56);
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        let grid = wavelength_grid(&set);
        let g = crate::chain::shot_sampling_grid(&set, &grid);
        let gk = SceneCache::grid_key(&set, &grid);
        let same = |a: &[f32], b: &[f32]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
        };
        let mut charts = 0;
        for si in 0..set.shots.len() {
            let id = &set.shots[si].id;
            let (scene, factor) = crate::chain::shot_scene_and_factor(&set, si, &grid).unwrap();
            charts += usize::from(scene.radiance.terms() > 4);
            let strips = crate::chain::shot_scene_luminance_factor(&set, si, &grid).unwrap();
            assert_eq!(strips.to_bits(), factor.to_bits(), "{id}: luminance factor");
            let (ch, want) = crate::chain::channel_scene(&set, &scene).unwrap();
            for (r0, r1) in [(0, g.rows), (3, 17), (g.rows - 5, g.rows)] {
                let (ch2, got) =
                    crate::chain::shot_channel_scene_rows(&set, si, &grid, r0..r1, factor).unwrap();
                assert_eq!(ch, ch2);
                assert_eq!(got.sample_aperture, want.sample_aperture);
                assert_eq!(got.sample_pitch_m, want.sample_pitch_m);
                for (a, b) in got.radiance.planes.iter().zip(&want.radiance.planes) {
                    assert!(
                        same(a, &b[r0 * g.cols..r1 * g.cols]),
                        "{id} rows {r0}..{r1}"
                    );
                }
            }
            let kept = fw
                .scenes
                .lock()
                .unwrap()
                .channel_scene(&set, si, &grid, &gk, &fw.work)
                .unwrap();
            assert_eq!(kept.radiance.planes.len(), want.radiance.planes.len());
            for (a, b) in kept.radiance.planes.iter().zip(&want.radiance.planes) {
                assert!(same(a, b), "{id}: kept channel scene");
            }
        }
        assert!(charts >= 2, "the set has {charts} charts");
    }

    /// The glare sums of the believed optics come from the believed camera's whole-sensor run
    /// on the channel planes (the fit check's: without glare its channel image is the image
    /// before the glare): a glare spec's bands then render no whole scene and run no
    /// whole-sensor optics for the sums, and their rates are bit for bit those of a forward
    /// model that computed the sums itself (the whole scene's channel planes through the
    /// optics without the glare).
    #[test]
    fn glare_sums_of_the_believed_channel_run_are_reused() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 96, 24);
        let rows: Vec<usize> = (0..6).collect();
        let spec = RateSpec {
            glare_fraction: Some(0.05),
            ..Default::default()
        };
        let fresh = SimForward::new(&set, (0..set.shots.len()).collect());
        let want = fresh.rates_rows(&spec, &rows).unwrap();
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        // no scene fits the cache (as a whole 12 MP chart does not)
        fw.scenes.lock().unwrap().lru.budget = 0;
        fw.rates(&RateSpec::default()).unwrap();
        let whole_renders =
            |w: &ForwardWork| w.scene_renders.get().0 + w.channel_scene_renders.get().0;
        let renders = whole_renders(&fw.work);
        let got = fw.rates_rows(&spec, &rows).unwrap();
        assert_eq!(fw.work.glare_sums.get().0, 0, "glare sums computed again");
        assert_eq!(
            whole_renders(&fw.work),
            renders,
            "a whole scene rendered for the glare"
        );
        assert!(fresh.work.glare_sums.get().0 > 0);
        for (si, (a, b)) in want.iter().zip(&got).enumerate() {
            assert!(
                a.iter()
                    .zip(b.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "shot {si}: rates differ from the run that computed its sums"
            );
        }
    }

    /// A veiling-glare spec on the fit rows' bands renders each target's whole scene once:
    /// the glare's whole-field sums need it, and the bands are cut from that same render
    /// (before, a scene too large for the scene cache — a 12 MP chart is 4.8 GB — was rendered
    /// a second time for the bands). Same rates, bit for bit, as with the scenes cached.
    #[test]
    fn glare_bands_are_cut_from_the_glare_sums_render() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 96, 24);
        let rows: Vec<usize> = (0..6).collect();
        let spec = RateSpec {
            glare_fraction: Some(0.05),
            ..Default::default()
        };
        let cached = SimForward::new(&set, (0..set.shots.len()).collect());
        let want = cached.rates_rows(&spec, &rows).unwrap();
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        // no scene fits the cache (as a whole 12 MP chart does not)
        fw.scenes.lock().unwrap().lru.budget = 0;
        {
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(&spec).unwrap();
            let grid = wavelength_grid(&s2);
            assert!(row_bands(&s2, &grid, &rows).is_some(), "not run as bands");
        }
        let got = fw.rates_rows(&spec, &rows).unwrap();
        let targets: std::collections::HashSet<&str> =
            set.shots.iter().map(|s| s.target_key.as_str()).collect();
        // (a chart's whole scene rendered straight onto the channel planes)
        let renders = fw.work.scene_renders.get().0 + fw.work.channel_scene_renders.get().0;
        assert!(
            fw.work.channel_scene_renders.get().0 > 0,
            "no chart on the channels"
        );
        assert_eq!(
            renders,
            targets.len() as u64,
            "one whole render per target ({} targets)",
            targets.len()
        );
        assert_eq!(fw.work.glare_sums.get().0, targets.len() as u64);
        for (si, (a, b)) in want.iter().zip(&got).enumerate() {
            assert!(
                a.iter()
                    .zip(b.iter())
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "shot {si}: rates differ from the cached scenes' run"
            );
        }
    }

    /// The glare sums of candidate optics from the decimated whole field ([`GlareDecimation`],
    /// the 480 × 640 charts set on a 2× coarser pixel grid at oversampling 1: 4× fewer samples
    /// per side than the full grid's oversampling 2) match the whole field's
    /// exact sums (the chain's whole scene through the candidate's optics without the glare,
    /// in the representation the bands run) for the optics a fit visits — fall-off,
    /// defocus, distortion barrel and pincushion, lateral colour (basis terms split into
    /// wavelength bands), a QE candidate (basis terms, believed optics) and combinations —
    /// within [`DECIMATED_GLARE_TOLERANCE`] of each plane's mean, and equal them exactly at
    /// the reference (the believed optics).
    /// Largest relative error of a plane's whole-field mean from the decimated field
    /// ([`decimated_glare_sums_match_the_whole_field_sums`]): 5e-4, 2.3× the largest measured
    /// (2.1e-4, fall-off, pincushion distortion, lateral colour and defocus at once; the
    /// single blocks 1e-6 to 1e-4). The glare adds `f · mean` to every sample, so an error δ
    /// of the mean moves the rates by `f · δ` of the mean signal, as a glare fraction off by
    /// `f · δ` would: 1.5e-5 at f = 0.03, 0.4 σ of the 2 MP set's fitted glare (σ ≈
    /// f / √(2 ΔlnL) = 0.03 / √(2 · 365 569) = 3.5e-5, its finding's ΔlnL) and 0.15 % of one
    /// pixel's shot noise in one frame at 10⁴ e⁻ (the demo's full well). At the reference
    /// optics the error is 0 (rounding), and the candidates a round-2 fit visits lie near it.
    const DECIMATED_GLARE_TOLERANCE: f64 = 5e-4;

    #[test]
    fn decimated_glare_sums_match_the_whole_field_sums() {
        let (_dir, set) = demo_set(vec![], Concealment::Charts, 480, 640);
        let fw = SimForward::new(&set, (0..set.shots.len()).collect());
        // the fit check's whole-sensor run stores the believed optics' exact sums
        fw.rates(&RateSpec::default()).unwrap();
        let (qe, _) = test_colour_shifts(&set);
        let g = Some(0.03);
        let mut specs = vec![RateSpec {
            glare_fraction: g,
            falloff: Some(vec![0.0, 0.0, 0.0]),
            ..Default::default()
        }];
        // fall-off, barrel distortion, defocus (the sampling grids' specs); pincushion at the
        // distortion fit's bracket end, lateral colour (bands), a QE candidate (basis terms of
        // the believed optics) and all blocks at once
        let [falloff, barrel, _, _, defocus] = sampling_grid_specs();
        specs.extend([falloff, barrel, defocus].map(|s| RateSpec {
            glare_fraction: g,
            ..s
        }));
        specs.extend([
            RateSpec {
                glare_fraction: g,
                distortion: Some([0.3, 0.0]),
                ..Default::default()
            },
            RateSpec {
                glare_fraction: g,
                lateral_color_um: Some(-3.0),
                ..Default::default()
            },
            RateSpec {
                glare_fraction: g,
                qe_shift_nm: Some(qe),
                ..Default::default()
            },
            RateSpec {
                glare_fraction: g,
                falloff: Some(vec![-0.2, 0.0, 0.0]),
                distortion: Some([0.05, 0.0]),
                lateral_color_um: Some(-1.0),
                defocus_sigma_um: Some(2.0),
                ..Default::default()
            },
        ]);
        let mut worst = 0f64;
        let mut worst_plain = 0f64;
        let mut kinds = std::collections::HashSet::new();
        for spec in &specs {
            let mut s2 = set.clone();
            s2.camera = fw.camera_for(spec).unwrap();
            let grid = wavelength_grid(&s2);
            let (coarse, k) = crate::chain::decimated_glare_field(&s2).expect("decimated field");
            assert_eq!(k, 2);
            let (capable, channels) = channel_path(&s2, &fw.believed);
            let mut done = std::collections::HashSet::new();
            for si in 0..s2.shots.len() {
                // the charts and one flat (the darks have no glare)
                let flat = matches!(
                    s2.shots[si].target.target,
                    camsim_core::scene::Target::Uniform { .. }
                );
                if !done.insert(if flat {
                    "flat".into()
                } else {
                    s2.shots[si].target_key.clone()
                }) {
                    continue;
                }
                let (dec, channel) = fw
                    .decimated_glare(&s2, spec, si, &grid, capable, channels.len())
                    .unwrap()
                    .expect("a decimated field and the believed sums");
                let scene = crate::chain::shot_scene(&s2, si, &grid).unwrap();
                assert_eq!(channel, capable && scene.radiance.terms() > channels.len());
                let exact = if channel {
                    let (_, chs) = crate::chain::channel_scene(&s2, &scene).unwrap();
                    crate::chain::shot_glare_sums(&s2, &chs, &grid)
                } else {
                    crate::chain::shot_glare_sums(&s2, &scene, &grid)
                }
                .unwrap()
                .unwrap();
                let (plain, _) =
                    crate::chain::decimated_glare_sums(&coarse, si, &grid, channel, None).unwrap();
                assert_eq!(dec.sums.len(), exact.sums.len());
                let top = exact
                    .sums
                    .iter()
                    .fold(0f64, |m, x| m.max(x.abs() / exact.count));
                if top == 0.0 {
                    continue; // a dark target
                }
                kinds.insert((channel, exact.sums.len() > scene.radiance.terms()));
                let rel = |g: &camsim_optics::GlareSums, j: usize| {
                    let e = exact.sums[j] / exact.count;
                    (g.sums[j] / g.count - e).abs() / e.abs().max(1e-3 * top)
                };
                for j in 0..exact.sums.len() {
                    let (r, rp) = (rel(&dec, j), rel(&plain, j));
                    worst_plain = worst_plain.max(rp);
                    if r > worst {
                        worst = r;
                        eprintln!(
                            "{spec:?} shot {} plane {j}/{}: relative error {r:.2e} (plain coarse {rp:.2e})",
                            s2.shots[si].id,
                            exact.sums.len()
                        );
                    }
                    // at the reference optics (no fall-off): the exact sums, to rounding
                    if spec.falloff.as_deref() == Some(&[0.0, 0.0, 0.0][..]) {
                        assert!(
                            r <= 1e-12,
                            "{spec:?} shot {} plane {j}: {r:.2e} at the reference (plain coarse {rp:.2e})",
                            s2.shots[si].id
                        );
                    }
                    assert!(
                        r <= DECIMATED_GLARE_TOLERANCE,
                        "{spec:?} shot {} plane {j}: decimated mean off by {r:.2e} (plain coarse {rp:.2e})",
                        s2.shots[si].id
                    );
                }
            }
        }
        eprintln!("worst relative error {worst:.2e}; plain coarse {worst_plain:.2e}");
        // channel planes, basis terms, basis terms split into bands
        assert_eq!(kinds.len(), 3, "{kinds:?}");
    }
}
