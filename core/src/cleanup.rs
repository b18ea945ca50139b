//! Temporary files in flight: [`crate::exr_io::write_atomically`] registers each temporary
//! file while it exists, so that a signal handler (camsim's: `camsim_pipeline::staging`) can
//! remove them when the process is interrupted.
use std::path::{Path, PathBuf};
use std::sync::Mutex;

static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn pending() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    PENDING.lock().unwrap_or_else(|p| p.into_inner())
}

/// Note a temporary file that must not outlive the process.
pub fn register(path: &Path) {
    pending().push(path.to_path_buf());
}

/// The temporary file was renamed into place or removed.
pub fn unregister(path: &Path) {
    pending().retain(|p| p != path);
}

/// Remove every registered temporary file (on interruption).
pub fn remove_all() {
    for p in pending().drain(..) {
        let _ = std::fs::remove_file(p);
    }
}
