//! Errors of the optics stage.
use thiserror::Error;

/// Everything that can go wrong forming the optical image.
#[derive(Debug, Error)]
pub enum OpticsError {
    /// A numeric parameter is out of its valid range; the message names it and its value.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidParameter {
        /// Name of the parameter (e.g. `f_number`).
        name: &'static str,
        /// The offending value.
        value: f64,
        /// What is required of it.
        reason: &'static str,
    },
    /// A PSF file could not be read or parsed.
    #[error("PSF file {path}: {msg}")]
    PsfFile {
        /// The file.
        path: String,
        /// What went wrong.
        msg: String,
    },
    /// A PSF set is malformed (shapes, negative values, wavelengths).
    #[error("PSF set: {0}")]
    Psf(String),
    /// A lens prescription / field model problem (`Blur::Lens`).
    #[error("{0}")]
    Lens(String),
    /// The scene cannot be imaged (empty, inconsistent).
    #[error("scene: {0}")]
    Scene(String),
    /// An optics effect block is invalid or cannot be applied (the message names its key).
    #[error("{0}")]
    Effect(String),
}

/// Check `value` is finite and `> 0` (or `>= 0` when `allow_zero`).
pub(crate) fn check_positive(
    name: &'static str,
    value: f64,
    allow_zero: bool,
) -> Result<(), OpticsError> {
    let ok = value.is_finite() && (value > 0.0 || (allow_zero && value == 0.0));
    if ok {
        Ok(())
    } else {
        Err(OpticsError::InvalidParameter {
            name,
            value,
            reason: if allow_zero {
                "must be a finite number >= 0"
            } else {
                "must be a finite number > 0"
            },
        })
    }
}
