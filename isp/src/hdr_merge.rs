//! HDR merge: the readouts of an HDR pixel ([`camsim_sensor::hdr`]: split pixel, dual
//! conversion gain, bracketing) combined into one linear image of the exposure `H`
//! (photo-electrons of the camera's pixel).
//!
//! Each unsaturated readout gives an unbiased estimate `x_i` of `H`
//! ([`HdrReadoutModel::estimate_h_e`]); the merge is their weighted mean with weights from
//! the readouts' shot-plus-read noise model ([`HdrReadoutModel::estimate_variance`]):
//! inverse-variance weights across independent charge packets, the minimum-variance
//! combination of independent unbiased estimates (Granados, Ajdin, Wand, Theobalt, Seidel & Lensch, "Optimal HDR
//! reconstruction with linear digital cameras", CVPR 2010; Hasinoff, Durand & Freeman,
//! "Noise-optimal capture for high dynamic range photography", CVPR 2010). The variances are
//! evaluated at a first estimate `Ĥ₀`: that of the usable readout with the largest
//! sensitivity `s_i` (lowest relative read noise). Saturation-aware: a readout whose value is
//! above [`camsim_sensor::USABLE_FRACTION`] of its clipping signal gets weight 0; a pixel
//! with every readout saturated takes the least sensitive readout's (clipped) estimate.
//! Readouts of one charge packet share its shot noise: within a packet the weights are
//! inverse read variances, which makes the whole combination the best linear unbiased one
//! for this covariance (Aitken 1935; [`merge_weights`]). The variance of the merged value is
//! [`merged_variance`].
use crate::IspError;
use camsim_core::image::Plane;
use camsim_sensor::{HdrFrame, HdrReadoutModel};
use rayon::prelude::*;

/// Merge weights of the readouts marked `usable` (0 for the others) at exposure `h_e`
/// (photo-electrons of the camera's pixel): the best linear unbiased combination (Aitken's
/// generalised least squares) for the readouts' covariance, in which the readouts of one
/// charge packet share its shot noise and the packets are independent. Within packet `p`,
/// `w_i ∝ s_p²/σ_e,i²` (inverse read variance: the shared shot noise does not depend on the
/// choice); the packets' combined estimates, of variance
/// `V_p = (s_p H + d_p)/s_p² + 1/Σ_{i∈p} (s_p²/σ_e,i²)`, are weighted `1/V_p` (inverse
/// variance). For one readout per packet (bracketing) these are the plain inverse-variance
/// weights `1/Var_i(H)` of [`HdrReadoutModel::estimate_variance`].
pub fn merge_weights(models: &[HdrReadoutModel], usable: &[bool], h_e: f64) -> Vec<f64> {
    let h = h_e.max(0.0);
    let n_packets = models.iter().map(|m| m.packet + 1).max().unwrap_or(0);
    let mut w = vec![0.0; models.len()];
    for p in 0..n_packets {
        // Σ_{i∈p} s²/σ_i² over the usable readouts of the packet.
        let mut precision = 0.0;
        let mut shot_var = 0.0;
        for (m, &u) in models.iter().zip(usable) {
            if u && m.packet == p {
                precision += m.gain_over_pixel.powi(2) / m.read_variance_e2;
                shot_var = (m.estimate_variance(h)
                    - m.read_variance_e2 / m.gain_over_pixel.powi(2))
                .max(0.0);
            }
        }
        if !(precision > 0.0) {
            continue;
        }
        let packet_var = shot_var + 1.0 / precision;
        for (i, (m, &u)) in models.iter().zip(usable).enumerate() {
            if u && m.packet == p {
                w[i] = (m.gain_over_pixel.powi(2) / m.read_variance_e2) / precision / packet_var;
            }
        }
    }
    w
}

/// Variance of the merged estimate `Σ w_i x_i / Σ w_i` at exposure `h_e` with weights `w`:
/// `[Σ_p (s_p H + d_p)(Σ_{i∈p} w_i/s_i)² + Σ_i w_i² σ_e,i²/s_i²] / (Σ w_i)²` — the shot noise
/// of a charge packet is common to its readouts, read noises are independent. Infinite
/// when every weight is 0.
pub fn merged_variance(models: &[HdrReadoutModel], w: &[f64], h_e: f64) -> f64 {
    let total: f64 = w.iter().sum();
    if !(total > 0.0) {
        return f64::INFINITY;
    }
    let n_packets = models.iter().map(|m| m.packet + 1).max().unwrap_or(0);
    let mut shot = 0.0;
    for p in 0..n_packets {
        let mut coef = 0.0;
        let mut mean_e = 0.0;
        for (m, &wi) in models.iter().zip(w) {
            if m.packet == p {
                coef += wi / m.gain_over_pixel;
                mean_e = m.mean_e(h_e).max(0.0);
            }
        }
        shot += mean_e * coef * coef;
    }
    let read: f64 = models
        .iter()
        .zip(w)
        .map(|(m, &wi)| wi * wi * m.read_variance_e2 / m.gain_over_pixel.powi(2))
        .sum();
    (shot + read) / (total * total)
}

/// Merge the readouts of `frame` (DN, in the order of `models`) into one linear plane of the
/// exposure H (photo-electrons of the camera's pixel), per pixel as in the module docs.
pub fn hdr_merge(frame: &HdrFrame, models: &[HdrReadoutModel]) -> Result<Plane, IspError> {
    if frame.readouts.len() != models.len() || models.is_empty() {
        return Err(IspError::InvalidMosaic(format!(
            "HDR merge: {} readout frames for {} readout models (need the same number, ≥ 1)",
            frame.readouts.len(),
            models.len()
        )));
    }
    let (rows, cols) = (frame.readouts[0].rows, frame.readouts[0].cols);
    for (f, m) in frame.readouts.iter().zip(models) {
        if f.rows != rows || f.cols != cols || f.dn.len() != rows * cols {
            return Err(IspError::InvalidMosaic(format!(
                "HDR merge: readout {} is {}×{}, readout {} is {rows}×{cols}",
                m.name, f.rows, f.cols, models[0].name
            )));
        }
    }
    // Readout order by decreasing sensitivity (first usable one gives Ĥ₀), and the least
    // sensitive readout (fallback when all are saturated).
    let mut by_sens: Vec<usize> = (0..models.len()).collect();
    by_sens.sort_by(|&a, &b| {
        models[b]
            .gain_over_pixel
            .total_cmp(&models[a].gain_over_pixel)
            .then(
                models[a]
                    .read_variance_e2
                    .total_cmp(&models[b].read_variance_e2),
            )
    });
    let least = *by_sens.last().expect("non-empty");
    let data: Vec<f32> = (0..rows * cols)
        .into_par_iter()
        .map(|px| {
            let mut usable = vec![false; models.len()];
            let mut x = vec![0.0; models.len()];
            for (i, m) in models.iter().enumerate() {
                let dn = frame.readouts[i].dn[px] as f64;
                usable[i] = m.usable_at(m.electrons_of_dn(dn));
                x[i] = m.estimate_h_e(dn);
            }
            let Some(&first) = by_sens.iter().find(|&&i| usable[i]) else {
                return x[least] as f32;
            };
            let w = merge_weights(models, &usable, x[first]);
            let total: f64 = w.iter().sum();
            (w.iter().zip(&x).map(|(a, b)| a * b).sum::<f64>() / total) as f32
        })
        .collect();
    Ok(Plane { rows, cols, data })
}
