//! One study point: its document, the evaluator chosen by the document's `kind`, and the
//! folder it is written to (`point.json`, images, then `result.json` last and atomically, so
//! a point is finished exactly when its `result.json` exists).
//!
//! Evaluators are a closed enum keyed by `kind`: today `"capture"` (the camera's sensor-level
//! pipeline, [`super::capture`]). A renderer-based kind (`"render"`: a glTF scene through the
//! render crate's cameras, then the same metrics on the rendered irradiance) is added by a new
//! variant of [`PointKind`] and its own module; the spec, hashing, folders, engines, tables
//! and reports do not change.
use super::capture;
pub use super::hash::cache_key;
pub use super::output::PointOutput;
use super::render;
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// The point evaluators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PointKind {
    /// Sensor-level capture of test targets through the camera (MTF50, SNR, vSNR, ΔE, DR).
    Capture,
    /// glTF scenes through the render crate's cameras (depth of field: real lens vs depth
    /// path), measured on the rendered images ([`super::render`]).
    Render,
    /// A moving edge under a PWM light through a rolling shutter: skew and flicker band
    /// period against their closed forms ([`super::rolling`]).
    RollingShutter,
    /// One HDR pixel design (split pixel, DCG, bracketing, or the standard pixel) at one
    /// exposure: merged SNR simulated and in closed form, dynamic range, SNR holes
    /// ([`super::hdr`]).
    Hdr,
    /// A vertical edge at one distance through a dual-pixel camera: disparity against the
    /// thin-lens closed form, and a phase-detection autofocus loop ([`super::dual_pixel`]).
    DualPixel,
}

impl PointKind {
    /// The evaluator named by the document's `kind`.
    pub fn of(doc: &Value) -> Result<Self, String> {
        match doc.get("kind").and_then(Value::as_str) {
            Some("capture") => Ok(PointKind::Capture),
            Some("render") => Ok(PointKind::Render),
            Some("rolling_shutter") => Ok(PointKind::RollingShutter),
            Some("hdr") => Ok(PointKind::Hdr),
            Some("dual_pixel") => Ok(PointKind::DualPixel),
            Some(other) => Err(format!(
                "kind: unknown point kind \"{other}\" (expected \"capture\", \"render\", \"rolling_shutter\", \"hdr\" or \"dual_pixel\")"
            )),
            None => Err("kind: required (a string)".into()),
        }
    }
}

/// Check a point document without evaluating it (cheap: no lens field model, no images).
pub fn validate(doc: &Value) -> Result<(), String> {
    match PointKind::of(doc)? {
        PointKind::Capture => capture::validate(doc),
        PointKind::Render => render::validate(doc),
        PointKind::RollingShutter => super::rolling::validate(doc),
        PointKind::Hdr => super::hdr::validate(doc),
        PointKind::DualPixel => super::dual_pixel::validate(doc),
    }
}

/// The per-point seed: the document's `seed`, else the first 64 bits of its hash.
pub fn seed_of(doc: &Value, hash: &str) -> u64 {
    doc.get("seed")
        .and_then(Value::as_u64)
        .unwrap_or_else(|| u64::from_str_radix(&hash[..16], 16).unwrap_or(0))
}

/// Is the point in `dir` finished (result.json present and for this hash)?
pub fn is_done(dir: &Path, hash: &str) -> bool {
    read_result(dir)
        .map(|r| r["hash"].as_str() == Some(hash))
        .unwrap_or(false)
}

/// The result.json of a finished point.
pub fn read_result(dir: &Path) -> Option<Value> {
    let text = std::fs::read_to_string(dir.join("result.json")).ok()?;
    serde_json::from_str(&text).ok()
}

/// Write `point.json` (the document and its hash) into `dir`, atomically.
pub fn write_point_file(dir: &Path, doc: &Value, hash: &str) -> Result<PathBuf, CliError> {
    std::fs::create_dir_all(dir).map_err(|e| CliError::output(dir, e))?;
    let p = dir.join("point.json");
    let text = serde_json::to_string_pretty(&json!({"hash": hash, "document": doc})).expect("json");
    write_atomically(&p, |tmp| std::fs::write(tmp, text.as_bytes()))
        .map_err(|e| CliError::output(&p, e))?;
    Ok(p)
}

/// Read a `point.json` written by [`write_point_file`]; the hash is checked against the
/// document's content.
pub fn read_point_file(path: &Path) -> Result<(Value, String), CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::input(path, format!("cannot read: {e}")))?;
    let v: Value =
        serde_json::from_str(&text).map_err(|e| CliError::input(path, format!("invalid: {e}")))?;
    let doc = v
        .get("document")
        .cloned()
        .ok_or_else(|| CliError::input(path, "document: required"))?;
    let hash = super::hash::json_hash(&doc);
    if let Some(h) = v.get("hash").and_then(Value::as_str) {
        if h != hash {
            return Err(CliError::input(
                path,
                format!("hash: {h} does not match the document's content hash {hash}"),
            ));
        }
    }
    Ok((doc, hash))
}

/// Evaluate the point `doc` (content hash `hash`) into `dir`: images first, result.json last
/// (atomically). Returns the result.
pub fn evaluate_into(
    doc: &Value,
    hash: &str,
    dir: &Path,
    caches: &capture::StudyCaches,
) -> Result<Value, CliError> {
    std::fs::create_dir_all(dir).map_err(|e| CliError::output(dir, e))?;
    let point_path = dir.join("point.json");
    let kind = PointKind::of(doc).map_err(|m| CliError::input(&point_path, m))?;
    let seed = seed_of(doc, hash);
    let out = match kind {
        PointKind::Capture => capture::evaluate(doc, seed, dir, caches)
            .map_err(|e| CliError::input(&point_path, e.one_line()))?,
        PointKind::Render => render::evaluate(doc, seed, dir)
            .map_err(|e| CliError::input(&point_path, e.one_line()))?,
        PointKind::RollingShutter => super::rolling::evaluate(doc, seed, dir)
            .map_err(|e| CliError::input(&point_path, e.one_line()))?,
        PointKind::Hdr => super::hdr::evaluate(doc, seed, dir)
            .map_err(|e| CliError::input(&point_path, e.one_line()))?,
        PointKind::DualPixel => super::dual_pixel::evaluate(doc, seed, dir)
            .map_err(|e| CliError::input(&point_path, e.one_line()))?,
    };
    let metrics: serde_json::Map<String, Value> = out
        .metrics
        .iter()
        .map(|(k, v)| (k.clone(), v.map_or(Value::Null, |x| json!(x))))
        .collect();
    let result = json!({
        "hash": hash,
        "camsim_version": env!("CARGO_PKG_VERSION"),
        "seed": seed,
        "metric_order": out.metrics.iter().map(|m| m.0.clone()).collect::<Vec<_>>(),
        "metrics": metrics,
        "images": out.images.iter().map(|(f, c)| json!({"file": f, "caption": c})).collect::<Vec<_>>(),
        "detail": out.detail,
    });
    let p = dir.join("result.json");
    let text = serde_json::to_string_pretty(&result).expect("json");
    write_atomically(&p, |tmp| std::fs::write(tmp, text.as_bytes()))
        .map_err(|e| CliError::output(&p, e))?;
    Ok(result)
}
