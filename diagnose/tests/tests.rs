//! Integration tests of camsim-diagnose: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-diagnose --test tests <module>::`).

#[allow(dead_code)]
mod common;
mod coverage;
mod coverage_more;
mod noise_profiles;
mod oracles;
mod spectral_and_sets;
