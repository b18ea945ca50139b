//! Issue 16: hostile input and output integrity (docs/limits.md).
//!
//! * [`examples`]: every example of the issue, under `ulimit -v 8000000` and a 30 s timeout;
//! * [`integrity`]: SIGINT on a real child, inputs never overwritten, all-or-nothing sets,
//!   byte-identical outputs at 1 and 2 threads;
//! * [`fuzz`]: ≥ 10 000 deterministic mutations per reader.
mod examples;
mod fuzz;
mod integrity;

use std::path::Path;
use std::time::{Duration, Instant};

/// What one limited run of the camsim binary did.
pub struct Outcome {
    /// Exit status (None: killed by a signal).
    pub code: Option<i32>,
    /// stderr.
    pub stderr: String,
    /// Wall time.
    pub elapsed: Duration,
    /// The arguments (for messages).
    pub args: Vec<String>,
}

impl Outcome {
    /// Exit 2 with one error line that contains every key; no panic or abort.
    #[track_caller]
    pub fn assert_refused(&self, keys: &[&str]) {
        let lines: Vec<&str> = self
            .stderr
            .lines()
            .filter(|l| !l.trim().is_empty())
            .collect();
        assert_eq!(
            self.code,
            Some(2),
            "{:?}: expected exit 2, got {:?} after {:.1} s: {}",
            self.args,
            self.code,
            self.elapsed.as_secs_f64(),
            self.stderr
        );
        assert_eq!(
            lines.len(),
            1,
            "{:?}: not one line: {}",
            self.args,
            self.stderr
        );
        assert!(
            lines[0].starts_with("camsim: error: "),
            "{:?}: {}",
            self.args,
            lines[0]
        );
        for k in keys {
            assert!(
                lines[0].contains(k),
                "{:?}: {k:?} missing from: {}",
                self.args,
                lines[0]
            );
        }
    }

    /// Exit 0.
    #[track_caller]
    pub fn assert_ok(&self) {
        assert_eq!(
            self.code,
            Some(0),
            "{:?}: failed after {:.1} s: {}",
            self.args,
            self.elapsed.as_secs_f64(),
            self.stderr
        );
    }
}

/// Run camsim in `dir` with `args` under `ulimit -v 8000000` (8 GB of address space) and a
/// 30 s timeout (SIGKILL), as acceptance 1 of issue 16 asks.
pub fn camsim_limited(args: &[&str], dir: &Path) -> Outcome {
    let start = Instant::now();
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -v 8000000 && exec timeout -s KILL 30 \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_camsim"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("sh");
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        !stderr.contains("panicked") && !stderr.contains("memory allocation"),
        "{args:?}: {stderr}"
    );
    Outcome {
        code: out.status.code(),
        stderr,
        elapsed: start.elapsed(),
        args: args.iter().map(|s| s.to_string()).collect(),
    }
}
