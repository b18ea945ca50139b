//! # camsim-isp
//!
//! The image processor of camsim (§2.D of Farrell, Catrysse & Wandell, "Digital camera
//! simulation", Applied Optics 2012): the raw mosaic is converted into a rendered image by
//!
//! 1. black-level subtraction and normalisation ([`Mosaic::from_raw`]);
//! 2. demosaicking ([`demosaic`], [`DemosaicMethod`]): bilinear (ISETCam's kernels and
//!    boundary), Malvar–He–Cutler 2004 gradient-corrected linear interpolation, and a
//!    Hamilton–Adams style edge-adaptive method;
//! 3. white balance ([`WhiteBalance`], [`illuminant_gains`]);
//! 4. colour correction by a 3×3 matrix fitted by least squares on a target such as the
//!    Macbeth chart ([`fit_color_correction`], [`macbeth_target_linear_srgb`]);
//! 5. sRGB encoding (IEC 61966-2-1) and quantisation ([`srgb_encode`], [`to_srgb8`],
//!    [`to_srgb16`]).
//!
//! 6. HDR merge of the readouts of split-pixel, dual-gain and bracketed sensors into one
//!    linear image, inverse-variance weighted ([`hdr_merge`](mod@hdr_merge)).
//!
//! [`develop`] chains the steps for an [`IspPipeline`]. The [`isetcam`] module holds the
//! ISETCam-compatible "MCC optimized" sensor → XYZ → display transform used by the oracle
//! tests; it is never the default.
//!
//! Images are linear `f32` values; channel order of [`RgbImage`] is always (R, G, B).
#![deny(missing_docs)]

pub mod cfa_generic;
mod channel_color;
mod color;
mod demosaic;
pub mod dng_color;
pub mod hdr_merge;
pub mod isetcam;
mod mosaic;
mod pipeline;
mod srgb;
mod tone;

pub use camsim_core::hdr::{merge_weights, merged_variance};
pub use cfa_generic::{demosaic_cokriging, demosaic_planes, ChannelPlanes, CoKrigingModel};
pub use channel_color::{
    fit_channel_matrix, illuminant_channel_gains, macbeth_channel_responses, reference_channel,
    ChannelBalance, ChannelMatrix, FIT_RELATIVE_TOLERANCE,
};
pub use color::{
    fit_color_correction, illuminant_gains, macbeth_sensor_rgb, macbeth_target_linear_srgb,
    macbeth_xyz, ColorMatrix, WhiteBalance, MACBETH_WHITE_INDEX, XYZ_TO_LINEAR_SRGB,
};
pub use demosaic::{demosaic, demosaic_channels, DemosaicMethod};
pub use hdr_merge::hdr_merge;
pub use mosaic::{BayerLayout, Mosaic, RgbImage};
pub use pipeline::{clip_below_zero, develop, IspPipeline, RenderedImage};
pub use srgb::{from_srgb8, srgb_decode, srgb_encode, to_srgb16, to_srgb8};
pub use tone::{Bilateral, ToneCurve};

use thiserror::Error;

/// Errors of the image processor. Every message names the offending value.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum IspError {
    /// The mosaic (size, data, tile or channel names) is inconsistent.
    #[error("mosaic: {0}")]
    InvalidMosaic(String),
    /// A demosaic method name that is not known.
    #[error("unknown demosaic method '{name}'; expected one of: bilinear, malvar, edge_adaptive, lmmse, quad_binning, quad_remosaic")]
    UnknownDemosaic {
        /// The name that was given.
        name: String,
    },
    /// The method needs a 2×2 RGB Bayer tile and the mosaic has another one.
    #[error("demosaic '{method}' needs a 2×2 RGB Bayer tile (RGGB, GRBG, GBRG or BGGR): {reason}")]
    NotBayer {
        /// The method name.
        method: String,
        /// What is wrong with the tile.
        reason: String,
    },
    /// A parameter is out of range.
    #[error("{name} = {value}: {reason}")]
    InvalidParameter {
        /// The parameter.
        name: String,
        /// The bad value, formatted.
        value: String,
        /// What is required of it.
        reason: String,
    },
    /// A least-squares fit could not be computed.
    #[error("colour-correction fit: {0}")]
    Fit(String),
    /// Embedded data or a spectral computation failed.
    #[error("data: {0}")]
    Data(String),
}

impl From<camsim_core::CoreError> for IspError {
    fn from(e: camsim_core::CoreError) -> Self {
        IspError::Data(e.to_string())
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod tests_cfa;

#[cfg(test)]
mod tests_color;
