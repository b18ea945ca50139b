//! Output integrity (issue 16, acceptance 3 and 4): SIGINT part-way leaves no staging folder
//! and no partial set; an `--out` that would overwrite an input is refused; the output files
//! of simulate, run, render, study, calibrate, validate and diagnose are byte-identical across
//! runs and at 1 and 2 threads.
use crate::cli::{camera, write_set};
use crate::util::{camsim, camsim_ok};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Every file under `dir`: relative path → bytes.
fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(base: &Path, d: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        let Ok(rd) = std::fs::read_dir(d) else {
            return;
        };
        // a live staging folder changes while it is read (temporary files are renamed or
        // removed between the listing and the read): entries that vanish are skipped
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(base, &p, out);
            } else if let Ok(bytes) = std::fs::read(&p) {
                out.insert(p.strip_prefix(base).unwrap().display().to_string(), bytes);
            }
        }
    }
    let mut m = BTreeMap::new();
    walk(dir, dir, &mut m);
    m
}

/// Names starting with `.camsim-` anywhere under `dir` (staging and backup folders, temp files).
fn debris(dir: &Path) -> Vec<String> {
    let mut v = Vec::new();
    fn walk(d: &Path, v: &mut Vec<String>) {
        let Ok(rd) = std::fs::read_dir(d) else {
            return;
        };
        for e in rd {
            let p = e.unwrap().path();
            let n = p.file_name().unwrap().to_string_lossy().to_string();
            if n.starts_with(".camsim-") || n.ends_with(".tmp") {
                v.push(p.display().to_string());
            }
            if p.is_dir() {
                walk(&p, v);
            }
        }
    }
    walk(dir, &mut v);
    v
}

/// A capture set slow enough to interrupt: `shots` blurred slanted edges of 256×256 pixels,
/// four frames each.
fn slow_set(dir: &Path, shots: usize) {
    let mut cam = camera(256, 256);
    cam["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 3.0});
    let shots: Vec<Value> = (0..shots)
        .map(|i| {
            json!({"id": format!("s{i}"), "exposure_s": 0.001 * (i + 1) as f64,
                   "target": {"kind": "slanted_edge", "dark": 0.1, "light": 1.0, "angle_deg": 5 + i},
                   "frames": (0..4).map(|k| format!("raw/s{i}-{k}.png")).collect::<Vec<_>>()})
        })
        .collect();
    write_set(dir, &cam, &json!({"camera": "camera.json", "shots": shots}));
}

/// Start `camsim simulate` in `dir`, wait until its staging folder holds a file, send
/// `signal`, and return its exit status.
fn interrupt_simulate(dir: &Path, out: &str, signal: &str) -> Option<i32> {
    let mut child = camsim()
        .args(["--threads", "1", "simulate", "captures.json", "--out", out])
        .current_dir(dir)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let staging = dir
        .join(out)
        .join(format!(".camsim-staging-{}", child.id()));
    let start = Instant::now();
    loop {
        if !snapshot(&staging).is_empty() {
            break;
        }
        if let Some(st) = child.try_wait().unwrap() {
            panic!("simulate finished ({st}) before it could be interrupted; make slow_set slower");
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no staging folder appeared"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let st = std::process::Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    child.wait().unwrap().code()
}

#[test]
fn sigint_part_way_leaves_no_debris_and_no_partial_set() {
    let d = tempfile::tempdir().unwrap();
    slow_set(d.path(), 150);
    // 1. A new output folder: after SIGINT it does not exist.
    assert_eq!(interrupt_simulate(d.path(), "new", "-INT"), Some(130));
    assert!(
        !d.path().join("new").exists(),
        "{:?}",
        snapshot(&d.path().join("new")).keys()
    );
    // 2. An existing output folder with an earlier set: after SIGINT (and SIGTERM) it holds
    //    exactly the earlier files, and no staging or backup folder.
    let old = d.path().join("old");
    std::fs::create_dir_all(old.join("raw")).unwrap();
    std::fs::write(old.join("raw/s0-0.png"), "earlier run").unwrap();
    std::fs::write(old.join("notes.txt"), "mine").unwrap();
    let before = snapshot(&old);
    for sig in ["-INT", "-TERM"] {
        let code = interrupt_simulate(d.path(), "old", sig);
        assert_eq!(code, Some(if sig == "-INT" { 130 } else { 143 }));
        assert_eq!(snapshot(&old), before, "{sig}");
        assert!(debris(d.path()).is_empty(), "{sig}: {:?}", debris(d.path()));
    }
}

#[test]
fn out_over_the_recording_is_refused_and_the_recording_kept() {
    // `camsim simulate captures.json --out .` inside a capture folder used to overwrite the
    // recorded frames with simulated ones.
    let d = tempfile::tempdir().unwrap();
    let caps = crate::cli::captures(1.0, 0.01);
    write_set(d.path(), &camera(8, 8), &caps);
    let st = camsim()
        .args(["simulate", "captures.json", "--out", "rec"])
        .current_dir(d.path())
        .output()
        .unwrap();
    assert!(st.status.success());
    for f in ["camera.json", "captures.json"] {
        std::fs::copy(d.path().join(f), d.path().join("rec").join(f)).unwrap();
    }
    let rec = d.path().join("rec");
    let before = snapshot(&rec);
    for cmd in [
        vec!["simulate", "captures.json", "--out", ".", "--seed", "9"],
        vec!["simulate", "captures.json", "--out", "raw/.."],
    ] {
        let st = camsim().args(&cmd).current_dir(&rec).output().unwrap();
        let err = String::from_utf8_lossy(&st.stderr);
        assert_eq!(st.status.code(), Some(2), "{cmd:?}: {err}");
        assert!(err.contains("would overwrite an input"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert_eq!(snapshot(&rec), before, "{cmd:?}");
        assert!(debris(&rec).is_empty());
    }
}

#[test]
fn a_folder_in_the_way_leaves_the_earlier_set_whole() {
    let d = tempfile::tempdir().unwrap();
    write_set(d.path(), &camera(8, 8), &crate::cli::captures(1.0, 0.01));
    let sim = |seed: &str| {
        camsim()
            .args(["simulate", "captures.json", "--out", "o", "--seed", seed])
            .current_dir(d.path())
            .output()
            .unwrap()
    };
    assert!(sim("1").status.success());
    // the last frame's place is taken by a folder: the second run fails as a whole
    std::fs::remove_file(d.path().join("o/raw/flat-1.png")).unwrap();
    std::fs::create_dir_all(d.path().join("o/raw/flat-1.png")).unwrap();
    let before = snapshot(&d.path().join("o"));
    let st = sim("2");
    let err = String::from_utf8_lossy(&st.stderr);
    assert_eq!(st.status.code(), Some(2), "{err}");
    assert!(
        err.contains("flat-1.png") && err.contains("folder is in the way"),
        "{err}"
    );
    assert_eq!(
        snapshot(&d.path().join("o")),
        before,
        "old and new files mixed"
    );
    assert!(debris(d.path()).is_empty());
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// Run `args` in `dir` with `--threads threads`; return the files of `out` and remove it.
fn outputs_of(dir: &Path, threads: &str, args: &[&str], out: &str) -> BTreeMap<String, Vec<u8>> {
    let st = camsim()
        .args(["--threads", threads])
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{args:?} --threads {threads}: {}",
        String::from_utf8_lossy(&st.stderr)
    );
    let p = dir.join(out);
    let s = if p.is_dir() {
        let s = snapshot(&p);
        std::fs::remove_dir_all(&p).unwrap();
        s
    } else {
        let s = BTreeMap::from([(out.to_string(), std::fs::read(&p).unwrap())]);
        std::fs::remove_file(&p).unwrap();
        s
    };
    assert!(!s.is_empty(), "{args:?} wrote nothing");
    s
}

#[test]
fn outputs_are_byte_identical_across_runs_and_thread_counts() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path();
    // Inputs: a generated capture set (with frames), a small run config, a two-point study.
    camsim_ok(
        camsim()
            .args([
                "demo", "diagnose", "--effect", "prnu=1.5", "--rows", "16", "--cols", "24",
                "--out", "set",
            ])
            .current_dir(p),
    );
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["rows"] = json!(24);
    cam["sensor"]["cols"] = json!(32);
    std::fs::write(
        p.join("run.json"),
        json!({"camera": cam, "target": {"kind": "macbeth"}, "exposure_s": 0.01}).to_string(),
    )
    .unwrap();
    let mut scam: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_codesign/camera.json")).unwrap(),
    )
    .unwrap();
    scam["optics"]["blur"] = json!({"kind": "none"});
    scam["sensor"]["rows"] = json!(32);
    scam["sensor"]["cols"] = json!(32);
    std::fs::write(
        p.join("study.json"),
        json!({"name": "det", "point": {"camera": scam, "conditions": {"luminance_cd_m2": 100, "exposure_s": 0.01},
                                        "metrics": {"snr": {}, "dynamic_range": {}}},
               "parameters": [{"name": "lum", "path": "conditions.luminance_cd_m2", "values": [30, 300]}]})
        .to_string(),
    )
    .unwrap();
    let scene = repo()
        .join("scenes/uniform_emitter.gltf")
        .display()
        .to_string();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "simulate",
                "set/captures.json",
                "--out",
                "sim",
                "--seed",
                "5",
            ],
            "sim",
        ),
        (
            vec![
                "simulate",
                "set/captures.json",
                "--out",
                "exp",
                "--expected",
            ],
            "exp",
        ),
        (vec!["run", "run.json", "--out", "run"], "run"),
        (
            vec![
                "render", &scene, "--width", "16", "--spp", "4", "--out", "r.exr",
            ],
            "r.exr",
        ),
        (vec!["study", "study.json", "--out", "st"], "st"),
        (
            vec!["calibrate", "set/captures.json", "--out", "cal"],
            "cal",
        ),
        (vec!["validate", "set/captures.json", "--out", "val"], "val"),
        (
            vec![
                "diagnose",
                "set/captures.json",
                "--out",
                "dia",
                "--effects",
                "prnu",
            ],
            "dia",
        ),
    ];
    for (args, out) in cases {
        let a = outputs_of(p, "1", &args, out);
        let b = outputs_of(p, "2", &args, out);
        let c = outputs_of(p, "2", &args, out);
        assert_eq!(
            a.keys().collect::<Vec<_>>(),
            b.keys().collect::<Vec<_>>(),
            "{args:?}: different files"
        );
        for (k, v) in &a {
            assert!(
                b[k] == *v,
                "{args:?}: {k} differs between --threads 1 and 2"
            );
            assert!(c[k] == *v, "{args:?}: {k} differs between two runs");
        }
        eprintln!("deterministic: {args:?}: {} files", a.len());
    }
}
