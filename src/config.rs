//! Input files: `camera.json` and `captures.json` exactly as ../spec/capture-format.md defines
//! them, plus camsim's documented extensions (docs/config.md). Raw serde types (as written,
//! unknown keys rejected) are turned into validated models (SI units, spectra in photons).
use crate::error::CliError;
use camsim_core::constants::SI;
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_optics::{Blur, CameraEquation, Diffuser, OpticsModel, Padding, RelativeIllumination};
use camsim_sensor::{Cfa, ColumnFpn, NoiseSwitches, ResetNoise, SensorModel};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A spectrum as written in a file: a bare number or `{"wavelength_nm": [...], "values": [...]}`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumValue(pub Spectrum);

impl<'de> Deserialize<'de> for SpectrumValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        spectrum_from_value(&v)
            .map(SpectrumValue)
            .map_err(D::Error::custom)
    }
}

fn spectrum_from_value(v: &Value) -> Result<Spectrum, String> {
    match v {
        Value::Number(n) => Ok(Spectrum::constant(n.as_f64().unwrap_or(f64::NAN))),
        Value::Object(m) => {
            for k in m.keys() {
                if k != "wavelength_nm" && k != "values" {
                    return Err(format!(
                        "unknown key `{k}` in a spectrum (expected `wavelength_nm` and `values`)"
                    ));
                }
            }
            let list = |key: &str| -> Result<Vec<f64>, String> {
                let a = m
                    .get(key)
                    .ok_or_else(|| format!("a spectrum needs `{key}`"))?
                    .as_array()
                    .ok_or_else(|| format!("`{key}` must be a list of numbers"))?;
                a.iter()
                    .enumerate()
                    .map(|(i, x)| {
                        x.as_f64()
                            .ok_or_else(|| format!("`{key}[{i}]` is not a number"))
                    })
                    .collect()
            };
            Spectrum::sampled(list("wavelength_nm")?, list("values")?).map_err(|e| e.to_string())
        }
        _ => Err(
            "a spectrum must be a number or {\"wavelength_nm\": [...], \"values\": [...]}".into(),
        ),
    }
}

/// `camera.json` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Camera name.
    #[serde(default)]
    pub name: Option<String>,
    /// Optics section.
    pub optics: OpticsFile,
    /// Sensor section.
    pub sensor: SensorFile,
}

/// `camera.optics` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpticsFile {
    /// f-number N.
    pub f_number: f64,
    /// Focal length (mm).
    pub focal_length_mm: f64,
    /// Lens transmittance T(λ) (default 1).
    #[serde(default)]
    pub transmittance: Option<SpectrumValue>,
    /// `"cos4"` (default), `"none"`, or the extension `"isetcam"`.
    #[serde(default)]
    pub relative_illumination: Option<String>,
    /// Blur model (default none).
    #[serde(default)]
    pub blur: Option<BlurFile>,
    /// Extension: optical diffuser (Gaussian) of the paper's §3.A.
    #[serde(default)]
    pub diffuser: Option<DiffuserFile>,
    /// Extension: object distance (m) for the camera equation's magnification (default ∞).
    #[serde(default)]
    pub object_distance_m: Option<f64>,
    /// Extension: `"baseline"` (default) or `"isetcam"` (π/(1 + 4N²(1+|m|)²)).
    #[serde(default)]
    pub camera_equation: Option<String>,
}

/// `optics.blur` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlurFile {
    /// none | diffraction | gaussian | pillbox | psf | wavefront | lens
    pub kind: String,
    /// gaussian: σ (µm)
    #[serde(default)]
    pub sigma_um: Option<f64>,
    /// pillbox: side (µm)
    #[serde(default)]
    pub width_um: Option<f64>,
    /// psf: a PSF file
    #[serde(default)]
    pub psf_file: Option<String>,
    /// wavefront: Zernike defocus coefficient (µm RMS)
    #[serde(default)]
    pub defocus_um: Option<f64>,
    /// lens: a prescription (needs the lens ray tracer)
    #[serde(default)]
    pub lens_file: Option<String>,
}

/// `optics.diffuser` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiffuserFile {
    /// Full width at half maximum (µm); default = the pixel pitch.
    #[serde(default)]
    pub fwhm_um: Option<f64>,
}

/// `camera.sensor` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFile {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Pixel pitch (µm).
    pub pixel_pitch_um: f64,
    /// Fill factor (default 1).
    #[serde(default)]
    pub fill_factor: Option<f64>,
    /// CFA tile rows.
    pub cfa: Vec<String>,
    /// Combined QE per channel letter.
    pub channels: BTreeMap<String, SpectrumValue>,
    /// Well capacity (electrons).
    pub well_capacity_e: f64,
    /// Conversion gain (V/e⁻).
    pub conversion_gain_v_per_e: f64,
    /// Voltage swing (V).
    pub voltage_swing_v: f64,
    /// Analog gain (default 1).
    #[serde(default)]
    pub analog_gain: Option<f64>,
    /// Analog offset (V, default 0).
    #[serde(default)]
    pub analog_offset_v: Option<f64>,
    /// ADC bits (1–16).
    pub adc_bits: u32,
    /// Black level (DN, default 0).
    #[serde(default)]
    pub black_level_dn: Option<f64>,
    /// Dark voltage (V/s, default 0).
    #[serde(default)]
    pub dark_voltage_v_per_s: Option<f64>,
    /// Read noise σ (V, default 0).
    #[serde(default)]
    pub read_noise_v: Option<f64>,
    /// DSNU σ (V, default 0).
    #[serde(default)]
    pub dsnu_sigma_v: Option<f64>,
    /// PRNU σ (percent, default 0).
    #[serde(default)]
    pub prnu_sigma_percent: Option<f64>,
    /// Extension: noise switches.
    #[serde(default)]
    pub noise: Option<NoiseFile>,
    /// Effect block `column_fpn` (effects.md): fixed per-column offsets.
    #[serde(default)]
    pub column_fpn: Option<ColumnFpnFile>,
    /// Extension: reset (kTC) noise, cancelled by correlated double sampling.
    #[serde(default)]
    pub reset_noise: Option<ResetNoiseFile>,
}

/// `sensor.noise` switches (all default true).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseFile {
    /// Photon shot noise.
    #[serde(default)]
    pub shot: Option<bool>,
    /// Dark current (its mean and its shot noise).
    #[serde(default)]
    pub dark: Option<bool>,
    /// Read noise.
    #[serde(default)]
    pub read: Option<bool>,
    /// DSNU.
    #[serde(default)]
    pub dsnu: Option<bool>,
    /// PRNU.
    #[serde(default)]
    pub prnu: Option<bool>,
}

/// `sensor.column_fpn`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnFpnFile {
    /// σ of the per-column offsets (V).
    pub sigma_v: f64,
}

/// `sensor.reset_noise`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResetNoiseFile {
    /// kTC noise σ (V) per frame.
    pub sigma_v: f64,
    /// Correlated double sampling (default true: the reset noise cancels).
    #[serde(default)]
    pub cds: Option<bool>,
}

/// `captures.json` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CapturesFile {
    /// Path of camera.json, relative to the captures file.
    pub camera: String,
    /// The shots.
    pub shots: Vec<ShotFile>,
    /// Extension: simulation settings.
    #[serde(default)]
    pub simulation: Option<SimulationFile>,
    /// Extension: layout of headerless raw frames (`.raw` / `.bin` frame files).
    #[serde(default)]
    pub raw_format: Option<RawFormatFile>,
}

/// `captures.raw_format` as written: how to read headerless raw frames.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawFormatFile {
    /// Rows (default: the sensor's).
    #[serde(default)]
    pub rows: Option<usize>,
    /// Columns (default: the sensor's).
    #[serde(default)]
    pub cols: Option<usize>,
    /// 8 or 16 bits per stored sample.
    pub bits_per_sample: u32,
    /// "little" or "big" (16-bit samples).
    #[serde(default)]
    pub endianness: Option<String>,
    /// Bytes to skip at the start of each file (default 0).
    #[serde(default)]
    pub header_bytes: Option<u64>,
}

/// One shot as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShotFile {
    /// Shot id (output file stem).
    pub id: String,
    /// The target.
    pub target: Value,
    /// Exposure time (s); absent with `auto_exposure`.
    #[serde(default)]
    pub exposure_s: Option<f64>,
    /// Extension: auto-exposure to this fraction of the voltage swing.
    #[serde(default)]
    pub auto_exposure: Option<f64>,
    /// Analog gain for this shot.
    #[serde(default)]
    pub analog_gain: Option<f64>,
    /// Frame files, relative to the captures file.
    pub frames: Vec<String>,
}

/// `captures.simulation` (extension).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationFile {
    /// Wavelength grid for wavelength-dependent optics: `{start_nm, stop_nm, step_nm}`.
    #[serde(default)]
    pub wavelength_nm: Option<GridFile>,
    /// Scene samples per pixel side (default: from the blur).
    #[serde(default)]
    pub oversample: Option<usize>,
    /// Default seed when --seed is not given.
    #[serde(default)]
    pub seed: Option<u64>,
}

/// A regular wavelength grid as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridFile {
    /// first wavelength
    pub start_nm: f64,
    /// last wavelength
    pub stop_nm: f64,
    /// step
    pub step_nm: f64,
}

/// A validated camera.
#[derive(Debug, Clone)]
pub struct Camera {
    /// Name.
    pub name: String,
    /// Optics model.
    pub optics: OpticsModel,
    /// Sensor model.
    pub sensor: SensorModel,
}

/// A validated shot.
#[derive(Debug, Clone)]
pub struct Shot {
    /// id
    pub id: String,
    /// Target with spectra in photon units, its luminance scaling and illuminant.
    pub target: crate::targets::ParsedTarget,
    /// A key identifying the target (shots with equal keys share the irradiance).
    pub target_key: String,
    /// Exposure.
    pub exposure: Exposure,
    /// Analog gain of this shot.
    pub analog_gain: f64,
    /// Frame paths relative to the captures file.
    pub frames: Vec<String>,
}

/// How a shot's exposure time is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Exposure {
    /// Fixed time (s).
    Fixed(f64),
    /// Auto-exposure: the brightest expected pixel reaches this fraction of the swing.
    Auto(f64),
}

/// A validated capture set.
#[derive(Debug, Clone)]
pub struct CaptureSet {
    /// The captures file.
    pub path: PathBuf,
    /// Its folder (frames are relative to it).
    pub dir: PathBuf,
    /// The camera.
    pub camera: Camera,
    /// Where the camera came from.
    pub camera_path: PathBuf,
    /// Shots.
    pub shots: Vec<Shot>,
    /// Simulation settings.
    pub simulation: SimulationFile,
    /// Layout of headerless raw frames, when given.
    pub raw_format: Option<crate::raw_input::RawFormat>,
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::input(path, format!("cannot read: {e}")))?;
    serde_json::from_str(&text).map_err(|e| CliError::input(path, format!("invalid: {e}")))
}

fn check(path: &Path, ok: bool, key: &str, msg: impl std::fmt::Display) -> Result<(), CliError> {
    if ok {
        Ok(())
    } else {
        Err(CliError::input(path, format!("{key}: {msg}")))
    }
}

fn positive(path: &Path, key: &str, v: f64) -> Result<f64, CliError> {
    check(
        path,
        v.is_finite() && v > 0.0,
        key,
        format!("must be a positive number, got {v}"),
    )?;
    Ok(v)
}

fn non_negative(path: &Path, key: &str, v: f64) -> Result<f64, CliError> {
    check(
        path,
        v.is_finite() && v >= 0.0,
        key,
        format!("must be ≥ 0, got {v}"),
    )?;
    Ok(v)
}

/// Read and validate a camera file.
pub fn load_camera(path: &Path) -> Result<Camera, CliError> {
    let raw: CameraFile = read_json(path)?;
    camera_from_file(path, raw)
}

/// Validate a parsed camera file (`path` is used in messages and to resolve relative paths).
pub fn camera_from_file(path: &Path, raw: CameraFile) -> Result<Camera, CliError> {
    let o = &raw.optics;
    let f_number = positive(path, "optics.f_number", o.f_number)?;
    let focal_length_m = positive(path, "optics.focal_length_mm", o.focal_length_mm)? * 1e-3;
    let transmittance = o
        .transmittance
        .clone()
        .map(|s| s.0)
        .unwrap_or(Spectrum::constant(1.0));
    if let Some((w, v)) = transmittance.first_negative() {
        return Err(CliError::input(
            path,
            format!("optics.transmittance: negative value {v} at {w} nm"),
        ));
    }
    let relative_illumination = match o.relative_illumination.as_deref().unwrap_or("cos4") {
        "cos4" => RelativeIllumination::Cos4,
        "none" => RelativeIllumination::None,
        "isetcam" => RelativeIllumination::IsetCam,
        other => {
            return Err(CliError::input(
                path,
                format!("optics.relative_illumination: unknown value \"{other}\" (expected \"cos4\", \"none\" or \"isetcam\")"),
            ))
        }
    };
    let camera_equation = match o.camera_equation.as_deref().unwrap_or("baseline") {
        "baseline" => CameraEquation::Baseline,
        "isetcam" => CameraEquation::IsetCam,
        other => {
            return Err(CliError::input(
                path,
                format!("optics.camera_equation: unknown value \"{other}\" (expected \"baseline\" or \"isetcam\")"),
            ))
        }
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let pixel_pitch_m = positive(path, "sensor.pixel_pitch_um", raw.sensor.pixel_pitch_um)? * 1e-6;
    let blur = match &o.blur {
        None => Blur::None,
        Some(b) => {
            let (r, c) = (raw.sensor.rows as f64, raw.sensor.cols as f64);
            blur_from_file(
                path,
                dir,
                b,
                (0.5 * pixel_pitch_m * (r * r + c * c).sqrt()).max(pixel_pitch_m),
            )?
        }
    };
    let diffuser = match &o.diffuser {
        None => None,
        Some(d) => Some(Diffuser {
            fwhm_um: match d.fwhm_um {
                Some(v) => positive(path, "optics.diffuser.fwhm_um", v)?,
                None => pixel_pitch_m * 1e6,
            },
        }),
    };
    if let Some(d) = o.object_distance_m {
        check(
            path,
            d.is_finite() && d > focal_length_m,
            "optics.object_distance_m",
            format!("must exceed the focal length, got {d}"),
        )?;
    }
    let optics = OpticsModel {
        f_number,
        focal_length_m,
        transmittance,
        relative_illumination,
        camera_equation,
        blur,
        diffuser,
        padding: Padding::Replicate,
    };
    let sensor = sensor_from_file(path, &raw.sensor)?;
    Ok(Camera {
        name: raw.name.unwrap_or_else(|| "camera".into()),
        optics,
        sensor,
    })
}

fn blur_from_file(
    path: &Path,
    dir: &Path,
    b: &BlurFile,
    sensor_half_diagonal_m: f64,
) -> Result<Blur, CliError> {
    let allowed: &[&str] = match b.kind.as_str() {
        "none" | "diffraction" => &[],
        "gaussian" => &["sigma_um"],
        "pillbox" => &["width_um"],
        "psf" => &["psf_file"],
        "wavefront" => &["defocus_um"],
        "lens" => &["lens_file"],
        other => {
            return Err(CliError::input(
                path,
                format!("optics.blur.kind: unknown value \"{other}\" (expected none, diffraction, gaussian, pillbox, psf, wavefront or lens)"),
            ))
        }
    };
    let present = [
        ("sigma_um", b.sigma_um.is_some()),
        ("width_um", b.width_um.is_some()),
        ("psf_file", b.psf_file.is_some()),
        ("defocus_um", b.defocus_um.is_some()),
        ("lens_file", b.lens_file.is_some()),
    ];
    for (k, p) in present {
        if p && !allowed.contains(&k) {
            return Err(CliError::input(
                path,
                format!("optics.blur.{k}: not used by blur kind \"{}\"", b.kind),
            ));
        }
    }
    let need = |k: &str, v: Option<f64>| -> Result<f64, CliError> {
        v.ok_or_else(|| {
            CliError::input(
                path,
                format!("optics.blur.{k}: required for blur kind \"{}\"", b.kind),
            )
        })
    };
    Ok(match b.kind.as_str() {
        "none" => Blur::None,
        "diffraction" => Blur::Diffraction,
        "gaussian" => Blur::Gaussian {
            sigma_um: non_negative(path, "optics.blur.sigma_um", need("sigma_um", b.sigma_um)?)?,
        },
        "pillbox" => Blur::Pillbox {
            width_um: positive(path, "optics.blur.width_um", need("width_um", b.width_um)?)?,
        },
        "wavefront" => Blur::Wavefront {
            defocus_um: need("defocus_um", b.defocus_um)?,
            pupil_samples: 64,
        },
        "psf" => {
            let f = b.psf_file.as_ref().ok_or_else(|| {
                CliError::input(path, "optics.blur.psf_file: required for blur kind \"psf\"")
            })?;
            let p = dir.join(f);
            Blur::Psf(
                camsim_optics::PsfSet::from_json_file(&p).map_err(|e| CliError::input(&p, e))?,
            )
        }
        _ => {
            // "lens": the prescription's field model, covering the sensor's half-diagonal
            // (camsim_optics::LensBlur; the camera's f_number / focal_length_mm and
            // relative_illumination are not used by this kind: the lens's own are).
            let f = b.lens_file.as_ref().ok_or_else(|| {
                CliError::input(
                    path,
                    "optics.blur.lens_file: required for blur kind \"lens\"",
                )
            })?;
            let p = dir.join(f);
            if !p.is_file() {
                return Err(CliError::input(
                    path,
                    format!("optics.blur.lens_file: cannot read {}", p.display()),
                ));
            }
            let lens = camsim_optics::lens::LensPrescription::from_json_file(
                &p,
                &camsim_optics::lens::GlassCatalog::bundled(),
            )
            .map_err(|e| CliError::input(&p, e))?;
            let opts = camsim_optics::LensBlurOptions::covering(sensor_half_diagonal_m * 1e3);
            Blur::Lens(
                camsim_optics::LensBlur::from_prescription(&lens, &opts)
                    .map_err(|e| CliError::input(&p, e))?,
            )
        }
    })
}

fn sensor_from_file(path: &Path, s: &SensorFile) -> Result<SensorModel, CliError> {
    check(
        path,
        s.rows > 0 && s.cols > 0,
        "sensor.rows/cols",
        format!("must be positive, got {}×{}", s.rows, s.cols),
    )?;
    check(
        path,
        (1..=16).contains(&s.adc_bits),
        "sensor.adc_bits",
        format!("must be 1–16 (frames are 16-bit PNG), got {}", s.adc_bits),
    )?;
    let ff = s.fill_factor.unwrap_or(1.0);
    check(
        path,
        ff > 0.0 && ff <= 1.0,
        "sensor.fill_factor",
        format!("must be in (0, 1], got {ff}"),
    )?;
    check(
        path,
        !s.cfa.is_empty(),
        "sensor.cfa",
        "needs at least one row",
    )?;
    let width = s.cfa[0].chars().count();
    let names: Vec<String> = s.channels.keys().cloned().collect();
    let mut tile = Vec::new();
    for (i, row) in s.cfa.iter().enumerate() {
        check(
            path,
            row.chars().count() == width && width > 0,
            "sensor.cfa",
            format!(
                "row {i} \"{row}\" has {} letters; every row needs {width}",
                row.chars().count()
            ),
        )?;
        let mut r = Vec::new();
        for ch in row.chars() {
            let k = names.iter().position(|n| n == &ch.to_string()).ok_or_else(|| {
                CliError::input(path, format!("sensor.cfa: letter '{ch}' in row \"{row}\" names no key of sensor.channels (have: {})", names.join(", ")))
            })?;
            r.push(k);
        }
        tile.push(r);
    }
    for (n, q) in &s.channels {
        if let Some((w, v)) = q.0.first_negative() {
            return Err(CliError::input(
                path,
                format!("sensor.channels.{n}: negative QE {v} at {w} nm"),
            ));
        }
        check(
            path,
            n.chars().count() == 1,
            &format!("sensor.channels.{n}"),
            "channel names must be single letters (they are used in sensor.cfa)",
        )?;
    }
    let noise = s.noise.as_ref();
    let sw = |f: fn(&NoiseFile) -> Option<bool>| noise.and_then(f).unwrap_or(true);
    let model = SensorModel {
        rows: s.rows,
        cols: s.cols,
        pixel_pitch_m: s.pixel_pitch_um * 1e-6,
        fill_factor: ff,
        cfa: Cfa { tile },
        channel_names: names,
        channel_qe: s.channels.values().map(|v| v.0.clone()).collect(),
        well_capacity_e: positive(path, "sensor.well_capacity_e", s.well_capacity_e)?,
        conversion_gain_v_per_e: positive(
            path,
            "sensor.conversion_gain_v_per_e",
            s.conversion_gain_v_per_e,
        )?,
        voltage_swing_v: positive(path, "sensor.voltage_swing_v", s.voltage_swing_v)?,
        analog_gain: positive(path, "sensor.analog_gain", s.analog_gain.unwrap_or(1.0))?,
        analog_offset_v: s.analog_offset_v.unwrap_or(0.0),
        adc_bits: s.adc_bits,
        black_level_dn: s.black_level_dn.unwrap_or(0.0),
        dark_voltage_v_per_s: non_negative(
            path,
            "sensor.dark_voltage_v_per_s",
            s.dark_voltage_v_per_s.unwrap_or(0.0),
        )?,
        read_noise_v: non_negative(path, "sensor.read_noise_v", s.read_noise_v.unwrap_or(0.0))?,
        dsnu_sigma_v: non_negative(path, "sensor.dsnu_sigma_v", s.dsnu_sigma_v.unwrap_or(0.0))?,
        prnu_sigma_percent: non_negative(
            path,
            "sensor.prnu_sigma_percent",
            s.prnu_sigma_percent.unwrap_or(0.0),
        )?,
        noise: NoiseSwitches {
            shot: sw(|n| n.shot),
            dark: sw(|n| n.dark),
            read: sw(|n| n.read),
            dsnu: sw(|n| n.dsnu),
            prnu: sw(|n| n.prnu),
        },
        column_fpn: match &s.column_fpn {
            Some(c) => Some(ColumnFpn {
                offset_sigma_v: non_negative(path, "sensor.column_fpn.sigma_v", c.sigma_v)?,
            }),
            None => None,
        },
        reset_noise: match &s.reset_noise {
            Some(r) => Some(ResetNoise {
                sigma_v: non_negative(path, "sensor.reset_noise.sigma_v", r.sigma_v)?,
                cds: r.cds.unwrap_or(true),
            }),
            None => None,
        },
    };
    model.validate().map_err(|e| CliError::input(path, e))?;
    Ok(model)
}

/// Read and validate a capture set; `camera_override` replaces the camera it names.
pub fn load_captures(path: &Path, camera_override: Option<&Path>) -> Result<CaptureSet, CliError> {
    let raw: CapturesFile = read_json(path)?;
    let dir = path
        .parent()
        .map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        })
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let camera_path = match camera_override {
        Some(p) => p.to_path_buf(),
        None => dir.join(&raw.camera),
    };
    let camera = load_camera(&camera_path)?;
    check(
        path,
        !raw.shots.is_empty(),
        "shots",
        "the capture set has no shots",
    )?;
    let mut shots = Vec::with_capacity(raw.shots.len());
    let mut ids = std::collections::HashSet::new();
    for (i, s) in raw.shots.iter().enumerate() {
        let key = format!("shots[{i}] ({})", s.id);
        check(
            path,
            !s.id.is_empty() && !s.id.contains(['/', '\\']) && s.id != "." && s.id != "..",
            &key,
            "id must be a non-empty file name",
        )?;
        check(path, ids.insert(s.id.clone()), &key, "duplicate shot id")?;
        let exposure = match (s.exposure_s, s.auto_exposure) {
            (Some(t), None) => {
                Exposure::Fixed(non_negative(path, &format!("{key}.exposure_s"), t)?)
            }
            (None, Some(f)) => {
                check(
                    path,
                    f > 0.0 && f <= 1.0,
                    &format!("{key}.auto_exposure"),
                    format!("must be a fraction of the swing in (0, 1], got {f}"),
                )?;
                Exposure::Auto(f)
            }
            (Some(_), Some(_)) => {
                return Err(CliError::input(
                    path,
                    format!("{key}: give exposure_s or auto_exposure, not both"),
                ))
            }
            (None, None) => {
                return Err(CliError::input(path, format!("{key}.exposure_s: required")))
            }
        };
        let analog_gain = positive(
            path,
            &format!("{key}.analog_gain"),
            s.analog_gain.unwrap_or(camera.sensor.analog_gain),
        )?;
        for (j, f) in s.frames.iter().enumerate() {
            check(
                path,
                !f.is_empty()
                    && !Path::new(f).is_absolute()
                    && !f.split(['/', '\\']).any(|c| c == ".."),
                &format!("{key}.frames[{j}]"),
                format!("\"{f}\" must be a relative path inside the capture folder"),
            )?;
        }
        let target = crate::targets::target_from_value(&s.target, &dir, &camera.sensor)
            .map_err(|m| CliError::input(path, format!("{key}.target{m}")))?;
        shots.push(Shot {
            id: s.id.clone(),
            target,
            target_key: s.target.to_string(),
            exposure,
            analog_gain,
            frames: s.frames.clone(),
        });
    }
    let simulation = raw.simulation.unwrap_or_default();
    if let Some(g) = &simulation.wavelength_nm {
        WavelengthGrid::regular(g.start_nm, g.stop_nm, g.step_nm)
            .map_err(|e| CliError::input(path, format!("simulation.wavelength_nm: {e}")))?;
    }
    if let Some(o) = simulation.oversample {
        check(
            path,
            (1..=16).contains(&o),
            "simulation.oversample",
            format!("must be 1–16, got {o}"),
        )?;
    }
    let raw_format = match &raw.raw_format {
        None => None,
        Some(r) => {
            let bytes = match r.bits_per_sample {
                8 => 1,
                16 => 2,
                b => {
                    return Err(CliError::input(
                        path,
                        format!("raw_format.bits_per_sample: must be 8 or 16, got {b}"),
                    ))
                }
            };
            let little_endian = match r.endianness.as_deref().unwrap_or("little") {
                "little" => true,
                "big" => false,
                e => {
                    return Err(CliError::input(
                        path,
                        format!(
                            "raw_format.endianness: expected \"little\" or \"big\", got \"{e}\""
                        ),
                    ))
                }
            };
            Some(crate::raw_input::RawFormat {
                rows: r.rows.unwrap_or(camera.sensor.rows),
                cols: r.cols.unwrap_or(camera.sensor.cols),
                bytes_per_sample: bytes,
                little_endian,
                header_bytes: r.header_bytes.unwrap_or(0),
            })
        }
    };
    Ok(CaptureSet {
        path: path.to_path_buf(),
        dir,
        camera,
        camera_path,
        shots,
        simulation,
        raw_format,
    })
}

/// Energy (W) spectra → photons with the SI constants.
pub fn to_photons(s: &Spectrum) -> Spectrum {
    s.energy_to_photons(&SI)
}
