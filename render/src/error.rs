//! Errors of the render crate: one line each, naming the file, key or value at fault.
use thiserror::Error;

/// A render error.
#[derive(Debug, Error)]
pub enum RenderError {
    /// A scene file that cannot be read or is not a scene camsim can render.
    #[error("{path}: {msg}")]
    Scene {
        /// The scene file.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// A bad render setting.
    #[error("{0}")]
    Settings(String),
    /// An output that cannot be written.
    #[error("{path}: cannot write: {msg}")]
    Output {
        /// The output file.
        path: String,
        /// Why.
        msg: String,
    },
}
