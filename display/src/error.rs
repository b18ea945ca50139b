//! Errors of the display stage.
use camsim_core::CoreError;
use thiserror::Error;

/// Everything that can go wrong loading a display or showing an image on it.
#[derive(Debug, Error)]
pub enum DisplayError {
    /// No embedded display has this name.
    #[error("unknown display {name:?}; available displays: {available}")]
    UnknownDisplay {
        /// The name asked for.
        name: String,
        /// Comma-separated list of the embedded display names.
        available: String,
    },
    /// A field of a display description is missing or malformed.
    #[error("display data field `{field}`: {message}")]
    InvalidData {
        /// The JSON field (path) at fault, e.g. `gamma[12][1]`.
        field: String,
        /// What is wrong with it, naming the bad value.
        message: String,
    },
    /// A primary index beyond the display's primaries.
    #[error("primary index {primary} out of range: the display has {n_primaries} primaries")]
    PrimaryOutOfRange {
        /// The index asked for.
        primary: usize,
        /// How many primaries the display has.
        n_primaries: usize,
    },
    /// A bit depth outside 1..=16.
    #[error("bit depth {bits} is not supported (1..=16 bits)")]
    BadBitDepth {
        /// The bit depth asked for.
        bits: u32,
    },
    /// A digital value beyond the largest code of its bit depth.
    #[error("digital value {value} exceeds the largest {bits}-bit code {max}")]
    DigitalOutOfRange {
        /// The value.
        value: u32,
        /// Its bit depth.
        bits: u32,
        /// The largest code, 2^bits − 1.
        max: u32,
    },
    /// A linear intensity that is NaN or infinite.
    #[error("linear intensity {value} is not a finite number")]
    NonFiniteLinear {
        /// The value.
        value: f64,
    },
    /// A digital image whose shape or values do not fit the display.
    #[error("digital image: {0}")]
    BadImage(String),
    /// `samples_per_pixel` of 0 (or an output too large to address).
    #[error("samples_per_pixel = {0} is invalid: {1}")]
    BadSampling(usize, String),
    /// An error from camsim-core (spectra, images, embedded data).
    #[error(transparent)]
    Core(#[from] CoreError),
}
