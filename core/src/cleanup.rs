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

/// Writers hold this for reading while they create something on disk; the signal handler
/// takes it for writing (and never gives it back), so that nothing is created after it has
/// started removing the staging folders.
static GATE: std::sync::RwLock<()> = std::sync::RwLock::new(());
/// Set when the process is being interrupted: every gated write then waits for the exit.
static STOPPING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn park_forever() -> ! {
    loop {
        std::thread::park();
    }
}

/// Run `create` (a file write, a rename, a `create_dir_all`) unless the process is being
/// interrupted, in which case the calling thread waits for the exit instead. The signal
/// handler calls [`stop_writes`] before it removes anything, so a folder it removed can not be
/// created again by a writer that was mid-way. Do not nest calls.
pub fn gated<T>(create: impl FnOnce() -> T) -> T {
    use std::sync::atomic::Ordering;
    if STOPPING.load(Ordering::SeqCst) {
        park_forever();
    }
    let _g = GATE.read().unwrap_or_else(|p| p.into_inner());
    if STOPPING.load(Ordering::SeqCst) {
        drop(_g);
        park_forever();
    }
    create()
}

/// `std::fs::create_dir_all` through [`gated`].
pub fn create_dir_all(path: &Path) -> std::io::Result<()> {
    gated(|| std::fs::create_dir_all(path))
}

/// For the signal handler: make every later [`gated`] call wait for the exit, and wait for
/// the ones in flight to finish. Call it before removing staging folders; the process must
/// exit afterwards.
pub fn stop_writes() {
    STOPPING.store(true, std::sync::atomic::Ordering::SeqCst);
    let g = GATE.write().unwrap_or_else(|p| p.into_inner());
    std::mem::forget(g);
}

#[cfg(test)]
mod tests {
    #[test]
    fn gated_runs_the_write() {
        assert_eq!(super::gated(|| 7), 7);
    }
}
