//! # camsim-sensor
//!
//! The sensor stage of camsim: [`SensorIrradiance`] → [`RawFrame`], implementing the baseline
//! forward model of `spec/capture-format.md` ("The baseline forward model", steps 2–7):
//!
//! 2. mean photo-electrons `e_i = t · p² · FF · ∫ QE_c(λ) Ē(λ) dλ` ([`electron_rate`]);
//! 3. dark electrons `d = t · dark_voltage / conversion_gain`;
//! 4. `n_i ~ Poisson(e_i (1 + P_i) + d)`, `P_i ~ N(0, prnu²)` fixed per pixel, clipped at the
//!    well capacity;
//! 5. `v_i = n_i g + D_i + r`, `D_i ~ N(0, dsnu²)` fixed per pixel, `r ~ N(0, read²)` per frame;
//! 6. `u_i = analog_gain · v_i + analog_offset`, clipped above at the voltage swing;
//! 7. `DN = clamp(round(u / swing · (2^bits − 1) + black_level), 0, 2^bits − 1)`.
//!
//! [`expected_dn`] is the same chain with every random term at its mean and no rounding;
//! [`expose`] draws a frame; [`fixed_pattern`] draws the per-camera PRNU/DSNU/column maps
//! and hot pixels. The optional effect blocks of `spec/effects.md` (hot pixels,
//! nonlinearity, crosstalk, IR leakage, QE shift) live in [`effects`] and
//! [`SensorModel::effects`]; absent, they cost nothing.
//! The [`dual_pixel`] module holds the dual-pixel readout (two half-photodiodes under one
//! microlens, the left and right halves of the exit pupil).
//! The [`hdr`] module holds HDR pixels (split pixel, dual conversion gain, exposure
//! bracketing): several charge packets and readouts per pixel ([`expose_hdr`]).
//! The [`isetcam`] module holds documented ISETCam-compatible variants (bilinear pixel
//! sampling, Riemann spectral sums, ISETCam auto-exposure, SNR components) used only for
//! oracle tests; they are never the default.
//!
//! Units live in names: `_m`, `_s`, `_v`, `_e` (electrons), `_dn`.
#![deny(missing_docs)]

pub mod dual_pixel;
pub mod effects;
pub mod hdr;
mod integrate;
pub mod isetcam;
pub mod line_noise;
mod noise;
pub mod normal;
pub mod pixel_optics;
pub mod pixel_rng;
pub mod poisson;
pub mod temporal;
pub mod temporal_nodes;

use camsim_core::Spectrum;
use thiserror::Error;

pub use camsim_core::{RawFrame, SensorIrradiance};
pub use dual_pixel::{
    expected_dual_pixel_dn, expose_dual_pixel, DualPixel, DualPixelExpected, DualPixelFrame,
    DualPixelRates,
};
pub use effects::{
    apply_crosstalk, channel_basis_integrals, channel_term_integrals, hot_pixel_count,
    hot_pixel_map, Crosstalk, HotPixel, HotPixels, IrLeakage, Nonlinearity, QeShift, SensorEffects,
};
pub use hdr::{
    expose_hdr, ChargePacket, HdrFrame, HdrModel, HdrReadout, HdrReadoutModel, USABLE_FRACTION,
};
pub use integrate::{
    box_weights, channel_planes, channel_weights, electron_rate, electron_rate_from_channel_planes,
    electron_rate_from_term_planes, pixel_term_planes, ChannelPlanes, ChannelWeights,
    PixelTermPlanes,
};
pub use line_noise::{
    dark_voltage_at, row_offsets_v, rtn_offsets_v, rtn_pixel_count, rtn_pixel_map, rtn_state,
    BlackLevelDrift, DarkTemperature, RowNoise, Rtn, RtnPixel,
};
pub use noise::{
    auto_exposure_s, expected_dn, expected_volts, expose, expose_frame, expose_with, fixed_pattern,
    nonlinearity_magnitude, PatternSource, FIXED_PATTERN_TAG,
};
pub use temporal::{
    dark_at_temperature, flicker_period_rows, time_averaged_rate, time_averaged_rate_from, Motion,
    PwmLight, Readout, ShutterMode, TimeModel,
};
pub use temporal_nodes::{
    frame_span_s, row_node_weights, NodeIntegrator, RowNodeWeights, TimeNodes,
};

/// Errors of the sensor stage.
#[derive(Debug, Error, PartialEq)]
pub enum SensorError {
    /// A sensor parameter is out of range; names the field and the offending value.
    #[error("sensor.{field} = {value}: {reason}")]
    InvalidField {
        /// The field (as in camera.json, e.g. `fill_factor`, `cfa[1][0]`).
        field: String,
        /// The bad value, formatted.
        value: String,
        /// What is required of it.
        reason: String,
    },
    /// The requested computation is outside what a compatibility path implements.
    #[error("unsupported: {0}")]
    Unsupported(String),
}

/// The repeating colour-filter tile.
#[derive(Debug, Clone, PartialEq)]
pub struct Cfa {
    /// Channel index per tile position, row-major (`tile[r][c]`).
    pub tile: Vec<Vec<usize>>,
}

impl Cfa {
    /// A monochrome tile (one channel, index 0).
    pub fn mono() -> Self {
        Cfa {
            tile: vec![vec![0]],
        }
    }
    /// Tile rows.
    pub fn tile_rows(&self) -> usize {
        self.tile.len()
    }
    /// Tile columns.
    pub fn tile_cols(&self) -> usize {
        self.tile.first().map_or(0, |r| r.len())
    }
    /// Channel index of sensor pixel (row, col).
    #[inline]
    pub fn channel_at(&self, row: usize, col: usize) -> usize {
        let t = &self.tile[row % self.tile.len()];
        t[col % t.len()]
    }
}

/// Which random terms are drawn. A term that is off is replaced by its mean (shot: the
/// photo-electron count is `e(1+P)` instead of a Poisson draw; dark: the dark count is `d`
/// instead of a Poisson draw; read, DSNU, PRNU: zero).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoiseSwitches {
    /// Poisson noise of the photo-electrons (step 4).
    pub shot: bool,
    /// Poisson noise of the dark electrons (step 4).
    pub dark: bool,
    /// Read noise `r` (step 5).
    pub read: bool,
    /// Fixed per-pixel offset `D_i` (step 5).
    pub dsnu: bool,
    /// Fixed per-pixel gain `P_i` (step 4).
    pub prnu: bool,
}

impl Default for NoiseSwitches {
    fn default() -> Self {
        NoiseSwitches {
            shot: true,
            dark: true,
            read: true,
            dsnu: true,
            prnu: true,
        }
    }
}

impl NoiseSwitches {
    /// Every random term off (frames equal the rounded expected image plus fixed patterns of
    /// optional effects).
    pub fn none() -> Self {
        NoiseSwitches {
            shot: false,
            dark: false,
            read: false,
            dsnu: false,
            prnu: false,
        }
    }
}

/// Column fixed-pattern noise: one fixed offset per column, added in volts at step 5.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColumnFpn {
    /// Standard deviation of the per-column offset (V).
    pub offset_sigma_v: f64,
}

/// Reset (kTC) noise: a new N(0, sigma²) per pixel and frame, in volts at step 5.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResetNoise {
    /// Standard deviation of the reset level (V).
    pub sigma_v: f64,
    /// Correlated double sampling: the reset level is subtracted and the noise cancels.
    pub cds: bool,
}

/// The sensor parameters of camera.json (pitch in metres here).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorModel {
    /// Pixel rows.
    pub rows: usize,
    /// Pixel columns.
    pub cols: usize,
    /// Pixel pitch p (m); pixels are p × p squares centred on the optical axis as a grid.
    pub pixel_pitch_m: f64,
    /// Fill factor FF in (0, 1]: scales the signal only (step 2).
    pub fill_factor: f64,
    /// Colour-filter tile.
    pub cfa: Cfa,
    /// Channel names (index = channel index of the tile).
    pub channel_names: Vec<String>,
    /// Combined spectral QE per channel, electrons per photon.
    pub channel_qe: Vec<Spectrum>,
    /// Full-well capacity (electrons), step 4.
    pub well_capacity_e: f64,
    /// Conversion gain g (V per electron), steps 3 and 5.
    pub conversion_gain_v_per_e: f64,
    /// Voltage swing (V), steps 6–7.
    pub voltage_swing_v: f64,
    /// Camera's analog gain (a [`Shot`] may override it), step 6.
    pub analog_gain: f64,
    /// Analog offset (V), step 6.
    pub analog_offset_v: f64,
    /// ADC bit depth, step 7.
    pub adc_bits: u32,
    /// Black level (DN, may be fractional), step 7.
    pub black_level_dn: f64,
    /// Dark voltage rate (V/s), step 3.
    pub dark_voltage_v_per_s: f64,
    /// Read noise standard deviation (V), step 5.
    pub read_noise_v: f64,
    /// DSNU standard deviation (V), step 5.
    pub dsnu_sigma_v: f64,
    /// PRNU standard deviation (percent of the signal), step 4.
    pub prnu_sigma_percent: f64,
    /// Which random terms are drawn.
    pub noise: NoiseSwitches,
    /// Optional column fixed-pattern offsets (effect block).
    pub column_fpn: Option<ColumnFpn>,
    /// Optional reset (kTC) noise (effect block).
    pub reset_noise: Option<ResetNoise>,
    /// Optional effect blocks of effects.md (hot pixels, nonlinearity, crosstalk, IR leakage,
    /// QE shift); `SensorEffects::default()` = none.
    pub effects: SensorEffects,
}

/// One shot's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shot {
    /// Exposure (integration) time t (s).
    pub exposure_s: f64,
    /// Analog gain used for this shot (the camera's unless the shot overrides it).
    pub analog_gain: f64,
}

impl Shot {
    /// A shot with the sensor's own analog gain.
    pub fn new(sensor: &SensorModel, exposure_s: f64) -> Self {
        Shot {
            exposure_s,
            analog_gain: sensor.analog_gain,
        }
    }
}

/// Mean photo-electron rate per pixel: `p² · FF · ∫ QE_c(λ) Ē(λ) dλ` (electrons/s) for the
/// pixel's own channel c (step 2 without the exposure time).
#[derive(Debug, Clone, PartialEq)]
pub struct ElectronRate {
    /// Rows (the sensor's).
    pub rows: usize,
    /// Columns (the sensor's).
    pub cols: usize,
    /// Row-major electrons per second.
    pub electrons_per_s: Vec<f32>,
}

/// Fixed per-pixel patterns of one camera (same for all its frames and shots).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedPattern {
    /// `1 + P_i` per pixel (step 4), row-major.
    pub prnu_gain: Vec<f32>,
    /// `D_i` per pixel (V, step 5), row-major.
    pub dsnu_v: Vec<f32>,
    /// Per-column offset (V, step 5), `cols` values (zeros without column FPN).
    pub column_offset_v: Vec<f32>,
    /// Hot pixels (effect block), sorted by (row, col); empty without the block.
    pub hot_pixels: Vec<HotPixel>,
}

fn bad(field: impl Into<String>, value: impl std::fmt::Display, reason: &str) -> SensorError {
    SensorError::InvalidField {
        field: field.into(),
        value: value.to_string(),
        reason: reason.to_string(),
    }
}

impl SensorModel {
    /// A monochrome test sensor, every noise term on: 2 µm pixels, fill factor 1, a flat QE of
    /// 1, a 10 000 e⁻ well, 100 µV/e⁻, a 1 V swing, unity analog gain, a 12-bit ADC with a black
    /// level of 64 DN, 1 mV/s dark voltage, 1 mV read noise, 1 mV DSNU and 1 % PRNU. The one
    /// fixture of the workspace's tests (its fields are public: a test overrides what it needs).
    pub fn mono_test(rows: usize, cols: usize) -> SensorModel {
        SensorModel {
            rows,
            cols,
            pixel_pitch_m: 2e-6,
            fill_factor: 1.0,
            cfa: Cfa::mono(),
            channel_names: vec!["m".into()],
            channel_qe: vec![Spectrum::constant(1.0)],
            well_capacity_e: 10000.0,
            conversion_gain_v_per_e: 1e-4,
            voltage_swing_v: 1.0,
            analog_gain: 1.0,
            analog_offset_v: 0.0,
            adc_bits: 12,
            black_level_dn: 64.0,
            dark_voltage_v_per_s: 1e-3,
            read_noise_v: 1e-3,
            dsnu_sigma_v: 1e-3,
            prnu_sigma_percent: 1.0,
            noise: NoiseSwitches::default(),
            column_fpn: None,
            reset_noise: None,
            effects: SensorEffects::default(),
        }
    }
}

impl SensorModel {
    /// Largest DN, `2^bits − 1` (step 7).
    pub fn max_dn(&self) -> f64 {
        ((1u64 << self.adc_bits) - 1) as f64
    }

    /// The layout of this sensor's raw frames: CFA tile, channel names, black level and
    /// `2^bits − 1` as white.
    pub fn raw_layout(&self) -> camsim_core::RawLayout {
        camsim_core::RawLayout {
            cfa_tile: self.cfa.tile.clone(),
            channel_names: self.channel_names.clone(),
            black_dn: self.black_level_dn,
            white_dn: self.max_dn(),
        }
    }

    /// DN per volt of output voltage u: `(2^bits − 1) / swing` (step 7).
    pub fn dn_per_output_v(&self) -> f64 {
        self.max_dn() / self.voltage_swing_v
    }

    /// Conversion gain in DN per electron at analog gain `analog_gain`:
    /// `analog_gain · g / swing · (2^bits − 1)` (steps 5–7).
    pub fn dn_per_e(&self, analog_gain: f64) -> f64 {
        analog_gain * self.conversion_gain_v_per_e * self.dn_per_output_v()
    }

    /// Checks every field; the error names the first bad field and its value.
    pub fn validate(&self) -> Result<(), SensorError> {
        let pos = |name: &str, v: f64| -> Result<(), SensorError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(name, v, "must be a positive finite number"))
            }
        };
        let nonneg = |name: &str, v: f64| -> Result<(), SensorError> {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(bad(name, v, "must be a finite number ≥ 0"))
            }
        };
        if self.rows == 0 {
            return Err(bad("rows", self.rows, "must be ≥ 1"));
        }
        if self.cols == 0 {
            return Err(bad("cols", self.cols, "must be ≥ 1"));
        }
        pos("pixel_pitch_m", self.pixel_pitch_m)?;
        if !(self.fill_factor > 0.0 && self.fill_factor <= 1.0) {
            return Err(bad("fill_factor", self.fill_factor, "must be in (0, 1]"));
        }
        if self.channel_qe.is_empty() {
            return Err(bad("channels", "{}", "at least one channel is required"));
        }
        if self.channel_names.len() != self.channel_qe.len() {
            return Err(bad(
                "channel_names",
                format!("{} names", self.channel_names.len()),
                &format!(
                    "must name each of the {} channel QE spectra",
                    self.channel_qe.len()
                ),
            ));
        }
        for (name, qe) in self.channel_names.iter().zip(&self.channel_qe) {
            if let Err(e) = qe.clone().validated() {
                return Err(bad(format!("channels.{name}"), "spectrum", &e.to_string()));
            }
            if let Some((w, v)) = qe.first_negative() {
                return Err(bad(
                    format!("channels.{name}"),
                    format!("{v} at {w} nm"),
                    "quantum efficiency must be ≥ 0",
                ));
            }
        }
        let tr = self.cfa.tile_rows();
        let tc = self.cfa.tile_cols();
        if tr == 0 || tc == 0 {
            return Err(bad(
                "cfa",
                "[]",
                "the tile must have at least one row and column",
            ));
        }
        for (r, row) in self.cfa.tile.iter().enumerate() {
            if row.len() != tc {
                return Err(bad(
                    format!("cfa[{r}]"),
                    format!("{} entries", row.len()),
                    &format!("every tile row must have {tc} entries like row 0"),
                ));
            }
            for (c, &ch) in row.iter().enumerate() {
                if ch >= self.channel_qe.len() {
                    return Err(bad(
                        format!("cfa[{r}][{c}]"),
                        ch,
                        &format!("channel index must be < {}", self.channel_qe.len()),
                    ));
                }
            }
        }
        pos("well_capacity_e", self.well_capacity_e)?;
        pos("conversion_gain_v_per_e", self.conversion_gain_v_per_e)?;
        pos("voltage_swing_v", self.voltage_swing_v)?;
        pos("analog_gain", self.analog_gain)?;
        if !self.analog_offset_v.is_finite() {
            return Err(bad(
                "analog_offset_v",
                self.analog_offset_v,
                "must be finite",
            ));
        }
        if !(1..=16).contains(&self.adc_bits) {
            return Err(bad("adc_bits", self.adc_bits, "must be between 1 and 16"));
        }
        if !self.black_level_dn.is_finite() {
            return Err(bad("black_level_dn", self.black_level_dn, "must be finite"));
        }
        nonneg("dark_voltage_v_per_s", self.dark_voltage_v_per_s)?;
        nonneg("read_noise_v", self.read_noise_v)?;
        nonneg("dsnu_sigma_v", self.dsnu_sigma_v)?;
        nonneg("prnu_sigma_percent", self.prnu_sigma_percent)?;
        if let Some(c) = &self.column_fpn {
            nonneg("column_fpn.offset_sigma_v", c.offset_sigma_v)?;
        }
        if let Some(r) = &self.reset_noise {
            nonneg("reset_noise.sigma_v", r.sigma_v)?;
        }
        effects::validate(self)?;
        line_noise::validate(self)
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    use super::*;

    /// [`SensorModel::mono_test`].
    pub fn mono(rows: usize, cols: usize) -> SensorModel {
        SensorModel::mono_test(rows, cols)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validate_names_field_and_value() {
        let s = test_util::mono(4, 4);
        assert!(s.validate().is_ok());
        let mut b = s.clone();
        b.fill_factor = 1.5;
        let e = b.validate().unwrap_err().to_string();
        assert!(e.contains("fill_factor") && e.contains("1.5"), "{e}");
        let mut b = s.clone();
        b.cfa = Cfa {
            tile: vec![vec![0, 1]],
        };
        let e = b.validate().unwrap_err().to_string();
        assert!(e.contains("cfa[0][1]") && e.contains('1'), "{e}");
        let mut b = s.clone();
        b.adc_bits = 17;
        assert!(b
            .validate()
            .unwrap_err()
            .to_string()
            .contains("adc_bits = 17"));
        let mut b = s.clone();
        b.read_noise_v = -1.0;
        assert!(b
            .validate()
            .unwrap_err()
            .to_string()
            .contains("read_noise_v = -1"));
        let mut b = s;
        b.channel_qe = vec![Spectrum::sampled(vec![400.0, 500.0], vec![0.1, -0.2]).unwrap()];
        assert!(b.validate().unwrap_err().to_string().contains("channels.m"));
    }

    #[test]
    fn cfa_lookup_is_row_major() {
        let c = Cfa {
            tile: vec![vec![1, 0], vec![2, 1]],
        };
        assert_eq!(c.channel_at(0, 0), 1);
        assert_eq!(c.channel_at(0, 1), 0);
        assert_eq!(c.channel_at(1, 0), 2);
        assert_eq!(c.channel_at(3, 3), 1);
    }
}
