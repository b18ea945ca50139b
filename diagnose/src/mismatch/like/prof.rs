//! Stage timers (nanoseconds, calls): fit-row and all-row likelihood evaluations,
//! forward-model calls and the identifiability check. `CAMSIM_PROFILE` prints them; each
//! diagnosis also reports its share ([`since`]) in timing.json.
use crate::mismatch::StageTime;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// The timers' names, in index order.
const NAMES: [&str; 4] = [
    "likelihood, fit rows",
    "likelihood, all rows",
    "forward model",
    "identifiability (Fisher information)",
];

/// (nanoseconds, calls) per stage.
pub static T: [AtomicU64; 8] = [const { AtomicU64::new(0) }; 8];
/// Adds the time since `t0` to timer `k` and counts a call.
pub fn add(k: usize, t0: std::time::Instant) {
    T[2 * k].fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
    T[2 * k + 1].fetch_add(1, Relaxed);
}
/// Likelihood evaluations so far (fit and all rows).
pub fn calls() -> u64 {
    T[1].load(Relaxed) + T[3].load(Relaxed)
}
/// The timers now.
pub fn snapshot() -> [u64; 8] {
    std::array::from_fn(|k| T[k].load(Relaxed))
}
/// Time and calls per timer since `s` (a [`snapshot`]); concurrent diagnoses in one process
/// count into each other's.
pub fn since(s: &[u64; 8]) -> Vec<StageTime> {
    let now = snapshot();
    NAMES
        .iter()
        .enumerate()
        .map(|(k, n)| StageTime {
            stage: n.to_string(),
            seconds: now[2 * k].saturating_sub(s[2 * k]) as f64 * 1e-9,
            calls: Some(now[2 * k + 1].saturating_sub(s[2 * k + 1])),
        })
        .collect()
}
/// One line: time and calls per stage.
pub fn summary() -> String {
    NAMES
        .iter()
        .enumerate()
        .map(|(k, n)| {
            format!(
                "{n}: {:.2} s / {} calls",
                T[2 * k].load(Relaxed) as f64 * 1e-9,
                T[2 * k + 1].load(Relaxed)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}
