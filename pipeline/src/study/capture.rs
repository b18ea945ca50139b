//! The `"capture"` point evaluator: the camera (optionally behind a real lens) captures test
//! targets at the point's light level and exposure, and the metrics are measured on the
//! simulated frames (docs/study.md has the definitions and the standards they follow):
//!
//! * `mtf50`: ISO 12233 slanted edge (4:1 contrast, 5°) through the full optics (lens PSFs or
//!   the camera's blur); the raw frame is flat-fielded pixel by pixel (divided by the
//!   camera's response to a uniform field of the same light), so every CFA pixel samples the
//!   edge: the e-SFR is that of the pixel grid, Nyquist 0.5 cycles/pixel;
//! * `snr`: a uniform grey field; mean / standard deviation of one channel's pixels over the
//!   central region of one simulated frame (ISO 15739 total noise, temporal + fixed pattern),
//!   and the model's prediction from the noise terms (`snr_model_db`);
//! * `vsnr`: the same field through demosaicking, white balance and colour correction; visible
//!   SNR = 1 / RMS S-CIELAB ΔE*ab (Zhang & Wandell 1996 filters) against the field's mean
//!   (Farrell et al., SPIE 7537, 2010);
//! * `delta_e`: Macbeth chart through the `camsim run` processor (demosaic, white balance,
//!   3×3 matrix fitted to the D65 sRGB targets, 8-bit sRGB); CIEDE2000 per patch;
//! * `dynamic_range`: saturation / noise floor from the model (well or swing in electrons over
//!   √(read² + quantisation²)) and measured from a dark and a saturated frame.
//!
//! Targets other than the slanted edge are imaged with the lens's (or camera's) geometry and
//! relative illumination but without PSF convolution by default (`"psf": true` in the metric
//! turns it on): a normalised PSF leaves a uniform field uniform and only changes patch
//! borders, which the patch statistics exclude. Optics results are computed at a reference
//! luminance and scaled (the chain is linear up to the sensor), and cached in-process by
//! content, so points that differ only in light level or exposure share them; the values are
//! bit-identical with or without the cache.
use super::hash::cache_key;
use super::output::PointOutput;
use crate::color_eval::{patch_delta_e, patch_means, srgb_to_xyz};
use crate::config::{
    camera_from_file, Camera, CameraFile, CaptureSet, Exposure, Shot, SimulationFile,
};
use crate::error::CliError;
use crate::targets::ParsedTarget;
use camsim_core::colorimetry::Xyz;
use camsim_core::constants::SI;
use camsim_core::scene::Target;
use camsim_core::spectrum::Spectrum;
use camsim_core::stats::Rect;
use camsim_isp::{
    demosaic_planes, fit_channel_matrix, illuminant_channel_gains, macbeth_channel_responses,
    macbeth_target_linear_srgb, to_srgb8, ChannelBalance, ChannelPlanes, DemosaicMethod, Mosaic,
    RgbImage,
};
use camsim_metrics::{slanted_edge_mtf, ChartLayout};
use camsim_optics::Blur;
use camsim_sensor::{expected_dn, fixed_pattern, ElectronRate, SensorModel};
use serde::Deserialize;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Luminance (cd/m²) at which optics results are computed before scaling to the point's.
const REFERENCE_LUMINANCE_CD_M2: f64 = 100.0;

/// MTF50 of a full-pitch square pixel aperture alone: |sinc(f p)| = 0.5 at f p = 0.603355.
pub const PIXEL_MTF50_CY_PER_PX: f64 = 0.603_355;

/// The document of a capture point as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct CaptureDoc {
    #[allow(dead_code)]
    camsim_version: String,
    #[allow(dead_code)]
    kind: String,
    camera: Value,
    #[serde(default)]
    lens: Option<Value>,
    conditions: Conditions,
    #[serde(default)]
    simulation: Option<SimulationFile>,
    #[serde(default)]
    processor: Option<ProcessorDoc>,
    metrics: MetricsDoc,
    #[serde(default)]
    #[allow(dead_code)]
    seed: Option<u64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct Conditions {
    /// Mean luminance of the targets (cd/m²).
    luminance_cd_m2: f64,
    /// Exposure time (s).
    exposure_s: f64,
    /// Illuminant: an ISET name or a spectrum (default D65).
    #[serde(default)]
    illuminant: Option<Value>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProcessorDoc {
    #[serde(default)]
    demosaic: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MetricsDoc {
    #[serde(default)]
    mtf50: Option<Mtf50Opts>,
    #[serde(default)]
    snr: Option<SnrOpts>,
    #[serde(default)]
    vsnr: Option<VsnrOpts>,
    #[serde(default)]
    delta_e: Option<DeltaEOpts>,
    #[serde(default)]
    dynamic_range: Option<DrOpts>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Mtf50Opts {
    #[serde(default)]
    angle_deg: Option<f64>,
    #[serde(default)]
    contrast: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct SnrOpts {
    #[serde(default)]
    channel: Option<String>,
    #[serde(default)]
    roi_fraction: Option<f64>,
    #[serde(default)]
    psf: Option<bool>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct VsnrOpts {
    #[serde(default)]
    display_dpi: Option<f64>,
    #[serde(default)]
    viewing_distance_m: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct DeltaEOpts {
    #[serde(default)]
    psf: Option<bool>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct DrOpts {}

fn parse(doc: &Value) -> Result<CaptureDoc, String> {
    let d: CaptureDoc = serde_json::from_value(doc.clone()).map_err(|e| e.to_string())?;
    let c = &d.conditions;
    if !(c.luminance_cd_m2.is_finite() && c.luminance_cd_m2 >= 0.0) {
        return Err(format!(
            "conditions.luminance_cd_m2: must be ≥ 0, got {}",
            c.luminance_cd_m2
        ));
    }
    if !(c.exposure_s.is_finite() && c.exposure_s > 0.0) {
        return Err(format!(
            "conditions.exposure_s: must be > 0, got {}",
            c.exposure_s
        ));
    }
    if let Some(m) = &d.metrics.mtf50 {
        if let Some(a) = m.angle_deg {
            if !(a.abs() >= 1.0 && a.abs() <= 20.0) {
                return Err(format!("metrics.mtf50.angle_deg: must be 1–20° in magnitude (ISO 12233 uses ≈ 5°), got {a}"));
            }
        }
        if let Some(k) = m.contrast {
            if !(k.is_finite() && k > 1.0) {
                return Err(format!(
                    "metrics.mtf50.contrast: must be > 1 (light/dark ratio), got {k}"
                ));
            }
        }
    }
    if let Some(s) = &d.metrics.snr {
        if let Some(f) = s.roi_fraction {
            if !(f > 0.0 && f <= 1.0) {
                return Err(format!(
                    "metrics.snr.roi_fraction: must be in (0, 1], got {f}"
                ));
            }
        }
    }
    if let Some(v) = &d.metrics.vsnr {
        for (k, x) in [
            ("display_dpi", v.display_dpi),
            ("viewing_distance_m", v.viewing_distance_m),
        ] {
            if let Some(x) = x {
                if !(x.is_finite() && x > 0.0) {
                    return Err(format!("metrics.vsnr.{k}: must be > 0, got {x}"));
                }
            }
        }
    }
    if let Some(p) = &d.processor {
        if let Some(m) = &p.demosaic {
            m.parse::<DemosaicMethod>()
                .map_err(|e| format!("processor.demosaic: {e}"))?;
        }
    }
    illuminant_energy(&d)?;
    Ok(d)
}

/// The camera as a validated file with the lens slot applied: blur "lens" (or absent) when a
/// lens is given; the returned file has blur "none" in its place.
fn camera_file(d: &CaptureDoc) -> Result<CameraFile, String> {
    let mut cam = d.camera.clone();
    if d.lens.is_some() {
        let kind = cam["optics"]["blur"]["kind"].as_str().map(String::from);
        match kind.as_deref() {
            None | Some("lens") => {}
            Some(k) => {
                return Err(format!(
                    "camera.optics.blur.kind: \"{k}\" but the point has a lens; use \"lens\" (or leave the blur out)"
                ))
            }
        }
        if cam["optics"]["blur"].get("lens_file").is_some() {
            return Err("camera.optics.blur.lens_file: in a study the lens is the point's \"lens\" (e.g. {\"$file\": \"lens.json\"}), so that it is hashed and can be swept".into());
        }
        if let Some(o) = cam.get_mut("optics").and_then(Value::as_object_mut) {
            o.insert("blur".into(), json!({"kind": "none"}));
        }
    } else if cam["optics"]["blur"]["kind"].as_str() == Some("lens") {
        return Err("camera.optics.blur: kind \"lens\" needs the point's \"lens\" (e.g. {\"$file\": \"lens.json\"})".into());
    } else if cam["optics"]["blur"].get("psf_file").is_some() {
        return Err(
            "camera.optics.blur.psf_file: PSF files are not supported in studies yet".into(),
        );
    }
    serde_json::from_value(cam).map_err(|e| format!("camera: {e}"))
}

fn lens_prescription(lens: &Value) -> Result<camsim_lens::LensPrescription, String> {
    camsim_lens::LensPrescription::from_json_str(
        &lens.to_string(),
        &camsim_lens::GlassCatalog::bundled(),
    )
    .map_err(|e| format!("lens: {e}"))
}

/// Cheap validation of a capture document (no field model, no images).
pub fn validate(doc: &Value) -> Result<(), String> {
    let d = parse(doc)?;
    let f = camera_file(&d)?;
    let cam = camera_from_file(Path::new("camera"), f).map_err(|e| e.one_line())?;
    if let Some(l) = &d.lens {
        lens_prescription(l)?;
    }
    let names = &cam.sensor.channel_names;
    if let Some(s) = &d.metrics.snr {
        if let Some(c) = &s.channel {
            if !names.iter().any(|n| n == c) {
                return Err(format!(
                    "metrics.snr.channel: \"{c}\" is not a sensor channel (have {})",
                    names.join(", ")
                ));
            }
        }
    }
    Ok(())
}

fn illuminant_energy(d: &CaptureDoc) -> Result<Spectrum, String> {
    match &d.conditions.illuminant {
        None => camsim_core::data::illuminant("D65").map_err(|e| e.to_string()),
        Some(Value::String(n)) => {
            camsim_core::data::illuminant(n).map_err(|e| format!("conditions.illuminant: {e}"))
        }
        Some(v) => serde_json::from_value::<crate::config::SpectrumValue>(v.clone())
            .map(|s| s.0)
            .map_err(|e| format!("conditions.illuminant: {e}")),
    }
}

/// What the points of one study share, keyed by content: validated cameras (with their lens
/// field models), lens field models by prescription and covered field, and electron rates at
/// the reference luminance. One value per study run, created by its caller and passed to
/// every point; each map is cleared when it holds `CACHE_LIMIT` (64) entries.
#[derive(Default)]
pub struct StudyCaches {
    cameras: Mutex<HashMap<String, Arc<Camera>>>,
    lens_blurs: Mutex<HashMap<String, Arc<camsim_optics::LensBlur>>>,
    rates: Mutex<HashMap<String, Arc<ElectronRate>>>,
}

/// Number of entries kept per cache before it is cleared (memory bound for long studies).
const CACHE_LIMIT: usize = 64;

/// Get from a cache or compute without holding the lock (the computation may use rayon, and a
/// rayon worker waiting on a lock could be asked to run another point that needs it).
fn cached<T>(
    cache: &Mutex<HashMap<String, Arc<T>>>,
    key: &str,
    make: impl FnOnce() -> Result<T, CliError>,
) -> Result<Arc<T>, CliError> {
    if let Some(v) = cache.lock().expect("cache").get(key) {
        return Ok(v.clone());
    }
    let v = Arc::new(make()?);
    let mut c = cache.lock().expect("cache");
    if c.len() >= CACHE_LIMIT {
        c.clear();
    }
    Ok(c.entry(key.to_string()).or_insert(v).clone())
}

/// The camera of the document (with its lens field model), cached by content.
fn load_camera(d: &CaptureDoc, caches: &StudyCaches) -> Result<(String, Arc<Camera>), CliError> {
    let lens = d.lens.clone().unwrap_or(Value::Null);
    let key = cache_key(&[&d.camera, &lens]);
    let cam = cached(&caches.cameras, &key, || {
        let f = camera_file(d).map_err(CliError::Other)?;
        let mut cam = camera_from_file(Path::new("camera"), f)?;
        if let Some(l) = &d.lens {
            let s = &cam.sensor;
            let (r, c) = (s.rows as f64, s.cols as f64);
            // Cover the sensor's half-diagonal (as camera.json's blur kind "lens" does), rounded
            // up to 0.05 mm × 2^k so that sensors of similar size (a pixel-pitch sweep) share
            // one field model.
            let half_diag_mm =
                (0.5 * s.pixel_pitch_m * (r * r + c * c).sqrt()).max(s.pixel_pitch_m) * 1e3;
            let mut cover_mm = 0.05;
            while cover_mm < half_diag_mm {
                cover_mm *= 2.0;
            }
            let lkey = cache_key(&[l, &json!(cover_mm)]);
            let blur = cached(&caches.lens_blurs, &lkey, || {
                let lens = lens_prescription(l).map_err(CliError::Other)?;
                let opts = camsim_optics::LensBlurOptions::covering(cover_mm);
                camsim_optics::LensBlur::from_prescription(&lens, &opts)
                    .map_err(|e| CliError::Other(format!("lens: {e}")))
            })?;
            cam.optics.blur = Blur::Lens((*blur).clone());
        }
        Ok(cam)
    })?;
    Ok((key, cam))
}

/// The camera without PSF convolution (geometry and relative illumination only).
fn without_psf(cam: &Camera) -> Camera {
    let mut c = cam.clone();
    c.optics.blur = match &cam.optics.blur {
        Blur::Lens(l) => {
            let mut l = l.clone();
            l.apply_psf = false;
            Blur::Lens(l)
        }
        _ => Blur::None,
    };
    c.optics.diffuser = None;
    c
}

/// Everything a metric needs about the point.
struct Ctx<'a> {
    caches: &'a StudyCaches,
    cam_key: String,
    cam: Arc<Camera>,
    sim: SimulationFile,
    sim_json: Value,
    luminance_cd_m2: f64,
    exposure_s: f64,
    illuminant_json: Value,
    illuminant_photons: Spectrum,
    seed: u64,
    fixed: camsim_sensor::FixedPattern,
    demosaic: DemosaicMethod,
    dir: &'a Path,
}

impl Ctx<'_> {
    fn sensor(&self) -> &SensorModel {
        &self.cam.sensor
    }

    fn shot(&self) -> camsim_sensor::Shot {
        camsim_sensor::Shot {
            exposure_s: self.exposure_s,
            analog_gain: self.cam.sensor.analog_gain,
        }
    }

    /// Electron rate of `target` at the point's luminance (computed at the reference
    /// luminance, cached, then scaled).
    fn rate(&self, what: &str, target: ParsedTarget, psf: bool) -> Result<ElectronRate, CliError> {
        let key = cache_key(&[
            &Value::String(self.cam_key.clone()),
            &self.sim_json,
            &Value::String(what.into()),
            &self.illuminant_json,
            &Value::Bool(psf),
        ]);
        let base = cached(&self.caches.rates, &key, || {
            let cam = if psf {
                (*self.cam).clone()
            } else {
                without_psf(&self.cam)
            };
            let set = CaptureSet {
                path: PathBuf::from("<study point>"),
                dir: PathBuf::from("."),
                camera: cam,
                camera_path: PathBuf::from("camera"),
                shots: vec![Shot {
                    id: what.into(),
                    target,
                    target_key: what.into(),
                    exposure: Exposure::Fixed(0.0),
                    analog_gain: self.cam.sensor.analog_gain,
                    frames: vec![],
                    light: None,
                    motion: None,
                    temperature_c: None,
                    frame_rate_hz: None,
                }],
                simulation: self.sim.clone(),
                raw_format: None,
            };
            let grid = crate::chain::wavelength_grid(&set);
            crate::chain::shot_electron_rate(&set, 0, &grid)
        })?;
        let k = (self.luminance_cd_m2 / REFERENCE_LUMINANCE_CD_M2) as f32;
        Ok(ElectronRate {
            rows: base.rows,
            cols: base.cols,
            electrons_per_s: base.electrons_per_s.iter().map(|&r| r * k).collect(),
        })
    }

    fn uniform_target(&self) -> ParsedTarget {
        ParsedTarget {
            target: Target::Uniform {
                radiance: self.illuminant_photons.clone(),
            },
            mean_luminance_cd_m2: Some(REFERENCE_LUMINANCE_CD_M2),
            illuminant: Some(self.illuminant_photons.clone()),
            patch_labels: None,
            world: Default::default(),
            gltf: None,
        }
    }

    fn frame(&self, rate: &ElectronRate, stream: u64) -> camsim_core::image::RawFrame {
        crate::chain::simulate_frame(
            self.sensor(),
            rate,
            &self.shot(),
            camsim_sensor::PatternSource::Maps(&self.fixed),
            self.seed,
            &[stream, 0],
        )
    }

    fn planes(&self, raw: &camsim_core::image::RawFrame) -> Result<ChannelPlanes, CliError> {
        let m = Mosaic::from_frame(raw).map_err(|e| CliError::Other(format!("processor: {e}")))?;
        demosaic_planes(&m, self.demosaic)
            .map_err(|e| CliError::Other(format!("processor.demosaic: {e}")))
    }

    fn png(&self, name: &str, rgb: &[u8], rows: usize, cols: usize) -> Result<(), CliError> {
        crate::plots::rgb8_png(&self.dir.join(name), rgb, rows, cols)
    }
}

/// Mean dark-current electrons of one exposure of `t` seconds (0 when dark current is off).
fn dark_e(s: &SensorModel, t: f64) -> f64 {
    if s.noise.dark {
        t * s.dark_voltage_v_per_s / s.conversion_gain_v_per_e
    } else {
        0.0
    }
}

/// Evaluate a capture point into `dir` (images) and return its metrics.
pub fn evaluate(
    doc: &Value,
    seed: u64,
    dir: &Path,
    caches: &StudyCaches,
) -> Result<PointOutput, CliError> {
    let d = parse(doc).map_err(CliError::Other)?;
    validate(doc).map_err(CliError::Other)?;
    let (cam_key, cam) = load_camera(&d, caches)?;
    let ill_e = illuminant_energy(&d).map_err(CliError::Other)?;
    let sim = d.simulation.clone().unwrap_or_default();
    let sim_json = doc.get("simulation").cloned().unwrap_or(Value::Null);
    let fixed = fixed_pattern(&cam.sensor, seed);
    let ctx = Ctx {
        caches,
        cam_key,
        sim,
        sim_json,
        luminance_cd_m2: d.conditions.luminance_cd_m2,
        exposure_s: d.conditions.exposure_s,
        illuminant_json: d.conditions.illuminant.clone().unwrap_or(json!("D65")),
        illuminant_photons: ill_e.energy_to_photons(&SI),
        seed,
        fixed,
        demosaic: d
            .processor
            .as_ref()
            .and_then(|p| p.demosaic.as_deref())
            .unwrap_or("malvar")
            .parse()
            .map_err(|e| CliError::Other(format!("processor.demosaic: {e}")))?,
        dir,
        cam,
    };
    let mut out = PointOutput::default();
    let mut detail = serde_json::Map::new();
    let s = ctx.sensor();
    let pitch_mm = s.pixel_pitch_m * 1e3;
    out.put("nyquist_cy_per_mm", 0.5 / pitch_mm);
    // A measurement that fails on the data (e.g. no contrast left in the dark) gives empty
    // values and its message in result.json's detail.errors; bad input was rejected earlier.
    let mut errors = serde_json::Map::new();
    if let Some(o) = &d.metrics.mtf50 {
        out.put("pixel_mtf50_cy_per_mm", PIXEL_MTF50_CY_PER_PX / pitch_mm);
        match mtf50(&ctx, o) {
            Ok(m) => {
                out.put_opt("mtf50_cy_per_px", m.measured_cy_per_px);
                out.put_opt(
                    "mtf50_cy_per_mm",
                    m.measured_cy_per_px.map(|f| f / pitch_mm),
                );
                out.put_opt(
                    "mtf50_noise_free_cy_per_mm",
                    m.noise_free_cy_per_px.map(|f| f / pitch_mm),
                );
                out.put("mtf_edge_saturated_fraction", m.saturated_fraction);
                detail.insert("mtf".into(), m.curve);
                if let Some(e) = m.measured_error {
                    errors.insert("mtf50".into(), json!(e));
                }
                out.images
                    .push(("edge.png".into(), "slanted edge (flat-fielded raw)".into()));
            }
            Err(e) => {
                for k in [
                    "mtf50_cy_per_px",
                    "mtf50_cy_per_mm",
                    "mtf50_noise_free_cy_per_mm",
                    "mtf_edge_saturated_fraction",
                ] {
                    out.put_opt(k, None);
                }
                errors.insert("mtf50".into(), json!(e.one_line()));
            }
        }
    }
    let mut flat_frame = None;
    if d.metrics.snr.is_some() || d.metrics.vsnr.is_some() {
        let o = d.metrics.snr.clone().unwrap_or_default();
        let rate = ctx.rate("uniform", ctx.uniform_target(), o.psf.unwrap_or(false))?;
        let raw = ctx.frame(&rate, 2);
        if d.metrics.snr.is_some() {
            let r = snr(&ctx, &o, &rate, &raw)?;
            out.put("signal_e", r.signal_e);
            out.put("snr_db", r.measured_db);
            out.put("snr_model_db", r.model_db);
            // Photon shot noise alone: SNR = √e.
            out.put("snr_shot_limit_db", 10.0 * r.signal_e.log10());
        }
        flat_frame = Some(raw);
    }
    if let Some(o) = &d.metrics.vsnr {
        let raw = flat_frame.as_ref().expect("drawn above");
        match vsnr(&ctx, o, raw) {
            Ok(v) => {
                out.put("vsnr", v);
                out.images
                    .push(("flat.png".into(), "uniform grey, processed (vSNR)".into()));
            }
            Err(e) => {
                out.put_opt("vsnr", None);
                errors.insert("vsnr".into(), json!(e.one_line()));
            }
        }
    }
    if let Some(o) = &d.metrics.delta_e {
        match delta_e(&ctx, o) {
            Ok(r) => {
                out.put("delta_e_2000_mean", r.mean);
                out.put("delta_e_2000_max", r.max);
                detail.insert("delta_e_2000_per_patch".into(), json!(r.per_patch));
                out.images
                    .push(("chart.png".into(), "Macbeth chart, rendered sRGB".into()));
            }
            Err(e) => {
                out.put_opt("delta_e_2000_mean", None);
                out.put_opt("delta_e_2000_max", None);
                errors.insert("delta_e".into(), json!(e.one_line()));
            }
        }
    }
    if d.metrics.dynamic_range.is_some() {
        let r = dynamic_range(&ctx)?;
        out.put("dr_model_db", r.model_db);
        out.put("dr_measured_db", r.measured_db);
    }
    if !errors.is_empty() {
        detail.insert("errors".into(), Value::Object(errors));
    }
    out.detail = Value::Object(detail);
    Ok(out)
}

struct MtfResult {
    measured_cy_per_px: Option<f64>,
    noise_free_cy_per_px: Option<f64>,
    saturated_fraction: f64,
    measured_error: Option<String>,
    curve: Value,
}

fn mtf50(ctx: &Ctx, o: &Mtf50Opts) -> Result<MtfResult, CliError> {
    let s = ctx.sensor();
    let angle = o.angle_deg.unwrap_or(5.0);
    let contrast = o.contrast.unwrap_or(4.0);
    let ill = &ctx.illuminant_photons;
    let edge = ParsedTarget {
        target: Target::SlantedEdge {
            dark: ill.scaled(1.0 / contrast),
            light: ill.clone(),
            angle_deg: angle,
        },
        mean_luminance_cd_m2: Some(REFERENCE_LUMINANCE_CD_M2),
        illuminant: Some(ill.clone()),
        patch_labels: None,
        world: Default::default(),
        gltf: None,
    };
    let what = format!("slanted_edge:{angle}:{contrast}");
    let rate = ctx.rate(&what, edge, true)?;
    // Flat field of the light side: the response to a uniform field (no PSF needed).
    let flat = ctx.rate("uniform", ctx.uniform_target(), false)?;
    let raw = ctx.frame(&rate, 1);
    let shot = ctx.shot();
    let dn_per_e = s.dn_per_e(shot.analog_gain);
    let dark_dn = dark_e(s, ctx.exposure_s) * dn_per_e + s.black_level_dn;
    let gain: Vec<f64> = flat
        .electrons_per_s
        .iter()
        .map(|&r| (r as f64 * ctx.exposure_s * dn_per_e).max(1e-30))
        .collect();
    let norm = |dn: &dyn Fn(usize) -> f64| -> Vec<f32> {
        (0..raw.dn.len())
            .map(|i| ((dn(i) - dark_dn) / gain[i]) as f32)
            .collect()
    };
    let measured = norm(&|i| raw.dn[i] as f64);
    let expected = expected_dn(s, &rate, &shot);
    let noise_free = norm(&|i| expected[i] as f64);
    let (rows, cols) = (s.rows, s.cols);
    let half_w = (3 * cols / 8).clamp(6, 48);
    let roi = Rect {
        row0: rows / 8,
        row1: rows - rows / 8,
        col0: (cols / 2).saturating_sub(half_w),
        col1: (cols / 2 + half_w).min(cols),
    };
    let max = s.max_dn() as u16;
    let mut sat = 0usize;
    for r in roi.row0..roi.row1 {
        for c in roi.col0..roi.col1 {
            if raw.dn[r * cols + c] >= max {
                sat += 1;
            }
        }
    }
    let n_roi = (roi.row1 - roi.row0) * (roi.col1 - roi.col0);
    // The noisy measurement may fail on dark data (no contrast left); the noise-free one is
    // kept regardless.
    let m0 = slanted_edge_mtf(&noise_free, rows, cols, roi)
        .map_err(|e| CliError::Other(format!("metrics.mtf50: {e}")))?;
    let m = slanted_edge_mtf(&measured, rows, cols, roi);
    let measured_error = m
        .as_ref()
        .err()
        .map(|e| format!("metrics.mtf50 (simulated frame): {e}"));
    let m = m.ok();
    // Image: the ROI of the flat-fielded frame, its 1st–99th percentile range → 0–255.
    let mut vals: Vec<f32> = (roi.row0..roi.row1)
        .flat_map(|r| (roi.col0..roi.col1).map(move |c| (r, c)))
        .map(|(r, c)| measured[r * cols + c])
        .collect();
    vals.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let (a, b) = (
        vals[vals.len() / 100] as f64,
        vals[vals.len() * 99 / 100] as f64,
    );
    let span = (b - a).max(1e-30);
    let (rr, rc) = (roi.row1 - roi.row0, roi.col1 - roi.col0);
    let mut png = Vec::with_capacity(rr * rc * 3);
    for r in roi.row0..roi.row1 {
        for c in roi.col0..roi.col1 {
            let v = (((measured[r * cols + c] as f64 - a) / span).clamp(0.0, 1.0) * 255.0).round()
                as u8;
            png.extend_from_slice(&[v, v, v]);
        }
    }
    ctx.png("edge.png", &png, rr, rc)?;
    let keep: Vec<usize> = (0..m0.frequencies_cycles_per_pixel.len())
        .filter(|&i| m0.frequencies_cycles_per_pixel[i] <= 1.0)
        .collect();
    Ok(MtfResult {
        measured_cy_per_px: m.as_ref().and_then(|m| m.mtf50_cycles_per_pixel),
        noise_free_cy_per_px: m0.mtf50_cycles_per_pixel,
        saturated_fraction: sat as f64 / n_roi.max(1) as f64,
        measured_error,
        curve: json!({
            "frequencies_cy_per_px": keep.iter().map(|&i| m0.frequencies_cycles_per_pixel[i]).collect::<Vec<_>>(),
            "mtf": keep.iter().map(|&i| m.as_ref().and_then(|m| m.mtf.get(i).copied())).collect::<Vec<_>>(),
            "mtf_noise_free": keep.iter().map(|&i| m0.mtf[i]).collect::<Vec<_>>(),
            "edge_angle_deg": m0.angle_deg,
        }),
    })
}

struct SnrResult {
    signal_e: f64,
    measured_db: f64,
    model_db: f64,
}

fn central_rect(rows: usize, cols: usize, f: f64) -> Rect {
    let h = ((rows as f64 * f).round() as usize).clamp(2, rows);
    let w = ((cols as f64 * f).round() as usize).clamp(2, cols);
    Rect {
        row0: (rows - h) / 2,
        row1: (rows - h) / 2 + h,
        col0: (cols - w) / 2,
        col1: (cols - w) / 2 + w,
    }
}

fn snr(
    ctx: &Ctx,
    o: &SnrOpts,
    rate: &ElectronRate,
    raw: &camsim_core::image::RawFrame,
) -> Result<SnrResult, CliError> {
    let s = ctx.sensor();
    let ch_name = o.channel.clone().unwrap_or_else(|| {
        if s.channel_names.iter().any(|n| n == "g") {
            "g".into()
        } else {
            s.channel_names[0].clone()
        }
    });
    let ch = s
        .channel_names
        .iter()
        .position(|n| *n == ch_name)
        .ok_or_else(|| CliError::Other(format!("metrics.snr.channel: no channel \"{ch_name}\"")))?;
    let roi = central_rect(s.rows, s.cols, o.roi_fraction.unwrap_or(0.5));
    let t = ctx.exposure_s;
    let (mut n, mut sum, mut sum2, mut e_sum) = (0usize, 0f64, 0f64, 0f64);
    for r in roi.row0..roi.row1 {
        for c in roi.col0..roi.col1 {
            if s.cfa.channel_at(r, c) != ch {
                continue;
            }
            let v = raw.dn[r * s.cols + c] as f64 - s.black_level_dn;
            n += 1;
            sum += v;
            sum2 += v * v;
            e_sum += rate.electrons_per_s[r * s.cols + c] as f64 * t;
        }
    }
    let nf = n as f64;
    let mean = sum / nf;
    let var = ((sum2 - nf * mean * mean) / (nf - 1.0)).max(0.0);
    let measured_db = 20.0 * (mean / var.sqrt()).log10();
    // Model (capture-format steps 3–7): spatial variance over one frame of the pixels of a
    // uniform field, in electrons: photon shot e, dark shot d, PRNU (σ_P e)², DSNU and read
    // noise (σ/g)², then the ADC's quantisation 1/12 DN².
    let e = e_sum / nf;
    let g = s.conversion_gain_v_per_e;
    let d = dark_e(s, t);
    let sw = &s.noise;
    let mut var_e = 0.0;
    if sw.shot {
        var_e += e;
    }
    if sw.dark {
        var_e += d;
    }
    if sw.prnu {
        var_e += (s.prnu_sigma_percent * 0.01 * e).powi(2);
    }
    if sw.dsnu {
        var_e += (s.dsnu_sigma_v / g).powi(2);
    }
    if sw.read {
        var_e += (s.read_noise_v / g).powi(2);
    }
    let dn_per_e = s.dn_per_e(ctx.cam.sensor.analog_gain);
    let var_dn = var_e * dn_per_e * dn_per_e + 1.0 / 12.0;
    let model_db = 20.0 * ((e + d) * dn_per_e / var_dn.sqrt()).log10();
    Ok(SnrResult {
        signal_e: e,
        measured_db,
        model_db,
    })
}

/// White balance for the point's illuminant, then the paper's colour correction (3 × K for K
/// sensor channels) fitted on the camera's noise-free responses to the Macbeth chart (D65
/// sRGB targets).
fn process_uniform(ctx: &Ctx, raw: &camsim_core::image::RawFrame) -> Result<RgbImage, CliError> {
    let mut planes = ctx.planes(raw)?;
    let s = ctx.sensor();
    let qe = &s.channel_qe;
    let gains = illuminant_channel_gains(qe, &s.channel_names, &ctx.illuminant_photons)
        .map_err(|e| CliError::Other(format!("white balance: {e}")))?;
    ChannelBalance::Gains(gains.clone())
        .apply(&mut planes)
        .map_err(|e| CliError::Other(format!("white balance: {e}")))?;
    let mut v = macbeth_channel_responses(qe, &ctx.illuminant_photons)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))?;
    for p in v.iter_mut() {
        for (x, g) in p.iter_mut().zip(&gains) {
            *x *= g;
        }
    }
    let d65 = camsim_core::data::illuminant("D65").map_err(|e| CliError::Other(e.to_string()))?;
    let targets = macbeth_target_linear_srgb(&d65, 0.9)
        .map_err(|e| CliError::Other(format!("colour targets: {e}")))?;
    let ccm = fit_channel_matrix(&v, &targets)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))?;
    ccm.apply_planes(&planes)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))
}

fn vsnr(ctx: &Ctx, o: &VsnrOpts, raw: &camsim_core::image::RawFrame) -> Result<f64, CliError> {
    let rgb = process_uniform(ctx, raw)?;
    // Display: the grey shown at Y = 0.18 of the display white (a scalar gain, the ISP's
    // exposure normalisation), clipped to the display's range.
    let ys: f64 = rgb
        .data
        .iter()
        .map(|p| srgb_to_xyz([p[0] as f64, p[1] as f64, p[2] as f64])[1])
        .sum::<f64>()
        / rgb.data.len() as f64;
    if ys.is_nan() || ys <= 0.0 {
        return Err(CliError::Other(
            "metrics.vsnr: the processed grey field has no signal".into(),
        ));
    }
    let k = 0.18 / ys;
    let lin: Vec<[f64; 3]> = rgb
        .data
        .iter()
        .map(|p| [0, 1, 2].map(|c| (p[c] as f64 * k).clamp(0.0, 1.0)))
        .collect();
    let xyz: Vec<Xyz> = lin
        .iter()
        .map(|v| {
            let x = srgb_to_xyz(*v);
            Xyz {
                x: x[0],
                y: x[1],
                z: x[2],
            }
        })
        .collect();
    let n = xyz.len() as f64;
    let mean = xyz.iter().fold(
        Xyz {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        },
        |a, p| Xyz {
            x: a.x + p.x / n,
            y: a.y + p.y / n,
            z: a.z + p.z / n,
        },
    );
    let reference = vec![mean; xyz.len()];
    let w = srgb_to_xyz([1.0, 1.0, 1.0]);
    let white = Xyz {
        x: w[0],
        y: w[1],
        z: w[2],
    };
    // Samples per degree of a display of `dpi` seen from `d` (ISETCam defaults 100 dpi, 0.2 m).
    let dpi = o.display_dpi.unwrap_or(100.0);
    let dist = o.viewing_distance_m.unwrap_or(0.2);
    let deg_per_px = 2.0 * (0.0254 / dpi / (2.0 * dist)).atan().to_degrees();
    let res = camsim_metrics::scielab(
        &xyz,
        &reference,
        rgb.rows,
        rgb.cols,
        white,
        1.0 / deg_per_px,
    )
    .map_err(|e| CliError::Other(format!("metrics.vsnr: {e}")))?;
    // Central 80 % (S-CIELAB's border handling), RMS ΔE*ab about the mean.
    let roi = central_rect(rgb.rows, rgb.cols, 0.8);
    let (mut s2, mut m) = (0.0, 0usize);
    for r in roi.row0..roi.row1 {
        for c in roi.col0..roi.col1 {
            let e = res.delta_e_map[r * rgb.cols + c];
            s2 += e * e;
            m += 1;
        }
    }
    let rms = (s2 / m as f64).sqrt();
    let png: Vec<u8> = lin
        .iter()
        .flat_map(|v| v.map(|x| (camsim_isp::srgb_encode(x) * 255.0).round() as u8))
        .collect();
    ctx.png("flat.png", &png, rgb.rows, rgb.cols)?;
    Ok(if rms > 0.0 { 1.0 / rms } else { f64::INFINITY })
}

struct DeltaEResult {
    mean: f64,
    max: f64,
    per_patch: Vec<f64>,
}

fn delta_e(ctx: &Ctx, o: &DeltaEOpts) -> Result<DeltaEResult, CliError> {
    let target = crate::targets::target_from_value(
        &json!({"kind": "macbeth", "illuminant": ctx.illuminant_json, "patch_fraction": 0.8,
                "mean_luminance_cd_m2": REFERENCE_LUMINANCE_CD_M2}),
        Path::new("."),
        ctx.sensor(),
    )
    .map_err(|m| CliError::Other(format!("conditions.illuminant{m}")))?;
    let rate = ctx.rate("macbeth:0.8", target, o.psf.unwrap_or(false))?;
    let raw = ctx.frame(&rate, 3);
    let mut planes = ctx.planes(&raw)?;
    let s = ctx.sensor();
    let (qe, names) = (&s.channel_qe, &s.channel_names);
    let layout = ChartLayout {
        chart_rows: 4,
        chart_cols: 6,
        patch_fraction: 0.8,
        margin_fraction: 0.2,
    };
    let d65 = camsim_core::data::illuminant("D65").map_err(|e| CliError::Other(e.to_string()))?;
    let targets = macbeth_target_linear_srgb(&d65, 0.9)
        .map_err(|e| CliError::Other(format!("colour targets: {e}")))?;
    // Held out (docs/isp.md): the matrix is fitted on a D65 calibration capture of the chart
    // (known-illuminant white balance there and here), then scored on this point's chart.
    let cal = crate::honest_color::CaptureStats::calibration(qe, &d65.energy_to_photons(&SI))?;
    let calibrated = crate::honest_color::calibrate(
        crate::honest_color::WbMethod::KnownIlluminant,
        &cal,
        qe,
        names,
        &targets,
        0.9,
    )?;
    let gains = illuminant_channel_gains(qe, names, &ctx.illuminant_photons)
        .map_err(|e| CliError::Other(format!("white balance: {e}")))?;
    ChannelBalance::Gains(gains)
        .apply(&mut planes)
        .map_err(|e| CliError::Other(format!("white balance: {e}")))?;
    let mut rgb = calibrated
        .matrix
        .apply_planes(&planes)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))?;
    let k = crate::honest_color::exposure_scale(&patch_means(&rgb, &layout), 0.9) as f32;
    rgb.data
        .iter_mut()
        .for_each(|p| p.iter_mut().for_each(|x| *x *= k));
    let rendered8 = to_srgb8(&rgb);
    ctx.png("chart.png", &rendered8, rgb.rows, rgb.cols)?;
    let rendered_lin = camsim_isp::from_srgb8(&rendered8, rgb.rows, rgb.cols);
    let de = patch_delta_e(&targets, &patch_means(&rendered_lin, &layout))?;
    Ok(DeltaEResult {
        mean: de.stats2000.mean,
        max: de.stats2000.max,
        per_patch: de.de2000,
    })
}

struct DrResult {
    model_db: f64,
    measured_db: f64,
}

fn dynamic_range(ctx: &Ctx) -> Result<DrResult, CliError> {
    let s = ctx.sensor();
    let shot = ctx.shot();
    let g = s.conversion_gain_v_per_e;
    let dn_per_e = s.dn_per_e(shot.analog_gain);
    // Saturation: the well, or the electrons that fill the swing (steps 4–6).
    let swing_e = (s.voltage_swing_v - s.analog_offset_v) / (shot.analog_gain * g);
    let sat_e = s.well_capacity_e.min(swing_e);
    let read_e = if s.noise.read {
        s.read_noise_v / g
    } else {
        0.0
    };
    let q_e = 1.0 / dn_per_e;
    let floor_e = (read_e * read_e + q_e * q_e / 12.0).sqrt();
    let model_db = 20.0 * (sat_e / floor_e).log10();
    // Measured: a dark frame (noise floor: std over all pixels, DN) and a frame 20× over
    // saturation (mean DN); DR = (saturated − dark mean) / dark std.
    let zeros = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: vec![0.0; s.rows * s.cols],
    };
    let dark = ctx.frame(&zeros, 4);
    let flat = ctx.rate("uniform", ctx.uniform_target(), false)?;
    let mean_rate = flat.electrons_per_s.iter().map(|&r| r as f64).sum::<f64>()
        / flat.electrons_per_s.len() as f64;
    let k = if mean_rate > 0.0 {
        20.0 * sat_e / (mean_rate * ctx.exposure_s)
    } else {
        0.0
    };
    let bright = ElectronRate {
        rows: s.rows,
        cols: s.cols,
        electrons_per_s: if k > 0.0 {
            flat.electrons_per_s.iter().map(|&r| r * k as f32).collect()
        } else {
            vec![(20.0 * sat_e / ctx.exposure_s) as f32; s.rows * s.cols]
        },
    };
    let sat = ctx.frame(&bright, 5);
    let stats = |f: &camsim_core::image::RawFrame| {
        let n = f.dn.len() as f64;
        let m = f.dn.iter().map(|&v| v as f64).sum::<f64>() / n;
        let v = f.dn.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / (n - 1.0);
        (m, v.sqrt())
    };
    let (dark_mean, dark_std) = stats(&dark);
    let (sat_mean, _) = stats(&sat);
    let measured_db = 20.0 * ((sat_mean - dark_mean) / dark_std).log10();
    Ok(DrResult {
        model_db,
        measured_db,
    })
}
