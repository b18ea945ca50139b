//! Generates the table of embedded ISETCam data files (data/iset/**.json) so the binary needs
//! no data files at run time.
use std::{env, fs, path::Path};

fn walk(dir: &Path, root: &Path, out: &mut Vec<String>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .expect("read data dir")
        .flatten()
        .collect();
    entries.sort_by_key(|e| e.path());
    for e in entries {
        let p = e.path();
        if p.is_dir() {
            walk(&p, root, out);
        } else if p.extension().and_then(|s| s.to_str()) == Some("json") {
            out.push(
                p.strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .replace('\\', "/"),
            );
        }
    }
}

fn main() {
    let manifest = env::var("CARGO_MANIFEST_DIR").unwrap();
    let root = Path::new(&manifest).join("../data/iset");
    let root = root.canonicalize().expect("data/iset exists");
    println!("cargo:rerun-if-changed={}", root.display());
    let mut files = Vec::new();
    walk(&root, &root, &mut files);
    let mut src = String::from("/// (relative path, JSON text) of every embedded ISETCam data file.\npub static EMBEDDED: &[(&str, &str)] = &[\n");
    for f in &files {
        src.push_str(&format!(
            "    ({:?}, include_str!({:?})),\n",
            f.trim_end_matches(".json"),
            root.join(f).display().to_string()
        ));
    }
    src.push_str("];\n");
    let out = Path::new(&env::var("OUT_DIR").unwrap()).join("embedded_data.rs");
    fs::write(out, src).unwrap();
}
