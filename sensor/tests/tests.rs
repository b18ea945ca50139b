//! Integration tests of camsim-sensor: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-sensor --test tests <module>::`).

mod effects;
mod hdr;
mod isetcam_oracle;
mod line_noise;
mod pixel_optics;
mod statistics;
mod temporal;
mod temporal_nodes;
