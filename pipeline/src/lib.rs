//! # camsim
//!
//! The `camsim` command and its library: input files (camera + capture-set format of
//! ../spec/capture-format.md), and the commands that run the pipeline stages
//! (`camsim-core` → `camsim-optics` → `camsim-sensor`).
#![deny(missing_docs)]

pub mod animated;
pub mod autofocus;
pub mod budget;
pub mod calibrate_cmd;
pub mod chain;
pub mod color_eval;
pub mod config;
pub mod datasets;
pub mod demo;
pub mod develop_cmd;
pub mod diagnose_cmd;
pub mod emva1288_cmd;
pub mod error;
pub mod frames;
pub mod gltf_target;
pub mod guard;
pub mod honest_color;
pub mod lens_cmd;
pub mod metric_cmd;
pub mod noise_profiles_cmd;
pub mod pdaf;
#[doc = include_str!("../../docs/physics.md")]
pub mod physics {}
pub mod pixel_optics_config;
pub mod plots;
pub mod png_stored;
pub mod progress;
pub mod raw_input;
pub mod render_cmd;
pub mod report;
pub mod run;
pub mod scene_cmd;
pub mod scene_files;
pub mod simulate;
pub mod spectrum_file;
pub mod staging;
pub mod study;
pub mod targets;
pub mod validate_cmd;
pub mod world_targets;
