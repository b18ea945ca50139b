//! # camsim-diagnose
//!
//! Camera calibration from already-loaded capture sets: the estimators of Appendix A
//! (dark voltage, read noise, DSNU, PRNU) and Appendix B (channel spectral efficiency) of
//! Farrell, Catrysse & Wandell, "Digital camera simulation", Applied Optics 51(4) 2012,
//! and EMVA 1288-style photon transfer (conversion gain, saturation, linearity).
//!
//! Input: [`CalibrationShot`]s (dark, uniform flat, narrowband flat; each with its frames)
//! and the camera as believed ([`SensorModel`]: CFA, ADC bits, voltage swing, pitch, and the
//! fall-back values of parameters that cannot be estimated). Output: a
//! [`CalibrationResult`] in which every quantity is an [`Outcome`]: an [`Estimate`] with its
//! standard error, unit, method and the number of data used, or `NotEstimable` with the
//! reason. One missing input never stops the other estimators.
//!
//! Conventions (the forward model of `spec/capture-format.md`, steps 3–7):
//! * DN per pixel volt at analog gain G: `k = G · (2^bits − 1) / swing`;
//! * pedestal `P = black_level_dn + analog_offset_v · (2^bits − 1) / swing` (DN at zero
//!   signal, independent of G);
//! * mean dark DN `= P + k · dark_voltage · t`; temporal variance (DN²)
//!   `= k² (read² + g² n_e) + 1/12` (quantisation), `n_e` the photo- plus dark electrons;
//! * "unit-gain DN" divides DN above the pedestal by G (and variances by G²), so shots at
//!   different analog gains share one photon-transfer line.
#![deny(missing_docs)]

mod dark;
pub mod emva1288;
pub mod fit;
pub mod mismatch;
pub mod noise_profiles;
mod prnu;
mod ptc;
mod spectral;
mod stack;

use camsim_core::{Spectrum, WavelengthGrid};
use camsim_sensor::SensorModel;
use serde::Serialize;
use stack::{ChannelMap, Stack};

pub use camsim_core::RawFrame;
pub use prnu::PrnuChannel;
pub use ptc::PtcPoint;
pub use spectral::{
    fit_spectral_efficiency, regularisation_weights, ObservationFit, SpectralFit,
    SpectralObservation,
};
pub use spectral::{ChannelQe, SpectralQe};

/// What a calibration shot looked at.
#[derive(Debug, Clone, PartialEq)]
pub enum ShotKind {
    /// No light reaches the sensor.
    Dark,
    /// A uniform field of this spectral radiance (photons / (s · sr · m² · nm)).
    Flat {
        /// Spectral radiance.
        radiance: Spectrum,
    },
    /// A uniform narrowband field of known spectral radiance (photons / (s · sr · m² · nm)),
    /// for the spectral-efficiency estimate (Appendix B).
    Narrowband {
        /// Spectral radiance.
        radiance: Spectrum,
    },
}

/// One shot of a capture set: every frame has the same exposure and gain.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationShot {
    /// Shot id (for reasons and reports).
    pub id: String,
    /// Target.
    pub kind: ShotKind,
    /// Exposure time (s).
    pub exposure_s: f64,
    /// Analog gain used.
    pub analog_gain: f64,
    /// The frames (raw mosaics in DN).
    pub frames: Vec<RawFrame>,
}

/// An estimated scalar.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Estimate {
    /// The estimate.
    pub value: f64,
    /// Its standard error (1 σ), in the same unit.
    pub std_error: f64,
    /// Unit (e.g. "V/s", "DN", "%").
    pub unit: String,
    /// How it was obtained.
    pub method: String,
    /// Number of data used (shots, points or pixels; the method says which).
    pub n_used: usize,
}

/// An estimate or the reason it could not be made.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Outcome<T> {
    /// Estimated.
    Estimated(T),
    /// Not estimable from this capture set.
    NotEstimable {
        /// Why, naming what the set lacks.
        reason: String,
    },
}

impl<T> Outcome<T> {
    /// The estimate, if any.
    pub fn get(&self) -> Option<&T> {
        match self {
            Outcome::Estimated(t) => Some(t),
            Outcome::NotEstimable { .. } => None,
        }
    }
    /// The reason it is not estimable, if so.
    pub fn reason(&self) -> Option<&str> {
        match self {
            Outcome::Estimated(_) => None,
            Outcome::NotEstimable { reason } => Some(reason),
        }
    }
    pub(crate) fn not(reason: impl Into<String>) -> Self {
        Outcome::NotEstimable {
            reason: reason.into(),
        }
    }
}

impl Estimate {
    /// The reported 99 % interval, value ± 2.576 standard errors (what `calibration.json`
    /// states as `interval_99`; the coverage tests check it holds the truth in ≥ 95 % of
    /// trials).
    pub fn interval_99(&self) -> [f64; 2] {
        let h = 2.5758 * self.std_error;
        [self.value - h, self.value + h]
    }
}

impl Outcome<Estimate> {
    /// The estimated value, if any.
    pub fn value(&self) -> Option<f64> {
        self.get().map(|e| e.value)
    }
}

/// Hot pixels: dark-current outliers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HotPixels {
    /// What was tested: "dark current (V/s)" or "dark level (V)" with a single exposure.
    pub quantity: String,
    /// Robust centre (median) of the quantity.
    pub median: f64,
    /// Robust spread (1.4826 · MAD).
    pub robust_sigma: f64,
    /// Threshold: median + k · robust sigma.
    pub threshold: f64,
    /// Pixels above the threshold: (row, col, value).
    pub pixels: Vec<(usize, usize, f64)>,
}

/// A shot left out of every estimator, with the reason.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RejectedShot {
    /// Shot id.
    pub id: String,
    /// Why.
    pub reason: String,
}

/// Tuning of the estimators.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationOptions {
    /// Sensor irradiance per unit scene radiance on the axis, π·T/(4N²) of the camera
    /// equation (the optics' factor; the spectral estimate divides it out). 1 means the
    /// shots' "radiance" already is sensor irradiance, photons/(s·m²·nm).
    pub irradiance_per_radiance: f64,
    /// Largest fraction of pixel-frames at 0 DN or at the ADC maximum (per channel) for a
    /// shot to be used by the mean/variance estimators.
    pub max_clipped_fraction: f64,
    /// Total degree of the 2-D polynomial removed from the PRNU slope maps per channel
    /// (illumination fall-off, e.g. cos⁴); 0 = divide by the channel mean only.
    pub shading_degree: usize,
    /// Hot-pixel threshold in robust standard deviations above the median.
    pub hot_pixel_sigmas: f64,
    /// Grid of the estimated QE curves.
    pub spectral_grid: WavelengthGrid,
    /// Side fraction of the central region used for the spectral estimate (where the
    /// illumination fall-off is negligible).
    pub spectral_roi_fraction: f64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        CalibrationOptions {
            irradiance_per_radiance: 1.0,
            max_clipped_fraction: 1e-3,
            shading_degree: 4,
            hot_pixel_sigmas: 6.0,
            spectral_grid: WavelengthGrid::default_visible(),
            spectral_roi_fraction: 0.5,
        }
    }
}

/// Everything the calibration found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationResult {
    /// Pedestal at zero signal (DN): `black_level_dn + analog offset` in DN.
    pub black_level_dn: Outcome<Estimate>,
    /// Dark voltage (V/s).
    pub dark_voltage_v_per_s: Outcome<Estimate>,
    /// Read noise (V, pixel volts before analog gain).
    pub read_noise_v: Outcome<Estimate>,
    /// DSNU standard deviation (V).
    pub dsnu_sigma_v: Outcome<Estimate>,
    /// PRNU standard deviation (% of the signal), shot-noise corrected.
    pub prnu_sigma_percent: Outcome<Estimate>,
    /// PRNU per channel (corrected and naive).
    pub prnu_channels: Vec<PrnuChannel>,
    /// Hot pixels.
    pub hot_pixels: Outcome<HotPixels>,
    /// Conversion gain (V per electron) from photon transfer.
    pub conversion_gain_v_per_e: Outcome<Estimate>,
    /// Full-well capacity (electrons) from the photon-transfer plateau.
    pub full_well_e: Outcome<Estimate>,
    /// EMVA saturation point: mean DN (at the camera's analog gain) of the photon-transfer
    /// point of largest temporal variance.
    pub saturation_dn: Outcome<Estimate>,
    /// EMVA linearity error (%): half the spread of relative deviations from a line of mean
    /// signal vs exposure, 5–95 % of the range.
    pub linearity_error_percent: Outcome<Estimate>,
    /// Photon-transfer points (per shot and channel).
    pub ptc: Vec<PtcPoint>,
    /// Channel spectral QE (Appendix B).
    pub channel_qe: Outcome<SpectralQe>,
    /// Shots left out entirely.
    pub rejected_shots: Vec<RejectedShot>,
}

/// Shared state of one calibration run.
pub(crate) struct Ctx<'a> {
    pub sensor: &'a SensorModel,
    pub opts: &'a CalibrationOptions,
    pub map: ChannelMap,
    pub shots: Vec<&'a CalibrationShot>,
    pub stacks: Vec<Stack>,
    /// Pixels excluded everywhere (hot pixels).
    pub excluded: Vec<bool>,
}

impl Ctx<'_> {
    /// DN per pixel volt for a shot: G · (2^bits − 1) / swing.
    pub fn k(&self, shot: &CalibrationShot) -> f64 {
        shot.analog_gain * self.sensor.dn_per_output_v()
    }
    /// The believed pedestal (DN).
    pub fn believed_pedestal(&self) -> f64 {
        self.sensor.black_level_dn + self.sensor.analog_offset_v * self.sensor.dn_per_output_v()
    }
    pub fn n_pix(&self) -> usize {
        self.map.rows * self.map.cols
    }
}

fn check_shot(s: &CalibrationShot, sensor: &SensorModel) -> Result<(), String> {
    if s.frames.is_empty() {
        return Err("has no frames".into());
    }
    if !(s.exposure_s.is_finite() && s.exposure_s >= 0.0) {
        return Err(format!("exposure_s = {} is not ≥ 0", s.exposure_s));
    }
    if !(s.analog_gain.is_finite() && s.analog_gain > 0.0) {
        return Err(format!("analog_gain = {} is not > 0", s.analog_gain));
    }
    for (j, f) in s.frames.iter().enumerate() {
        if f.rows != sensor.rows || f.cols != sensor.cols || f.dn.len() != f.rows * f.cols {
            return Err(format!(
                "frame {j} is {}×{} ({} values) but the sensor is {}×{}",
                f.rows,
                f.cols,
                f.dn.len(),
                sensor.rows,
                sensor.cols
            ));
        }
        if f.adc_bits != sensor.adc_bits {
            return Err(format!(
                "frame {j} has {} ADC bits but the sensor has {}",
                f.adc_bits, sensor.adc_bits
            ));
        }
    }
    Ok(())
}

/// Runs every estimator on the capture set.
pub fn calibrate(
    believed: &SensorModel,
    shots: &[CalibrationShot],
    opts: &CalibrationOptions,
) -> CalibrationResult {
    let map = ChannelMap::new(believed);
    let mut rejected = Vec::new();
    let mut ok = Vec::new();
    for s in shots {
        match check_shot(s, believed) {
            Ok(()) => ok.push(s),
            Err(reason) => rejected.push(RejectedShot {
                id: s.id.clone(),
                reason,
            }),
        }
    }
    let max_dn = believed.max_dn() as u16;
    let stacks: Vec<Stack> = ok
        .iter()
        .map(|s| stack::stack(&s.frames, &map, max_dn))
        .collect();
    let mut ctx = Ctx {
        sensor: believed,
        opts,
        excluded: vec![false; map.rows * map.cols],
        map,
        shots: ok,
        stacks,
    };
    // Order matters: hot pixels are excluded from everything else; the pedestal and dark
    // voltage feed photon transfer; the conversion gain feeds read noise and the spectral fit.
    let hot = dark::hot_pixels(&mut ctx);
    let dark_fit = dark::dark_signal(&ctx);
    let pedestal = dark_fit
        .black
        .value()
        .unwrap_or_else(|| ctx.believed_pedestal());
    let ptc = ptc::photon_transfer(&ctx, pedestal);
    let g = ptc
        .conversion_gain
        .get()
        .map(|e| (e.value, e.std_error))
        .unwrap_or((believed.conversion_gain_v_per_e, 0.0));
    let vd = dark_fit
        .dark_voltage
        .get()
        .map(|e| (e.value, e.std_error))
        .unwrap_or((believed.dark_voltage_v_per_s, 0.0));
    let read = dark::read_noise(&ctx, g, vd);
    let (dsnu, black) = dark::dsnu(&ctx, dark_fit.black);
    let prnu = prnu::prnu(&ctx, pedestal, vd.0, ptc.saturation_unit_dn);
    let qe = spectral::spectral_qe(&ctx, pedestal, g.0, vd.0);
    CalibrationResult {
        black_level_dn: black,
        dark_voltage_v_per_s: dark_fit.dark_voltage,
        read_noise_v: read,
        dsnu_sigma_v: dsnu,
        prnu_sigma_percent: prnu.0,
        prnu_channels: prnu.1,
        hot_pixels: hot,
        conversion_gain_v_per_e: ptc.conversion_gain,
        full_well_e: ptc.full_well,
        saturation_dn: ptc.saturation_dn,
        linearity_error_percent: ptc.linearity,
        ptc: ptc.points,
        channel_qe: qe,
        rejected_shots: rejected,
    }
}

/// The believed camera with every estimated parameter replaced by its estimate.
///
/// The black level is the estimated pedestal minus the believed analog offset (in DN);
/// channel QE curves become sampled spectra on the estimate's grid.
pub fn fitted_camera(believed: &SensorModel, result: &CalibrationResult) -> SensorModel {
    let mut s = believed.clone();
    if let Some(v) = result.black_level_dn.value() {
        s.black_level_dn = v - believed.analog_offset_v * believed.dn_per_output_v();
    }
    if let Some(v) = result.dark_voltage_v_per_s.value() {
        s.dark_voltage_v_per_s = v.max(0.0);
    }
    if let Some(v) = result.read_noise_v.value() {
        s.read_noise_v = v;
    }
    if let Some(v) = result.dsnu_sigma_v.value() {
        s.dsnu_sigma_v = v;
    }
    if let Some(v) = result.prnu_sigma_percent.value() {
        s.prnu_sigma_percent = v;
    }
    if let Some(v) = result.conversion_gain_v_per_e.value() {
        s.conversion_gain_v_per_e = v;
    }
    if let Some(v) = result.full_well_e.value() {
        s.well_capacity_e = v;
    }
    if let Some(q) = result.channel_qe.get() {
        for ch in &q.channels {
            if let Some(i) = s.channel_names.iter().position(|n| *n == ch.name) {
                if let Ok(sp) = Spectrum::sampled(
                    q.wavelength_nm.clone(),
                    ch.qe.iter().map(|v| v.max(0.0)).collect(),
                ) {
                    s.channel_qe[i] = sp;
                }
            }
        }
    }
    s
}
