//! Helpers shared by the integration tests.
use serde_json::Value;
use std::path::{Path, PathBuf};

/// ../shared/oracles/isetcam
pub fn oracle_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/oracles/isetcam")
}

/// A parsed oracle case.
pub fn case(id: &str) -> Value {
    let p = oracle_dir().join("cases").join(format!("{id}.json"));
    serde_json::from_str(
        &std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
    )
    .unwrap()
}

/// The `values` of an inline array.
pub fn values(v: &Value) -> Vec<f64> {
    v["values"]
        .as_array()
        .expect("values")
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The camsim binary built for these tests.
pub fn camsim() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_camsim"))
}

/// Run a camsim command and return its output, panicking with camsim's stderr when it fails.
pub fn camsim_ok(cmd: &mut std::process::Command) -> std::process::Output {
    let o = cmd.output().expect("camsim could not be started");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Run `camsim study SPEC --out OUT` and return the rows of OUT/table.json (panicking with
/// camsim's stderr when the study fails).
pub fn study_rows(spec: &Path, out: &Path) -> Vec<Value> {
    camsim_ok(camsim().arg("study").arg(spec).arg("--out").arg(out));
    let t: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap()).unwrap();
    t["rows"].as_array().expect("table.json rows").clone()
}

/// A number in a study table row, naming the key when it is missing.
pub fn num(r: &Value, k: &str) -> f64 {
    r[k].as_f64()
        .unwrap_or_else(|| panic!("{k} missing in {r}"))
}
