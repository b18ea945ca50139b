//! Noise the field has measured since the ISET paper (issue 21): row (line) noise, random
//! telegraph noise (RTN) pixels, black-level drift and dark current against temperature.
//! Each is an optional block of [`crate::SensorEffects`]; absent = off, and a sensor without
//! them simulates bit-identically (their random draws come from their own streams, never
//! from a pixel row's stream).
//!
//! * **Row noise** ([`RowNoise`]): every row of every frame gets one offset N(0, σ_row²) in
//!   volts at step 5, new each frame (EMVA 1288 Release 4.0, §8.3: the temporal part of the
//!   row/column noise, measured as the variance of row means across frames,
//!   `σ²(row mean) = σ_row² + σ_pixel²/cols`). Drawn from `stream(seed, [ROW_NOISE_TAG,
//!   stream…])`, one normal per row in row order.
//! * **RTN** ([`Rtn`]): `round(fraction · rows · cols)` pixels at fixed positions (Floyd's
//!   sampling from the camera seed, stream kind [`RTN_STREAM_KIND`] of the fixed-pattern
//!   streams) carry a two-state trap: the pixel voltage is raised by its amplitude A while the
//!   trap is in its high state. The state is a two-state Markov chain in the global frame
//!   index with per-frame switching probabilities `p_up` (low → high) and `p_down`
//!   (high → low) (Kandiah, IEEE Trans. Electron Devices 41(11), 1994; Hung, Ko, Hu & Cheng,
//!   IEEE Electron Device Lett. 11(2), 1990: exponential dwell times, mean dwell
//!   1/p_down high and 1/p_up low frames). Stationary occupancy of the high state
//!   `p = p_up/(p_up + p_down)`; a frame's RTN voltage has mean `A·p` and variance
//!   `A²·p(1−p)`; its lag-k autocorrelation is `(1 − p_up − p_down)^k`. The chain starts in
//!   its stationary distribution at frame 0 and is stepped to the frame's index with uniforms
//!   of the pixel's own stream. Amplitudes: all A (fitted form, `log_sigma = 0`) or lognormal
//!   `A·exp(log_sigma·z)` (generator form, median A).
//! * **Black-level drift** ([`BlackLevelDrift`]): the black level of the frame with global
//!   index j (capture order: shots in captures.json order, frames in their order) is
//!   `black_level_dn + rate·j` DN (a linear drift of the pedestal, as the thermal drift of
//!   the analog offset; EMVA 1288 R4.0 §4.1 requires the offset to be stable, which is what
//!   this violates). Magnitude: the drift over the capture set `rate·(N_frames − 1)` DN.
//! * **Dark current against temperature** ([`DarkTemperature`]): the dark voltage of a shot
//!   at temperature T is `dark(T_ref)·2^((T − T_ref)/T_d)` (Janesick, *Photon Transfer*, SPIE
//!   2007, §7: dark current doubles every 5–8 °C near room temperature);
//!   [`crate::dark_at_temperature`] is the law, [`dark_voltage_at`] applies it to a shot.
use crate::{SensorError, SensorModel};
use camsim_core::rng::stream;
use rand::Rng;

/// `row_noise`: a temporal offset per row and frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowNoise {
    /// σ of the per-row offset (V), new every frame.
    pub sigma_v: f64,
}

/// `rtn`: random-telegraph-noise pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rtn {
    /// Fraction of the pixels with a trap (the effect's magnitude).
    pub fraction: f64,
    /// Step between the two levels (V): median amplitude with a lognormal spread.
    pub amplitude_v: f64,
    /// σ of ln(amplitude) (0: every RTN pixel has the amplitude `amplitude_v`).
    pub log_sigma: f64,
    /// Probability per frame of a low → high switch.
    pub p_up: f64,
    /// Probability per frame of a high → low switch.
    pub p_down: f64,
}

impl Rtn {
    /// Stationary probability of the high state, `p_up / (p_up + p_down)`.
    pub fn high_probability(&self) -> f64 {
        self.p_up / (self.p_up + self.p_down)
    }
}

/// `black_level_drift`: a pedestal changing linearly with the global frame index.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlackLevelDrift {
    /// Drift rate (DN per frame).
    pub dn_per_frame: f64,
}

impl BlackLevelDrift {
    /// Black level (DN) of the frame with global index `frame_index`.
    pub fn black_level_dn(&self, black_level_dn: f64, frame_index: u64) -> f64 {
        black_level_dn + self.dn_per_frame * frame_index as f64
    }

    /// The effect's magnitude: the drift over a capture set of `frames` frames,
    /// `rate · (frames − 1)` DN.
    pub fn magnitude_dn(&self, frames: usize) -> f64 {
        self.dn_per_frame * frames.saturating_sub(1) as f64
    }
}

/// `dark_temperature`: the doubling law of the dark current.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DarkTemperature {
    /// Temperature (°C) at which `dark_voltage_v_per_s` holds.
    pub reference_temperature_c: f64,
    /// Temperature step (°C) that doubles the dark current (the effect's magnitude).
    pub doubling_temperature_c: f64,
}

/// The dark voltage rate (V/s) of a shot at `temperature_c`: the sensor's own without the
/// `dark_temperature` block or without a shot temperature, else the doubling law
/// ([`crate::dark_at_temperature`]) from the block's reference temperature.
pub fn dark_voltage_at(sensor: &SensorModel, temperature_c: Option<f64>) -> f64 {
    match (sensor.effects.dark_temperature, temperature_c) {
        (Some(d), Some(t)) => crate::dark_at_temperature(
            sensor.dark_voltage_v_per_s,
            t,
            d.reference_temperature_c,
            d.doubling_temperature_c,
        ),
        _ => sensor.dark_voltage_v_per_s,
    }
}

/// Tag of the row-noise streams: `stream(seed, [ROW_NOISE_TAG, stream…])`.
pub const ROW_NOISE_TAG: u64 = 0x524F_575F_4E4F_4953; // "ROW_NOIS"
/// Tag of the RTN state streams: `stream(seed, [RTN_STATE_TAG, pixel index])`.
pub const RTN_STATE_TAG: u64 = 0x5254_4E5F_5354_4154; // "RTN_STAT"
/// Stream kind of the RTN pixel map: `stream(seed, [FIXED_PATTERN_TAG, 4])`.
pub const RTN_STREAM_KIND: u64 = 4;

/// The row offsets (V) of one frame: one N(0, σ²) per row in row order from
/// `stream(seed, [ROW_NOISE_TAG, stream_ids…])`; `None` without the block.
pub fn row_offsets_v(sensor: &SensorModel, seed: u64, stream_ids: &[u64]) -> Option<Vec<f64>> {
    let r = sensor.effects.row_noise?;
    let mut ids = vec![ROW_NOISE_TAG];
    ids.extend_from_slice(stream_ids);
    let mut rng = stream(seed, &ids);
    Some(
        (0..sensor.rows)
            .map(|_| r.sigma_v * crate::normal::standard_normal(&mut rng))
            .collect(),
    )
}

/// One RTN pixel of a camera's fixed pattern.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RtnPixel {
    /// Row.
    pub row: u32,
    /// Column.
    pub col: u32,
    /// Step between its two levels (V).
    pub amplitude_v: f64,
}

/// Number of RTN pixels: `round(fraction · rows · cols)`.
pub fn rtn_pixel_count(sensor: &SensorModel) -> usize {
    sensor.effects.rtn.map_or(0, |r| {
        ((r.fraction * (sensor.rows * sensor.cols) as f64).round() as usize)
            .min(sensor.rows * sensor.cols)
    })
}

/// The camera's RTN pixels sorted by (row, col): [`rtn_pixel_count`] distinct positions
/// (Floyd's sampling without replacement, Bentley & Floyd, CACM 30(9), 1987) and their
/// amplitudes, from the camera seed's fixed-pattern stream kind [`RTN_STREAM_KIND`]. Empty
/// without the block.
pub fn rtn_pixel_map(sensor: &SensorModel, seed: u64) -> Vec<RtnPixel> {
    let Some(b) = sensor.effects.rtn else {
        return Vec::new();
    };
    let n = sensor.rows * sensor.cols;
    let k = rtn_pixel_count(sensor);
    if k == 0 {
        return Vec::new();
    }
    let mut rng = stream(
        seed,
        &[crate::pixel_rng::FIXED_PATTERN_TAG, RTN_STREAM_KIND],
    );
    crate::effects::distinct_sorted_indices(&mut rng, n, k)
        .into_iter()
        .map(|i| RtnPixel {
            row: (i / sensor.cols) as u32,
            col: (i % sensor.cols) as u32,
            amplitude_v: if b.log_sigma > 0.0 {
                b.amplitude_v * (b.log_sigma * crate::normal::standard_normal(&mut rng)).exp()
            } else {
                b.amplitude_v
            },
        })
        .collect()
}

/// The trap state (true = high) of pixel `pixel_index` at global frame `frame_index`: the
/// Markov chain of the module docs, started in its stationary distribution at frame 0 and
/// stepped with one uniform per frame from `stream(seed, [RTN_STATE_TAG, pixel_index])`.
pub fn rtn_state(rtn: &Rtn, seed: u64, pixel_index: u64, frame_index: u64) -> bool {
    let mut rng = stream(seed, &[RTN_STATE_TAG, pixel_index]);
    let mut u = || (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    let mut high = u() < rtn.high_probability();
    for _ in 0..frame_index {
        let x = u();
        high = if high { x >= rtn.p_down } else { x < rtn.p_up };
    }
    high
}

/// The RTN voltages of one frame: (pixel index, volts added) for every RTN pixel in its high
/// state at global frame `frame_index`, in pixel order.
pub fn rtn_offsets_v(sensor: &SensorModel, seed: u64, frame_index: u64) -> Vec<(usize, f64)> {
    let Some(b) = sensor.effects.rtn else {
        return Vec::new();
    };
    rtn_pixel_map(sensor, seed)
        .into_iter()
        .filter_map(|p| {
            let i = p.row as usize * sensor.cols + p.col as usize;
            rtn_state(&b, seed, i as u64, frame_index).then_some((i, p.amplitude_v))
        })
        .collect()
}

/// Checks the blocks; errors name the block's key.
pub(crate) fn validate(sensor: &SensorModel) -> Result<(), SensorError> {
    let bad = |field: &str, value: f64, reason: &str| SensorError::InvalidField {
        field: field.to_string(),
        value: value.to_string(),
        reason: reason.to_string(),
    };
    let e = &sensor.effects;
    if let Some(r) = e.row_noise {
        if !(r.sigma_v.is_finite() && r.sigma_v >= 0.0) {
            return Err(bad("row_noise.sigma_v", r.sigma_v, "must be ≥ 0 (V)"));
        }
    }
    if let Some(r) = e.rtn {
        if !(r.fraction.is_finite() && (0.0..=1.0).contains(&r.fraction)) {
            return Err(bad("rtn.fraction", r.fraction, "must be in [0, 1]"));
        }
        if !(r.amplitude_v.is_finite() && r.amplitude_v >= 0.0) {
            return Err(bad("rtn.amplitude_v", r.amplitude_v, "must be ≥ 0 (V)"));
        }
        if !(r.log_sigma.is_finite() && r.log_sigma >= 0.0) {
            return Err(bad("rtn.log_sigma", r.log_sigma, "must be ≥ 0"));
        }
        for (k, p) in [("rtn.p_up", r.p_up), ("rtn.p_down", r.p_down)] {
            if !(p.is_finite() && p > 0.0 && p <= 1.0) {
                return Err(bad(k, p, "must be a probability per frame in (0, 1]"));
            }
        }
    }
    if let Some(d) = e.black_level_drift {
        if !d.dn_per_frame.is_finite() {
            return Err(bad(
                "black_level_drift.dn_per_frame",
                d.dn_per_frame,
                "must be a finite number of DN per frame",
            ));
        }
    }
    if let Some(d) = e.dark_temperature {
        if !(d.reference_temperature_c.is_finite() && d.reference_temperature_c > -273.15) {
            return Err(bad(
                "dark_reference_temperature_c",
                d.reference_temperature_c,
                "must be a temperature above absolute zero (°C)",
            ));
        }
        if !(d.doubling_temperature_c.is_finite() && d.doubling_temperature_c > 0.0) {
            return Err(bad(
                "dark_doubling_temperature_c",
                d.doubling_temperature_c,
                "must be > 0 (°C)",
            ));
        }
    }
    Ok(())
}
