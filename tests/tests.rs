//! camsim's integration tests: one test binary (ripgrep style), one module per concern.
mod calibrate;
mod cli;
mod diagnose;
mod effects;
mod hostile;
mod lens_blur;
mod lens_cli;
mod oracles;
mod raw_formats;
mod real_data;
mod render;
mod run;
mod statistics;
mod study;
mod util;
mod validate;
