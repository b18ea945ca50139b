//! Integration tests of camsim-isp: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-isp --test tests <module>::`).

mod hdr_merge;
