//! Errors of the lens crate. Every message names the bad value and where it was found.
use thiserror::Error;

/// Everything that can go wrong building or reading a lens.
#[derive(Debug, Error)]
pub enum LensError {
    /// The prescription is malformed (message names the surface / key and value).
    #[error("prescription: {0}")]
    Prescription(String),
    /// A glass is unknown or its data file is malformed.
    #[error("glass '{name}': {msg}")]
    Glass {
        /// The glass name as written.
        name: String,
        /// What went wrong.
        msg: String,
    },
    /// A wavelength is outside what is allowed (not positive, or outside a formula's range).
    #[error("wavelength {wavelength_nm} nm: {msg}")]
    Wavelength {
        /// The bad wavelength.
        wavelength_nm: f64,
        /// What went wrong.
        msg: String,
    },
    /// A paraxial quantity does not exist (e.g. an afocal system has no focal length).
    #[error("paraxial: {0}")]
    Paraxial(String),
    /// Ray aiming did not converge or the chief ray is lost.
    #[error("ray aiming at field {field_deg} deg: {msg}")]
    Aiming {
        /// The field angle.
        field_deg: f64,
        /// What went wrong.
        msg: String,
    },
    /// A file could not be read.
    #[error("file {path}: {msg}")]
    Io {
        /// The file.
        path: String,
        /// What went wrong.
        msg: String,
    },
    /// A foreign lens file (Zemax, ISET .dat) is malformed or unsupported.
    #[error("{format} line {line}: {msg}")]
    Reader {
        /// File format name.
        format: &'static str,
        /// 1-based line number (0 = whole file).
        line: usize,
        /// What went wrong.
        msg: String,
    },
    /// A JSON document does not match the format.
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
}
