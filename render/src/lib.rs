//! # camsim-render
//!
//! A spectral path tracer on obvhs that turns glTF 2.0 scenes into depth-aware spectral
//! radiance for the camsim pipeline (scene → optics → sensor → ISP → display), checked against
//! Mitsuba 3 (../shared/tools/mitsuba_ref).
//!
//! * [`gltf_load`]: glTF 2.0 (.gltf/.glb) → [`scene::Scene`] (meshes, node hierarchy, cameras,
//!   materials, KHR lights, textures) with the Mitsuba harness's conventions;
//! * [`animation`]: glTF node translation animations sampled at a time (motion within an
//!   exposure, video);
//! * [`bsdf`]: Lambertian, rough conductor (spectral η/κ), rough dielectric with dispersion,
//!   rough plastic;
//! * [`envmap`]: emissive textures and the equirectangular environment map (RGB EXR upsampled
//!   to spectra, importance-sampled by luminance);
//! * [`normal_map`]: tangent-space normal maps (glTF normalTexture), tangents;
//! * [`integrator`]: path tracing with NEE + MIS, Russian roulette, hero-wavelength sampling,
//!   per-pixel random streams (thread-count independent), rayon over rows;
//! * [`camera`]: the camera contract, pinhole and thin lens;
//! * [`output`]: spectral OpenEXR (Fichet 2021) with `Z` depth and variance, and the core
//!   `SceneRadiance` for the optics stage;
//! * [`gltf_write`]: a small glTF writer used to generate the test scenes.
#![deny(missing_docs)]

pub mod animation;
pub mod bsdf;
pub mod bvh4;
mod bvh8_flat;
mod bvh8_tree;
pub mod camera;
pub mod depth_optics;
pub mod depth_path;
pub mod dof_scene;
pub mod envmap;
pub mod error;
pub mod gltf_load;
pub mod gltf_write;
mod huge_pages;
pub mod integrator;
pub mod job;
pub mod normal_map;
pub mod output;
pub mod plane_fft;
pub mod sampling;
pub mod scene;
pub mod spectral;
pub mod test_scenes;

pub use error::RenderError;
pub use integrator::{render, RenderOutput, RenderSettings};
pub use spectral::Bands;
