//! Errors of the core crate.
use thiserror::Error;

/// Everything that can go wrong building core values from user data.
#[derive(Debug, Error)]
pub enum CoreError {
    /// A spectrum's wavelengths or values are malformed.
    #[error("spectrum: {0}")]
    Spectrum(String),
    /// A wavelength grid is malformed.
    #[error("wavelength grid: {0}")]
    Grid(String),
    /// An image or plane has inconsistent dimensions.
    #[error("image: {0}")]
    Image(String),
    /// An embedded data file is missing or malformed.
    #[error("embedded data '{0}': {1}")]
    Data(String, String),
    /// A scene target is malformed.
    #[error("target: {0}")]
    Target(String),
    /// Reading or writing an EXR file failed.
    #[error("EXR file {path}: {msg}")]
    Exr {
        /// The file.
        path: String,
        /// What went wrong.
        msg: String,
    },
}
