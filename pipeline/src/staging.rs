//! All-or-nothing output sets.
//!
//! A command writes its files into a staging folder inside the output folder; only when the
//! whole command succeeded are they moved into place, as one set:
//!
//! * the set is checked first (relative paths, no duplicates, no folder where a file should
//!   go, no file where a folder should go, no file that is an input of the command);
//! * files of an earlier run that the set replaces are moved aside into a backup folder, the
//!   new files are moved in, and the backup is removed. If any move fails, the new files are
//!   removed and the old ones moved back, so `--out` holds either the old set or the new one,
//!   never a mix;
//! * the staging (and backup) folder is removed on error, on panic (a drop guard) and on
//!   SIGINT/SIGTERM/SIGHUP (see [`install_signal_cleanup`]: the signal waits for a commit in
//!   progress to finish or roll back, then removes every staging folder and exits with
//!   128 + the signal number);
//! * an output file that would replace an input of the command (registered with
//!   [`protect_input`]: recordings, captures, cameras, configs, scenes, lenses) is refused
//!   before anything is moved.
//!
//! Only a SIGKILL or a power cut during the (short) commit can leave a mix; the backup folder
//! `.camsim-backup-<pid>` then still holds the old files.
use crate::error::CliError;
use std::collections::HashSet;
use std::path::{Component, Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// Folders to remove when the process is interrupted (staging and backup folders, and output
/// folders this process created and has not filled yet).
static CLEANUP: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Held while a set is being moved into place; the signal handler takes it before cleaning
/// up, so an interrupt never lands in the middle of a commit.
static COMMIT: Mutex<()> = Mutex::new(());
/// Set by the signal thread when an interrupt arrives.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// When an interrupt is being handled, never return: the signal thread is removing the
/// staging folders and will end the process with 128 + signal. Called on error paths, so that
/// an error caused by the cleanup (a vanished staging folder) does not race the exit status.
pub fn wait_if_interrupted() {
    if INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        loop {
            std::thread::park();
        }
    }
}

/// Canonical paths of the command's input files.
static INPUTS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn lock<T>(m: &'static Mutex<T>) -> MutexGuard<'static, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Register an input file of the running command: no output set may replace it. Paths that do
/// not exist (yet) are ignored.
pub fn protect_input(path: &Path) {
    if let Ok(c) = std::fs::canonicalize(path) {
        let mut v = lock(&INPUTS);
        if !v.contains(&c) {
            v.push(c);
        }
    }
}

/// Forget every registered input (for tests and long-running callers that run several
/// commands in one process).
pub fn clear_protected_inputs() {
    lock(&INPUTS).clear();
}

fn is_protected(path: &Path) -> bool {
    match std::fs::canonicalize(path) {
        Ok(c) => lock(&INPUTS).contains(&c),
        Err(_) => false,
    }
}

fn register(dir: &Path) {
    lock(&CLEANUP).push(dir.to_path_buf());
}

fn unregister(dir: &Path) {
    lock(&CLEANUP).retain(|d| d != dir);
}

/// Block SIGINT, SIGTERM and SIGHUP in the calling thread (and so in every thread it starts
/// afterwards) and start a thread that waits for them: on a signal it waits for a commit in
/// progress, removes every staging folder and exits with status 128 + signal. Call it first
/// thing in `main`, before any thread is started. Child processes get the default signal mask
/// back (the standard library resets it on spawn). Idempotent.
#[cfg(unix)]
pub fn install_signal_cleanup() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: plain POSIX calls on a local, zero-initialised sigset_t.
        let set = unsafe {
            let mut set: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut set);
            libc::sigaddset(&mut set, libc::SIGINT);
            libc::sigaddset(&mut set, libc::SIGTERM);
            libc::sigaddset(&mut set, libc::SIGHUP);
            libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
            set
        };
        let _ = std::thread::Builder::new()
            .name("camsim-signals".into())
            .spawn(move || loop {
                let mut sig: libc::c_int = 0;
                // SAFETY: `set` is a valid sigset_t; sigwait only writes `sig`.
                if unsafe { libc::sigwait(&set, &mut sig) } != 0 {
                    continue;
                }
                INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
                camsim_core::cleanup::stop_writes();
                let _commit = lock(&COMMIT);
                cleanup_all();
                eprintln!("camsim: interrupted (signal {sig}); no output was written");
                std::process::exit(128 + sig);
            });
    });
}

/// No signal handling on this platform.
#[cfg(not(unix))]
pub fn install_signal_cleanup() {}

fn cleanup_all() {
    camsim_core::cleanup::remove_all();
    let dirs: Vec<PathBuf> = lock(&CLEANUP).drain(..).collect();
    for d in dirs.iter().rev() {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// Removes the staging folder (and the output folder, when this call created it and the set
/// was not committed) when dropped: on error and on panic.
struct Guard {
    staging: PathBuf,
    out: PathBuf,
    created_out: bool,
    committed: bool,
}

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
        unregister(&self.staging);
        if self.created_out {
            if !self.committed {
                let _ = std::fs::remove_dir_all(&self.out);
            }
            unregister(&self.out);
        }
    }
}

/// Run `work` with a staging folder; it returns the files it wrote (relative paths), which
/// are then moved to `out` as one set (module docs). On error or panic the staging folder (and
/// `out`, if this call created it) is removed and `out` keeps its earlier files.
pub fn with_staging(
    out: &Path,
    work: impl FnOnce(&Path) -> Result<Vec<PathBuf>, CliError>,
) -> Result<Vec<PathBuf>, CliError> {
    if out.exists() && !out.is_dir() {
        return Err(CliError::output(out, "exists and is not a folder"));
    }
    if is_protected(out) {
        return Err(CliError::output(out, "is an input of this command"));
    }
    let created_out = !out.exists();
    std::fs::create_dir_all(out).map_err(|e| CliError::output(out, e))?;
    let staging = out.join(format!(".camsim-staging-{}", std::process::id()));
    let mut guard = Guard {
        staging: staging.clone(),
        out: out.to_path_buf(),
        created_out,
        committed: false,
    };
    if created_out {
        register(out);
    }
    register(&staging);
    std::fs::create_dir_all(&staging).map_err(|e| CliError::output(&staging, e))?;
    let files = match work(&staging) {
        Ok(f) => f,
        Err(e) => {
            wait_if_interrupted();
            return Err(e);
        }
    };
    let _commit = lock(&COMMIT);
    commit(out, &staging, &files)?;
    guard.committed = true;
    Ok(files)
}

/// Check that `rel` is a plain relative path (no root, no `..`, no `.` only).
fn plain_relative(rel: &Path) -> bool {
    !rel.as_os_str().is_empty()
        && rel
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
        && rel.components().any(|c| matches!(c, Component::Normal(_)))
}

fn normalised(rel: &Path) -> PathBuf {
    rel.components()
        .filter(|c| matches!(c, Component::Normal(_)))
        .collect()
}

/// Check the whole set, then move it into place with rollback (module docs).
fn commit(out: &Path, staging: &Path, files: &[PathBuf]) -> Result<(), CliError> {
    // 1. Check everything before touching `out`.
    let mut seen = HashSet::new();
    let mut rels = Vec::with_capacity(files.len());
    for rel in files {
        if !plain_relative(rel) {
            return Err(CliError::output(
                &out.join(rel),
                "an output path must be relative and inside the output folder",
            ));
        }
        let rel = normalised(rel);
        if !seen.insert(rel.clone()) {
            return Err(CliError::output(
                &out.join(&rel),
                "written twice by this command (duplicate output path)",
            ));
        }
        let src = staging.join(&rel);
        if !src.is_file() {
            return Err(CliError::output(&src, "missing from the staging folder"));
        }
        let dst = out.join(&rel);
        if dst.is_dir() {
            return Err(CliError::output(
                &dst,
                "a folder is in the way of this file",
            ));
        }
        let mut anc = rel.parent();
        while let Some(a) = anc.filter(|a| !a.as_os_str().is_empty()) {
            let p = out.join(a);
            if p.exists() && !p.is_dir() {
                return Err(CliError::output(&p, "a file is in the way of this folder"));
            }
            anc = a.parent();
        }
        if is_protected(&dst) {
            return Err(CliError::output(
                &dst,
                "would overwrite an input of this command (recording, captures, camera, \
                 config, scene or lens); choose another --out",
            ));
        }
        rels.push(rel);
    }
    // 2. Move old files aside, new files in; roll back on the first failure.
    let backup = out.join(format!(".camsim-backup-{}", std::process::id()));
    let mut backed_up: Vec<&PathBuf> = Vec::new();
    let mut moved_in: Vec<&PathBuf> = Vec::new();
    let mut result = Ok(());
    for rel in &rels {
        let dst = out.join(rel);
        if dst.exists() {
            let b = backup.join(rel);
            let r = b
                .parent()
                .map_or(Ok(()), std::fs::create_dir_all)
                .and_then(|_| std::fs::rename(&dst, &b));
            if let Err(e) = r {
                result = Err(CliError::output(&dst, e));
                break;
            }
            backed_up.push(rel);
        }
        let r = dst
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|_| std::fs::rename(staging.join(rel), &dst));
        if let Err(e) = r {
            result = Err(CliError::output(&dst, e));
            break;
        }
        moved_in.push(rel);
    }
    if result.is_err() {
        for rel in moved_in {
            let _ = std::fs::remove_file(out.join(rel));
        }
        for rel in backed_up {
            let _ = std::fs::rename(backup.join(rel), out.join(rel));
        }
    }
    let _ = std::fs::remove_dir_all(&backup);
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, rel: &str, text: &str) -> PathBuf {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, text).unwrap();
        PathBuf::from(rel)
    }

    fn listing(dir: &Path) -> Vec<(String, String)> {
        let mut v = Vec::new();
        fn walk(base: &Path, d: &Path, v: &mut Vec<(String, String)>) {
            for e in std::fs::read_dir(d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    walk(base, &p, v);
                } else {
                    v.push((
                        p.strip_prefix(base).unwrap().display().to_string(),
                        std::fs::read_to_string(&p).unwrap_or_default(),
                    ));
                }
            }
        }
        walk(dir, dir, &mut v);
        v.sort();
        v
    }

    #[test]
    fn a_failed_set_leaves_the_old_files_untouched() {
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("out");
        with_staging(&out, |s| {
            Ok(vec![
                write(s, "a.txt", "old a"),
                write(s, "b/c.txt", "old c"),
            ])
        })
        .unwrap();
        let before = listing(&out);
        // A duplicate path, a folder in the way, a file in the way: nothing changes.
        let dup = with_staging(&out, |s| {
            Ok(vec![write(s, "a.txt", "new a"), PathBuf::from("a.txt")])
        });
        assert!(dup.unwrap_err().one_line().contains("duplicate"));
        assert_eq!(listing(&out), before);
        std::fs::create_dir_all(out.join("d.txt")).unwrap();
        let folder = with_staging(&out, |s| {
            Ok(vec![write(s, "a.txt", "new a"), write(s, "d.txt", "new d")])
        });
        assert!(folder
            .unwrap_err()
            .one_line()
            .contains("folder is in the way"));
        std::fs::remove_dir(out.join("d.txt")).unwrap();
        assert_eq!(listing(&out), before);
        let file = with_staging(&out, |s| {
            Ok(vec![write(s, "z.txt", "new z"), write(s, "a.txt/x", "new")])
        });
        assert!(file.unwrap_err().one_line().contains("file is in the way"));
        assert_eq!(listing(&out), before);
        // A failing command and a panicking one leave no staging folder.
        let err = with_staging(&out, |s| {
            write(s, "a.txt", "new a");
            Err(CliError::Other("boom".into()))
        });
        assert!(err.is_err());
        let r = std::panic::catch_unwind(|| {
            let _ = with_staging(&out, |s| {
                write(s, "a.txt", "new a");
                panic!("boom")
            });
        });
        assert!(r.is_err());
        assert_eq!(listing(&out), before);
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 2); // a.txt, b/
                                                                 // A good set replaces the old one.
        with_staging(&out, |s| Ok(vec![write(s, "a.txt", "new a")])).unwrap();
        assert_eq!(std::fs::read_to_string(out.join("a.txt")).unwrap(), "new a");
    }

    #[test]
    fn a_failed_set_removes_an_output_folder_it_created() {
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("new");
        let r = with_staging(&out, |_| Err(CliError::Other("boom".into())));
        assert!(r.is_err());
        assert!(!out.exists());
    }

    #[test]
    fn an_input_is_never_overwritten() {
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("rec");
        std::fs::create_dir_all(out.join("frames")).unwrap();
        std::fs::write(out.join("frames/f0.png"), "recorded").unwrap();
        protect_input(&out.join("frames/f0.png"));
        let r = with_staging(&out, |s| Ok(vec![write(s, "frames/f0.png", "simulated")]));
        let msg = r.unwrap_err().one_line();
        assert!(msg.contains("would overwrite an input"), "{msg}");
        assert_eq!(
            std::fs::read_to_string(out.join("frames/f0.png")).unwrap(),
            "recorded"
        );
    }
}
