//! Input files: `camera.json` and `captures.json` exactly as ../spec/capture-format.md defines
//! them, plus camsim's documented extensions (docs/config.md). Raw serde types (as written,
//! unknown keys rejected) are turned into validated models (SI units, spectra in photons).
use crate::error::CliError;
pub use crate::spectrum_file::{to_photons, SpectrumValue};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_optics::{
    Blur, CameraEquation, Defocus, Diffuser, Distortion, Falloff, LateralColor, LateralColorKind,
    OpticsEffects, OpticsModel, Padding, RelativeIllumination,
};
use camsim_sensor::{
    Cfa, ChargePacket, ColumnFpn, Crosstalk, HdrModel, HdrReadout, HotPixels, IrLeakage, Motion,
    NoiseSwitches, Nonlinearity, PwmLight, QeShift, Readout, ResetNoise, SensorEffects,
    SensorModel, ShutterMode,
};
use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `camera.json` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Camera name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Optics section.
    pub optics: OpticsFile,
    /// Sensor section.
    pub sensor: SensorFile,
}

/// `camera.optics` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpticsFile {
    /// f-number N.
    pub f_number: f64,
    /// Focal length (mm).
    pub focal_length_mm: f64,
    /// Lens transmittance T(λ) (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transmittance: Option<SpectrumValue>,
    /// `"cos4"` (default), `"none"`, or the extension `"isetcam"`; or the effect block's
    /// object form `{"model": …, "falloff": …}` (docs/effects.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_illumination: Option<RelativeIlluminationFile>,
    /// Blur model (default none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blur: Option<BlurFile>,
    /// Extension: optical diffuser (Gaussian) of the paper's §3.A.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diffuser: Option<DiffuserFile>,
    /// Extension: object distance (m) for the camera equation's magnification (default ∞).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_distance_m: Option<f64>,
    /// Extension: `"baseline"` (default) or `"isetcam"` (π/(1 + 4N²(1+|m|)²)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_equation: Option<String>,
    /// Effect block `exposure_scale` (docs/effects.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_scale: Option<ExposureScaleFile>,
    /// Effect block `veiling_glare`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub veiling_glare: Option<VeilingGlareFile>,
    /// Effect block `defocus`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub defocus: Option<DefocusFile>,
    /// Effect block `distortion`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<DistortionFile>,
    /// Effect block `lateral_color`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral_color: Option<LateralColorFile>,
    /// Extension (ISETCam parity, issue 17 §4): keep the optical image uncropped, ISETCam's
    /// `oiCompute` with `crop = false` (default false: the spec's optics, unchanged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncropped_optical_image: Option<bool>,
    /// Extension: thin-lens focus distance (m). With it, a scene with depth (a glTF render)
    /// is defocused by depth as a thin lens of `focal_length_mm` and `f_number` focused there
    /// (docs/run.md, depth-aware optics); not with `blur.kind = "lens"`, which focuses by
    /// `blur.focus_distance_m`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance_m: Option<f64>,
}

/// `optics.relative_illumination`: the model name, or the object form with an extra
/// fall-off (effect block `relative_illumination`).
#[derive(Debug, Clone, PartialEq)]
pub enum RelativeIlluminationFile {
    /// `"cos4"`, `"none"` or `"isetcam"`.
    Model(String),
    /// `{"model": …, "falloff": …}`.
    Object(RelativeIlluminationObject),
}

/// The object form of `optics.relative_illumination`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RelativeIlluminationObject {
    /// `"cos4"` (default), `"none"` or `"isetcam"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Extra fall-off F(h) multiplying the irradiance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub falloff: Option<FalloffFile>,
}

impl RelativeIlluminationFile {
    /// The model name (`"cos4"` when the object form omits it).
    pub fn model(&self) -> &str {
        match self {
            RelativeIlluminationFile::Model(m) => m,
            RelativeIlluminationFile::Object(o) => o.model.as_deref().unwrap_or("cos4"),
        }
    }
    /// The extra fall-off, if any.
    pub fn falloff(&self) -> Option<&FalloffFile> {
        match self {
            RelativeIlluminationFile::Model(_) => None,
            RelativeIlluminationFile::Object(o) => o.falloff.as_ref(),
        }
    }
}

impl Serialize for RelativeIlluminationFile {
    fn serialize<S: Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        match self {
            RelativeIlluminationFile::Model(m) => ser.serialize_str(m),
            RelativeIlluminationFile::Object(o) => o.serialize(ser),
        }
    }
}

impl<'de> Deserialize<'de> for RelativeIlluminationFile {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match Value::deserialize(d)? {
            Value::String(m) => Ok(RelativeIlluminationFile::Model(m)),
            v @ Value::Object(_) => serde_json::from_value(v)
                .map(RelativeIlluminationFile::Object)
                .map_err(|e| D::Error::custom(format!("optics.relative_illumination: {e}"))),
            _ => Err(D::Error::custom(
                "optics.relative_illumination: expected \"cos4\", \"none\", \"isetcam\" or {\"model\": …, \"falloff\": …}",
            )),
        }
    }
}

/// `optics.relative_illumination.falloff` (`"kind"` selects the form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FalloffFile {
    /// Fitted: `1 + a1·h² + a2·h⁴ + …`.
    Polynomial {
        /// a1, a2, … (coefficient i multiplies h^(2i+2)).
        coefficients: Vec<f64>,
    },
    /// Generator: overlap of two unit circles `s·h` apart, over π.
    TwoCircle {
        /// s.
        separation_at_h1: f64,
    },
}

/// `optics.exposure_scale`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExposureScaleFile {
    /// Factor multiplying the sensor irradiance.
    pub factor: f64,
}

/// `optics.veiling_glare`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VeilingGlareFile {
    /// Fraction of the mean irradiance added uniformly.
    pub fraction: f64,
}

/// `optics.defocus` (`"kind"` selects the form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DefocusFile {
    /// Fitted: Gaussian PSF.
    Gaussian {
        /// σ (µm).
        sigma_um: f64,
    },
    /// Generator: uniform disk.
    Pillbox {
        /// Radius (µm).
        radius_um: f64,
    },
}

/// `optics.distortion` (`"kind"` selects the form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum DistortionFile {
    /// Fitted: `D = 1 + k1·h² + k2·h⁴`.
    Polynomial {
        /// k1.
        k1: f64,
        /// k2 (default 0).
        #[serde(default)]
        k2: f64,
    },
    /// Generator: `D = 1/(1 − k·h²)`.
    Division {
        /// k.
        k: f64,
    },
}

/// `optics.lateral_color` (`"kind"` selects the form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LateralColorFile {
    /// Fitted: `w = (λ − 550)/200`.
    Linear {
        /// d (µm).
        displacement_um: f64,
    },
    /// Generator: Cauchy-shaped w(λ).
    Cauchy {
        /// d (µm).
        displacement_um: f64,
    },
}

/// `sensor.hot_pixels`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HotPixelsFile {
    /// Fraction of pixels that are hot.
    pub fraction: f64,
    /// Extra dark voltage rate of a hot pixel (V/s; the median with `log_sigma`).
    pub dark_voltage_v_per_s: f64,
    /// Generator: σ of ln(rate) (lognormal spread).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_sigma: Option<f64>,
}

/// `sensor.row_noise` (effect block, docs/effects.md): a temporal offset per row, new every
/// frame ([`camsim_sensor::line_noise`]).
///
/// | key | default | meaning |
/// |---|---|---|
/// | `sigma_v` | required | σ of the per-row offset (V), ≥ 0 |
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RowNoiseFile {
    /// σ of the per-row offset (V).
    pub sigma_v: f64,
}

/// `sensor.rtn` (effect block, docs/effects.md): random-telegraph-noise pixels, a two-state
/// trap per pixel stepping as a Markov chain in the global frame index
/// ([`camsim_sensor::line_noise`]).
///
/// | key | default | meaning |
/// |---|---|---|
/// | `fraction` | required | fraction of pixels with a trap, in [0, 1] |
/// | `amplitude_v` | required | step between the two levels (V), ≥ 0 (median with `log_sigma`) |
/// | `p_up` | 0.5 | probability per frame of a low → high switch, in (0, 1] |
/// | `p_down` | 0.5 | probability per frame of a high → low switch, in (0, 1] |
/// | `log_sigma` | 0 | generator form: σ of ln(amplitude) (lognormal amplitudes) |
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RtnFile {
    /// Fraction of pixels with a trap.
    pub fraction: f64,
    /// Step between the two levels (V).
    pub amplitude_v: f64,
    /// Probability per frame of a low → high switch (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_up: Option<f64>,
    /// Probability per frame of a high → low switch (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p_down: Option<f64>,
    /// Generator: σ of ln(amplitude).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub log_sigma: Option<f64>,
}

/// `sensor.black_level_drift` (effect block, docs/effects.md): the black level of the frame
/// with global index j (capture order) is `black_level_dn + dn_per_frame · j`.
///
/// | key | default | meaning |
/// |---|---|---|
/// | `dn_per_frame` | required | drift rate (DN per frame), finite |
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlackLevelDriftFile {
    /// Drift rate (DN per frame).
    pub dn_per_frame: f64,
}

/// `sensor.nonlinearity` (`"kind"` selects the form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum NonlinearityFile {
    /// Fitted: `v' = v − a·v²`.
    Quadratic {
        /// a (1/V).
        coefficient_per_v: f64,
    },
    /// Generator: `v' = S·tanh(v/S)`.
    Tanh {
        /// S (V).
        saturation_v: f64,
    },
}

/// `sensor.crosstalk`: `{"fraction": f}` (fitted) or `{"left", "right", "up", "down"}`
/// (generator; missing directions are 0).
#[derive(Debug, Clone, PartialEq)]
pub enum CrosstalkFile {
    /// f/4 to each neighbour.
    Symmetric {
        /// f.
        fraction: f64,
    },
    /// Fractions sent to each neighbour.
    Directional {
        /// to column − 1
        left: f64,
        /// to column + 1
        right: f64,
        /// to row − 1
        up: f64,
        /// to row + 1
        down: f64,
    },
}

impl Serialize for CrosstalkFile {
    fn serialize<S: Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        match self {
            CrosstalkFile::Symmetric { fraction } => {
                let mut m = ser.serialize_map(Some(1))?;
                m.serialize_entry("fraction", fraction)?;
                m.end()
            }
            CrosstalkFile::Directional {
                left,
                right,
                up,
                down,
            } => {
                let mut m = ser.serialize_map(Some(4))?;
                m.serialize_entry("left", left)?;
                m.serialize_entry("right", right)?;
                m.serialize_entry("up", up)?;
                m.serialize_entry("down", down)?;
                m.end()
            }
        }
    }
}

impl<'de> Deserialize<'de> for CrosstalkFile {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = Value::deserialize(d)?;
        let m = v.as_object().ok_or_else(|| {
            D::Error::custom("sensor.crosstalk: expected {\"fraction\": f} or {\"left\", \"right\", \"up\", \"down\"}")
        })?;
        let num = |k: &str| -> Result<f64, D::Error> {
            m[k].as_f64()
                .ok_or_else(|| D::Error::custom(format!("sensor.crosstalk.{k}: must be a number")))
        };
        if m.contains_key("fraction") {
            if let Some(k) = m.keys().find(|k| *k != "fraction") {
                return Err(D::Error::custom(format!(
                    "sensor.crosstalk.{k}: unknown key with `fraction` (give `fraction` alone, or `left`/`right`/`up`/`down`)"
                )));
            }
            return Ok(CrosstalkFile::Symmetric {
                fraction: num("fraction")?,
            });
        }
        const DIRS: [&str; 4] = ["left", "right", "up", "down"];
        if let Some(k) = m.keys().find(|k| !DIRS.contains(&k.as_str())) {
            return Err(D::Error::custom(format!(
                "sensor.crosstalk.{k}: unknown key (expected `fraction`, or `left`, `right`, `up`, `down`)"
            )));
        }
        if m.is_empty() {
            return Err(D::Error::custom(
                "sensor.crosstalk: needs `fraction` or at least one of `left`, `right`, `up`, `down`",
            ));
        }
        let dir = |k: &str| -> Result<f64, D::Error> {
            if m.contains_key(k) {
                num(k)
            } else {
                Ok(0.0)
            }
        };
        Ok(CrosstalkFile::Directional {
            left: dir("left")?,
            right: dir("right")?,
            up: dir("up")?,
            down: dir("down")?,
        })
    }
}

/// `sensor.ir_leakage`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IrLeakageFile {
    /// Added QE per channel letter: a number = that constant on [700, 1000] nm with 1 nm
    /// ramps (fitted form); a spectrum = itself (generator form).
    pub channels: BTreeMap<String, SpectrumValue>,
}

/// `sensor.qe_shift`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QeShiftFile {
    /// Shift per channel letter (nm, + = towards red).
    pub shift_nm: BTreeMap<String, f64>,
}

/// `optics.blur` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlurFile {
    /// none | diffraction | gaussian | pillbox | psf | wavefront | lens
    pub kind: String,
    /// gaussian: σ (µm)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_um: Option<f64>,
    /// pillbox: side (µm)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_um: Option<f64>,
    /// psf: a PSF file
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf_file: Option<String>,
    /// wavefront: Zernike defocus coefficient (µm RMS)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub defocus_um: Option<f64>,
    /// wavefront: Zernike terms, OSA/ANSI index j (as a string key) → µm RMS
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zernike_um: Option<BTreeMap<String, f64>>,
    /// wavefront: diameter (mm) of the pupil the Zernike coefficients are given over
    /// (default: the aperture focal_length / f_number)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zernike_pupil_diameter_mm: Option<f64>,
    /// wavefront: longitudinal chromatic aberration
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chromatic_defocus: Option<ChromaticDefocusFile>,
    /// wavefront: aperture blades (a regular polygon, ≥ 3; default a circle)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blades: Option<u32>,
    /// wavefront: minimum pupil samples across the diameter (16–4096, default 64)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pupil_samples: Option<usize>,
    /// lens: a prescription (needs the lens ray tracer)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens_file: Option<String>,
    /// lens: focus distance (m, from the first vertex; default `optics.object_distance_m`,
    /// i.e. the lens focused on its object, infinity when that is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_distance_m: Option<f64>,
    /// lens: focus criterion, `"best"` (default: maximum polychromatic MTF up to the focus
    /// frequency, weighted over the sensor's field) or `"paraxial"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_criterion: Option<String>,
    /// lens: merit frequency of the best focus (cycles/mm; default half the pixel Nyquist,
    /// 1/(4·pixel_pitch)).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_frequency_cyc_per_mm: Option<f64>,
    /// lens: focusing group `[first, last]` (0-based surface indices of the prescription,
    /// first ≥ 1); default: the lens moves as a unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub focus_group_surfaces: Option<[usize; 2]>,
}

/// `optics.blur.chromatic_defocus` as written: `{"model": "human", "reference_nm": λ}` or
/// `{"wavelength_nm": [...], "defocus_um": [...]}`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChromaticDefocusFile {
    /// `"human"` (Thibos et al. 1992 chromatic eye, as ISETCam) or absent for a table.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// human: the wavelength in focus (nm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_nm: Option<f64>,
    /// table: wavelengths (nm), strictly increasing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelength_nm: Option<Vec<f64>>,
    /// table: Zernike defocus (µm RMS over the Zernike pupil) at each wavelength.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub defocus_um: Option<Vec<f64>>,
}

/// `optics.diffuser` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiffuserFile {
    /// Full width at half maximum (µm); default = the pixel pitch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fwhm_um: Option<f64>,
}

/// `camera.sensor` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFile {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Pixel pitch (µm).
    pub pixel_pitch_um: f64,
    /// Fill factor (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analog_gain: Option<f64>,
    /// Analog offset (V, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analog_offset_v: Option<f64>,
    /// ADC bits (1–16).
    pub adc_bits: u32,
    /// Black level (DN, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub black_level_dn: Option<f64>,
    /// Dark voltage (V/s, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_voltage_v_per_s: Option<f64>,
    /// Read noise σ (V, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub read_noise_v: Option<f64>,
    /// DSNU σ (V, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dsnu_sigma_v: Option<f64>,
    /// PRNU σ (percent, default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prnu_sigma_percent: Option<f64>,
    /// Extension: noise switches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<NoiseFile>,
    /// Effect block `column_fpn` (effects.md): fixed per-column offsets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub column_fpn: Option<ColumnFpnFile>,
    /// Extension: reset (kTC) noise, cancelled by correlated double sampling.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reset_noise: Option<ResetNoiseFile>,
    /// Effect block `hot_pixels` (docs/effects.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hot_pixels: Option<HotPixelsFile>,
    /// Effect block `nonlinearity`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nonlinearity: Option<NonlinearityFile>,
    /// Effect block `crosstalk`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crosstalk: Option<CrosstalkFile>,
    /// Effect block `ir_leakage`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ir_leakage: Option<IrLeakageFile>,
    /// Effect block `qe_shift`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub qe_shift: Option<QeShiftFile>,
    /// Extension: readout timing (default: global shutter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub readout: Option<ReadoutFile>,
    /// Extension: operating temperature (°C); with `dark_reference_temperature_c` and
    /// `dark_doubling_temperature_c`, scales `dark_voltage_v_per_s` by the doubling law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_c: Option<f64>,
    /// Extension: temperature (°C) at which `dark_voltage_v_per_s` holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_reference_temperature_c: Option<f64>,
    /// Extension: temperature step (°C) over which the dark current doubles.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_doubling_temperature_c: Option<f64>,
    /// Extension: HDR pixel (split pixel, dual conversion gain, bracketing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hdr: Option<HdrFile>,
    /// Effect block `row_noise` ([`RowNoiseFile`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row_noise: Option<RowNoiseFile>,
    /// Effect block `rtn` ([`RtnFile`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rtn: Option<RtnFile>,
    /// Effect block `black_level_drift` ([`BlackLevelDriftFile`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub black_level_drift: Option<BlackLevelDriftFile>,
    /// Extension: dual-pixel readout (two half-photodiodes under one microlens).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dual_pixel: Option<DualPixelFile>,
    /// Extension: pixel optics (microlens, chief-ray angle, shift; issue 21).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_optics: Option<crate::pixel_optics_config::PixelOpticsFile>,
}

/// `sensor.dual_pixel` (extension): every pixel is two half-photodiodes (left, right) under
/// one microlens, each collecting the light of one half of the exit pupil
/// ([`camsim_sensor::dual_pixel`], [`camsim_optics::dual_pixel`]); their sum is the normal
/// pixel. Absent: off, and every output is the baseline chain's. The two images are formed by
/// [`crate::chain::dual_pixel_irradiance`].
///
/// | key | default | meaning |
/// |---|---|---|
/// | `separation` | 1 | fraction of one pupil half's light reaching its own half-photodiode (0.5 = no split … 1 = ideal) |
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DualPixelFile {
    /// Separation (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub separation: Option<f64>,
}

/// `sensor.hdr` (extension): an HDR pixel of charge packets (photodiodes, or exposures of
/// one) read at one or more conversion gains ([`camsim_sensor::hdr`]). Absent: the standard
/// pixel, and every output is the baseline chain's.
///
/// | key | default | meaning |
/// |---|---|---|
/// | `photodiodes` | required | list of charge packets (below), ≥ 1 |
/// | `readouts` | required | list of readouts (below), ≥ 1 |
///
/// A photodiode:
///
/// | key | default | meaning |
/// |---|---|---|
/// | `name` | required | unique name (`lpd`, `spd`, `long`, …) |
/// | `sensitivity` | required | electrons it collects per photo-electron of the camera's pixel (its share of the light), > 0 |
/// | `exposure_ratio` | 1 | its exposure time over the shot's (bracketing), > 0 |
/// | `well_capacity_e` | the sensor's | full well (electrons) |
///
/// A readout:
///
/// | key | default | meaning |
/// |---|---|---|
/// | `name` | required | unique name (`lpd_hcg`, …) |
/// | `photodiode` | required | name of the photodiode it reads |
/// | `conversion_gain_v_per_e` | required | conversion gain (V/e⁻) |
/// | `read_noise_v` | the sensor's | read noise σ (V) |
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HdrFile {
    /// Charge packets.
    pub photodiodes: Vec<HdrPhotodiodeFile>,
    /// Readouts.
    pub readouts: Vec<HdrReadoutFile>,
}

/// One `sensor.hdr.photodiodes[i]`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HdrPhotodiodeFile {
    /// Name.
    pub name: String,
    /// Electrons per photo-electron of the camera's pixel.
    pub sensitivity: f64,
    /// Exposure time over the shot's (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_ratio: Option<f64>,
    /// Full well (electrons; default the sensor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub well_capacity_e: Option<f64>,
}

/// One `sensor.hdr.readouts[i]`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HdrReadoutFile {
    /// Name.
    pub name: String,
    /// Name of the photodiode read.
    pub photodiode: String,
    /// Conversion gain (V/e⁻).
    pub conversion_gain_v_per_e: f64,
    /// Read noise σ (V; default the sensor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub read_noise_v: Option<f64>,
}

/// `sensor.readout` (extension): when the rows expose.
///
/// | key | default | meaning |
/// |---|---|---|
/// | `mode` | required | `"global"` (every row over `[0, T]`) or `"rolling"` (row r over `[r·row_time, r·row_time + T]`) |
/// | `row_time_us` | 0 | time between the exposure starts of consecutive rows (µs); required > 0 for `"rolling"` |
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReadoutFile {
    /// `"global"` or `"rolling"`.
    pub mode: String,
    /// Row time (µs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub row_time_us: Option<f64>,
}

/// `shots[i].light_modulation` (extension): the scene's light is pulse-width modulated.
///
/// | key | default | meaning |
/// |---|---|---|
/// | `frequency_hz` | required | modulation frequency f (Hz) |
/// | `duty_cycle` | required | on-fraction D of each period, in (0, 1] |
/// | `phase` | 0 | start of the on-phase at t = 0 as a fraction of the period, in [0, 1) |
///
/// The mean light is the target's (the peak is 1/D times it).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightModulationFile {
    /// f (Hz).
    pub frequency_hz: f64,
    /// D.
    pub duty_cycle: f64,
    /// Phase (fraction of a period).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase: Option<f64>,
}

/// `shots[i].motion` (extension): rigid image motion during the exposure.
///
/// | key | default | meaning |
/// |---|---|---|
/// | `velocity_px_per_s` | required | `[v_x, v_y]`: image velocity on the sensor (pixels/s; x along columns, y down the rows); at time t the image is shifted by v·t |
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionFile {
    /// `[v_x, v_y]` (pixels/s).
    pub velocity_px_per_s: [f64; 2],
}

/// `sensor.noise` switches (all default true).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseFile {
    /// Photon shot noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shot: Option<bool>,
    /// Dark current (its mean and its shot noise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark: Option<bool>,
    /// Read noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub read: Option<bool>,
    /// DSNU.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dsnu: Option<bool>,
    /// PRNU.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prnu: Option<bool>,
}

/// `sensor.column_fpn`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnFpnFile {
    /// σ of the per-column offsets (V).
    pub sigma_v: f64,
}

/// `sensor.reset_noise`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResetNoiseFile {
    /// kTC noise σ (V) per frame.
    pub sigma_v: f64,
    /// Correlated double sampling (default true: the reset noise cancels).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cds: Option<bool>,
}

/// `captures.json` as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CapturesFile {
    /// Path of camera.json, relative to the captures file.
    pub camera: String,
    /// The shots.
    pub shots: Vec<ShotFile>,
    /// Extension: simulation settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<SimulationFile>,
    /// Extension: layout of headerless raw frames (`.raw` / `.bin` frame files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw_format: Option<RawFormatFile>,
}

/// `captures.raw_format` as written: how to read headerless raw frames.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawFormatFile {
    /// Rows (default: the sensor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rows: Option<usize>,
    /// Columns (default: the sensor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cols: Option<usize>,
    /// 8 or 16 bits per stored sample.
    pub bits_per_sample: u32,
    /// "little" or "big" (16-bit samples).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub endianness: Option<String>,
    /// Bytes to skip at the start of each file (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub header_bytes: Option<u64>,
}

/// One shot as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShotFile {
    /// Shot id (output file stem).
    pub id: String,
    /// The target.
    pub target: Value,
    /// Exposure time (s); absent with `auto_exposure`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_s: Option<f64>,
    /// Extension: auto-exposure to this fraction of the voltage swing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub auto_exposure: Option<f64>,
    /// Analog gain for this shot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub analog_gain: Option<f64>,
    /// Frame files, relative to the captures file.
    pub frames: Vec<String>,
    /// Extension: PWM modulation of the light during the exposure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_modulation: Option<LightModulationFile>,
    /// Extension: image motion during the exposure.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionFile>,
    /// Extension: sensor temperature (°C) during this shot; with the camera's doubling law
    /// (`sensor.temperature_c`, `dark_reference_temperature_c`, `dark_doubling_temperature_c`)
    /// it scales the dark current of the shot (docs/effects.md, `dark_temperature`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_c: Option<f64>,
    /// Extension: the frames are a video at this frame rate (Hz): frame k starts its exposure
    /// at k / frame_rate_hz, the light modulation and the motion carrying on (absent: every
    /// frame is a repeat of the same exposure window).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_rate_hz: Option<f64>,
}

/// `captures.simulation` (extension).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationFile {
    /// Wavelength grid for wavelength-dependent optics: `{start_nm, stop_nm, step_nm}`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wavelength_nm: Option<GridFile>,
    /// Scene samples per pixel side (default: from the blur).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oversample: Option<usize>,
    /// Default seed when --seed is not given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// What a scene sample stands for: `"auto"` (default: the cubic B-spline filter under a
    /// band-limited blur, [`crate::simulate::sample_aperture_for`]) or `"cell"` (always the
    /// cell average, as before issue 17 §5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_aperture: Option<SampleApertureChoice>,
}

/// `simulation.sample_aperture`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SampleApertureChoice {
    /// The most exact aperture the optics allow.
    Auto,
    /// Cell averages.
    Cell,
}

/// A regular wavelength grid as written.
#[derive(Debug, Clone, Serialize, Deserialize)]
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
    /// Readout timing (`sensor.readout`; default global shutter).
    pub readout: Readout,
    /// `optics.uncropped_optical_image`: form the optical image of the scene image (the
    /// target's extent) the ISETCam way with `crop = false`, ring of blurred light included
    /// (`crate::chain::optical_image`). Default false.
    pub uncropped_optical_image: bool,
    /// HDR pixel (`sensor.hdr`; None: the standard pixel).
    pub hdr: Option<HdrModel>,
    /// Dual-pixel readout (`sensor.dual_pixel`; None: one photodiode per pixel).
    pub dual_pixel: Option<camsim_sensor::DualPixel>,
    /// Thin-lens focus distance (m, `optics.focus_distance_m`): scenes with depth are
    /// defocused by depth as a thin lens focused there ([`crate::chain::irradiance_of`]).
    pub thin_lens_focus_m: Option<f64>,
    /// Pixel optics (`sensor.pixel_optics`; None: off): CRA shading and optical crosstalk,
    /// applied by [`crate::chain::apply_pixel_optics`].
    pub pixel_optics: Option<crate::pixel_optics_config::CameraPixelOptics>,
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
    /// PWM light modulation (`light_modulation`; None: steady light).
    pub light: Option<PwmLight>,
    /// Image motion during the exposure (`motion`; None: static).
    pub motion: Option<Motion>,
    /// Sensor temperature during the shot (°C, `temperature_c`; None: the camera's).
    pub temperature_c: Option<f64>,
    /// Video frame rate (`frame_rate_hz`; None: the frames repeat one exposure window).
    pub frame_rate_hz: Option<f64>,
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
    crate::staging::protect_input(path);
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
    let relative_illumination = match o
        .relative_illumination
        .as_ref()
        .map(|r| r.model())
        .unwrap_or("cos4")
    {
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
                o.object_distance_m,
                pixel_pitch_m,
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
        effects: optics_effects_from_file(path, o, &raw.sensor)?,
    };
    let uncropped_optical_image = o.uncropped_optical_image.unwrap_or(false);
    if uncropped_optical_image {
        let fft_blur = matches!(
            optics.blur,
            Blur::None | Blur::Diffraction | Blur::Psf(_) | Blur::Wavefront { .. } | Blur::Pupil(_)
        );
        check(
            path,
            fft_blur && optics.effects.is_empty() && optics.diffuser.is_none(),
            "optics.uncropped_optical_image",
            "true needs blur.kind none, diffraction, psf or wavefront, no diffuser and no effect \
             blocks (ISETCam's FFT optical image)"
                .to_string(),
        )?;
    }
    let sensor = sensor_from_file(path, &raw.sensor)?;
    let readout = readout_from_file(path, raw.sensor.readout.as_ref())?;
    let hdr = match &raw.sensor.hdr {
        None => None,
        Some(h) => Some(hdr_from_file(path, h, &sensor)?),
    };
    let dual_pixel = match &raw.sensor.dual_pixel {
        None => None,
        Some(d) => {
            let dp = camsim_sensor::DualPixel {
                separation: d.separation.unwrap_or(1.0),
            };
            dp.validate()
                .map_err(|e| CliError::input(path, e.to_string()))?;
            Some(dp)
        }
    };
    let thin_lens_focus_m = match o.focus_distance_m {
        None => None,
        Some(_) if matches!(optics.blur, Blur::Lens(_)) => {
            return Err(CliError::input(
                path,
                "optics.focus_distance_m: a thin-lens key; with blur kind \"lens\" the lens is focused by optics.blur.focus_distance_m",
            ))
        }
        Some(d) => {
            let d = positive(path, "optics.focus_distance_m", d)?;
            if !(d.is_finite() && d > focal_length_m) {
                return Err(CliError::input(
                    path,
                    format!("optics.focus_distance_m: must be finite and beyond the focal length ({} m), got {d}", focal_length_m),
                ));
            }
            Some(d)
        }
    };
    let pixel_optics = match &raw.sensor.pixel_optics {
        None => None,
        Some(po) => Some(crate::pixel_optics_config::pixel_optics_from_file(
            path,
            dir,
            po,
            pixel_pitch_m * 1e6,
            optics.f_number,
            optics.focal_length_m * 1e3,
        )?),
    };
    Ok(Camera {
        name: raw.name.unwrap_or_else(|| "camera".into()),
        optics,
        sensor,
        readout,
        uncropped_optical_image,
        hdr,
        dual_pixel,
        thin_lens_focus_m,
        pixel_optics,
    })
}

/// `sensor.hdr` → [`HdrModel`] (names resolved, defaults from the sensor, fields checked).
fn hdr_from_file(path: &Path, h: &HdrFile, sensor: &SensorModel) -> Result<HdrModel, CliError> {
    let mut packets = Vec::with_capacity(h.photodiodes.len());
    for (i, p) in h.photodiodes.iter().enumerate() {
        if h.photodiodes[..i].iter().any(|q| q.name == p.name) {
            return Err(CliError::input(
                path,
                format!(
                    "sensor.hdr.photodiodes[{i}].name: \"{}\" is used twice",
                    p.name
                ),
            ));
        }
        packets.push(ChargePacket {
            name: p.name.clone(),
            sensitivity: p.sensitivity,
            exposure_ratio: p.exposure_ratio.unwrap_or(1.0),
            well_capacity_e: p.well_capacity_e.unwrap_or(sensor.well_capacity_e),
        });
    }
    let mut readouts = Vec::with_capacity(h.readouts.len());
    for (i, r) in h.readouts.iter().enumerate() {
        if h.readouts[..i].iter().any(|q| q.name == r.name) {
            return Err(CliError::input(
                path,
                format!(
                    "sensor.hdr.readouts[{i}].name: \"{}\" is used twice",
                    r.name
                ),
            ));
        }
        let packet = packets
            .iter()
            .position(|p| p.name == r.photodiode)
            .ok_or_else(|| {
                CliError::input(
                    path,
                    format!(
                        "sensor.hdr.readouts[{i}].photodiode: \"{}\" is not a photodiode (have: {})",
                        r.photodiode,
                        packets.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
        readouts.push(HdrReadout {
            name: r.name.clone(),
            packet,
            conversion_gain_v_per_e: r.conversion_gain_v_per_e,
            read_noise_v: r.read_noise_v.unwrap_or(sensor.read_noise_v),
        });
    }
    let model = HdrModel { packets, readouts };
    model
        .validate()
        .map_err(|e| CliError::input(path, e.to_string()))?;
    Ok(model)
}

/// `sensor.readout` → [`Readout`] (absent: global shutter).
fn readout_from_file(path: &Path, r: Option<&ReadoutFile>) -> Result<Readout, CliError> {
    let Some(r) = r else {
        return Ok(Readout::default());
    };
    let row_time_s = non_negative(
        path,
        "sensor.readout.row_time_us",
        r.row_time_us.unwrap_or(0.0),
    )? * 1e-6;
    let mode = match r.mode.as_str() {
        "global" => ShutterMode::Global,
        "rolling" => {
            positive(path, "sensor.readout.row_time_us", row_time_s * 1e6)?;
            ShutterMode::Rolling
        }
        other => {
            return Err(CliError::input(
                path,
                format!(
                    "sensor.readout.mode: unknown value \"{other}\" (expected global or rolling)"
                ),
            ))
        }
    };
    Ok(Readout { mode, row_time_s })
}

/// The dark voltage at the operating temperature: `dark_voltage_v_per_s` (at
/// `dark_reference_temperature_c`) through [`camsim_sensor::dark_at_temperature`] when
/// `temperature_c` is given (the three keys go together).
fn dark_voltage_at_temperature(
    path: &Path,
    s: &SensorFile,
    dark_v_per_s: f64,
) -> Result<f64, CliError> {
    match (s.temperature_c, s.dark_reference_temperature_c, s.dark_doubling_temperature_c) {
        (None, None, None) => Ok(dark_v_per_s),
        (Some(t), Some(t_ref), Some(t_double)) => {
            for (k, v) in [("sensor.temperature_c", t), ("sensor.dark_reference_temperature_c", t_ref)] {
                check(path, v.is_finite() && v > -273.15, k, format!("must be a temperature above absolute zero (°C), got {v}"))?;
            }
            let t_double = positive(path, "sensor.dark_doubling_temperature_c", t_double)?;
            Ok(camsim_sensor::dark_at_temperature(dark_v_per_s, t, t_ref, t_double))
        }
        _ => Err(CliError::input(
            path,
            "sensor.temperature_c: give temperature_c, dark_reference_temperature_c and dark_doubling_temperature_c together".to_string(),
        )),
    }
}

fn blur_from_file(
    path: &Path,
    dir: &Path,
    b: &BlurFile,
    sensor_half_diagonal_m: f64,
    object_distance_m: Option<f64>,
    pixel_pitch_m: f64,
) -> Result<Blur, CliError> {
    let allowed: &[&str] = match b.kind.as_str() {
        "none" | "diffraction" => &[],
        "gaussian" => &["sigma_um"],
        "pillbox" => &["width_um"],
        "psf" => &["psf_file"],
        "wavefront" => &[
            "defocus_um",
            "zernike_um",
            "zernike_pupil_diameter_mm",
            "chromatic_defocus",
            "blades",
            "pupil_samples",
        ],
        "lens" => &[
            "lens_file",
            "focus_distance_m",
            "focus_criterion",
            "focus_frequency_cyc_per_mm",
            "focus_group_surfaces",
        ],
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
        ("zernike_um", b.zernike_um.is_some()),
        (
            "zernike_pupil_diameter_mm",
            b.zernike_pupil_diameter_mm.is_some(),
        ),
        ("chromatic_defocus", b.chromatic_defocus.is_some()),
        ("blades", b.blades.is_some()),
        ("pupil_samples", b.pupil_samples.is_some()),
        ("lens_file", b.lens_file.is_some()),
        ("focus_distance_m", b.focus_distance_m.is_some()),
        ("focus_criterion", b.focus_criterion.is_some()),
        (
            "focus_frequency_cyc_per_mm",
            b.focus_frequency_cyc_per_mm.is_some(),
        ),
        ("focus_group_surfaces", b.focus_group_surfaces.is_some()),
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
        "wavefront" => wavefront_from_file(path, b)?,
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
            let lens = camsim_lens::LensPrescription::from_json_file(
                &p,
                &camsim_lens::GlassCatalog::bundled(),
            )
            .map_err(|e| CliError::input(&p, e))?;
            let mut opts = camsim_optics::LensBlurOptions::covering(sensor_half_diagonal_m * 1e3);
            // optics.object_distance_m: the object; the lens is focused on it unless
            // optics.blur.focus_distance_m says otherwise, by the focus model
            // (camsim_lens::focus_model; merit frequency default half the pixel Nyquist).
            opts.object_distance_mm = object_distance_m.map(|d| d * 1e3);
            if let Some(fd) = b.focus_distance_m {
                opts.focus = camsim_optics::LensFocus::At(Some(
                    positive(path, "optics.blur.focus_distance_m", fd)? * 1e3,
                ));
            }
            let mut method = camsim_lens::FocusMethod::from_keys(
                b.focus_criterion.as_deref(),
                b.focus_frequency_cyc_per_mm,
                b.focus_group_surfaces,
            )
            .map_err(|m| CliError::input(path, format!("optics.blur.{m}")))?;
            method.frequency_cyc_per_mm = method
                .frequency_cyc_per_mm
                .or(Some(0.25 / (pixel_pitch_m * 1e3)));
            opts.focus_method = method;
            Blur::Lens(
                camsim_optics::LensBlur::from_prescription(&lens, &opts)
                    .map_err(|e| CliError::input(&p, e))?,
            )
        }
    })
}

/// `blur.kind = "wavefront"`: Zernike defocus alone ([`Blur::Wavefront`], as before), or with
/// any of the keys beyond defocus the general pupil ([`camsim_optics::WavefrontPupil`]).
fn wavefront_from_file(path: &Path, b: &BlurFile) -> Result<Blur, CliError> {
    let general = b.zernike_um.is_some()
        || b.zernike_pupil_diameter_mm.is_some()
        || b.chromatic_defocus.is_some()
        || b.blades.is_some()
        || b.pupil_samples.is_some();
    let err = |k: &str, m: String| CliError::input(path, format!("optics.blur.{k}: {m}"));
    if let Some(d) = b.defocus_um {
        check(
            path,
            d.is_finite(),
            "optics.blur.defocus_um",
            format!("must be finite, got {d}"),
        )?;
    }
    if !general {
        let d = b.defocus_um.ok_or_else(|| {
            err(
                "defocus_um",
                "required for blur kind \"wavefront\" (or give zernike_um)".into(),
            )
        })?;
        return Ok(Blur::Wavefront {
            defocus_um: d,
            pupil_samples: 64,
        });
    }
    let mut zernike = Vec::new();
    if let Some(d) = b.defocus_um {
        zernike.push(camsim_optics::ZernikeTerm { j: 4, rms_um: d });
    }
    for (k, &v) in b.zernike_um.iter().flatten() {
        let j: usize = k.trim().parse().map_err(|_| {
            err(
                "zernike_um",
                format!("key \"{k}\" is not an OSA/ANSI index (0, 1, 2, …)"),
            )
        })?;
        check(
            path,
            j <= 65,
            "optics.blur.zernike_um",
            format!("index {j} out of 0–65"),
        )?;
        check(
            path,
            v.is_finite(),
            "optics.blur.zernike_um",
            format!("\"{k}\": must be finite, got {v}"),
        )?;
        zernike.push(camsim_optics::ZernikeTerm { j, rms_um: v });
    }
    let zernike_pupil_diameter_m = match b.zernike_pupil_diameter_mm {
        None => None,
        Some(v) => Some(positive(path, "optics.blur.zernike_pupil_diameter_mm", v)? * 1e-3),
    };
    let chromatic_defocus = match &b.chromatic_defocus {
        None => camsim_optics::ChromaticDefocus::None,
        Some(c) => match (c.model.as_deref(), c.reference_nm, &c.wavelength_nm, &c.defocus_um) {
            (Some("human"), Some(r), None, None) => {
                check(path, r.is_finite() && r > 300.0, "optics.blur.chromatic_defocus.reference_nm", format!("must be a wavelength > 300 nm, got {r}"))?;
                camsim_optics::ChromaticDefocus::HumanEye { reference_nm: r }
            }
            (None, None, Some(w), Some(d)) => {
                check(path, !w.is_empty() && w.len() == d.len(), "optics.blur.chromatic_defocus", format!("wavelength_nm ({}) and defocus_um ({}) need the same, non-zero length", w.len(), d.len()))?;
                check(path, w.iter().all(|x| x.is_finite()) && w.windows(2).all(|p| p[1] > p[0]), "optics.blur.chromatic_defocus.wavelength_nm", "must be finite and strictly increasing")?;
                check(path, d.iter().all(|x| x.is_finite()), "optics.blur.chromatic_defocus.defocus_um", "must be finite")?;
                camsim_optics::ChromaticDefocus::Table {
                    wavelength_nm: w.clone(),
                    defocus_um: d.clone(),
                }
            }
            _ => {
                return Err(err(
                    "chromatic_defocus",
                    "expected {\"model\": \"human\", \"reference_nm\": λ} or {\"wavelength_nm\": [...], \"defocus_um\": [...]}".into(),
                ))
            }
        },
    };
    if let Some(n) = b.blades {
        check(
            path,
            (3..=64).contains(&n),
            "optics.blur.blades",
            format!("must be 3–64, got {n}"),
        )?;
    }
    let pupil_samples = b.pupil_samples.unwrap_or(64);
    check(
        path,
        (16..=4096).contains(&pupil_samples),
        "optics.blur.pupil_samples",
        format!("must be 16–4096, got {pupil_samples}"),
    )?;
    Ok(Blur::Pupil(camsim_optics::WavefrontPupil {
        zernike,
        zernike_pupil_diameter_m,
        chromatic_defocus,
        blades: b.blades,
        pupil_samples,
    }))
}

fn sensor_from_file(path: &Path, s: &SensorFile) -> Result<SensorModel, CliError> {
    check(
        path,
        s.rows > 0 && s.cols > 0,
        "sensor.rows/cols",
        format!("must be positive, got {}×{}", s.rows, s.cols),
    )?;
    crate::budget::check_memory(
        Some(path),
        "sensor.rows/cols",
        s.rows as f64 * s.cols as f64 * 48.0,
        &format!("{}×{} pixels × 48 bytes", s.rows, s.cols),
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
        channel_names: names.clone(),
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
        dark_voltage_v_per_s: dark_voltage_at_temperature(
            path,
            s,
            non_negative(
                path,
                "sensor.dark_voltage_v_per_s",
                s.dark_voltage_v_per_s.unwrap_or(0.0),
            )?,
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
        effects: sensor_effects_from_file(path, s, &names)?,
    };
    model.validate().map_err(|e| CliError::input(path, e))?;
    Ok(model)
}

/// `what = value: must …` as a one-line input error.
fn bad_value(path: &Path, key: &str, value: impl std::fmt::Display, need: &str) -> CliError {
    CliError::input(path, format!("{key} = {value}: {need}"))
}

fn finite(path: &Path, key: &str, v: f64) -> Result<f64, CliError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(bad_value(path, key, v, "must be a finite number"))
    }
}

fn in_range(
    path: &Path,
    key: &str,
    v: f64,
    ok: impl Fn(f64) -> bool,
    need: &str,
) -> Result<f64, CliError> {
    if v.is_finite() && ok(v) {
        Ok(v)
    } else {
        Err(bad_value(path, key, v, need))
    }
}

/// The optics effect blocks (docs/effects.md) as the optics crate's [`OpticsEffects`].
fn optics_effects_from_file(
    path: &Path,
    o: &OpticsFile,
    sensor: &SensorFile,
) -> Result<OpticsEffects, CliError> {
    let p = sensor.pixel_pitch_um * 1e-6;
    let mut fx = OpticsEffects {
        sensor_width_m: sensor.cols as f64 * p,
        sensor_height_m: sensor.rows as f64 * p,
        ..Default::default()
    };
    if let Some(e) = &o.exposure_scale {
        fx.exposure_scale = Some(in_range(
            path,
            "optics.exposure_scale.factor",
            e.factor,
            |v| v > 0.0,
            "must be > 0",
        )?);
    }
    if let Some(f) = o.relative_illumination.as_ref().and_then(|r| r.falloff()) {
        fx.falloff = Some(match f {
            FalloffFile::Polynomial { coefficients } => {
                for (i, a) in coefficients.iter().enumerate() {
                    finite(
                        path,
                        &format!("optics.relative_illumination.falloff.coefficients[{i}]"),
                        *a,
                    )?;
                }
                Falloff::Polynomial {
                    coefficients: coefficients.clone(),
                }
            }
            FalloffFile::TwoCircle { separation_at_h1 } => Falloff::TwoCircle {
                separation_at_h1: in_range(
                    path,
                    "optics.relative_illumination.falloff.separation_at_h1",
                    *separation_at_h1,
                    |v| (0.0..=2.0).contains(&v),
                    "must be in [0, 2] (circle radii)",
                )?,
            },
        });
    }
    if let Some(g) = &o.veiling_glare {
        fx.veiling_glare = Some(in_range(
            path,
            "optics.veiling_glare.fraction",
            g.fraction,
            |v| v >= 0.0,
            "must be ≥ 0",
        )?);
    }
    if let Some(d) = &o.defocus {
        fx.defocus = Some(match d {
            DefocusFile::Gaussian { sigma_um } => Defocus::Gaussian {
                sigma_um: in_range(
                    path,
                    "optics.defocus.sigma_um",
                    *sigma_um,
                    |v| v >= 0.0,
                    "must be ≥ 0",
                )?,
            },
            DefocusFile::Pillbox { radius_um } => Defocus::Pillbox {
                radius_um: in_range(
                    path,
                    "optics.defocus.radius_um",
                    *radius_um,
                    |v| v >= 0.0,
                    "must be ≥ 0",
                )?,
            },
        });
    }
    if let Some(d) = &o.distortion {
        fx.distortion = Some(match d {
            DistortionFile::Polynomial { k1, k2 } => Distortion::Polynomial {
                k1: finite(path, "optics.distortion.k1", *k1)?,
                k2: finite(path, "optics.distortion.k2", *k2)?,
            },
            DistortionFile::Division { k } => Distortion::Division {
                k: in_range(
                    path,
                    "optics.distortion.k",
                    *k,
                    |v| v < 1.0,
                    "must be < 1 (the division model has a pole at h = 1/√k)",
                )?,
            },
        });
    }
    if let Some(l) = &o.lateral_color {
        let (kind, d) = match l {
            LateralColorFile::Linear { displacement_um } => {
                (LateralColorKind::Linear, displacement_um)
            }
            LateralColorFile::Cauchy { displacement_um } => {
                (LateralColorKind::Cauchy, displacement_um)
            }
        };
        fx.lateral_color = Some(LateralColor {
            kind,
            displacement_um: finite(path, "optics.lateral_color.displacement_um", *d)?,
        });
    }
    fx.validate().map_err(|e| CliError::input(path, e))?;
    Ok(fx)
}

/// The sensor effect blocks (docs/effects.md) as the sensor crate's [`SensorEffects`];
/// `names` are the channel letters in channel-index order.
fn sensor_effects_from_file(
    path: &Path,
    s: &SensorFile,
    names: &[String],
) -> Result<SensorEffects, CliError> {
    let mut fx = SensorEffects::default();
    let channel = |key: &str, name: &str| -> Result<usize, CliError> {
        names.iter().position(|n| n == name).ok_or_else(|| {
            CliError::input(
                path,
                format!(
                    "{key}.{name}: no such channel (sensor.channels has: {})",
                    names.join(", ")
                ),
            )
        })
    };
    if let Some(r) = &s.row_noise {
        fx.row_noise = Some(camsim_sensor::RowNoise {
            sigma_v: non_negative(path, "sensor.row_noise.sigma_v", r.sigma_v)?,
        });
    }
    if let Some(r) = &s.rtn {
        let prob = |key: &str, v: Option<f64>| {
            in_range(
                path,
                key,
                v.unwrap_or(0.5),
                |p| p > 0.0 && p <= 1.0,
                "must be a probability per frame in (0, 1]",
            )
        };
        fx.rtn = Some(camsim_sensor::Rtn {
            fraction: in_range(
                path,
                "sensor.rtn.fraction",
                r.fraction,
                |v| (0.0..=1.0).contains(&v),
                "must be in [0, 1]",
            )?,
            amplitude_v: non_negative(path, "sensor.rtn.amplitude_v", r.amplitude_v)?,
            log_sigma: non_negative(path, "sensor.rtn.log_sigma", r.log_sigma.unwrap_or(0.0))?,
            p_up: prob("sensor.rtn.p_up", r.p_up)?,
            p_down: prob("sensor.rtn.p_down", r.p_down)?,
        });
    }
    if let Some(d) = &s.black_level_drift {
        fx.black_level_drift = Some(camsim_sensor::BlackLevelDrift {
            dn_per_frame: finite(
                path,
                "sensor.black_level_drift.dn_per_frame",
                d.dn_per_frame,
            )?,
        });
    }
    // The doubling law, once validated by `dark_voltage_at_temperature`: the dark voltage
    // holds at the operating temperature `temperature_c`; a shot's `temperature_c` scales it.
    if let (Some(t), Some(_), Some(td)) = (
        s.temperature_c,
        s.dark_reference_temperature_c,
        s.dark_doubling_temperature_c,
    ) {
        fx.dark_temperature = Some(camsim_sensor::DarkTemperature {
            reference_temperature_c: t,
            doubling_temperature_c: td,
        });
    }
    if let Some(h) = &s.hot_pixels {
        fx.hot_pixels = Some(HotPixels {
            fraction: in_range(
                path,
                "sensor.hot_pixels.fraction",
                h.fraction,
                |v| (0.0..=1.0).contains(&v),
                "must be in [0, 1]",
            )?,
            dark_voltage_v_per_s: in_range(
                path,
                "sensor.hot_pixels.dark_voltage_v_per_s",
                h.dark_voltage_v_per_s,
                |v| v >= 0.0,
                "must be ≥ 0",
            )?,
            log_sigma: match h.log_sigma {
                Some(v) => in_range(
                    path,
                    "sensor.hot_pixels.log_sigma",
                    v,
                    |v| v >= 0.0,
                    "must be ≥ 0",
                )?,
                None => 0.0,
            },
        });
    }
    if let Some(n) = &s.nonlinearity {
        fx.nonlinearity = Some(match n {
            NonlinearityFile::Quadratic { coefficient_per_v } => Nonlinearity::Quadratic {
                coefficient_per_v: in_range(
                    path,
                    "sensor.nonlinearity.coefficient_per_v",
                    *coefficient_per_v,
                    |v| v >= 0.0,
                    "must be ≥ 0",
                )?,
            },
            NonlinearityFile::Tanh { saturation_v } => Nonlinearity::Tanh {
                saturation_v: in_range(
                    path,
                    "sensor.nonlinearity.saturation_v",
                    *saturation_v,
                    |v| v > 0.0,
                    "must be > 0",
                )?,
            },
        });
    }
    if let Some(c) = &s.crosstalk {
        fx.crosstalk = Some(match c {
            CrosstalkFile::Symmetric { fraction } => Crosstalk::symmetric(in_range(
                path,
                "sensor.crosstalk.fraction",
                *fraction,
                |v| (0.0..1.0).contains(&v),
                "must be in [0, 1)",
            )?),
            CrosstalkFile::Directional {
                left,
                right,
                up,
                down,
            } => {
                let mut d = [0.0; 4];
                for (i, (k, v)) in [("left", left), ("right", right), ("up", up), ("down", down)]
                    .into_iter()
                    .enumerate()
                {
                    d[i] = in_range(
                        path,
                        &format!("sensor.crosstalk.{k}"),
                        *v,
                        |v| (0.0..1.0).contains(&v),
                        "must be in [0, 1)",
                    )?;
                }
                let t: f64 = d.iter().sum();
                if t >= 1.0 {
                    return Err(bad_value(
                        path,
                        "sensor.crosstalk (left + right + up + down)",
                        t,
                        "must be < 1",
                    ));
                }
                Crosstalk {
                    left: d[0],
                    right: d[1],
                    up: d[2],
                    down: d[3],
                }
            }
        });
    }
    if let Some(ir) = &s.ir_leakage {
        let mut channels = vec![None; names.len()];
        for (name, v) in &ir.channels {
            let c = channel("sensor.ir_leakage.channels", name)?;
            let key = format!("sensor.ir_leakage.channels.{name}");
            let spec = match &v.0 {
                Spectrum::Affine {
                    offset,
                    slope_per_nm,
                } if *slope_per_nm == 0.0 => IrLeakage::band(in_range(
                    path,
                    &key,
                    *offset,
                    |v| v >= 0.0,
                    "must be ≥ 0 (QE added on 700–1000 nm)",
                )?),
                other => {
                    if let Some((w, q)) = other.first_negative() {
                        return Err(CliError::input(
                            path,
                            format!("{key}: negative QE {q} at {w} nm"),
                        ));
                    }
                    other.clone()
                }
            };
            channels[c] = Some(spec);
        }
        fx.ir_leakage = Some(IrLeakage { channels });
    }
    if let Some(q) = &s.qe_shift {
        let mut shift_nm = vec![0.0; names.len()];
        for (name, v) in &q.shift_nm {
            let c = channel("sensor.qe_shift.shift_nm", name)?;
            shift_nm[c] = finite(path, &format!("sensor.qe_shift.shift_nm.{name}"), *v)?;
        }
        fx.qe_shift = Some(QeShift { shift_nm });
    }
    Ok(fx)
}

/// Read `camera.json` as written (unknown keys rejected), without validating values: the form
/// to edit and write back with [`write_camera_file`].
pub fn read_camera_file(path: &Path) -> Result<CameraFile, CliError> {
    read_json(path)
}

/// A camera file as pretty JSON (the format [`load_camera`] reads; `parse(serialize(x))` is
/// the same camera).
pub fn camera_file_json(camera: &CameraFile) -> Result<String, CliError> {
    serde_json::to_string_pretty(camera)
        .map_err(|e| CliError::Other(format!("cannot serialise the camera: {e}")))
}

/// Write a camera file as pretty JSON, atomically (temporary file + rename).
pub fn write_camera_file(path: &Path, camera: &CameraFile) -> Result<(), CliError> {
    let text = camera_file_json(camera)?;
    camsim_core::exr_io::write_atomically(path, |tmp| std::fs::write(tmp, text.as_bytes()))
        .map_err(|e| CliError::output(path, e))
}

/// The folder of a file (`.` for a bare file name).
fn folder_of(path: &Path) -> PathBuf {
    path.parent()
        .map(|p| {
            if p.as_os_str().is_empty() {
                Path::new(".")
            } else {
                p
            }
        })
        .unwrap_or(Path::new("."))
        .to_path_buf()
}

/// Read and validate a capture set; `camera_override` replaces the camera it names.
pub fn load_captures(path: &Path, camera_override: Option<&Path>) -> Result<CaptureSet, CliError> {
    let raw: CapturesFile = read_json(path)?;
    let dir = folder_of(path);
    let camera_path = match camera_override {
        Some(p) => p.to_path_buf(),
        None => dir.join(&raw.camera),
    };
    let camera = load_camera(&camera_path)?;
    captures_with_camera(path, raw, camera, camera_path)
}

/// Validate a parsed capture set whose camera is already loaded (`raw.camera` is not read):
/// the in-memory form of [`load_captures`] used by the Python package. `path` names the
/// capture set in messages and its folder resolves target files and frames.
pub fn captures_with_camera(
    path: &Path,
    raw: CapturesFile,
    camera: Camera,
    camera_path: PathBuf,
) -> Result<CaptureSet, CliError> {
    let dir = folder_of(path);
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
            let ext = Path::new(f)
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("")
                .to_ascii_lowercase();
            check(
                path,
                ["png", "tif", "tiff", "dng", "raw", "bin"].contains(&ext.as_str()),
                &format!("{key}.frames[{j}]"),
                format!(
                    "\"{f}\": frames are .png, .tif/.tiff, .dng or (with raw_format) .raw/.bin"
                ),
            )?;
        }
        let target = crate::targets::target_from_value(&s.target, &dir, &camera.sensor)
            .map_err(|m| CliError::input(path, format!("{key}.target{m}")))?;
        let light = s.light_modulation.as_ref().map(|l| PwmLight {
            frequency_hz: l.frequency_hz,
            duty_cycle: l.duty_cycle,
            phase: l.phase.unwrap_or(0.0),
        });
        let motion = s.motion.as_ref().map(|m| Motion {
            velocity_px_per_s: m.velocity_px_per_s,
        });
        let time = camsim_sensor::TimeModel {
            readout: camera.readout,
            light,
            motion,
        };
        time.validate()
            .map_err(|e| CliError::input(path, format!("{key}: {e}")))?;
        if let Some(f) = s.frame_rate_hz {
            if !(f.is_finite() && f > 0.0) {
                return Err(CliError::input(
                    path,
                    format!("{key}: frame_rate_hz = {f}: must be a positive number of frames per second"),
                ));
            }
        }
        shots.push(Shot {
            id: s.id.clone(),
            target,
            target_key: s.target.to_string(),
            exposure,
            analog_gain,
            frames: s.frames.clone(),
            light,
            motion,
            temperature_c: match s.temperature_c {
                Some(t) => Some(in_range(
                    path,
                    &format!("{key}.temperature_c"),
                    t,
                    |v| v > -273.15,
                    "must be a temperature above absolute zero (°C)",
                )?),
                None => None,
            },
            frame_rate_hz: s.frame_rate_hz,
        });
    }
    let simulation = raw.simulation.unwrap_or_default();
    if let Some(g) = &simulation.wavelength_nm {
        let grid = WavelengthGrid::regular(g.start_nm, g.stop_nm, g.step_nm)
            .map_err(|e| CliError::input(path, format!("simulation.wavelength_nm: {e}")))?;
        check(
            path,
            grid.len() >= 2,
            "simulation.wavelength_nm",
            format!(
                "needs at least two wavelengths (a one-band grid has no width and loses all \
                 the light), got start_nm = stop_nm = {}",
                g.start_nm
            ),
        )?;
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
            let (rows, cols) = (
                r.rows.unwrap_or(camera.sensor.rows),
                r.cols.unwrap_or(camera.sensor.cols),
            );
            check(
                path,
                rows == camera.sensor.rows && cols == camera.sensor.cols,
                "raw_format.rows/cols",
                format!(
                    "{rows}×{cols} differs from the camera's sensor {}×{}",
                    camera.sensor.rows, camera.sensor.cols
                ),
            )?;
            let header_bytes = r.header_bytes.unwrap_or(0);
            check(
                path,
                header_bytes <= 1 << 30,
                "raw_format.header_bytes",
                format!("must be at most 2^30 (1 GiB), got {header_bytes}"),
            )?;
            Some(crate::raw_input::RawFormat {
                rows,
                cols,
                bytes_per_sample: bytes,
                little_endian,
                header_bytes,
            })
        }
    };
    // The recorded frames are inputs: no output set may replace them.
    for fr in shots.iter().flat_map(|s| &s.frames) {
        crate::staging::protect_input(&dir.join(fr));
    }
    let set = CaptureSet {
        path: path.to_path_buf(),
        dir,
        camera,
        camera_path,
        shots,
        simulation,
        raw_format,
    };
    crate::simulate::check_budget(&set)?;
    Ok(set)
}

#[cfg(test)]
mod wavefront_keys_tests {
    //! The `blur.kind = "wavefront"` keys beyond defocus (issue 17 §4): defocus alone keeps
    //! the old blur; the new keys give the general pupil; bad values name their key.
    use super::*;

    fn camera(blur: Value) -> Result<Camera, CliError> {
        let path = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/table1/camera.json"
        ));
        let mut v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        v["optics"]["blur"] = blur;
        let raw: CameraFile = serde_json::from_value(v).map_err(|e| CliError::input(path, e))?;
        camera_from_file(path, raw)
    }

    #[test]
    fn wavefront_keys_select_the_general_pupil_and_name_bad_values() {
        let c = camera(serde_json::json!({"kind": "wavefront", "defocus_um": 0.1})).unwrap();
        assert!(
            matches!(c.optics.blur, Blur::Wavefront { defocus_um, pupil_samples: 64 } if defocus_um == 0.1)
        );
        let c = camera(serde_json::json!({
            "kind": "wavefront", "defocus_um": 0.1, "zernike_um": {"8": 0.05, "12": -0.02},
            "zernike_pupil_diameter_mm": 3.0, "blades": 6,
            "chromatic_defocus": {"model": "human", "reference_nm": 555.0}
        }))
        .unwrap();
        let Blur::Pupil(p) = &c.optics.blur else {
            panic!("general pupil expected")
        };
        let mut js: Vec<(usize, f64)> = p.zernike.iter().map(|t| (t.j, t.rms_um)).collect();
        js.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(js, vec![(4, 0.1), (8, 0.05), (12, -0.02)]);
        assert_eq!(p.zernike_pupil_diameter_m, Some(3e-3));
        assert_eq!(p.blades, Some(6));
        assert_eq!(
            p.chromatic_defocus,
            camsim_optics::ChromaticDefocus::HumanEye {
                reference_nm: 555.0
            }
        );
        // A bare polygonal aperture (no aberration) is valid.
        let c = camera(serde_json::json!({"kind": "wavefront", "blades": 5})).unwrap();
        assert!(matches!(&c.optics.blur, Blur::Pupil(p) if p.zernike.is_empty()));
        for (blur, key) in [
            (
                serde_json::json!({"kind": "wavefront", "zernike_um": {"x": 0.1}}),
                "optics.blur.zernike_um",
            ),
            (
                serde_json::json!({"kind": "wavefront", "zernike_um": {"99": 0.1}}),
                "optics.blur.zernike_um",
            ),
            (
                serde_json::json!({"kind": "wavefront", "zernike_um": {"7": 0.1}, "blades": 2}),
                "optics.blur.blades",
            ),
            (
                serde_json::json!({"kind": "wavefront", "defocus_um": 0.1, "pupil_samples": 8}),
                "optics.blur.pupil_samples",
            ),
            (
                serde_json::json!({"kind": "wavefront", "zernike_um": {"7": 0.1}, "zernike_pupil_diameter_mm": -1.0}),
                "optics.blur.zernike_pupil_diameter_mm",
            ),
            (
                serde_json::json!({"kind": "wavefront", "chromatic_defocus": {"model": "human"}}),
                "optics.blur.chromatic_defocus",
            ),
            (
                serde_json::json!({"kind": "wavefront", "chromatic_defocus": {"wavelength_nm": [500, 400], "defocus_um": [0, 1]}}),
                "optics.blur.chromatic_defocus.wavelength_nm",
            ),
            (
                serde_json::json!({"kind": "gaussian", "sigma_um": 1.0, "blades": 5}),
                "optics.blur.blades",
            ),
            (
                serde_json::json!({"kind": "wavefront"}),
                "optics.blur.defocus_um",
            ),
        ] {
            let e = camera(blur.clone()).map(|_| ()).unwrap_err().one_line();
            assert!(e.contains(key), "{blur}: {e}");
        }
    }
}
