//! All-or-nothing output: files are written into a staging folder inside the output folder
//! and moved into place only when the whole command succeeded; on error nothing is left.
use crate::error::CliError;
use std::path::{Path, PathBuf};

/// Run `work` with a staging folder; it returns the files it wrote (relative paths), which
/// are then moved to `out`. On error the staging folder (and `out`, if this call created it)
/// is removed.
pub fn with_staging(
    out: &Path,
    work: impl FnOnce(&Path) -> Result<Vec<PathBuf>, CliError>,
) -> Result<Vec<PathBuf>, CliError> {
    let created_out = !out.exists();
    std::fs::create_dir_all(out).map_err(|e| CliError::output(out, e))?;
    let staging = out.join(format!(".camsim-staging-{}", std::process::id()));
    std::fs::create_dir_all(&staging).map_err(|e| CliError::output(&staging, e))?;
    let result = work(&staging).and_then(|files| {
        for rel in &files {
            let dst = out.join(rel);
            if let Some(parent) = dst.parent() {
                std::fs::create_dir_all(parent).map_err(|e| CliError::output(parent, e))?;
            }
            std::fs::rename(staging.join(rel), &dst).map_err(|e| CliError::output(&dst, e))?;
        }
        Ok(files)
    });
    let _ = std::fs::remove_dir_all(&staging);
    if result.is_err() && created_out {
        let _ = std::fs::remove_dir_all(out);
    }
    result
}
