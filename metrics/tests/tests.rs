//! Integration tests of camsim-metrics: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-metrics --test tests <module>::`).

mod hdr_snr;
mod scielab_isetcam;
mod scielab_oracle;
