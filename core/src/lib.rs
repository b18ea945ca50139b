//! # camsim-core
//!
//! The small shared vocabulary of the camsim pipeline (Farrell, Catrysse & Wandell, "Digital
//! camera simulation", Applied Optics 2012):
//!
//! * [`spectrum`]: piecewise-linear spectra (zero outside their range, as in the capture-format
//!   spec), exact integrals of their products, energy ↔ photon conversion;
//! * [`image`]: spectral images stored as a linear model (basis spectra × coefficient planes,
//!   §2.A of the paper; a plain band cube is the special case of "hat" basis functions), and the
//!   typed stage products [`image::SceneRadiance`] → [`image::SensorIrradiance`] →
//!   [`image::RawFrame`];
//! * [`scene`]: test targets (Macbeth, uniform, slanted edge, sweep, ramp, point array, grid
//!   lines, patch charts) and luminance scaling;
//! * [`scene_import`]: RGB pictures on a display → radiance (ISETCam `sceneFromFile`);
//!   [`scene_view`]: a scene's field of view and distance in the image plane;
//!   [`illuminant`]: CIE daylight, illuminant swap and estimation;
//! * [`colorimetry`]: XYZ, luminance, CIELAB, ΔE*ab; [`cieluv`]: u′v′, CIELUV, ΔE*uv;
//! * [`data`]: ISETCam spectral and device data embedded in the binary (MIT, see data/iset);
//! * [`exr_io`]: spectral OpenEXR in the Fichet et al. (JCGT 2021) layout;
//! * [`linear_model`]: SVD compression of spectral images with round-trip error;
//! * [`stats`]: region statistics and the photon-transfer curve;
//! * [`rng`]: seeded random streams that do not depend on the thread count;
//! * [`sample_aperture`]: what one sample of a rendered scene stands for (cell average or
//!   cubic B-spline filter).
//!
//! Units live in names: `_nm`, `_m`, `_um`, `_s`, `_v`, `_e` (electrons), `_dn`.
#![deny(missing_docs)]

pub mod cieluv;
pub mod cleanup;
pub mod colorimetry;
pub mod constants;
pub mod data;
pub mod error;
pub mod exr_io;
pub mod fft_size;
pub mod hdr;
pub mod illuminant;
pub mod image;
pub mod linear_model;
pub mod npy;
pub mod rng;
pub mod sample_aperture;
pub mod scene;
pub mod scene_import;
pub mod scene_view;
pub mod spectrum;
pub mod stats;

pub use error::CoreError;
pub use image::{
    Plane, RawFrame, RawLayout, SceneRadiance, SensorIrradiance, SpectralBasis, SpectralImage,
};
pub use spectrum::{Spectrum, WavelengthGrid};
