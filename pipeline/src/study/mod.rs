//! `camsim study SPEC --out DIR`: parameter sweeps evaluated point by point into tables and an
//! HTML report (docs/study.md).
//!
//! * [`spec`]: the study file: a base point document, parameters patching it at JSON paths
//!   (grid or list sweep), plots;
//! * [`hash`]: content addressing: every point is the SHA-256 of its canonical document
//!   (camera, lens, conditions, metrics, camsim version, with referenced files inlined), and
//!   lives in `DIR/points/<first 16 hex digits>/`;
//! * [`point`]: one point: `point.json`, the evaluator chosen by the document's `kind`, and
//!   `result.json` written last and atomically: a point is finished exactly when its
//!   result.json exists, so an interrupted study resumes where it stopped;
//! * [`capture`]: the sensor-level evaluator (MTF50, SNR, vSNR, ΔE2000, dynamic range);
//! * [`render`]: the renderer-based evaluator (depth of field: real-lens camera vs depth path);
//! * [`rolling`]: the rolling-shutter evaluator (skew of a moving edge, LED flicker bands);
//! * [`hdr`](mod@hdr): the HDR pixel evaluator (split pixel, DCG, bracketing vs a standard pixel:
//!   merged SNR against exposure, dynamic range, SNR holes);
//! * [`dual_pixel`](mod@dual_pixel): the dual-pixel evaluator (disparity of an edge against the
//!   thin-lens closed form, phase-detection autofocus);
//! * [`table`] and [`report`]: CSV + JSON tables in spec order, HTML report with plots and
//!   image strips;
//! * [`ray`]: the Ray engine: the same points, each run by `camsim study-point` on a Ray
//!   worker (tools/ray_study.py), so results are those of the local engine.
//!
//! Each point's random seed is derived from its hash, so a point's result does not depend on
//! which other points run, in which order, on how many threads or on which machine.
pub mod capture;
pub mod dual_pixel;
pub mod hash;
pub mod hdr;
pub mod output;
pub mod point;
pub mod ray;
pub mod render;
pub mod report;
pub mod rolling;
pub mod rolling_scene;
pub mod spec;
pub mod table;

use crate::error::CliError;
use rayon::prelude::*;
use serde_json::{json, Value};
use spec::{load_study, Study};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Where the points are evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EngineKind {
    /// In this process, points in parallel (rayon).
    Local,
    /// On a Ray cluster (tools/ray_study.py; Ray installed by tools/ray_setup.sh).
    Ray,
}

/// Options of [`run_study`].
#[derive(Debug, Clone)]
pub struct StudyOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Engine.
    pub engine: EngineKind,
    /// Evaluate at most this many of the unfinished points, then stop (the rest stay pending).
    pub max_points: Option<usize>,
    /// Ray settings (engine ray).
    pub ray: ray::RayOptions,
    /// Progress bar on a terminal.
    pub progress: bool,
}

/// What a study run did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StudySummary {
    /// Points of the sweep (distinct contents).
    pub points: usize,
    /// Points evaluated by this run.
    pub evaluated: usize,
    /// Points found finished and reused.
    pub reused: usize,
    /// Points still unfinished (a --max-points limit).
    pub pending: usize,
}

/// The folder of a point under `out`.
pub fn point_dir(out: &Path, p: &spec::PlannedPoint) -> PathBuf {
    out.join("points").join(p.folder())
}

/// Parameter labels of a point, `name=label, …` (messages and captions).
pub fn point_labels(study: &Study, p: &spec::PlannedPoint) -> String {
    study
        .parameters
        .iter()
        .zip(&p.coords)
        .map(|(q, &i)| format!("{}={}", q.name, q.labels[i]))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Load a study and check every point document (cheaply) before any work.
pub fn plan(spec_path: &Path) -> Result<Study, CliError> {
    let study = load_study(spec_path)?;
    let mut seen = std::collections::HashSet::new();
    for p in &study.points {
        if seen.insert(p.hash.clone()) {
            point::validate(&p.doc).map_err(|m| {
                CliError::input(
                    spec_path,
                    format!("point {} ({}): {m}", p.index, point_labels(&study, p)),
                )
            })?;
        }
    }
    Ok(study)
}

/// Run (or resume) a study: evaluate the unfinished points, then write the tables and report.
pub fn run_study(spec_path: &Path, opts: &StudyOptions) -> Result<StudySummary, CliError> {
    let study = plan(spec_path)?;
    let out = &opts.out;
    std::fs::create_dir_all(out.join("points")).map_err(|e| CliError::output(out, e))?;
    // Distinct points in spec order; finished ones are reused.
    let mut seen = std::collections::HashSet::new();
    let distinct: Vec<&spec::PlannedPoint> = study
        .points
        .iter()
        .filter(|p| seen.insert(p.hash.clone()))
        .collect();
    let (done, mut todo): (Vec<&spec::PlannedPoint>, Vec<&spec::PlannedPoint>) = distinct
        .into_iter()
        .partition(|p| point::is_done(&point_dir(out, p), &p.hash));
    let total_todo = todo.len();
    // Every unfinished point gets its point.json, and pending.txt lists their folders (one
    // per line, absolute): the work list of external launchers (Slurm job arrays).
    let mut pending_list = String::new();
    for p in &todo {
        let d = point_dir(out, p);
        point::write_point_file(&d, &p.doc, &p.hash)?;
        pending_list.push_str(&std::path::absolute(&d).unwrap_or(d).display().to_string());
        pending_list.push('\n');
    }
    let pending_path = out.join("pending.txt");
    camsim_core::exr_io::write_atomically(&pending_path, |tmp| {
        std::fs::write(tmp, pending_list.as_bytes())
    })
    .map_err(|e| CliError::output(&pending_path, e))?;
    if let Some(m) = opts.max_points {
        todo.truncate(m);
    }
    let evaluated = match opts.engine {
        EngineKind::Local => run_local(&study, out, &todo, opts.progress)?,
        EngineKind::Ray => {
            ray::run_ray(
                out,
                &todo.iter().map(|p| point_dir(out, p)).collect::<Vec<_>>(),
                &opts.ray,
            )?;
            for p in &todo {
                if !point::is_done(&point_dir(out, p), &p.hash) {
                    return Err(CliError::Other(format!(
                        "ray engine: point {} ({}) has no result in {}",
                        p.index,
                        point_labels(&study, p),
                        point_dir(out, p).display()
                    )));
                }
            }
            todo.len()
        }
    };
    let summary = StudySummary {
        points: done.len() + total_todo,
        evaluated,
        reused: done.len(),
        pending: total_todo - todo.len(),
    };
    let results: Vec<Option<Value>> = study
        .points
        .iter()
        .map(|p| {
            point::read_result(&point_dir(out, p)).filter(|r| r["hash"].as_str() == Some(&p.hash))
        })
        .collect();
    let tab = table::build(&study, &results);
    table::write(out, &tab)?;
    report::write(out, &study, &tab, &results, &summary)?;
    Ok(summary)
}

fn run_local(
    study: &Study,
    out: &Path,
    todo: &[&spec::PlannedPoint],
    progress: bool,
) -> Result<usize, CliError> {
    let bar = crate::progress::bar(
        progress,
        todo.len() as u64,
        "{spinner} study [{bar:40}] {pos}/{len} points ({eta}) {msg}",
    );
    let count = AtomicUsize::new(0);
    let caches = capture::StudyCaches::default();
    let errors: Vec<CliError> = todo
        .par_iter()
        .filter_map(|p| {
            let dir = point_dir(out, p);
            let r = point::evaluate_into(&p.doc, &p.hash, &dir, &caches).map_err(|e| {
                CliError::Other(format!(
                    "point {} ({}): {}",
                    p.index,
                    point_labels(study, p),
                    e.one_line()
                ))
            });
            count.fetch_add(1, Ordering::Relaxed);
            bar.inc(1);
            r.err()
        })
        .collect();
    bar.finish_and_clear();
    match errors.into_iter().next() {
        Some(e) => Err(e),
        None => Ok(count.into_inner()),
    }
}

/// `camsim study-point POINT.json --out DIR`: evaluate one point written by `camsim study`
/// (the Ray and Slurm workers run this). A point already finished is left as it is.
pub fn run_point_file(point_file: &Path, out: &Path) -> Result<Value, CliError> {
    let (doc, hash) = point::read_point_file(point_file)?;
    if point::is_done(out, &hash) {
        return Ok(point::read_result(out).unwrap_or(json!({})));
    }
    point::validate(&doc).map_err(|m| CliError::input(point_file, m))?;
    if !out.join("point.json").exists() {
        point::write_point_file(out, &doc, &hash)?;
    }
    point::evaluate_into(&doc, &hash, out, &capture::StudyCaches::default())
}
