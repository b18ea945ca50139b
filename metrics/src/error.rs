//! Errors of the metrics crate.
use thiserror::Error;

/// Everything that can go wrong computing an image-quality metric.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum MetricsError {
    /// Two inputs that must have the same size do not.
    #[error("{what}: expected {expected} values, got {actual}")]
    SizeMismatch {
        /// Which input.
        what: &'static str,
        /// The size implied by the other arguments.
        expected: usize,
        /// The size received.
        actual: usize,
    },
    /// An input that needs at least one value is empty.
    #[error("{0}: no values")]
    Empty(&'static str),
    /// A parameter is outside its valid range.
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// The offending value, formatted.
        value: String,
        /// What the valid range is.
        reason: &'static str,
    },
    /// A value is NaN or infinite where a finite number is required.
    #[error("{0}: contains a non-finite value (NaN or infinity)")]
    NonFinite(&'static str),
    /// A region of interest does not fit inside the image.
    #[error(
        "region rows {row0}..{row1}, cols {col0}..{col1} does not fit inside the {rows}×{cols} image"
    )]
    RoiOutOfBounds {
        /// first row
        row0: usize,
        /// one past the last row
        row1: usize,
        /// first column
        col0: usize,
        /// one past the last column
        col1: usize,
        /// image rows
        rows: usize,
        /// image columns
        cols: usize,
    },
    /// The slanted-edge analysis could not find or use an edge.
    #[error("slanted edge: {0}")]
    Edge(String),
    /// A chart patch has no pixel left to sample.
    #[error(
        "chart patch (row {chart_row}, col {chart_col}) has no pixel of the requested channel \
         inside its sampled area; lower margin_fraction or use a larger image"
    )]
    EmptyPatch {
        /// Chart row of the patch.
        chart_row: usize,
        /// Chart column of the patch.
        chart_col: usize,
    },
    /// A colour-filter-array description is malformed.
    #[error("CFA: {0}")]
    Cfa(String),
}
