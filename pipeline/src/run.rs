//! `camsim run [CONFIG]`: the paper's whole pipeline on one scene, with a report
//! (Farrell, Catrysse & Wandell 2012, §3: Macbeth under tungsten through the Table 1 camera,
//! colour accuracy as in Figs. 3–6).
//!
//! scene → optics → sensor (one noisy frame) → processor (demosaic, white balance, 3×3 colour
//! correction fitted to the chart's D65 sRGB targets, sRGB) → display (Eq. 8), then metrics:
//! per-patch SNR, ΔE76/ΔE2000 between desired and rendered sRGB, and figures.
use crate::chain::{shot_scene, wavelength_grid};
use crate::color_eval;
use crate::config::{camera_from_file, CameraFile, CaptureSet, Exposure, SimulationFile};
use crate::error::CliError;
use crate::honest_color::{self, CaptureStats, WbMethod};
use crate::plots;
use crate::staging::with_staging;
use crate::targets::target_from_value;
use camsim_core::constants::SI;
use camsim_core::exr_io::{
    bands_energy_to_photons, write_spectral_exr, IRRADIANCE_UNITS, RADIANCE_UNITS,
};
use camsim_core::image::SpectralImage;
use camsim_core::scene::{mean_luminance, Target};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_display::{show, DigitalImage, DisplayModel};
use camsim_isp::{
    demosaic_planes, fit_channel_matrix, macbeth_target_linear_srgb, to_srgb16, to_srgb8,
    Bilateral, ChannelBalance, ChannelMatrix, ChannelPlanes, DemosaicMethod, Mosaic, ToneCurve,
    XYZ_TO_LINEAR_SRGB,
};
use camsim_metrics::{patch_stats, ChartLayout};
use camsim_sensor::{electron_rate, fixed_pattern};
use serde::Deserialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The embedded default: the paper's §3 setup.
pub const DEFAULT_CONFIG: &str = include_str!("../../examples/run/default.json");
/// The Table 1 camera the default uses.
pub const TABLE1_CAMERA: &str = include_str!("../../examples/table1/camera.json");

/// A run configuration as written (docs/run.md).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunFile {
    /// Camera: a path (relative to the config) or an inline camera object; default Table 1.
    #[serde(default)]
    pub camera: Option<Value>,
    /// The scene target (a captures.json target object); not with `render`.
    #[serde(default)]
    pub target: Value,
    /// A glTF scene rendered by the path tracer instead of a target (docs/render.md).
    #[serde(default)]
    pub render: Option<RenderRunFile>,
    /// Fixed exposure (s); default auto-exposure.
    #[serde(default)]
    pub exposure_s: Option<f64>,
    /// Auto-exposure fraction of the swing (default 0.9 when exposure_s is absent).
    #[serde(default)]
    pub auto_exposure: Option<f64>,
    /// Seed.
    #[serde(default)]
    pub seed: Option<u64>,
    /// Simulation settings (as in captures.json).
    #[serde(default)]
    pub simulation: Option<SimulationFile>,
    /// Processor settings.
    #[serde(default)]
    pub processor: Option<ProcessorFile>,
    /// Display settings.
    #[serde(default)]
    pub display: Option<DisplayFile>,
}

/// `render` section: a glTF scene path-traced at the sensor's sampling grid.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderRunFile {
    /// The glTF scene (relative to the config).
    pub scene: PathBuf,
    /// Samples per pixel (default 16).
    #[serde(default)]
    pub spp: Option<u32>,
    /// Camera model: pinhole | thinlens | lens:FILE | lightfield:CONFIG (default: auto).
    #[serde(default)]
    pub camera: Option<String>,
    /// glTF camera name (default: the first).
    #[serde(default)]
    pub camera_name: Option<String>,
    /// Mitsuba-style path-length limit (default −1, unlimited).
    #[serde(default)]
    pub max_depth: Option<i32>,
    /// The field the sensor sees: `camera` (default: the glTF camera's yfov spans the sensor)
    /// or `optics` (the field the camera's lens images onto the sensor,
    /// [`crate::chain::optics_yfov_rad`]).
    #[serde(default)]
    pub field_of_view: Option<String>,
}

/// `processor` section.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessorFile {
    /// bilinear | malvar | edge_adaptive | lmmse | quad_binning | quad_remosaic (default
    /// malvar on RGB Bayer tiles, quad_remosaic on quad Bayer, lmmse on any other tile).
    #[serde(default)]
    pub demosaic: Option<String>,
    /// none | grey_world | white_patch | known_illuminant (default known_illuminant).
    #[serde(default)]
    pub white_balance: Option<String>,
    /// calibrated (default: fitted on a calibration capture of the Macbeth chart under
    /// `calibration_illuminant`, applied to this scene, scored held out) | chart_in_image
    /// (refitted on the chart being scored: flattering) | macbeth_d65 (chart_in_image when the
    /// scene is a chart, else calibrated under the scene's light) | fixed (`ccm`) | none.
    #[serde(default)]
    pub color_correction: Option<String>,
    /// Illuminant of the calibration capture (default D65).
    #[serde(default)]
    pub calibration_illuminant: Option<String>,
    /// Fixed 3 × K matrix (one column per sensor channel, channel order of sensor.channels),
    /// applied after white balance; with color_correction "fixed".
    #[serde(default)]
    pub ccm: Option<Vec<Vec<f64>>>,
    /// none (default) | reinhard | filmic.
    #[serde(default)]
    pub tone_curve: Option<String>,
    /// Reinhard white luminance (default 4).
    #[serde(default)]
    pub tone_white: Option<f64>,
    /// Bilateral denoiser on the demosaicked channels (default off).
    #[serde(default)]
    pub denoise: Option<DenoiseFile>,
    /// Linear sRGB level of the Macbeth white patch's Y in the targets (default 0.9).
    #[serde(default)]
    pub white_level: Option<f64>,
    /// 8 or 16 (default 8).
    #[serde(default)]
    pub output_bits: Option<u32>,
}

/// `processor.denoise`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DenoiseFile {
    /// Spatial σ (pixels).
    pub sigma_px: f64,
    /// Range σ (linear signal, 1 = white); absent = Gaussian blur.
    #[serde(default)]
    pub sigma_range: Option<f64>,
}

/// `display` section.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisplayFile {
    /// An ISET display name (default lcdExample).
    #[serde(default)]
    pub name: Option<String>,
    /// Samples per display pixel side (default 1).
    #[serde(default)]
    pub samples_per_pixel: Option<usize>,
}

/// What `run` reports: the headline numbers as fields, and the whole summary.json document.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Camera name.
    pub camera: String,
    /// Sensor size (rows, columns).
    pub rows: usize,
    /// Sensor columns.
    pub cols: usize,
    /// Exposure used (s).
    pub exposure_s: f64,
    /// Mean raw value (DN).
    pub raw_mean_dn: f64,
    /// ΔE2000 statistics over the chart patches, when the scene is a chart.
    pub delta_e_2000: Option<camsim_metrics::DeltaEStats>,
    /// Files written into `--out` (relative paths).
    pub files: Vec<PathBuf>,
    /// summary.json as written.
    pub json: Value,
}

fn bad(path: &Path, msg: impl std::fmt::Display) -> CliError {
    CliError::input(path, msg)
}

/// Validated run settings.
struct Run {
    set: CaptureSet,
    render: Option<RenderRunFile>,
    /// `render.field_of_view`, validated when the configuration is loaded.
    field_of_view: crate::chain::FieldOfView,
    seed: u64,
    demosaic: DemosaicMethod,
    white_balance: String,
    color_correction: String,
    white_level: f64,
    calibration_illuminant: String,
    ccm: Option<ChannelMatrix>,
    tone: ToneCurve,
    denoise: Option<Bilateral>,
    output_bits: u32,
    display: DisplayModel,
    samples_per_pixel: usize,
}

fn load(config: Option<&Path>) -> Result<Run, CliError> {
    if let Some(p) = config {
        crate::staging::protect_input(p);
    }
    let (path, text) = match config {
        Some(p) => (
            p.to_path_buf(),
            std::fs::read_to_string(p).map_err(|e| bad(p, format!("cannot read: {e}")))?,
        ),
        None => (
            PathBuf::from("<embedded default run>"),
            DEFAULT_CONFIG.to_string(),
        ),
    };
    let raw: RunFile =
        serde_json::from_str(&text).map_err(|e| bad(&path, format!("invalid: {e}")))?;
    let dir = match config {
        Some(p) => p
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf(),
        None => PathBuf::from("."),
    };
    // camera: default Table 1, a path, or inline
    let (camera_path, camera_file): (PathBuf, CameraFile) = match &raw.camera {
        None => (
            PathBuf::from("<embedded Table 1 camera>"),
            serde_json::from_str(TABLE1_CAMERA).expect("embedded camera"),
        ),
        Some(Value::String(p)) => {
            let cp = dir.join(p);
            crate::staging::protect_input(&cp);
            let t =
                std::fs::read_to_string(&cp).map_err(|e| bad(&cp, format!("cannot read: {e}")))?;
            let f = serde_json::from_str(&t).map_err(|e| bad(&cp, format!("invalid: {e}")))?;
            (cp, f)
        }
        Some(v) => (
            path.clone(),
            serde_json::from_value(v.clone()).map_err(|e| bad(&path, format!("camera: {e}")))?,
        ),
    };
    let camera = camera_from_file(&camera_path, camera_file)?;
    let render = raw.render.clone().map(|mut r| {
        r.scene = dir.join(&r.scene);
        r
    });
    let field_of_view = match render.as_ref().and_then(|r| r.field_of_view.as_deref()) {
        None => crate::chain::FieldOfView::Camera,
        Some(v) => crate::chain::FieldOfView::parse(v)
            .map_err(|e| bad(&path, format!("render.field_of_view = {e}")))?,
    };
    let target = match (&render, &raw.target) {
        (Some(_), Value::Null) => crate::targets::ParsedTarget {
            target: Target::Dark,
            mean_luminance_cd_m2: None,
            illuminant: None,
            patch_labels: None,
            world: Default::default(),
            gltf: None,
        },
        (Some(_), _) => return Err(bad(&path, "give either target or render, not both")),
        (None, Value::Null) => return Err(bad(&path, "target: required (or a render section)")),
        (None, t) => target_from_value(t, &dir, &camera.sensor)
            .map_err(|m| bad(&path, format!("target{m}")))?,
    };
    let exposure = match (raw.exposure_s, raw.auto_exposure) {
        (Some(t), None) if t >= 0.0 && t.is_finite() => Exposure::Fixed(t),
        (None, a) => {
            let f = a.unwrap_or(0.9);
            if !(f > 0.0 && f <= 1.0) {
                return Err(bad(
                    &path,
                    format!("auto_exposure: must be in (0, 1], got {f}"),
                ));
            }
            Exposure::Auto(f)
        }
        (Some(_), Some(_)) => return Err(bad(&path, "give exposure_s or auto_exposure, not both")),
        (Some(t), None) => return Err(bad(&path, format!("exposure_s: must be ≥ 0, got {t}"))),
    };
    let p = raw.processor.unwrap_or_default();
    let demosaic: DemosaicMethod = match p.demosaic.as_deref() {
        Some(d) => d
            .parse()
            .map_err(|e| bad(&path, format!("processor.demosaic: {e}")))?,
        None => {
            let probe = Mosaic::new(
                1,
                1,
                vec![0.0],
                camera.sensor.cfa.tile.clone(),
                camera.sensor.channel_names.clone(),
            );
            match probe {
                Ok(m) if m.bayer_layout().is_ok() => DemosaicMethod::Malvar,
                Ok(m) if camsim_isp::cfa_generic::quad_bayer_blocks(&m).is_ok() => {
                    DemosaicMethod::QuadRemosaic
                }
                _ => DemosaicMethod::Lmmse,
            }
        }
    };
    let white_balance = p.white_balance.unwrap_or_else(|| "known_illuminant".into());
    if !["none", "grey_world", "white_patch", "known_illuminant"].contains(&white_balance.as_str())
    {
        return Err(bad(&path, format!("processor.white_balance: unknown value \"{white_balance}\" (expected none, grey_world, white_patch or known_illuminant)")));
    }
    let color_correction = p.color_correction.unwrap_or_else(|| {
        if p.ccm.is_some() {
            "fixed"
        } else {
            "calibrated"
        }
        .into()
    });
    if ![
        "none",
        "macbeth_d65",
        "calibrated",
        "chart_in_image",
        "fixed",
    ]
    .contains(&color_correction.as_str())
    {
        return Err(bad(&path, format!("processor.color_correction: unknown value \"{color_correction}\" (expected calibrated, chart_in_image, macbeth_d65, fixed or none)")));
    }
    let k_channels = camera.sensor.channel_names.len();
    let ccm = match (&p.ccm, color_correction.as_str()) {
        (Some(m), "fixed") => {
            if m.len() != 3 || m.iter().any(|r| r.len() != k_channels || r.iter().any(|x| !x.is_finite())) {
                return Err(bad(&path, format!(
                    "processor.ccm: must be 3 rows of {k_channels} finite numbers (one column per sensor channel: {})",
                    camera.sensor.channel_names.join(", ")
                )));
            }
            Some(ChannelMatrix { m: [m[0].clone(), m[1].clone(), m[2].clone()] })
        }
        (None, "fixed") => return Err(bad(&path, "processor.color_correction \"fixed\" needs processor.ccm (3 rows, one column per sensor channel)")),
        (Some(_), c) => return Err(bad(&path, format!("processor.ccm is only used with color_correction \"fixed\" (have \"{c}\")"))),
        (None, _) => None,
    };
    if color_correction == "none"
        && ChannelMatrix::select_rgb(&camera.sensor.channel_names).is_none()
    {
        return Err(bad(&path, format!(
            "processor.color_correction \"none\" shows channels r, g, b as they are, but the sensor has {}; use calibrated or fixed",
            camera.sensor.channel_names.join(", ")
        )));
    }
    let calibration_illuminant = p
        .calibration_illuminant
        .clone()
        .unwrap_or_else(|| "D65".into());
    camsim_core::data::illuminant(&calibration_illuminant)
        .map_err(|e| bad(&path, format!("processor.calibration_illuminant: {e}")))?;
    let tone = ToneCurve::parse(p.tone_curve.as_deref().unwrap_or("none"), p.tone_white)
        .map_err(|e| bad(&path, format!("processor.{e}")))?;
    let denoise = match &p.denoise {
        None => None,
        Some(d) => Some(
            Bilateral::new(d.sigma_px, d.sigma_range.unwrap_or(f64::INFINITY))
                .map_err(|e| bad(&path, format!("processor.{e}")))?,
        ),
    };
    let white_level = p.white_level.unwrap_or(0.9);
    if !(white_level > 0.0 && white_level <= 1.0) {
        return Err(bad(
            &path,
            format!("processor.white_level: must be in (0, 1], got {white_level}"),
        ));
    }
    let output_bits = p.output_bits.unwrap_or(8);
    if output_bits != 8 && output_bits != 16 {
        return Err(bad(
            &path,
            format!("processor.output_bits: must be 8 or 16, got {output_bits}"),
        ));
    }
    let d = raw.display.unwrap_or_default();
    let display = DisplayModel::load(d.name.as_deref().unwrap_or("lcdExample"))
        .map_err(|e| bad(&path, format!("display.name: {e}")))?;
    let samples_per_pixel = d.samples_per_pixel.unwrap_or(1);
    if !(1..=32).contains(&samples_per_pixel) {
        return Err(bad(
            &path,
            format!("display.samples_per_pixel: must be 1–32, got {samples_per_pixel}"),
        ));
    }
    let shot = crate::config::Shot {
        id: "scene".into(),
        target_key: raw.target.to_string(),
        target,
        exposure,
        analog_gain: camera.sensor.analog_gain,
        frames: vec!["raw.png".into()],
        light: None,
        motion: None,
        temperature_c: None,
        frame_rate_hz: None,
    };
    let set = CaptureSet {
        path: path.clone(),
        dir,
        camera,
        camera_path,
        shots: vec![shot],
        simulation: raw.simulation.unwrap_or_default(),
        raw_format: None,
    };
    crate::simulate::check_budget(&set)?;
    {
        // Eq. 8 on the rendered image: rows·cols·n² samples per primary, then as bands.
        let s = &set.camera.sensor;
        let n = samples_per_pixel as f64;
        let planes = (set.camera.sensor.channel_names.len().max(3)
            + crate::simulate::wavelength_grid(&set).len()) as f64;
        crate::budget::check_memory(
            Some(&path),
            "display.samples_per_pixel",
            crate::budget::f32_bytes(s.rows as f64 * s.cols as f64 * n * n * planes, 1.0),
            &format!(
                "{}×{} pixels × {samples_per_pixel}² samples × {planes} planes of f32",
                s.rows, s.cols
            ),
        )?;
        if let Some(rf) = &render {
            let spp = rf.spp.unwrap_or(16) as f64;
            crate::budget::check_work(
                Some(&path),
                "render.spp",
                s.rows as f64 * s.cols as f64 * spp,
                &format!("{}×{} pixels × {spp} samples", s.rows, s.cols),
            )?;
        }
    }
    Ok(Run {
        set,
        render,
        field_of_view,
        seed: raw.seed.unwrap_or(0),
        demosaic,
        white_balance,
        color_correction,
        white_level,
        calibration_illuminant,
        ccm,
        tone,
        denoise,
        output_bits,
        display,
        samples_per_pixel,
    })
}

/// XYZ weights for photon spectra: 683 · cmf(λ) · hc/λ, sampled at 1 nm.
fn xyz_weights_photons() -> [Spectrum; 3] {
    let cmf = camsim_core::data::cie1931_xyz().expect("embedded CIE XYZ");
    cmf.map(|c| {
        let (lo, hi) = c.support_nm();
        let n = (hi - lo).round() as usize;
        let w: Vec<f64> = (0..=n).map(|i| lo + i as f64).collect();
        let v = w
            .iter()
            .map(|&x| 683.0 * c.eval(x) / SI.photons_per_joule(x))
            .collect();
        Spectrum::sampled(w, v).expect("valid")
    })
}

/// sRGB preview (8-bit) of a spectral radiance image: XYZ → linear sRGB, scaled so the 99th
/// percentile of Y maps to 1.
fn preview_rgb8(img: &SpectralImage) -> Vec<u8> {
    let w = xyz_weights_photons();
    let [x, y, z] = [
        img.integrate_against(&w[0]),
        img.integrate_against(&w[1]),
        img.integrate_against(&w[2]),
    ];
    let mut ys: Vec<f32> = y.clone();
    ys.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let top = ys[((ys.len() as f64) * 0.99) as usize].max(1e-30) as f64;
    let m = XYZ_TO_LINEAR_SRGB;
    let mut out = Vec::with_capacity(x.len() * 3);
    for i in 0..x.len() {
        let v = [x[i] as f64 / top, y[i] as f64 / top, z[i] as f64 / top];
        for row in m.iter() {
            let lin = row[0] * v[0] + row[1] * v[1] + row[2] * v[2];
            out.push((camsim_isp::srgb_encode(lin.clamp(0.0, 1.0)) * 255.0).round() as u8);
        }
    }
    out
}

/// The part of a scene-grid image that covers the sensor, averaged to one sample per pixel
/// (the grid has `os` samples per pixel side and `margin` extra pixels on every side).
fn to_sensor_pixels(
    img: &SpectralImage,
    os: usize,
    margin: usize,
    rows: usize,
    cols: usize,
) -> SpectralImage {
    if os == 1 && margin == 0 && img.rows == rows && img.cols == cols {
        return img.clone();
    }
    let planes = img
        .planes
        .iter()
        .map(|p| plane_to_sensor_pixels(p, img.cols, os, margin, rows, cols, true))
        .collect();
    SpectralImage {
        rows,
        cols,
        basis: img.basis.clone(),
        planes,
    }
}

/// One plane of the scene grid (`grid_cols` wide, `os` samples per pixel side, `margin`
/// pixels around the sensor) → one value per sensor pixel: the mean of the pixel's samples
/// (`mean`) or its centre sample.
fn plane_to_sensor_pixels(
    p: &[f32],
    grid_cols: usize,
    os: usize,
    margin: usize,
    rows: usize,
    cols: usize,
    mean: bool,
) -> Vec<f32> {
    let inv = 1.0 / (os * os) as f32;
    let mut out = vec![0f32; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let (y0, x0) = ((r + margin) * os, (c + margin) * os);
            out[r * cols + c] = if mean {
                let mut s = 0f32;
                for dy in 0..os {
                    let row = &p[(y0 + dy) * grid_cols..(y0 + dy + 1) * grid_cols];
                    for dx in 0..os {
                        s += row[x0 + dx];
                    }
                }
                s * inv
            } else {
                p[(y0 + os / 2) * grid_cols + x0 + os / 2]
            };
        }
    }
    out
}

/// Mean channel values of every chart patch (row-major).
fn planes_patch_means(p: &ChannelPlanes, layout: &ChartLayout) -> Vec<Vec<f64>> {
    let n = layout.chart_rows * layout.chart_cols;
    (0..n)
        .map(|i| {
            let r = camsim_metrics::patch_sample_rect(
                p.rows,
                p.cols,
                layout,
                i / layout.chart_cols,
                i % layout.chart_cols,
            );
            p.mean_in(r.row0, r.row1, r.col0, r.col1)
        })
        .collect()
}

/// Read and validate a run configuration (camera, target, processor, display, render and the
/// budget) without running it.
pub fn check_config(config: Option<&Path>) -> Result<(), CliError> {
    load(config).map(|_| ())
}

/// Run the pipeline and write everything into `out`.
pub fn run(config: Option<&Path>, out: &Path, progress: bool) -> Result<Summary, CliError> {
    let r = load(config)?;
    let mut summary = None;
    let files = with_staging(out, |st| {
        let (s, files) = run_into(&r, st, progress)?;
        summary = Some(s);
        Ok(files)
    })?;
    let mut s = summary.expect("run_into returned a summary");
    s.files = files;
    Ok(s)
}

fn run_into(r: &Run, st: &Path, progress: bool) -> Result<(Summary, Vec<PathBuf>), CliError> {
    let set = &r.set;
    let cam = &set.camera;
    let sensor = &cam.sensor;
    let bar = crate::progress::bar(progress, 7, "{spinner} run [{bar:30}] {pos}/{len} {msg}");
    let mut files: Vec<PathBuf> = Vec::new();
    let mut put = |name: &str| -> PathBuf {
        files.push(PathBuf::from(name));
        st.join(name)
    };
    let out_err = |p: &Path, e: &dyn std::fmt::Display| CliError::output(p, e);

    // 1. Scene
    bar.set_message("scene");
    let grid = wavelength_grid(set);
    let exr_grid = WavelengthGrid::regular(
        grid.wavelength_nm[0],
        grid.wavelength_nm[grid.len() - 1],
        10.0,
    )
    .expect("grid");
    let (os, margin) =
        crate::chain::sampling_for(&cam.optics, sensor, &grid, set.simulation.oversample);
    let scene = match &r.render {
        Some(rf) => crate::chain::render_gltf_on_grid(
            set,
            &crate::chain::GltfOnGrid {
                scene: &rf.scene,
                camera_name: rf.camera_name.clone(),
                camera: rf.camera.as_deref(),
                spp: rf.spp.unwrap_or(16),
                max_depth: rf.max_depth.unwrap_or(-1),
                seed: r.seed,
                bands: None,
                field_of_view: r.field_of_view,
            },
            &grid,
        )?,
        None => shot_scene(set, 0, &grid)?,
    };
    let window = (
        sensor.cols as f64 * sensor.pixel_pitch_m,
        sensor.rows as f64 * sensor.pixel_pitch_m,
    );
    let scene_luminance = mean_luminance(&scene, Some(window), &SI);
    let mut rad_w =
        to_sensor_pixels(&scene.radiance, os, margin, sensor.rows, sensor.cols).to_bands(&exr_grid);
    bands_energy_to_photons(&mut rad_w, &SI, true);
    let p = put("scene_radiance.exr");
    write_spectral_exr(&p, &rad_w, RADIANCE_UNITS, None).map_err(|e| out_err(&p, &e))?;
    let p = put("scene_preview.png");
    let scene_px = to_sensor_pixels(&scene.radiance, os, margin, sensor.rows, sensor.cols);
    plots::rgb8_png(&p, &preview_rgb8(&scene_px), scene_px.rows, scene_px.cols)?;
    bar.inc(1);

    // 2. Optics
    bar.set_message("optics");
    let optics_out = crate::chain::irradiance_and_blur_of(set, &scene, &grid)?;
    let irr = optics_out.irradiance;
    let mut irr_w =
        to_sensor_pixels(&irr.irradiance, os, margin, sensor.rows, sensor.cols).to_bands(&exr_grid);
    bands_energy_to_photons(&mut irr_w, &SI, true);
    let p = put("sensor_irradiance.exr");
    write_spectral_exr(&p, &irr_w, IRRADIANCE_UNITS, None).map_err(|e| out_err(&p, &e))?;
    // Depth-aware optics: the depth map and the blur-size map, per sensor pixel.
    let mut depth_files: Vec<&str> = Vec::new();
    let mut depth_figures: Vec<(&str, &str)> = Vec::new();
    let depth_report = match (&optics_out.depth, &scene.depth_m) {
        (Some(d), Some(z)) => {
            let px = |p: &[f32], mean: bool| {
                plane_to_sensor_pixels(
                    p,
                    scene.radiance.cols,
                    os,
                    margin,
                    sensor.rows,
                    sensor.cols,
                    mean,
                )
            };
            // depth: the sample at each pixel's centre (an average would mix the two sides of
            // a depth edge); blur: the mean over the pixel's samples
            let z_px = px(&z.data, false);
            let b_px = px(&d.blur_rms_radius_um.data, true);
            let write = |p: PathBuf, channel: &str, v: &[f32], units: &str| {
                camsim_render::output::write_planes_exr(
                    &p,
                    sensor.cols,
                    sensor.rows,
                    vec![(channel.to_string(), v.to_vec())],
                    units,
                )
                .map_err(|e| out_err(&p, &e))
            };
            write(put("depth.exr"), "Z", &z_px, "m")?;
            write(
                put("blur_rms_radius.exr"),
                "blur_rms_radius_um",
                &b_px,
                "um",
            )?;
            let finite: Vec<f32> = z_px
                .iter()
                .copied()
                .filter(|v| v.is_finite() && *v > 0.0)
                .collect();
            let (zmin, zmax) = finite
                .iter()
                .fold((f32::INFINITY, 0f32), |(a, b), v| (a.min(*v), b.max(*v)));
            // previews: depth as 1/z (near = bright), blur linear from 0 to its maximum
            let bmax = b_px.iter().copied().fold(0f32, f32::max);
            let grey = |v: &[f32], f: &dyn Fn(f32) -> f32| -> Vec<u8> {
                v.iter()
                    .flat_map(|x| {
                        let g = (f(*x).clamp(0.0, 1.0) * 255.0).round() as u8;
                        [g, g, g]
                    })
                    .collect()
            };
            let zinv = |x: f32| {
                if x.is_finite() && x > 0.0 && zmin.is_finite() {
                    zmin / x
                } else {
                    0.0
                }
            };
            let p = put("depth_preview.png");
            plots::rgb8_png(&p, &grey(&z_px, &zinv), sensor.rows, sensor.cols)?;
            let p = put("blur_rms_radius.png");
            plots::rgb8_png(
                &p,
                &grey(&b_px, &|x| if bmax > 0.0 { x / bmax } else { 0.0 }),
                sensor.rows,
                sensor.cols,
            )?;
            depth_files = vec!["depth.exr", "blur_rms_radius.exr"];
            depth_figures = vec![
                ("depth_preview.png", "Depth map (brightness ∝ 1/z, nearest = white; depth.exr holds metres)"),
                ("blur_rms_radius.png", "Blur size: PSF RMS radius per pixel (0 = black, white = the maximum; blur_rms_radius.exr holds µm)"),
            ];
            let bmean = b_px.iter().map(|v| *v as f64).sum::<f64>() / b_px.len().max(1) as f64;
            Some(json!({
                "kernels": d.kernels,
                "focus_distance_m": d.focus_distance_m,
                "focus_distance_from": if d.kernels == "lens" { "first vertex" } else { "lens (thin)" },
                "layers": d.layers,
                "field_nodes": d.field_nodes,
                "depth_map": {"file": "depth.exr", "channel": "Z", "units": "m", "meaning": "planar depth from the render camera, sample at each pixel centre (inf = nothing hit)",
                              "min_m": if finite.is_empty() { Value::Null } else { json!(zmin) },
                              "max_m": if finite.is_empty() { Value::Null } else { json!(zmax) }},
                "blur_map": {"file": "blur_rms_radius.exr", "channel": "blur_rms_radius_um", "units": "um",
                             "meaning": "RMS radius of the PSF applied to each pixel's depth slab (before diffraction or a diffuser), pixel mean",
                             "pixel_pitch_um": sensor.pixel_pitch_m * 1e6,
                             "mean_um": bmean, "max_um": bmax},
            }))
        }
        _ => None,
    };
    bar.inc(1);

    // 3. Sensor
    bar.set_message("sensor");
    let mut rate = electron_rate(sensor, &irr);
    crate::chain::apply_pixel_optics(&set.camera, &mut rate);
    let shot = crate::chain::shot_exposure(set, 0, &rate);
    let exposure_s = shot.exposure_s;
    let fixed = fixed_pattern(sensor, r.seed);
    let raw = crate::chain::simulate_frame(
        sensor,
        &rate,
        &shot,
        camsim_sensor::PatternSource::Maps(&fixed),
        r.seed,
        &[0, 0],
    );
    let p = put("raw.png");
    crate::frames::write_png16(&p, &raw)?;
    let max_dn = (1u32 << sensor.adc_bits) - 1;
    let raw8: Vec<u8> = raw
        .dn
        .iter()
        .flat_map(|&d| {
            let v = ((d as f64 / max_dn as f64).clamp(0.0, 1.0).sqrt() * 255.0).round() as u8;
            [v, v, v]
        })
        .collect();
    let p = put("raw_preview.png");
    plots::rgb8_png(&p, &raw8, raw.rows, raw.cols)?;
    bar.inc(1);

    // 4. Processor
    bar.set_message("processor");
    let mosaic =
        Mosaic::from_frame(&raw).map_err(|e| CliError::Other(format!("processor: {e}")))?;
    let mut planes = demosaic_planes(&mosaic, r.demosaic)
        .map_err(|e| CliError::input(&set.path, format!("processor.demosaic: {e}")))?;
    if let Some(b) = &r.denoise {
        b.apply(&mut planes);
    }
    let names = planes.names.clone();
    let qe_all: Vec<Spectrum> = sensor.channel_qe.clone();
    let scene_illuminant = set.shots[0].target.illuminant.clone().unwrap_or_else(|| {
        camsim_core::data::illuminant("D65")
            .expect("D65")
            .energy_to_photons(&SI)
    });
    let wb_method = WbMethod::parse(&r.white_balance).expect("validated white_balance");
    // The chart geometry when the target is a 4 × 6 chart (macbeth or patches).
    let chart = crate::targets::chart_layout(&set.shots[0].target.target);
    let d65 = camsim_core::data::illuminant("D65").expect("D65");
    let targets = macbeth_target_linear_srgb(&d65, r.white_level)
        .map_err(|e| CliError::Other(format!("colour targets: {e}")))?;
    let scored = CaptureStats::of_planes(
        &planes,
        chart
            .as_ref()
            .map(|l| planes_patch_means(&planes, l))
            .unwrap_or_default(),
        scene_illuminant.clone(),
    );
    let wb_gains = honest_color::gains(wb_method, &scored, &qe_all, &names)?;
    let cal_illum = camsim_core::data::illuminant(&r.calibration_illuminant)
        .map_err(|e| CliError::input(&set.path, format!("processor.calibration_illuminant: {e}")))?
        .energy_to_photons(&SI);
    let calibration = CaptureStats::calibration(&qe_all, &cal_illum)?;
    let mode = match (r.color_correction.as_str(), chart.is_some()) {
        ("macbeth_d65", true) => "chart_in_image",
        ("macbeth_d65", false) => "calibrated_scene_light",
        (m, _) => m,
    };
    let mut fitted: Option<crate::color_eval::PatchDeltaE> = None;
    let (ccm, ccm_source): (ChannelMatrix, String) = match mode {
        "none" => (
            ChannelMatrix::select_rgb(&names).expect("validated r, g, b"),
            "none".into(),
        ),
        "fixed" => (
            r.ccm.clone().expect("validated ccm"),
            "fixed matrix from the config".into(),
        ),
        "chart_in_image" => {
            let samples: Vec<Vec<f64>> = scored
                .patches
                .iter()
                .map(|p| p.iter().zip(&wb_gains).map(|(a, b)| a * b).collect())
                .collect();
            (
                fit_channel_matrix(&samples, &targets)
                    .map_err(|e| CliError::Other(format!("colour correction: {e}")))?,
                "chart in the image (refitted on the scored chart: not held out)".into(),
            )
        }
        "calibrated_scene_light" => {
            let cal_scene = CaptureStats::calibration(&qe_all, &scene_illuminant)?;
            let c = honest_color::calibrate(
                wb_method,
                &cal_scene,
                &qe_all,
                &names,
                &targets,
                r.white_level,
            )?;
            fitted = Some(c.fitted);
            (
                c.matrix,
                "camera's spectral responses to the chart under the scene light".into(),
            )
        }
        _ => {
            let c = honest_color::calibrate(
                wb_method,
                &calibration,
                &qe_all,
                &names,
                &targets,
                r.white_level,
            )?;
            fitted = Some(c.fitted);
            (
                c.matrix,
                format!(
                    "calibration capture: Macbeth chart under {} (noise-free camera responses)",
                    r.calibration_illuminant
                ),
            )
        }
    };
    ChannelBalance::Gains(wb_gains.clone())
        .apply(&mut planes)
        .map_err(|e| CliError::Other(format!("white balance: {e}")))?;
    let mut rgb = ccm
        .apply_planes(&planes)
        .map_err(|e| CliError::Other(format!("colour correction: {e}")))?;
    // Exposure normalisation (calibrated and fixed matrices): the brightest chart patch (or the
    // 99th percentile of luminance without a chart) is brought to the target white.
    let exposure_scale = if matches!(mode, "calibrated" | "calibrated_scene_light" | "fixed") {
        let k = match &chart {
            Some(l) => {
                let means: Vec<[f64; 3]> = planes_patch_means(&planes, l)
                    .iter()
                    .map(|p| ccm.apply(p))
                    .collect();
                honest_color::exposure_scale(&means, r.white_level)
            }
            None => {
                let mut ys: Vec<f64> = rgb
                    .data
                    .iter()
                    .map(|p| crate::color_eval::srgb_to_xyz(p.map(|x| x as f64))[1])
                    .collect();
                ys.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
                let y = ys[((ys.len() as f64 * 0.99) as usize).min(ys.len() - 1)];
                if y > 0.0 {
                    r.white_level / y
                } else {
                    1.0
                }
            }
        };
        let k32 = k as f32;
        rgb.data
            .iter_mut()
            .for_each(|p| p.iter_mut().for_each(|x| *x *= k32));
        k
    } else {
        1.0
    };
    r.tone.apply(&mut rgb);
    let wb_comparison = match (&chart, mode) {
        (Some(_), "calibrated") => Some(honest_color::compare_white_balance(
            &calibration,
            &scored,
            &qe_all,
            &names,
            &targets,
            r.white_level,
        )?),
        _ => None,
    };
    let rendered8 = to_srgb8(&rgb);
    let p = put("rendered.png");
    if r.output_bits == 16 {
        let d16 = to_srgb16(&rgb);
        write_rgb16(&p, &d16, rgb.rows, rgb.cols)?;
    } else {
        plots::rgb8_png(&p, &rendered8, rgb.rows, rgb.cols)?;
    }
    bar.inc(1);

    // 5. Display (Eq. 8)
    bar.set_message("display");
    let digital: Vec<[u16; 3]> = rendered8
        .chunks_exact(3)
        .map(|c| [c[0] as u16, c[1] as u16, c[2] as u16])
        .collect();
    let dimg = DigitalImage::from_rgb(rgb.rows, rgb.cols, 8, &digital);
    let disp = show(&r.display, &dimg, r.samples_per_pixel)
        .map_err(|e| CliError::Other(format!("display: {e}")))?;
    let disp_bands = disp.radiance.to_bands(&exr_grid);
    let p = put("display_radiance.exr");
    write_spectral_exr(&p, &disp_bands, RADIANCE_UNITS, None).map_err(|e| out_err(&p, &e))?;
    bar.inc(1);

    // 6. Metrics
    let raw_mean_dn = raw.dn.iter().map(|&d| d as f64).sum::<f64>() / raw.dn.len() as f64;
    let mut delta_e_2000 = None;
    bar.set_message("metrics");
    let mut report = json!({
        "camera": cam.name,
        "config": set.path.display().to_string(),
        "seed": r.seed,
        "sensor": {"rows": sensor.rows, "cols": sensor.cols, "pixel_pitch_um": sensor.pixel_pitch_m * 1e6, "adc_bits": sensor.adc_bits},
        "optics": {"f_number": cam.optics.f_number, "focal_length_mm": cam.optics.focal_length_m * 1e3},
        "scene_mean_luminance_cd_m2": scene_luminance,
        "scene_view": {
            "fov_deg": set.shots[0].target.world.fov_deg,
            "distance_m": set.shots[0].target.world.distance_m,
            "sensor_fov_deg": camsim_core::scene_view::fov_deg_of_width(
                sensor.cols as f64 * sensor.pixel_pitch_m,
                camsim_optics::thin_lens_image_distance_m(cam.optics.focal_length_m, set.shots[0].target.world.distance_m)),
            "illuminant": set.shots[0].target.world.illuminant_source,
        },
        "exposure_s": exposure_s,
        "raw_mean_dn": raw_mean_dn,
        "processor": {"demosaic": r.demosaic.name(), "channels": names, "white_balance": r.white_balance, "white_balance_gains": wb_gains,
                       "color_correction": r.color_correction, "ccm_fitted_on": ccm_source, "ccm": ccm.m,
                       "calibration_illuminant": r.calibration_illuminant, "exposure_scale": exposure_scale,
                       "tone_curve": r.tone.name(), "denoise": r.denoise.map(|b| json!({"sigma_px": b.sigma_px, "sigma_range": if b.sigma_range.is_finite() { json!(b.sigma_range) } else { json!("inf") }})),
                       "output_bits": r.output_bits},
        "display": {"name": r.display.name, "samples_per_pixel": r.samples_per_pixel},
    });
    if let Some(d) = depth_report {
        report["depth_optics"] = d;
    }
    let mut figures: Vec<(&str, &str)> = vec![
        (
            "scene_preview.png",
            "Scene (sRGB preview of the spectral radiance)",
        ),
        ("raw_preview.png", "Raw mosaic (square-root display of DN)"),
        ("rendered.png", "Rendered sRGB"),
    ];
    figures.extend(depth_figures);
    if let Some(layout) = &chart {
        // per-patch SNR of the raw data, per channel (paper Fig. 4)
        let tile_strings: Vec<String> = sensor
            .cfa
            .tile
            .iter()
            .map(|row| {
                row.iter()
                    .map(|&c| sensor.channel_names[c].clone())
                    .collect()
            })
            .collect();
        let data: Vec<f32> = raw
            .dn
            .iter()
            .map(|&d| d as f32 - sensor.black_level_dn as f32)
            .collect();
        let mut snr = serde_json::Map::new();
        let mut g_snr = Vec::new();
        let ref_name = names[camsim_isp::reference_channel(&names)].clone();
        for ch in sensor.channel_names.iter().map(|s| s.as_str()) {
            let t: Vec<&str> = tile_strings.iter().map(|s| s.as_str()).collect();
            let mask = camsim_metrics::cfa_channel_mask(&t, ch.chars().next().unwrap())
                .map_err(|e| CliError::Other(e.to_string()))?;
            let stats = patch_stats(&data, raw.rows, raw.cols, layout, mask)
                .map_err(|e| CliError::Other(format!("patch statistics: {e}")))?;
            let v: Vec<Value> = stats.iter().map(|s| json!({"mean_dn": s.mean, "std_dn": s.std, "snr_db": s.snr_db, "pixels": s.count})).collect();
            if ch == ref_name {
                g_snr = stats.iter().map(|s| s.snr_db).collect();
            }
            snr.insert(ch.into(), Value::Array(v));
        }
        report["patch_snr"] = Value::Object(snr);
        let labels: Vec<String> = (1..=24).map(|i| i.to_string()).collect();
        plots::bar_chart(
            &put("patch_snr.png"),
            "Per-patch SNR, green channel (raw)",
            &labels,
            &g_snr,
            "SNR (dB)",
        )?;
        figures.push((
            "patch_snr.png",
            "Per-patch SNR of the green pixels (raw DN)",
        ));
        // ΔE between desired (D65 sRGB targets) and rendered (output codes decoded), paper Figs. 5–6
        let rendered_lin = camsim_isp::from_srgb8(&rendered8, rgb.rows, rgb.cols);
        let rendered_stats = color_eval::patch_stats(&rendered_lin, layout);
        // The same patches before the output's clipping to [0, 1] and 8-bit rounding: the
        // noise of the patch means without their bias.
        let before_output = color_eval::patch_stats(&rgb, layout);
        let rendered_means: Vec<[f64; 3]> = rendered_stats.iter().map(|p| p.mean).collect();
        let de = color_eval::patch_delta_e(&targets, &rendered_means)?;
        let (de2000, s2000) = (&de.de2000, &de.stats2000);
        report["delta_e_2000"] = de.json_2000();
        delta_e_2000 = Some(de.stats2000);
        report["delta_e_76"] = de.json_76();
        report["delta_e_scored_on"] = json!(if mode == "chart_in_image" {
            "the chart the matrix was fitted on (not held out)"
        } else {
            "this scene's chart (held out: the matrix was not fitted on it)"
        });
        if let Some(f) = &fitted {
            report["delta_e_2000_fitted"] = f.json_2000();
        }
        if let Some(rows) = &wb_comparison {
            report["white_balance_comparison"] = json!(rows
                .iter()
                .map(|w| json!({
                    "white_balance": w.method.name(), "gains": w.gains,
                    "fitted_delta_e_2000_mean": w.fitted_mean,
                    "held_out_delta_e_2000_mean": w.held_out_mean,
                    "held_out_delta_e_2000_max": w.held_out_max,
                }))
                .collect::<Vec<_>>());
        }
        plots::histogram(
            &put("delta_e_histogram.png"),
            &format!("ΔE2000, desired vs rendered (mean {:.2})", s2000.mean),
            de2000,
            12,
            "ΔE2000",
        )?;
        figures.push((
            "delta_e_histogram.png",
            "Histogram of ΔE2000 over the 24 patches (paper Fig. 6)",
        ));
        let enc = |v: f64| camsim_isp::srgb_encode(v.clamp(0.0, 1.0)) * 255.0;
        let (mut xs, mut ys, mut cs) = (Vec::new(), Vec::new(), Vec::new());
        let chan_col = [[220u8, 30, 30], [30, 160, 30], [30, 60, 220]];
        for i in 0..24 {
            for c in 0..3 {
                xs.push(enc(targets[i][c]));
                ys.push(enc(rendered_means[i][c]));
                cs.push(chan_col[c]);
            }
        }
        plots::scatter(
            &put("srgb_scatter.png"),
            "Desired vs rendered sRGB (R, G, B of each patch)",
            &xs,
            &ys,
            Some(&cs),
            ("desired sRGB (0–255)", "rendered sRGB (0–255)"),
            true,
        )?;
        figures.push((
            "srgb_scatter.png",
            "Desired (D65 targets) vs rendered sRGB values (paper Fig. 5)",
        ));
        report["patches"] = json!((0..24)
            .map(|i| json!({
                "desired_linear_srgb": targets[i],
                "rendered_linear_srgb": rendered_means[i],
                "rendered_linear_srgb_standard_error": rendered_stats[i].standard_error,
                "before_output_linear_srgb": before_output[i].mean,
                "before_output_linear_srgb_standard_error": before_output[i].standard_error,
                "pixels": rendered_stats[i].pixels,
            }))
            .collect::<Vec<_>>());
    }
    bar.inc(1);

    // 7. Report
    bar.set_message("report");
    let mut listed = vec![
        "scene_radiance.exr",
        "sensor_irradiance.exr",
        "raw.png",
        "rendered.png",
        "display_radiance.exr",
        "summary.json",
        "report.html",
    ];
    listed.extend(depth_files);
    report["files"] = json!(listed);
    report["figures"] = json!(figures.iter().map(|f| f.0).collect::<Vec<_>>());
    let text = serde_json::to_string_pretty(&report).expect("json");
    let p = put("summary.json");
    std::fs::write(&p, &text).map_err(|e| out_err(&p, &e))?;
    let html = crate::report::run_report_html(&report, &figures);
    let p = put("report.html");
    std::fs::write(&p, html).map_err(|e| out_err(&p, &e))?;
    bar.inc(1);
    bar.finish_and_clear();
    let summary = Summary {
        camera: cam.name.clone(),
        rows: sensor.rows,
        cols: sensor.cols,
        exposure_s,
        raw_mean_dn,
        delta_e_2000,
        files: files.clone(),
        json: report,
    };
    Ok((summary, files))
}

fn write_rgb16(path: &Path, data: &[u16], rows: usize, cols: usize) -> Result<(), CliError> {
    let mut bytes = Vec::with_capacity(data.len() * 2);
    for v in data {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    let f = std::fs::File::create(path).map_err(|e| CliError::output(path, e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(f), cols as u32, rows as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Sixteen);
    let mut w = enc.write_header().map_err(|e| CliError::output(path, e))?;
    w.write_image_data(&bytes)
        .map_err(|e| CliError::output(path, e))?;
    w.finish().map_err(|e| CliError::output(path, e))
}
