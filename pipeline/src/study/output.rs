//! What evaluating one study point yields: metric values, images and detail.
use serde_json::Value;

/// Metric values and images of one evaluated point.
#[derive(Debug, Clone, Default)]
pub struct PointOutput {
    /// (column, value) in a fixed order; `None` = not measurable (written as null).
    pub metrics: Vec<(String, Option<f64>)>,
    /// (file name in the point folder, caption).
    pub images: Vec<(String, String)>,
    /// Curves and other detail kept in result.json only (not in the tables).
    pub detail: Value,
}

impl PointOutput {
    /// Add a metric value (non-finite values become `None`).
    pub fn put(&mut self, name: &str, v: f64) {
        self.metrics
            .push((name.to_string(), if v.is_finite() { Some(v) } else { None }));
    }
    /// Add a metric that may be missing.
    pub fn put_opt(&mut self, name: &str, v: Option<f64>) {
        self.metrics
            .push((name.to_string(), v.filter(|x| x.is_finite())));
    }
}
