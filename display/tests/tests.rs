//! Integration tests of camsim-display: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-display --test tests <module>::`).

mod display;
