//! `camsim run` with any colour filter array, and honest (held-out) colour accuracy: the
//! matrix is fitted on a D65 calibration capture and scored under tungsten and fluorescent
//! light, where the white-balance methods then differ.
use crate::util::camsim;
use serde_json::{json, Value};
use std::path::Path;

fn table1() -> Value {
    serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap()
}

fn spectrum(w: &[f64], v: Vec<f64>) -> Value {
    json!({"wavelength_nm": w, "values": v})
}

/// A small Table 1 camera with the given tile and channels (r, g, b from Table 1; w, c, m the
/// sum r + g + b; a..p 16 Gaussian bands of σ 15 nm at 400 + 20 k nm).
fn camera(tile: &[&str], letters: &str, rows: usize, cols: usize) -> Value {
    let mut cam = table1();
    let ch = cam["sensor"]["channels"].clone();
    let w: Vec<f64> = ch["r"]["wavelength_nm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let vals = |n: &str| -> Vec<f64> {
        ch[n]["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let sum: Vec<f64> = (0..w.len())
        .map(|i| vals("r")[i] + vals("g")[i] + vals("b")[i])
        .collect();
    let mut out = serde_json::Map::new();
    for l in letters.chars() {
        let s = l.to_string();
        let v = match l {
            'r' | 'g' | 'b' => vals(&s),
            'w' | 'c' | 'm' => sum.clone(),
            _ => {
                let k = (l as u8 - b'a') as f64;
                w.iter()
                    .map(|&x| 0.3 * (-(x - 400.0 - 20.0 * k).powi(2) / (2.0 * 15.0 * 15.0)).exp())
                    .collect()
            }
        };
        out.insert(s, spectrum(&w, v));
    }
    cam["sensor"]["channels"] = Value::Object(out);
    cam["sensor"]["cfa"] = json!(tile);
    cam["sensor"]["rows"] = json!(rows);
    cam["sensor"]["cols"] = json!(cols);
    cam["optics"]["blur"] = json!({"kind": "none"});
    cam
}

fn run(dir: &Path, name: &str, cfg: Value) -> Value {
    let p = dir.join(format!("{name}.json"));
    std::fs::write(&p, cfg.to_string()).unwrap();
    let out = dir.join(name);
    let o = camsim()
        .args(["run", p.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// Every CFA of the issue runs through `camsim run` (default demosaic for its tile, plus the
/// quad-Bayer binning path), renders an image of the expected size and is colour-scored.
#[test]
fn run_demosaics_every_cfa() {
    let d = tempfile::tempdir().unwrap();
    let cases: Vec<(&str, Vec<&str>, &str, Option<&str>, &str)> = vec![
        ("rgbw", vec!["rg", "wb"], "rgbw", None, "lmmse"),
        ("rccb", vec!["rc", "cb"], "rcb", None, "lmmse"),
        ("rccc", vec!["rc", "cc"], "rc", None, "lmmse"),
        (
            "quad",
            vec!["rrgg", "rrgg", "ggbb", "ggbb"],
            "rgb",
            None,
            "quad_remosaic",
        ),
        (
            "quad_bin",
            vec!["rrgg", "rrgg", "ggbb", "ggbb"],
            "rgb",
            Some("quad_binning"),
            "quad_binning",
        ),
        ("mono", vec!["m"], "m", None, "lmmse"),
        (
            "ms16",
            vec!["abcd", "efgh", "ijkl", "mnop"],
            "abcdefghijklmnop",
            None,
            "lmmse",
        ),
    ];
    let (rows, cols) = (48, 72);
    for (name, tile, letters, method, expect) in cases {
        let mut processor = json!({"white_balance": "known_illuminant"});
        if let Some(m) = method {
            processor["demosaic"] = json!(m);
        }
        let cfg = json!({
            "camera": camera(&tile, letters, rows, cols),
            "target": {"kind": "macbeth", "illuminant": "D65", "mean_luminance_cd_m2": 100, "patch_fraction": 0.8},
            "processor": processor,
        });
        let s = run(d.path(), name, cfg);
        assert_eq!(s["processor"]["demosaic"], json!(expect), "{name}");
        let img = image::open(d.path().join(name).join("rendered.png"))
            .unwrap()
            .to_rgb8();
        let want = if expect == "quad_binning" {
            (cols / 2, rows / 2)
        } else {
            (cols, rows)
        };
        assert_eq!(
            (img.width() as usize, img.height() as usize),
            want,
            "{name}"
        );
        let de = s["delta_e_2000"]["mean"].as_f64().unwrap();
        assert!(de.is_finite() && de > 0.0, "{name}: ΔE {de}");
        eprintln!("run {name}: demosaic {expect}, held-out mean ΔE2000 {de:.2}");
    }
}

/// Matrix fitted under D65 (calibration capture), scored under tungsten and fluorescent: the
/// held-out ΔE is reported beside the fitted one, and the white-balance methods differ
/// measurably (no white balance worst, known illuminant best).
#[test]
fn held_out_delta_e_depends_on_white_balance() {
    let d = tempfile::tempdir().unwrap();
    let mut cam = table1();
    cam["sensor"]["rows"] = json!(96);
    cam["sensor"]["cols"] = json!(144);
    cam["optics"]["blur"] = json!({"kind": "none"});
    for light in ["tungsten", "fluorescent"] {
        let cfg = json!({
            "camera": cam,
            "target": {"kind": "macbeth", "illuminant": light, "mean_luminance_cd_m2": 61, "patch_fraction": 0.8},
            "processor": {"white_balance": "known_illuminant", "calibration_illuminant": "D65"},
        });
        let s = run(d.path(), light, cfg);
        let fitted = s["delta_e_2000_fitted"]["mean"].as_f64().unwrap();
        let held = s["delta_e_2000"]["mean"].as_f64().unwrap();
        assert!(s["delta_e_scored_on"]
            .as_str()
            .unwrap()
            .contains("held out"));
        let rows = s["white_balance_comparison"].as_array().unwrap();
        let get = |m: &str| -> (f64, f64) {
            let r = rows
                .iter()
                .find(|r| r["white_balance"] == json!(m))
                .unwrap();
            (
                r["fitted_delta_e_2000_mean"].as_f64().unwrap(),
                r["held_out_delta_e_2000_mean"].as_f64().unwrap(),
            )
        };
        let table: Vec<String> = ["none", "grey_world", "white_patch", "known_illuminant"]
            .iter()
            .map(|m| {
                let (f, h) = get(m);
                format!("{m}: fitted {f:.2} held-out {h:.2}")
            })
            .collect();
        eprintln!("{light}: {}", table.join("; "));
        let (_, none) = get("none");
        let (f_known, known) = get("known_illuminant");
        // the run's own figures are the known-illuminant row
        assert!(
            (f_known - fitted).abs() < 1e-9 && (known - held).abs() < 0.5,
            "{light}: run {held:.3} vs table {known:.3}"
        );
        // measurable: no white balance is worse than the known illuminant by > 2 ΔE2000
        assert!(
            none > known + 2.0,
            "{light}: none {none:.2} vs known {known:.2}"
        );
        // held out is worse than fitted (the matrix did not see this light)
        assert!(
            known > f_known,
            "{light}: held-out {known:.2} ≤ fitted {f_known:.2}"
        );
        let spread = rows
            .iter()
            .map(|r| r["held_out_delta_e_2000_mean"].as_f64().unwrap())
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
                (lo.min(x), hi.max(x))
            });
        assert!(spread.1 - spread.0 > 2.0, "{light}: {table:?}");
        let html = std::fs::read_to_string(d.path().join(light).join("report.html")).unwrap();
        assert!(html.contains("held-out mean ΔE2000") && html.contains("grey_world"));
    }
}

/// A fixed matrix from the config is applied (and a wrong-sized one is refused in one line).
#[test]
fn fixed_matrix_from_the_config() {
    let d = tempfile::tempdir().unwrap();
    let mut cam = table1();
    cam["sensor"]["rows"] = json!(48);
    cam["sensor"]["cols"] = json!(72);
    cam["optics"]["blur"] = json!({"kind": "none"});
    // sensor channel order is b, g, r (sorted letters): the matrix columns follow it
    let m = json!([[0.0, -0.5, 2.0], [-0.2, 1.5, -0.3], [1.8, -0.6, 0.0]]);
    let cfg = json!({
        "camera": cam,
        "target": {"kind": "macbeth", "illuminant": "D65", "mean_luminance_cd_m2": 100, "patch_fraction": 0.8},
        "processor": {"ccm": m},
    });
    let s = run(d.path(), "fixed", cfg.clone());
    assert_eq!(s["processor"]["color_correction"], json!("fixed"));
    assert_eq!(s["processor"]["ccm"], m);
    let mut bad = cfg;
    bad["processor"]["ccm"] = json!([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]);
    let p = d.path().join("bad.json");
    std::fs::write(&p, bad.to_string()).unwrap();
    let o = camsim()
        .args([
            "run",
            p.to_str().unwrap(),
            "--out",
            d.path().join("bad").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    assert!(
        e.contains("processor.ccm") && e.contains("3 rows of 3"),
        "{e}"
    );
    assert!(!d.path().join("bad").exists());
}
