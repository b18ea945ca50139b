//! Write the depth-of-field scene scenes/dof_tiles.gltf (+ .bin):
//! `cargo run --release -p camsim-render --example make_dof_scene [-- OUT_DIR]`.
//! 16 slanted-edge tiles at vergences 0.12–0.88 m⁻¹ (camsim_render::dof_scene::shipped).
use std::path::PathBuf;

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes"));
    std::fs::create_dir_all(&dir).expect("create the output folder");
    let p = dir.join("dof_tiles.gltf");
    camsim_render::dof_scene::shipped()
        .builder()
        .write(&p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    println!("wrote {}", p.display());
}
