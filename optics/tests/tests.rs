//! Integration tests of camsim-optics: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-optics --test tests <module>::`).

mod lens_blur;
mod narrow_band;
mod wavefront;
