//! The noise model of an HDR pixel's readouts (split pixel, dual conversion gain,
//! bracketing) as every stage uses it: the sensor simulates the readouts
//! (`camsim_sensor::hdr`), the ISP merges them (`camsim_isp::hdr_merge`) with the weights
//! below, and the metrics (`camsim_metrics::hdr_snr`) draw SNR curves from the same model.
//! Here, so that those stages depend on the core only.
//!
//! Exposure `H` is in photo-electrons of the camera's (standard) pixel. Readout `i` reads
//! charge packet `p` (a photodiode, or one exposure of it) with `s_i` packet electrons per
//! photo-electron of the pixel, dark electrons `d_p`, `k_i` DN per electron and read plus
//! quantisation variance `σ_e,i²` (electrons²): its estimate of `H` has the variance
//! `(s H + d + σ_e²)/s²` (shot plus read, Janesick, *Photon Transfer*, 2007, ch. 2).
use crate::RawFrame;

/// Fraction of a readout's saturation signal up to which its value is used by the merge
/// (above it the readout counts as saturated): values within 5 % of clipping are left to the
/// less sensitive readouts.
pub const USABLE_FRACTION: f64 = 0.95;

/// What a readout's value means, and its noise: everything the ISP merge and the SNR
/// metrics need of one readout, for one shot.
#[derive(Debug, Clone, PartialEq)]
pub struct HdrReadoutModel {
    /// Readout name.
    pub name: String,
    /// Index of its charge packet (readouts of one packet share the shot noise).
    pub packet: usize,
    /// s_i: mean packet electrons per photo-electron of the camera's pixel.
    pub gain_over_pixel: f64,
    /// d_p: mean dark electrons of the packet.
    pub dark_e: f64,
    /// k_i: DN per packet electron.
    pub dn_per_e: f64,
    /// DN of zero electrons (black level + analog offset).
    pub zero_dn: f64,
    /// σ_e,i²: read noise plus quantisation, in packet electrons².
    pub read_variance_e2: f64,
    /// Packet electrons at which the readout clips: min(well, swing, ADC full scale).
    pub saturation_e: f64,
}

impl HdrReadoutModel {
    /// Mean packet electrons (photo + dark) at exposure `h_e` (photo-electrons of the
    /// camera's pixel).
    pub fn mean_e(&self, h_e: f64) -> f64 {
        self.gain_over_pixel * h_e + self.dark_e
    }

    /// Whether the readout is used at mean packet electrons `packet_e`: at most
    /// [`USABLE_FRACTION`] of its saturation signal.
    pub fn usable_at(&self, packet_e: f64) -> bool {
        packet_e <= USABLE_FRACTION * self.saturation_e
    }

    /// The exposure (photo-electrons of the camera's pixel) above which the readout is no
    /// longer used.
    pub fn last_usable_h_e(&self) -> f64 {
        (USABLE_FRACTION * self.saturation_e - self.dark_e) / self.gain_over_pixel
    }

    /// The readout's estimate of H from a DN value: `(DN − zero)/(k s) − d/s`.
    pub fn estimate_h_e(&self, dn: f64) -> f64 {
        ((dn - self.zero_dn) / self.dn_per_e - self.dark_e) / self.gain_over_pixel
    }

    /// Packet electrons of a DN value: `(DN − zero)/k`.
    pub fn electrons_of_dn(&self, dn: f64) -> f64 {
        (dn - self.zero_dn) / self.dn_per_e
    }

    /// Variance of the estimate of H (shot + dark + read + quantisation, no clipping) at
    /// exposure `h_e`: `(s H + d + σ_e²)/s²` — the shot-plus-read model of the module docs.
    pub fn estimate_variance(&self, h_e: f64) -> f64 {
        (self.mean_e(h_e).max(0.0) + self.read_variance_e2) / self.gain_over_pixel.powi(2)
    }

    /// SNR of the readout alone at exposure `h_e`: `H / √var` (0 when saturated).
    pub fn snr(&self, h_e: f64) -> f64 {
        if !self.usable_at(self.mean_e(h_e)) {
            return 0.0;
        }
        h_e / self.estimate_variance(h_e).sqrt()
    }
}

/// The readouts of one HDR shot, each a raw frame in DN (same order as the model's).
#[derive(Debug, Clone, PartialEq)]
pub struct HdrFrame {
    /// Readout names.
    pub names: Vec<String>,
    /// One frame per readout.
    pub readouts: Vec<RawFrame>,
}

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
