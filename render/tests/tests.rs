//! Integration tests of camsim-render: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-render --test tests <module>::`).

mod animation;
mod blender_features;
mod bvh;
mod crosscheck_scenes;
mod depth_crosscheck;
mod depth_path;
mod dual_pixel_lens;
mod gltf_input;
mod lightfield;
mod mitsuba;
mod physics;
mod real_lens;
mod real_lens_crosscheck;
mod samplers;
mod test_lenses;
