//! The Ray engine: camsim writes every unfinished point's `point.json`, lists them in
//! `DIR/ray_points.json`, and runs tools/ray_study.py (embedded in the binary) with the Ray
//! virtual environment's Python. The script submits one Ray task per point; each task runs
//! `camsim --threads 1 study-point POINT.json --out POINT_DIR`, the same Rust code as the
//! local engine, so results are identical. Workers must see the output folder and the camsim
//! binary at the same paths (one machine, or a shared file system).
use crate::error::CliError;
use serde_json::json;
use std::path::{Path, PathBuf};

/// The launcher script (tools/ray_study.py).
pub const RAY_STUDY_PY: &str = include_str!("../../../tools/ray_study.py");

/// Ray settings.
#[derive(Debug, Clone, Default)]
pub struct RayOptions {
    /// Address of a running cluster (`ray start --head` prints it); default: the RAY_ADDRESS
    /// environment variable, else a local cluster started (and stopped) by the launcher.
    pub address: Option<String>,
    /// CPUs of the local cluster the launcher starts (default: all).
    pub num_cpus: Option<usize>,
    /// The Python that has Ray (default: CAMSIM_RAY_PYTHON, else `.venv-ray/bin/python` in
    /// the current folder or above the camsim binary, as tools/ray_setup.sh makes it).
    pub python: Option<PathBuf>,
}

/// Find the Python interpreter with Ray.
pub fn find_python(opts: &RayOptions) -> Result<PathBuf, CliError> {
    if let Some(p) = &opts.python {
        return Ok(p.clone());
    }
    if let Some(p) = std::env::var_os("CAMSIM_RAY_PYTHON") {
        return Ok(PathBuf::from(p));
    }
    let mut starts: Vec<PathBuf> = Vec::new();
    if let Ok(d) = std::env::current_dir() {
        starts.push(d);
    }
    if let Ok(e) = std::env::current_exe() {
        if let Some(d) = e.parent() {
            starts.push(d.to_path_buf());
        }
    }
    for s in starts {
        for d in s.ancestors() {
            let p = d.join(".venv-ray/bin/python");
            if p.is_file() {
                return Ok(p);
            }
        }
    }
    Err(CliError::Other(
        "engine ray: no Python with Ray found (run tools/ray_setup.sh, or give --ray-python or CAMSIM_RAY_PYTHON)".into(),
    ))
}

/// Evaluate the points in `dirs` (each holding a point.json) on Ray.
pub fn run_ray(out: &Path, dirs: &[PathBuf], opts: &RayOptions) -> Result<(), CliError> {
    if dirs.is_empty() {
        return Ok(());
    }
    let python = find_python(opts)?;
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let list = json!({
        "points": dirs.iter().map(|d| json!({
            "point": abs(&d.join("point.json")).display().to_string(),
            "out": abs(d).display().to_string(),
        })).collect::<Vec<_>>()
    });
    let list_path = out.join("ray_points.json");
    std::fs::write(
        &list_path,
        serde_json::to_string_pretty(&list).expect("json"),
    )
    .map_err(|e| CliError::output(&list_path, e))?;
    let script = out.join(".ray_study.py");
    std::fs::write(&script, RAY_STUDY_PY).map_err(|e| CliError::output(&script, e))?;
    let exe = std::env::current_exe().map_err(|e| {
        CliError::Other(format!("engine ray: cannot locate the camsim binary: {e}"))
    })?;
    let mut cmd = std::process::Command::new(&python);
    cmd.arg(&script)
        .arg("--camsim")
        .arg(&exe)
        .arg("--points")
        .arg(abs(&list_path));
    if let Some(a) = opts
        .address
        .clone()
        .or_else(|| std::env::var("RAY_ADDRESS").ok().filter(|s| !s.is_empty()))
    {
        cmd.arg("--address").arg(a);
    }
    if let Some(n) = opts.num_cpus {
        cmd.arg("--num-cpus").arg(n.to_string());
    }
    let status = cmd.status().map_err(|e| {
        CliError::Other(format!(
            "engine ray: cannot run {}: {e} (run tools/ray_setup.sh)",
            python.display()
        ))
    })?;
    let _ = std::fs::remove_file(&script);
    if !status.success() {
        return Err(CliError::Other(format!(
            "engine ray: tools/ray_study.py failed ({status}); finished points are kept, run again to resume"
        )));
    }
    Ok(())
}
