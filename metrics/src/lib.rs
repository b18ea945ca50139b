//! # camsim-metrics
//!
//! Image-quality metrics used to evaluate simulated cameras (Farrell, Catrysse & Wandell,
//! "Digital camera simulation", Applied Optics 51(4), A80–A90, 2012, §3):
//!
//! * [`color_difference`]: CIEDE2000 (Sharma, Wu & Dalal 2005) and CIE94; ΔE*ab and CIELAB
//!   themselves are [`camsim_core::colorimetry::delta_e_76`] and
//!   [`camsim_core::colorimetry::xyz_to_lab`];
//! * [`scielab`](mod@scielab): S-CIELAB (Zhang & Wandell 1996);
//! * [`sfr`]: ISO 12233 slanted-edge spatial frequency response (e-SFR) and MTF50;
//! * [`patches`]: per-patch mean, noise and SNR of test charts laid out as in the capture-format
//!   spec (target kind `patches`), per CFA channel;
//! * [`hdr_snr`]: SNR-versus-exposure curves, dynamic range and SNR holes of HDR pixels
//!   (split pixel, dual gain, bracketing) in closed form;
//! * [`dual_pixel`]: the disparity between the left and right images of a dual-pixel sensor;
//! * [`rolling_shutter`]: edge skew per row and flicker band period of rolling-shutter frames;
//! * [`summary`]: PSNR and ΔE distribution statistics.
//!
//! Units live in names (`_db`, `_deg`, `_cycles_per_pixel`).
#![deny(missing_docs)]

pub mod color_difference;
pub mod dual_pixel;
pub mod error;
pub mod hdr_snr;
pub mod patches;
pub mod rolling_shutter;
pub mod scielab;
pub mod sfr;
pub mod summary;

pub use color_difference::{delta_e_2000, delta_e_2000_weighted, delta_e_94, Ciede2000Weights};
pub use error::MetricsError;
pub use patches::{cfa_channel_mask, patch_sample_rect, patch_stats, ChartLayout, PatchStats};
pub use scielab::{scielab, scielab_with_options, DeltaEFormula, ScielabOptions, ScielabResult};
pub use sfr::{
    slanted_edge_mtf, slanted_edge_mtf_with_options, EdgeMtf, EdgeMtfOptions, EdgeOrientation,
};
pub use summary::{delta_e_stats, psnr_db, DeltaEStats};
