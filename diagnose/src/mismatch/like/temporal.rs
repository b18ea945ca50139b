//! The temporal term: the sample variance of a pixel-shot's F frames.

/// Gamma log-density (constants dropped) of a sample variance v with F frames and true
/// variance σ²: (F−1)v/σ² ~ χ²(F−1).
#[inline]
pub(crate) fn temporal_ll(v: f64, var: f64, f: f64) -> f64 {
    -0.5 * (f - 1.0) * (v / var + var.ln())
}
