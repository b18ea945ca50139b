//! HDR merge: the readouts of an HDR pixel ([`camsim_core::hdr`]: split pixel, dual
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
//! above [`camsim_core::hdr::USABLE_FRACTION`] of its clipping signal gets weight 0; a pixel
//! with every readout saturated takes the least sensitive readout's (clipped) estimate.
//! Readouts of one charge packet share its shot noise: within a packet the weights are
//! inverse read variances, which makes the whole combination the best linear unbiased one
//! for this covariance (Aitken 1935; [`merge_weights`]). The variance of the merged value is
//! [`camsim_core::hdr::merged_variance`].
use crate::IspError;
use camsim_core::hdr::{merge_weights, HdrFrame, HdrReadoutModel};
use camsim_core::image::Plane;
use rayon::prelude::*;

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
