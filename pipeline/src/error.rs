//! The CLI's error type: every error names the file (and key or value) it is about, and is
//! printed as one line.
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A user-facing error.
#[derive(Debug, Error)]
pub enum CliError {
    /// A problem with an input file.
    #[error("{path}: {msg}")]
    Input {
        /// the file
        path: PathBuf,
        /// what is wrong
        msg: String,
    },
    /// A problem writing output.
    #[error("{path}: cannot write: {msg}")]
    Output {
        /// the file or folder
        path: PathBuf,
        /// what went wrong
        msg: String,
    },
    /// Anything else.
    #[error("{0}")]
    Other(String),
}

impl CliError {
    /// An input error about `path`.
    pub fn input(path: &Path, msg: impl std::fmt::Display) -> Self {
        CliError::Input {
            path: path.to_path_buf(),
            msg: msg.to_string(),
        }
    }
    /// An output error about `path`.
    pub fn output(path: &Path, msg: impl std::fmt::Display) -> Self {
        CliError::Output {
            path: path.to_path_buf(),
            msg: msg.to_string(),
        }
    }
    /// The message on one line.
    pub fn one_line(&self) -> String {
        self.to_string()
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
    }
}

impl From<std::io::Error> for CliError {
    fn from(e: std::io::Error) -> Self {
        CliError::Other(e.to_string())
    }
}
