//! SNR of HDR pixels (split pixel, dual conversion gain, bracketing) against exposure, their
//! dynamic range and the SNR drop ("SNR hole") where the merge hands over from one readout
//! to the next, in closed form from the readouts' shot-plus-read noise model
//! ([`HdrReadoutModel`]) and the ISP merge's weights
//! ([`merge_weights`], [`merged_variance`], in the core so that ISP and metrics share them).
//!
//! Exposure `H` is in photo-electrons of the camera's own pixel (a standard pixel with the
//! sensor's QE and fill factor collects `H`). Definitions:
//!
//! * SNR of readout i: `H / √Var_i(H)` while it is usable (mean packet electrons at most
//!   [`camsim_core::hdr::USABLE_FRACTION`] of its clipping signal), else 0;
//! * merged SNR: `H / √Var_merged(H)` with the usable readouts at their expected signal;
//! * dynamic range (dB) = `20 log₁₀(H_max / H_floor)`: `H_max` the largest exposure at which
//!   some readout is still usable (largest unsaturated signal), `H_floor` the exposure at
//!   which the merged SNR is 1 (the noise floor; EMVA 1288 release 4.0 §8.5 states the same
//!   ratio with the absolute sensitivity threshold, the signal equal to the dark noise);
//! * SNR hole at a crossover `H_c` (the last usable exposure of a readout that drops out
//!   while others remain): `20 log₁₀(SNR_below / SNR_above)`, both at `H_c`, with and without
//!   the readout (Solhusvik et al., IISW 2019, "SNR drop at the transition").
use camsim_core::hdr::{merge_weights, merged_variance, HdrReadoutModel};

/// The readouts used by the merge at exposure `h_e` (expected signal; see the module docs).
pub fn usable_mask(models: &[HdrReadoutModel], h_e: f64) -> Vec<bool> {
    models.iter().map(|m| m.usable_at(m.mean_e(h_e))).collect()
}

/// SNR (ratio, not dB) of the merged signal at `h_e` with the readouts in `usable`.
pub fn merged_snr_with(models: &[HdrReadoutModel], usable: &[bool], h_e: f64) -> f64 {
    let w = merge_weights(models, usable, h_e);
    let var = merged_variance(models, &w, h_e);
    if var.is_finite() && var > 0.0 {
        h_e / var.sqrt()
    } else {
        0.0
    }
}

/// SNR (ratio) of the merged signal at `h_e`, the usable readouts at their expected signal.
pub fn merged_snr(models: &[HdrReadoutModel], h_e: f64) -> f64 {
    merged_snr_with(models, &usable_mask(models, h_e), h_e)
}

/// `20 log₁₀ x` (−∞ for 0).
pub fn db(x: f64) -> f64 {
    20.0 * x.log10()
}

/// Closed-form SNR curves at the given exposures.
#[derive(Debug, Clone, PartialEq)]
pub struct HdrSnrCurves {
    /// Exposures H (photo-electrons of the camera's pixel).
    pub exposure_e: Vec<f64>,
    /// Readout names.
    pub readout_names: Vec<String>,
    /// SNR (dB) of each readout at each exposure (−∞ where it is saturated).
    pub readout_snr_db: Vec<Vec<f64>>,
    /// SNR (dB) of the merged signal.
    pub merged_snr_db: Vec<f64>,
}

/// The SNR curves of every readout and of the merged signal at `exposure_e`.
pub fn snr_curves(models: &[HdrReadoutModel], exposure_e: &[f64]) -> HdrSnrCurves {
    HdrSnrCurves {
        exposure_e: exposure_e.to_vec(),
        readout_names: models.iter().map(|m| m.name.clone()).collect(),
        readout_snr_db: models
            .iter()
            .map(|m| exposure_e.iter().map(|&h| db(m.snr(h))).collect())
            .collect(),
        merged_snr_db: exposure_e
            .iter()
            .map(|&h| db(merged_snr(models, h)))
            .collect(),
    }
}

/// Dynamic range of an HDR pixel (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicRange {
    /// Largest exposure with a usable readout (photo-electrons of the camera's pixel).
    pub max_signal_e: f64,
    /// Exposure at which the merged SNR is 1.
    pub noise_floor_e: f64,
    /// `20 log₁₀(max_signal / noise_floor)`.
    pub dynamic_range_db: f64,
}

/// The exposure at which the merged SNR first reaches 1 (log-grid scan at 100 points per
/// decade from 10⁻⁶ e⁻, then bisection to 10⁻¹² relative); NaN if it never does below
/// `h_max`.
pub fn noise_floor_e(models: &[HdrReadoutModel], h_max: f64) -> f64 {
    let f = |h: f64| merged_snr(models, h) - 1.0;
    let mut lo = 1e-6;
    if f(lo) >= 0.0 {
        return lo;
    }
    let step = 10f64.powf(0.01);
    while lo < h_max {
        let hi = (lo * step).min(h_max);
        if f(hi) >= 0.0 {
            let (mut a, mut b) = (lo, hi);
            while (b - a) > 1e-12 * b {
                let m = 0.5 * (a + b);
                if f(m) >= 0.0 {
                    b = m;
                } else {
                    a = m;
                }
            }
            return 0.5 * (a + b);
        }
        lo = hi;
    }
    f64::NAN
}

/// The dynamic range of the readouts' merged signal.
pub fn dynamic_range(models: &[HdrReadoutModel]) -> DynamicRange {
    let max_signal_e = dynamic_range_max(models);
    let floor = noise_floor_e(models, max_signal_e);
    DynamicRange {
        max_signal_e,
        noise_floor_e: floor,
        dynamic_range_db: db(max_signal_e / floor),
    }
}

/// The SNR drop where one readout leaves the merge.
#[derive(Debug, Clone, PartialEq)]
pub struct SnrHole {
    /// The readout that drops out.
    pub readout: String,
    /// Its last usable exposure `H_c` (photo-electrons of the camera's pixel).
    pub crossover_e: f64,
    /// Merged SNR (dB) at `H_c` with the readout.
    pub snr_below_db: f64,
    /// Merged SNR (dB) at `H_c` without it.
    pub snr_above_db: f64,
    /// `snr_below_db − snr_above_db`.
    pub drop_db: f64,
}

/// Every crossover below the largest usable exposure, by increasing exposure.
pub fn snr_holes(models: &[HdrReadoutModel]) -> Vec<SnrHole> {
    let h_max = dynamic_range_max(models);
    let mut order: Vec<usize> = (0..models.len()).collect();
    order.sort_by(|&a, &b| {
        models[a]
            .last_usable_h_e()
            .total_cmp(&models[b].last_usable_h_e())
    });
    let mut holes = Vec::new();
    for i in order {
        let hc = models[i].last_usable_h_e();
        if !(hc > 0.0 && hc < h_max) {
            continue;
        }
        let below = usable_mask(models, hc);
        let mut above = below.clone();
        above[i] = false;
        if !above.iter().any(|&u| u) {
            continue;
        }
        let b = db(merged_snr_with(models, &below, hc));
        let a = db(merged_snr_with(models, &above, hc));
        holes.push(SnrHole {
            readout: models[i].name.clone(),
            crossover_e: hc,
            snr_below_db: b,
            snr_above_db: a,
            drop_db: b - a,
        });
    }
    holes
}

fn dynamic_range_max(models: &[HdrReadoutModel]) -> f64 {
    models
        .iter()
        .map(HdrReadoutModel::last_usable_h_e)
        .fold(f64::NEG_INFINITY, f64::max)
}
