//! Lens files without field angles (pbrt `.dat`, ISET lens JSON): an off-axis field needs a
//! maximum field, from `--max-field-deg`, from `--sensor-diagonal-mm` (the paraxial chief ray
//! reaches the sensor corner: tan θ = (d/2)/EFL) or from a `<N>deg` part of the file name, and
//! stderr says which; otherwise one error line asks for it (issue 17 §3).
use crate::util::camsim;
use serde_json::Value;
use std::path::PathBuf;

fn dat() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/real/lens/prescriptions/pbrt_dgauss.50mm.dat")
}

fn run(args: &[&str]) -> (i32, String, String) {
    let o = camsim().args(args).output().expect("run camsim");
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn spot(lens: &str, extra: &[&str]) -> (i32, String, String) {
    let mut a = vec![
        "lens",
        "spot",
        lens,
        "--field-fraction",
        "1",
        "--wavelength-nm",
        "587.6",
        "--rays",
        "100",
        "--json",
    ];
    a.extend_from_slice(extra);
    run(&a)
}

#[test]
fn lens_cli_field_of_a_file_without_field_angles() {
    let p = dat();
    if !p.is_file() {
        eprintln!("SKIPPED: {} missing (link ../shared)", p.display());
        return;
    }
    let lens = p.to_str().unwrap();
    // no field anywhere: one error line naming the file and --max-field-deg
    let (code, out, err) = spot(lens, &[]);
    assert_eq!(code, 2, "{err}");
    assert!(out.trim().is_empty());
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].contains(lens) && lines[0].contains("--max-field-deg"),
        "{err}"
    );
    // --max-field-deg
    let (code, out, err) = spot(lens, &["--max-field-deg", "12.5"]);
    assert_eq!(code, 0, "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["field_deg"].as_f64().unwrap(), 12.5);
    // --sensor-diagonal-mm: the paraxial chief ray of the maximum field reaches the corner
    let (code, out, err) = run(&["lens", "report", lens, "--json", "--field-fraction", "0"]);
    assert_eq!(code, 0, "{err}");
    let r: Value = serde_json::from_str(&out).unwrap();
    let efl = r["efl_mm"].as_f64().unwrap();
    let d = 43.27;
    let (code, out, err) = spot(lens, &["--sensor-diagonal-mm", "43.27"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("from the sensor diagonal 43.27 mm"), "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    let th = v["field_deg"].as_f64().unwrap();
    let want = (d / 2.0 / efl).atan().to_degrees();
    assert!((th - want).abs() < 1e-6, "{th} vs {want} (EFL {efl})");
    let (code, _, err) = spot(lens, &["--sensor-diagonal-mm", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--sensor-diagonal-mm 0 must be"), "{err}");
    // a field stated in the file name (ISETCam naming): used, and said so
    let dir = tempfile::tempdir().unwrap();
    let named = dir.path().join("dgauss.22deg.50mm.dat");
    std::fs::copy(&p, &named).unwrap();
    let (code, out, err) = spot(named.to_str().unwrap(), &[]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("taken from its name"), "{err}");
    let v: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["field_deg"].as_f64().unwrap(), 22.0);
}

/// A hostile `--glass-catalog` file: one error line naming the file, the line and the value.
#[test]
fn lens_cli_bad_glass_catalog_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let agf = dir.path().join("acme.agf");
    std::fs::write(
        &agf,
        "NM MYGLASS 2 517642 1.5168 64.17 0 0 0\nCD 1.03 x 0.23 0.02 1.01 103.5\n",
    )
    .unwrap();
    let lens = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("lenses/double_gauss_50mm_f2.json");
    let (code, out, err) = run(&[
        "lens",
        "spot",
        lens.to_str().unwrap(),
        "--field-fraction",
        "0",
        "--wavelength-nm",
        "587.6",
        "--glass-catalog",
        agf.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(out.trim().is_empty(), "{out}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].contains("acme.agf") && lines[0].contains("line 2") && lines[0].contains("'x'"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}
