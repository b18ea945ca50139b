//! Regenerate the glTF scenes of scenes/ (`cargo run --release -p camsim-render --example
//! make_scenes [-- OUT_DIR]`, default `<repo>/scenes`). The same code builds the scenes the
//! tests check (camsim_render::test_scenes).
use std::path::PathBuf;

fn main() {
    let dir = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes"));
    std::fs::create_dir_all(&dir).expect("create the output folder");
    for (name, b) in camsim_render::test_scenes::all() {
        let p = dir.join(format!("{name}.gltf"));
        b.write(&p)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        println!("wrote {}", p.display());
    }
}
