//! The resource budget (docs/limits.md): before a command allocates, it estimates the memory
//! its validated inputs need (pixels × bands × samples, rays, PSF grids, study points) and
//! refuses anything over the limit with one line naming the key and the estimate.
//!
//! The limit is, in this order: the `--max-memory` value ([`set_max_memory`]); else three
//! quarters of the smaller of the available memory (`MemAvailable` of /proc/meminfo) and the
//! address-space limit (`ulimit -v`); else [`FALLBACK_LIMIT_BYTES`]. The quarter left over
//! covers what the estimates leave out (code, thread stacks, small buffers).
//!
//! Estimates are computed in f64 from the validated values, so they cannot overflow: a
//! size of 1e300 pixels is refused like one of 1e10.
use crate::error::CliError;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// The limit when neither `--max-memory` nor /proc/meminfo gives one: 4 GiB.
pub const FALLBACK_LIMIT_BYTES: u64 = 4 << 30;

/// The most worker threads a command accepts (`--threads`): more than this only adds
/// scheduling overhead and per-thread buffers.
pub const MAX_THREADS: usize = 256;

/// The default work limit: 1e11 elementary samples (path samples, traced rays, PSF
/// samples) — hours on this kind of machine; more is almost always a typo.
pub const DEFAULT_MAX_WORK: f64 = 1e11;

/// 0 = no override.
static OVERRIDE: AtomicU64 = AtomicU64::new(0);
/// 0 = no override (work limit).
static WORK_OVERRIDE: AtomicU64 = AtomicU64::new(0);

/// Override the work limit (`--max-work`, a count of samples); `None` restores the default.
pub fn set_max_work(samples: Option<u64>) {
    WORK_OVERRIDE.store(samples.unwrap_or(0), Ordering::SeqCst);
}

/// The work limit in force (samples).
pub fn work_limit() -> f64 {
    match WORK_OVERRIDE.load(Ordering::SeqCst) {
        0 => DEFAULT_MAX_WORK,
        w => w as f64,
    }
}

/// Refuse a job of more than [`work_limit`] elementary samples (rays, path samples, PSF
/// samples): `"{path}: {key}: needs about 1.2e15 samples (…), over the limit of 1e11;
/// reduce {key} or raise the limit with --max-work"`.
pub fn check_work(
    path: Option<&Path>,
    key: &str,
    samples: f64,
    what: &str,
) -> Result<(), CliError> {
    let lim = work_limit();
    if samples.is_finite() && samples <= lim {
        return Ok(());
    }
    let msg = format!(
        "{key}: needs about {samples:.2e} samples ({what}), over the limit of {lim:.2e}; \
         reduce {key} or raise the limit with --max-work (docs/limits.md)"
    );
    Err(match path {
        Some(p) => CliError::input(p, msg),
        None => CliError::Other(msg),
    })
}

/// Where the memory limit comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitSource {
    /// `--max-memory`.
    Flag,
    /// ¾ of the available memory / address-space limit.
    Available,
    /// [`FALLBACK_LIMIT_BYTES`].
    Fallback,
}

/// The memory limit in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MemoryLimit {
    /// Bytes.
    pub bytes: u64,
    /// Where it comes from.
    pub source: LimitSource,
}

/// Override the limit (`--max-memory`); `None` restores the default.
pub fn set_max_memory(bytes: Option<u64>) {
    OVERRIDE.store(bytes.unwrap_or(0), Ordering::SeqCst);
}

/// Parse a size: a number of bytes with an optional suffix K, M, G or T (powers of 1024;
/// `B`, `iB` and lower case accepted), e.g. `512M`, `1.5G`, `8GiB`, `1000000`.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let lower = t.to_ascii_lowercase();
    let body = lower
        .strip_suffix("ib")
        .or_else(|| lower.strip_suffix('b'))
        .unwrap_or(&lower);
    let (num, mult) = match body.chars().last() {
        Some('k') => (&body[..body.len() - 1], 1u64 << 10),
        Some('m') => (&body[..body.len() - 1], 1 << 20),
        Some('g') => (&body[..body.len() - 1], 1 << 30),
        Some('t') => (&body[..body.len() - 1], 1 << 40),
        _ => (body, 1),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("\"{s}\" is not a size (expected e.g. 512M, 8G or a byte count)"))?;
    let bytes = v * mult as f64;
    if !(bytes.is_finite() && bytes >= 1.0 && bytes < 1.8e19) {
        return Err(format!("\"{s}\" is not a size between 1 byte and 16 EiB"));
    }
    Ok(bytes as u64)
}

/// `MemAvailable` of /proc/meminfo, bytes (None where there is no such file).
pub fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kb.checked_mul(1024)
}

/// The address-space limit (`ulimit -v`), bytes, when one is set.
#[cfg(unix)]
pub fn address_space_limit_bytes() -> Option<u64> {
    // SAFETY: getrlimit writes into a local struct.
    let mut r: libc::rlimit = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut r) } != 0 || r.rlim_cur == libc::RLIM_INFINITY
    {
        return None;
    }
    Some(r.rlim_cur as u64)
}

/// No address-space limit on this platform.
#[cfg(not(unix))]
pub fn address_space_limit_bytes() -> Option<u64> {
    None
}

thread_local! {
    static THREAD_LIMIT: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// Run `f` with the memory limit `bytes` in force on this thread only (it takes precedence
/// over `--max-memory`); for tests and fuzzing, which share one process.
pub fn with_thread_max_memory<R>(bytes: u64, f: impl FnOnce() -> R) -> R {
    struct Reset(u64);
    impl Drop for Reset {
        fn drop(&mut self) {
            THREAD_LIMIT.with(|c| c.set(self.0));
        }
    }
    let _reset = Reset(THREAD_LIMIT.with(|c| c.replace(bytes)));
    f()
}

/// The limit in force (module docs).
pub fn memory_limit() -> MemoryLimit {
    let t = THREAD_LIMIT.with(|c| c.get());
    if t > 0 {
        return MemoryLimit {
            bytes: t,
            source: LimitSource::Flag,
        };
    }
    let o = OVERRIDE.load(Ordering::SeqCst);
    if o > 0 {
        return MemoryLimit {
            bytes: o,
            source: LimitSource::Flag,
        };
    }
    let avail = match (available_memory_bytes(), address_space_limit_bytes()) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    };
    match avail {
        Some(a) => MemoryLimit {
            bytes: a / 4 * 3,
            source: LimitSource::Available,
        },
        None => MemoryLimit {
            bytes: FALLBACK_LIMIT_BYTES,
            source: LimitSource::Fallback,
        },
    }
}

/// A byte count for people: `7.2 GB`, `512 MB`, `3e+15 GB` (decimal units).
pub fn human_bytes(b: f64) -> String {
    if !b.is_finite() {
        return "an unbounded amount".into();
    }
    if b >= 1e15 {
        format!("{:.1e} GB", b / 1e9)
    } else if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.0} MB", b / 1e6)
    } else {
        format!("{:.0} kB", (b / 1e3).ceil())
    }
}

/// Refuse `estimate_bytes` over the limit: `"{path}: {key}: needs about 9.7 GB of memory
/// (640×480 pixels × …), over the limit of 5.1 GB (¾ of the available memory); raise it with
/// --max-memory or reduce {key}"`. `what` spells out the estimate; `path` is the file the key
/// is in (None for command-line options, whose name is then the key).
pub fn check_memory(
    path: Option<&Path>,
    key: &str,
    estimate_bytes: f64,
    what: &str,
) -> Result<(), CliError> {
    let lim = memory_limit();
    if estimate_bytes.is_finite() && estimate_bytes <= lim.bytes as f64 {
        return Ok(());
    }
    let src = match lim.source {
        LimitSource::Flag => "--max-memory",
        LimitSource::Available => "3/4 of the available memory",
        LimitSource::Fallback => "the default when the available memory is unknown",
    };
    let msg = format!(
        "{key}: needs about {} of memory ({what}), over the limit of {} ({src}); \
         reduce {key} or raise the limit with --max-memory (docs/limits.md)",
        human_bytes(estimate_bytes),
        human_bytes(lim.bytes as f64),
    );
    Err(match path {
        Some(p) => CliError::input(p, msg),
        None => CliError::Other(msg),
    })
}

/// Check a worker-thread count (`--threads`): 1 ..= [`MAX_THREADS`].
pub fn check_threads(n: usize) -> Result<usize, CliError> {
    if n == 0 || n > MAX_THREADS {
        return Err(CliError::Other(format!(
            "--threads: must be 1–{MAX_THREADS}, got {n}"
        )));
    }
    Ok(n)
}

/// Install `--threads`, `--max-memory` and `--max-work` for this process: the global thread pool (when `n`
/// is given) and the memory limit.
pub fn configure(
    threads: Option<usize>,
    max_memory: Option<&str>,
    max_work: Option<f64>,
) -> Result<(), CliError> {
    if let Some(w) = max_work {
        if !(w.is_finite() && w >= 1.0 && w < 1.8e19) {
            return Err(CliError::Other(format!(
                "--max-work: must be a sample count ≥ 1, got {w}"
            )));
        }
        set_max_work(Some(w as u64));
    }
    if let Some(s) = max_memory {
        let b = parse_size(s).map_err(|e| CliError::Other(format!("--max-memory: {e}")))?;
        set_max_memory(Some(b));
    }
    if let Some(n) = threads {
        let n = check_threads(n)?;
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .map_err(|e| CliError::Other(format!("--threads: {e}")))?;
    }
    Ok(())
}

/// Bytes of `f32` planes: `count` values × 4 bytes × `copies`.
pub fn f32_bytes(count: f64, copies: f64) -> f64 {
    count * 4.0 * copies
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("1000").unwrap(), 1000);
        assert_eq!(parse_size("512M").unwrap(), 512 << 20);
        assert_eq!(parse_size("8GiB").unwrap(), 8 << 30);
        assert_eq!(parse_size("1.5g").unwrap(), 3 << 29);
        assert!(parse_size("lots").is_err());
        assert!(parse_size("-1G").is_err());
        assert!(parse_size("1e30T").is_err());
    }

    #[test]
    fn the_limit_refuses_with_one_line_naming_key_and_estimate() {
        with_thread_max_memory(1 << 30, || {
            assert!(check_memory(None, "k", 1e8, "x").is_ok());
            let e = check_memory(Some(Path::new("cam.json")), "sensor.rows", 9.7e9, "pixels")
                .unwrap_err()
                .one_line();
            assert!(
                e.starts_with("cam.json: sensor.rows: needs about 9.7 GB"),
                "{e}"
            );
            assert!(e.contains("--max-memory"), "{e}");
            assert!(check_memory(None, "k", f64::INFINITY, "x").is_err());
            assert!(check_memory(None, "k", f64::NAN, "x").is_err());
        });
        let l = memory_limit();
        assert_ne!(l.source, LimitSource::Flag);
        if let Some(a) = available_memory_bytes() {
            assert!(l.bytes <= a);
        }
    }

    #[test]
    fn thread_counts_are_bounded() {
        assert!(check_threads(0).is_err());
        assert!(check_threads(10_000).is_err());
        assert_eq!(check_threads(2).unwrap(), 2);
    }
}
