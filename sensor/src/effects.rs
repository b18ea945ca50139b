//! Optional sensor effect blocks of `spec/effects.md` (the JSON contract is
//! docs/effects.md): hot pixels, nonlinearity, crosstalk, IR leakage and QE shift. Every block
//! is absent by default and then costs nothing.
//!
//! Where they act in the forward model (capture-format.md steps 2–7):
//! * [`QeShift`] and [`IrLeakage`] change the combined QE of step 2:
//!   `QE'_c(λ) = QE_c(λ − s_c) + IR_c(λ)` ([`channel_term_integrals`]);
//! * [`Crosstalk`] redistributes the mean photo-electrons after pixel integration, before the
//!   Poisson draw (dark charge is not shared) ([`apply_crosstalk`]);
//! * [`HotPixels`] add a fixed per-pixel dark rate at fixed positions drawn from the camera
//!   seed ([`hot_pixel_map`]); like PRNU/DSNU they are not part of the expected image;
//! * [`Nonlinearity`] maps the pixel voltage `v = n·g` of step 5 before DSNU, column offsets and
//!   read noise are added.
use crate::{ElectronRate, SensorError, SensorModel};
use camsim_core::rng::stream;
use camsim_core::{SpectralImage, Spectrum};
use rand::Rng;
use rayon::prelude::*;

/// The optional sensor effect blocks (all `None` = the baseline model).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorEffects {
    /// `hot_pixels`: isolated pixels with a much larger dark current.
    pub hot_pixels: Option<HotPixels>,
    /// `nonlinearity`: compressive response of the pixel voltage.
    pub nonlinearity: Option<Nonlinearity>,
    /// `crosstalk`: photo-charge shared with the 4 nearest neighbours.
    pub crosstalk: Option<Crosstalk>,
    /// `ir_leakage`: QE added beyond 700 nm per channel.
    pub ir_leakage: Option<IrLeakage>,
    /// `qe_shift`: per-channel wavelength shift of the QE curves.
    pub qe_shift: Option<QeShift>,
    /// `row_noise`: a temporal offset per row and frame ([`crate::line_noise`]).
    pub row_noise: Option<crate::line_noise::RowNoise>,
    /// `rtn`: random-telegraph-noise pixels ([`crate::line_noise`]).
    pub rtn: Option<crate::line_noise::Rtn>,
    /// `black_level_drift`: the pedestal drifting with the frame index ([`crate::line_noise`]).
    pub black_level_drift: Option<crate::line_noise::BlackLevelDrift>,
    /// `dark_temperature`: the dark current's doubling law, applied to shots with a
    /// temperature ([`crate::line_noise::dark_voltage_at`]).
    pub dark_temperature: Option<crate::line_noise::DarkTemperature>,
}

impl SensorEffects {
    /// No block present.
    pub fn is_empty(&self) -> bool {
        *self == SensorEffects::default()
    }
}

/// Hot pixels: `round(fraction · rows · cols)` pixels at fixed positions carry an extra dark
/// voltage rate. With `log_sigma = 0` (the fitted form) all have the rate
/// `dark_voltage_v_per_s`; otherwise (the generator form) the rate of each is lognormal,
/// `V · exp(log_sigma · z)`, z ~ N(0, 1) (median V).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotPixels {
    /// Fraction of the pixels that are hot (the effect's magnitude).
    pub fraction: f64,
    /// Extra dark voltage rate of a hot pixel (V/s), the median with a lognormal spread.
    pub dark_voltage_v_per_s: f64,
    /// σ of ln(rate) (0: every hot pixel has the same rate).
    pub log_sigma: f64,
}

/// One hot pixel of a camera's fixed pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HotPixel {
    /// Row.
    pub row: u32,
    /// Column.
    pub col: u32,
    /// Its extra dark voltage rate (V/s).
    pub dark_voltage_v_per_s: f32,
}

/// Pixel-voltage nonlinearity of step 5, applied to `v = n·g`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Nonlinearity {
    /// Fitted form: `v' = v − a·v²` for `v < 1/(2a)`, else its maximum `1/(4a)`.
    Quadratic {
        /// a (1/V), ≥ 0.
        coefficient_per_v: f64,
    },
    /// Generator form: `v' = S · tanh(v / S)`.
    Tanh {
        /// S (V), > 0.
        saturation_v: f64,
    },
}

impl Nonlinearity {
    /// The compressed voltage `v'` of a pixel voltage `v ≥ 0`.
    #[inline]
    pub fn apply(&self, v: f64) -> f64 {
        match *self {
            Nonlinearity::Quadratic {
                coefficient_per_v: a,
            } => {
                if a <= 0.0 {
                    v
                } else if v < 0.5 / a {
                    v - a * v * v
                } else {
                    0.25 / a
                }
            }
            Nonlinearity::Tanh { saturation_v: s } => s * (v / s).tanh(),
        }
    }
}

/// Photo-electron crosstalk: fractions of a pixel's mean photo-signal collected by each of its
/// four nearest neighbours (left = column − 1, right = column + 1, up = row − 1, down =
/// row + 1). The pixel keeps `1 − total`; charge sent off the array is lost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crosstalk {
    /// Fraction sent to the left neighbour.
    pub left: f64,
    /// Fraction sent to the right neighbour.
    pub right: f64,
    /// Fraction sent to the neighbour above.
    pub up: f64,
    /// Fraction sent to the neighbour below.
    pub down: f64,
}

impl Crosstalk {
    /// The fitted form: `f/4` to each neighbour.
    pub fn symmetric(fraction: f64) -> Self {
        let q = fraction / 4.0;
        Crosstalk {
            left: q,
            right: q,
            up: q,
            down: q,
        }
    }
    /// Total fraction collected by the 4 neighbours (the effect's magnitude).
    pub fn total(&self) -> f64 {
        self.left + self.right + self.up + self.down
    }
}

/// IR leakage: extra combined QE per channel (indexed like `SensorModel::channel_qe`; `None`
/// = nothing added). The fitted form is a constant on [700, 1000] nm with 1 nm linear ramps
/// outside ([`IrLeakage::band`]); the generator form any spectrum.
#[derive(Debug, Clone, PartialEq)]
pub struct IrLeakage {
    /// Added QE spectrum per channel index.
    pub channels: Vec<Option<Spectrum>>,
}

/// Lower end (nm) of the IR-leakage band of effects.md.
pub const IR_BAND_LO_NM: f64 = 700.0;
/// Upper end (nm) of the IR-leakage band of effects.md.
pub const IR_BAND_HI_NM: f64 = 1000.0;

impl IrLeakage {
    /// The fitted form's spectrum: `value` on [700, 1000] nm, linear ramps to 0 at 699 and
    /// 1001 nm.
    pub fn band(value: f64) -> Spectrum {
        Spectrum::Sampled {
            wavelength_nm: vec![
                IR_BAND_LO_NM - 1.0,
                IR_BAND_LO_NM,
                IR_BAND_HI_NM,
                IR_BAND_HI_NM + 1.0,
            ],
            values: vec![0.0, value, value, 0.0],
        }
    }
    /// Mean added QE of channel `c` over 700–1000 nm (electrons/photon).
    pub fn band_mean(&self, c: usize) -> f64 {
        match self.channels.get(c) {
            Some(Some(s)) => band_mean(s),
            _ => 0.0,
        }
    }
    /// The magnitude of effects.md: largest over channels of the mean added QE over
    /// 700–1000 nm.
    pub fn magnitude(&self) -> f64 {
        (0..self.channels.len())
            .map(|c| self.band_mean(c))
            .fold(0.0, f64::max)
    }
}

/// Mean of a spectrum over [700, 1000] nm (exact for piecewise-linear spectra).
pub fn band_mean(s: &Spectrum) -> f64 {
    let window = Spectrum::Sampled {
        wavelength_nm: vec![IR_BAND_LO_NM, IR_BAND_HI_NM],
        values: vec![1.0, 1.0],
    };
    Spectrum::integrate_product(s, &window).unwrap_or(0.0) / (IR_BAND_HI_NM - IR_BAND_LO_NM)
}

/// QE shift: `QE'_c(λ) = QE_c(λ − s_c)` (positive = towards red), per channel index.
#[derive(Debug, Clone, PartialEq)]
pub struct QeShift {
    /// Shift per channel index (nm).
    pub shift_nm: Vec<f64>,
}

impl QeShift {
    /// The magnitude of effects.md: the shift of largest |s_c|, signed (0 without channels).
    pub fn magnitude(&self) -> f64 {
        self.shift_nm
            .iter()
            .copied()
            .fold(0.0, |m, s| if s.abs() > m.abs() { s } else { m })
    }
}

/// `s(λ − shift)`: a sampled spectrum moves its wavelengths; an affine one changes its offset.
pub fn shift_spectrum(s: &Spectrum, shift_nm: f64) -> Spectrum {
    match s {
        Spectrum::Affine {
            offset,
            slope_per_nm,
        } => Spectrum::Affine {
            offset: offset - slope_per_nm * shift_nm,
            slope_per_nm: *slope_per_nm,
        },
        Spectrum::Sampled {
            wavelength_nm,
            values,
        } => Spectrum::Sampled {
            wavelength_nm: wavelength_nm.iter().map(|w| w + shift_nm).collect(),
            values: values.clone(),
        },
    }
}

impl SensorModel {
    /// The spectra whose sum is the effective combined QE of channel `c` (step 2):
    /// `QE_c(λ − s_c)` and, with IR leakage, `IR_c(λ)`.
    pub fn effective_qe_parts(&self, c: usize) -> Vec<Spectrum> {
        let base = &self.channel_qe[c];
        let shift = self
            .effects
            .qe_shift
            .as_ref()
            .and_then(|q| q.shift_nm.get(c).copied())
            .unwrap_or(0.0);
        let mut parts = vec![if shift != 0.0 {
            shift_spectrum(base, shift)
        } else {
            base.clone()
        }];
        if let Some(Some(ir)) = self
            .effects
            .ir_leakage
            .as_ref()
            .and_then(|l| l.channels.get(c))
        {
            parts.push(ir.clone());
        }
        parts
    }

    /// Effective combined QE of channel `c` at one wavelength (QE shift and IR leakage
    /// included).
    pub fn effective_qe_at(&self, c: usize, wavelength_nm: f64) -> f64 {
        self.effective_qe_parts(c)
            .iter()
            .map(|s| s.eval(wavelength_nm))
            .sum()
    }

    /// Wavelength support (nm) of the effective QE of every channel used by the CFA: the
    /// range a simulation must cover (infinite ends for constant spectra).
    pub fn effective_qe_support_nm(&self) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for c in 0..self.channel_qe.len() {
            for p in self.effective_qe_parts(c) {
                let (a, b) = p.support_nm();
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        (lo, hi)
    }
}

/// `∫ QE'_c(λ) B_k(λ) dλ` of every basis term of `img` for the effective QE of channel `c`
/// (QE shift and IR leakage included; exact for piecewise-linear spectra).
pub fn channel_term_integrals(sensor: &SensorModel, img: &SpectralImage, c: usize) -> Vec<f64> {
    channel_basis_integrals(sensor, &img.basis, c)
}

/// [`channel_term_integrals`] of the terms of a basis (an image's, or a target's before it is
/// rendered: [`camsim_core::scene::target_basis`]).
pub fn channel_basis_integrals(
    sensor: &SensorModel,
    basis: &camsim_core::SpectralBasis,
    c: usize,
) -> Vec<f64> {
    if sensor.effects.qe_shift.is_none() && sensor.effects.ir_leakage.is_none() {
        return basis.term_integrals(&sensor.channel_qe[c]);
    }
    let mut sum = vec![0.0; basis.len()];
    for p in sensor.effective_qe_parts(c) {
        sum.iter_mut()
            .zip(basis.term_integrals(&p))
            .for_each(|(s, v)| *s += v);
    }
    sum
}

/// The crosstalk stencil at pixel (r, c): `keep` (= 1 − total) of its own signal plus the
/// shares its 4 neighbours pass to it; `at(row, col)` gives the signal before crosstalk.
#[inline]
pub fn crosstalk_at(
    ct: &Crosstalk,
    keep: f64,
    rows: usize,
    cols: usize,
    r: usize,
    c: usize,
    at: impl Fn(usize, usize) -> f64,
) -> f64 {
    let mut e = keep * at(r, c);
    if c + 1 < cols {
        e += ct.left * at(r, c + 1);
    }
    if c > 0 {
        e += ct.right * at(r, c - 1);
    }
    if r + 1 < rows {
        e += ct.up * at(r + 1, c);
    }
    if r > 0 {
        e += ct.down * at(r - 1, c);
    }
    e
}

/// Shares the mean photo-electron rate with the 4 nearest neighbours (in place): pixel i
/// keeps `(1 − total)·e_i` and receives `left·e` of its right neighbour, `right·e` of its left
/// neighbour, `up·e` of the pixel below and `down·e` of the pixel above. Charge crossing the
/// array's border is lost.
pub fn apply_crosstalk(ct: &Crosstalk, rate: &mut ElectronRate) {
    let (rows, cols) = (rate.rows, rate.cols);
    let src = std::mem::take(&mut rate.electrons_per_s);
    let keep = 1.0 - ct.total();
    let mut out = vec![0f32; rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        let at = |rr: usize, c: usize| src[rr * cols + c] as f64;
        for (c, o) in row.iter_mut().enumerate() {
            *o = crosstalk_at(ct, keep, rows, cols, r, c, at) as f32;
        }
    });
    rate.electrons_per_s = out;
}

/// Stream kind of the hot-pixel pattern: `stream(seed, &[FIXED_PATTERN_TAG, 3])`.
pub const HOT_PIXEL_STREAM_KIND: u64 = 3;

/// Number of hot pixels of a sensor: `round(fraction · rows · cols)`.
pub fn hot_pixel_count(sensor: &SensorModel) -> usize {
    match &sensor.effects.hot_pixels {
        Some(h) => ((h.fraction * (sensor.rows * sensor.cols) as f64).round() as usize)
            .min(sensor.rows * sensor.cols),
        None => 0,
    }
}

/// `k` distinct values of [0, n), sorted: Floyd's sampling without replacement (Bentley &
/// Floyd, "A sample of brilliance", CACM 30(9), 1987), each uniform integer in [0, m) by the
/// multiply-shift reduction of one 64-bit draw (bias < m / 2^64). Draws exactly k numbers.
pub(crate) fn distinct_sorted_indices(rng: &mut impl Rng, n: usize, k: usize) -> Vec<usize> {
    let mut chosen = std::collections::HashSet::with_capacity(k);
    for j in (n - k)..n {
        let t = ((rng.next_u64() as u128 * (j + 1) as u128) >> 64) as usize;
        if !chosen.insert(t) {
            chosen.insert(j);
        }
    }
    let mut idx: Vec<usize> = chosen.into_iter().collect();
    idx.sort_unstable();
    idx
}

/// The camera's hot pixels, sorted by (row, col): [`hot_pixel_count`] distinct positions
/// (Floyd's sampling without replacement) and their rates, drawn from the camera seed's
/// fixed-pattern stream (independent of the thread count). Empty without the block.
pub fn hot_pixel_map(sensor: &SensorModel, seed: u64) -> Vec<HotPixel> {
    let Some(h) = &sensor.effects.hot_pixels else {
        return Vec::new();
    };
    let n = sensor.rows * sensor.cols;
    let k = hot_pixel_count(sensor);
    if k == 0 {
        return Vec::new();
    }
    let mut rng = stream(
        seed,
        &[crate::pixel_rng::FIXED_PATTERN_TAG, HOT_PIXEL_STREAM_KIND],
    );
    distinct_sorted_indices(&mut rng, n, k)
        .into_iter()
        .map(|i| {
            let v = if h.log_sigma > 0.0 {
                h.dark_voltage_v_per_s
                    * (h.log_sigma * crate::normal::standard_normal(&mut rng)).exp()
            } else {
                h.dark_voltage_v_per_s
            };
            HotPixel {
                row: (i / sensor.cols) as u32,
                col: (i % sensor.cols) as u32,
                dark_voltage_v_per_s: v as f32,
            }
        })
        .collect()
}

/// The hot pixels of row `r` in a map sorted by (row, col).
pub(crate) fn hot_row(map: &[HotPixel], r: usize) -> &[HotPixel] {
    let r = r as u32;
    let a = map.partition_point(|h| h.row < r);
    let b = map.partition_point(|h| h.row <= r);
    &map[a..b]
}

/// Checks the effect blocks against the sensor; errors name the block's key.
pub(crate) fn validate(sensor: &SensorModel) -> Result<(), SensorError> {
    let bad = |field: &str, value: f64, reason: &str| SensorError::InvalidField {
        field: field.to_string(),
        value: value.to_string(),
        reason: reason.to_string(),
    };
    let e = &sensor.effects;
    if let Some(h) = &e.hot_pixels {
        if !(h.fraction.is_finite() && (0.0..=1.0).contains(&h.fraction)) {
            return Err(bad("hot_pixels.fraction", h.fraction, "must be in [0, 1]"));
        }
        if !(h.dark_voltage_v_per_s.is_finite() && h.dark_voltage_v_per_s >= 0.0) {
            return Err(bad(
                "hot_pixels.dark_voltage_v_per_s",
                h.dark_voltage_v_per_s,
                "must be ≥ 0",
            ));
        }
        if !(h.log_sigma.is_finite() && h.log_sigma >= 0.0) {
            return Err(bad("hot_pixels.log_sigma", h.log_sigma, "must be ≥ 0"));
        }
    }
    match e.nonlinearity {
        Some(Nonlinearity::Quadratic { coefficient_per_v }) => {
            if !(coefficient_per_v.is_finite() && coefficient_per_v >= 0.0) {
                return Err(bad(
                    "nonlinearity.coefficient_per_v",
                    coefficient_per_v,
                    "must be ≥ 0",
                ));
            }
        }
        Some(Nonlinearity::Tanh { saturation_v }) => {
            if !(saturation_v.is_finite() && saturation_v > 0.0) {
                return Err(bad(
                    "nonlinearity.saturation_v",
                    saturation_v,
                    "must be > 0",
                ));
            }
        }
        None => {}
    }
    if let Some(c) = &e.crosstalk {
        for (k, v) in [
            ("left", c.left),
            ("right", c.right),
            ("up", c.up),
            ("down", c.down),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(&format!("crosstalk.{k}"), v, "must be ≥ 0"));
            }
        }
        if c.total() >= 1.0 {
            return Err(bad(
                "crosstalk",
                c.total(),
                "the total fraction must be < 1",
            ));
        }
    }
    let n_ch = sensor.channel_qe.len();
    if let Some(ir) = &e.ir_leakage {
        if ir.channels.len() != n_ch {
            return Err(bad(
                "ir_leakage.channels",
                ir.channels.len() as f64,
                &format!("needs one entry per channel ({n_ch})"),
            ));
        }
        for (c, s) in ir.channels.iter().enumerate() {
            if let Some(s) = s {
                if let Some((w, v)) = s.first_negative() {
                    return Err(SensorError::InvalidField {
                        field: format!("ir_leakage.channels.{}", sensor.channel_names[c]),
                        value: format!("{v} at {w} nm"),
                        reason: "must be ≥ 0".into(),
                    });
                }
                if let Err(err) = s.clone().validated() {
                    return Err(SensorError::InvalidField {
                        field: format!("ir_leakage.channels.{}", sensor.channel_names[c]),
                        value: "spectrum".into(),
                        reason: err.to_string(),
                    });
                }
            }
        }
    }
    if let Some(q) = &e.qe_shift {
        if q.shift_nm.len() != n_ch {
            return Err(bad(
                "qe_shift.shift_nm",
                q.shift_nm.len() as f64,
                &format!("needs one entry per channel ({n_ch})"),
            ));
        }
        if let Some(s) = q.shift_nm.iter().find(|s| !s.is_finite()) {
            return Err(bad("qe_shift.shift_nm", *s, "must be finite"));
        }
    }
    Ok(())
}
