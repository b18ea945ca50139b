//! Embeds the glass catalogue (lenses/glass/<vendor>/<GLASS>.yml, CC0) so the binary needs no
//! data files at run time.
use std::{env, fs, path::Path};

fn main() {
    let root = Path::new(&env::var("CARGO_MANIFEST_DIR").unwrap()).join("../lenses/glass");
    let root = root.canonicalize().expect("lenses/glass exists");
    println!("cargo:rerun-if-changed={}", root.display());
    let mut entries = Vec::new();
    let mut vendors: Vec<_> = fs::read_dir(&root)
        .unwrap()
        .flatten()
        .filter(|e| e.path().is_dir())
        .collect();
    vendors.sort_by_key(|e| e.path());
    for v in vendors {
        let mut files: Vec<_> = fs::read_dir(v.path()).unwrap().flatten().collect();
        files.sort_by_key(|e| e.path());
        for f in files {
            let p = f.path();
            if p.extension().and_then(|s| s.to_str()) == Some("yml") {
                let stem = p.file_stem().unwrap().to_string_lossy().to_string();
                let vendor = v.file_name().to_string_lossy().to_string();
                entries.push(format!(
                    "    ({vendor:?}, {stem:?}, include_str!({:?})),\n",
                    p.display().to_string()
                ));
            }
        }
    }
    let src = format!(
        "/// (vendor, glass, refractiveindex.info YAML) of every bundled glass.\npub static EMBEDDED_GLASS: &[(&str, &str, &str)] = &[\n{}];\n",
        entries.concat()
    );
    fs::write(
        Path::new(&env::var("OUT_DIR").unwrap()).join("embedded_glass.rs"),
        src,
    )
    .unwrap();
}
