//! Stage timers for `CAMSIM_PROFILE` (nanoseconds, calls): fit-row and all-row evaluations,
//! forward-model calls.
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
/// (nanoseconds, calls) per stage.
pub static T: [AtomicU64; 6] = [const { AtomicU64::new(0) }; 6];
/// Adds the time since `t0` to timer `k` and counts a call.
pub fn add(k: usize, t0: std::time::Instant) {
    T[2 * k].fetch_add(t0.elapsed().as_nanos() as u64, Relaxed);
    T[2 * k + 1].fetch_add(1, Relaxed);
}
/// Likelihood evaluations so far (fit and all rows).
pub fn calls() -> u64 {
    T[1].load(Relaxed) + T[3].load(Relaxed)
}
/// One line: time and calls per stage.
pub fn summary() -> String {
    let names = [
        "likelihood, fit rows",
        "likelihood, all rows",
        "forward model",
    ];
    names
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
