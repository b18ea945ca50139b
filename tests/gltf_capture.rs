//! Capture sets whose shot target is a glTF scene (`"kind": "gltf"`, issue 18: depth-aware
//! image formation in `simulate` and `scene`): the frames of `camsim simulate` agree with
//! `camsim run` on the same scene and camera within the render's Monte Carlo noise, shots of
//! one scene render once, bad input is one line naming the key, and the frames are the same
//! bits at any thread count.
use crate::util::camsim;
use serde_json::{json, Value};
use std::path::Path;

const ROWS: usize = 32;
const COLS: usize = 48;

/// The Table 1 camera made small, with a thin lens focused at 2.5 m (depth-aware optics on).
fn camera() -> Value {
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["rows"] = json!(ROWS);
    cam["sensor"]["cols"] = json!(COLS);
    cam["sensor"]["pixel_pitch_um"] = json!(2.2);
    cam["optics"]["focal_length_mm"] = json!(8.0);
    cam["optics"]["f_number"] = json!(2.8);
    cam["optics"]["focus_distance_m"] = json!(2.5);
    cam
}

/// The thin-lens test scene (cards at several depths) copied beside the capture file.
fn copy_scene(dir: &Path) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/mitsuba");
    for f in ["thinlens.gltf", "thinlens.bin"] {
        std::fs::copy(src.join(f), dir.join(f)).unwrap();
    }
}

fn write_captures(dir: &Path, shots: Value) {
    std::fs::write(dir.join("camera.json"), camera().to_string()).unwrap();
    std::fs::write(
        dir.join("captures.json"),
        json!({"camera": "camera.json", "simulation": {"oversample": 1}, "shots": shots})
            .to_string(),
    )
    .unwrap();
}

fn read_png16(p: &Path) -> Vec<f64> {
    let img = image::open(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        .to_luma16();
    assert_eq!((img.height() as usize, img.width() as usize), (ROWS, COLS));
    img.pixels().map(|p| p.0[0] as f64).collect()
}

/// 4 × 4-pixel block means (whole CFA tiles) of a mosaic.
fn block_means(v: &[f64]) -> Vec<f64> {
    let b = 4;
    let mut out = Vec::new();
    for by in 0..ROWS / b {
        for bx in 0..COLS / b {
            let mut s = 0.0;
            for y in by * b..(by + 1) * b {
                for x in bx * b..(bx + 1) * b {
                    s += v[y * COLS + x];
                }
            }
            out.push(s / (b * b) as f64);
        }
    }
    out
}

/// `camsim simulate` on a glTF target and `camsim run` on the same scene and camera (both
/// depth-aware: pinhole render + thin-lens defocus by depth through the one chain), renders
/// with different seeds: the block-mean difference of the two raw frames has zero mean
/// (z-test over 96 blocks of 4 × 4 px, |z| < 4; each block's difference carries the render
/// noise and the sensor noise of both frames, so its scatter over the blocks estimates the
/// standard error) and they show the same scene (the block means correlate, r > 0.95). With
/// the run's render seed the render is the same and only the sensor noise differs.
#[test]
fn simulate_on_a_gltf_target_matches_run() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    // camsim run: the exposure it chooses (auto, half the swing) is used by simulate
    let cfg = json!({"camera": camera(), "render": {"scene": "thinlens.gltf", "spp": 16},
                     "auto_exposure": 0.5, "seed": 3, "simulation": {"oversample": 1}});
    std::fs::write(d.path().join("run.json"), cfg.to_string()).unwrap();
    let st = camsim()
        .args(["run", "run.json", "--out", "run_out"])
        .current_dir(d.path())
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let summary: Value = serde_json::from_str(
        &std::fs::read_to_string(d.path().join("run_out/summary.json")).unwrap(),
    )
    .unwrap();
    let t = summary["exposure_s"].as_f64().unwrap();
    assert_eq!(summary["depth_optics"]["kernels"], "thin_lens");
    write_captures(
        d.path(),
        json!([{"id": "a", "exposure_s": t, "frames": ["a.png"],
                "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 16, "seed": 11}},
               {"id": "b", "exposure_s": t, "frames": ["b.png"],
                "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 16, "seed": 3}}]),
    );
    let st = camsim()
        .args(["simulate", "captures.json", "--out", "sim", "--seed", "5"])
        .current_dir(d.path())
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let run = read_png16(&d.path().join("run_out/raw.png"));
    let sim = read_png16(&d.path().join("sim/a.png"));
    let (br, bs) = (block_means(&run), block_means(&sim));
    let n = br.len() as f64;
    let diff: Vec<f64> = br.iter().zip(&bs).map(|(a, b)| b - a).collect();
    let mean = diff.iter().sum::<f64>() / n;
    let sd = (diff.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let z = mean / (sd / n.sqrt());
    let (mr, ms) = (br.iter().sum::<f64>() / n, bs.iter().sum::<f64>() / n);
    let corr = {
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for (a, b) in br.iter().zip(&bs) {
            sxy += (a - mr) * (b - ms);
            sxx += (a - mr).powi(2);
            syy += (b - ms).powi(2);
        }
        sxy / (sxx * syy).sqrt()
    };
    eprintln!(
        "gltf target: run mean {mr:.2} DN, simulate mean {ms:.2} DN, block difference {mean:+.3} ± {:.3} DN (z {z:+.2}), block correlation {corr:.4}",
        sd / n.sqrt()
    );
    assert!(mr > 50.0, "the run frame is dark ({mr} DN)");
    assert!(z.abs() < 4.0, "simulate vs run: z = {z}");
    assert!(corr > 0.95, "block correlation {corr}");
    // The render seed of the run (3): the same render, so the frames differ by the sensor
    // noise only (independent per pixel): pixel z-test of the mean difference, |z| < 4, and
    // the means within 0.3 %.
    let same = read_png16(&d.path().join("sim/b.png"));
    let n = run.len() as f64;
    let diff: Vec<f64> = run.iter().zip(&same).map(|(a, b)| b - a).collect();
    let mean = diff.iter().sum::<f64>() / n;
    let sd = (diff.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let z = mean / (sd / n.sqrt());
    let m_same = same.iter().sum::<f64>() / n;
    let m_run = run.iter().sum::<f64>() / n;
    eprintln!(
        "gltf target, run's render seed: simulate mean {m_same:.3} DN vs run {m_run:.3} DN, pixel difference {mean:+.3} ± {:.3} DN (z {z:+.2})",
        sd / n.sqrt()
    );
    assert!(z.abs() < 4.0, "same render: z = {z}");
    assert!(
        (m_same / m_run - 1.0).abs() < 0.003,
        "same render: means {m_same} vs {m_run}"
    );
}

/// Shots of the same scene content and render settings render once (a second spelling of the
/// path and a different luminance scaling share the render); another seed renders again. The
/// expected images of the first two shots are then proportional, and `camsim scene` writes the
/// scene with depth-aware irradiance.
#[test]
fn gltf_shots_of_one_scene_render_once() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    let tgt = |file: &str, seed: u64| json!({"kind": "gltf", "file": file, "spp": 2, "seed": seed});
    write_captures(
        d.path(),
        json!([
            {"id": "a", "exposure_s": 0.01, "frames": ["a.png"], "target": tgt("thinlens.gltf", 1)},
            {"id": "b", "exposure_s": 0.02, "frames": ["b.png"], "target": tgt("./thinlens.gltf", 1)},
            {"id": "c", "exposure_s": 0.01, "frames": ["c.png"], "target": tgt("thinlens.gltf", 2)}
        ]),
    );
    let set =
        camsim_pipeline::config::load_captures(&d.path().join("captures.json"), None).unwrap();
    let grid = camsim_pipeline::chain::wavelength_grid(&set);
    let cache = camsim_pipeline::gltf_target::RenderCache::new();
    let scenes: Vec<_> = (0..3)
        .map(|i| {
            camsim_pipeline::simulate::shot_scene_cached(&set, i, &grid, Some(&cache)).unwrap()
        })
        .collect();
    assert_eq!(cache.renders(), 2, "three shots, two distinct renders");
    assert_eq!(scenes[0].radiance.planes, scenes[1].radiance.planes);
    assert_ne!(scenes[0].radiance.planes, scenes[2].radiance.planes);
    assert!(scenes[0].depth_m.is_some());
    // camsim scene: radiance, irradiance and the report for a glTF shot
    let st = camsim()
        .args(["scene", "captures.json", "--shot", "a", "--out", "sc"])
        .current_dir(d.path())
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for f in ["a_radiance.exr", "a_irradiance.exr", "a_scene.json"] {
        assert!(d.path().join("sc").join(f).is_file(), "{f} missing");
    }
}

/// Bad glTF targets: one line naming the capture file, the shot and the key; nothing written.
#[test]
fn gltf_target_errors_name_the_key() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    std::fs::write(
        d.path().join("broken.gltf"),
        "{\"asset\": {\"version\": \"2.0\"}, \"meshes\": [{",
    )
    .unwrap();
    let cases: Vec<(Value, &str)> = vec![
        (
            json!({"kind": "gltf", "file": "missing.gltf"}),
            "target.file: ",
        ),
        (json!({"kind": "gltf"}), "target.file: required"),
        (
            json!({"kind": "gltf", "file": "broken.gltf"}),
            "target.file: ",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "spp": 0}),
            "target.spp: ",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "spp": 1e12}),
            "target.spp: ",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "spp": 1e6}),
            "target.spp: needs about",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "sp": 4}),
            "target.sp: unknown key",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "fov_deg": 40}),
            "target.fov_deg: ",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "bands": {"start_nm": 700, "stop_nm": 400, "step_nm": 10}}),
            "target.bands: ",
        ),
        (
            json!({"kind": "gltf", "file": "thinlens.gltf", "camera_name": "nope"}),
            "target.file: ",
        ),
    ];
    for (i, (target, want)) in cases.iter().enumerate() {
        write_captures(
            d.path(),
            json!([{"id": "s", "exposure_s": 0.01, "frames": ["s.png"], "target": target}]),
        );
        let out = format!("out{i}");
        let st = camsim()
            .args([
                "--max-work",
                "1e8",
                "simulate",
                "captures.json",
                "--out",
                &out,
            ])
            .current_dir(d.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(!st.status.success(), "case {i} {target}: accepted");
        assert_eq!(
            err.trim().lines().count(),
            1,
            "case {i}: not one line: {err}"
        );
        assert!(
            err.contains("captures.json"),
            "case {i}: no file named: {err}"
        );
        assert!(err.contains(want), "case {i}: expected {want:?} in: {err}");
        assert!(!d.path().join(&out).exists(), "case {i}: output written");
    }
}

/// The same frames (bits) with 1 and 2 worker threads.
#[test]
fn gltf_target_frames_are_the_same_at_any_thread_count() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    write_captures(
        d.path(),
        json!([{"id": "a", "exposure_s": 0.01, "frames": ["a0.png", "a1.png"],
                "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 2}}]),
    );
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = format!("out{threads}");
        let st = camsim()
            .args([
                "--threads",
                threads,
                "simulate",
                "captures.json",
                "--out",
                &out,
                "--seed",
                "9",
            ])
            .current_dir(d.path())
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        outs.push(
            ["a0.png", "a1.png"].map(|f| std::fs::read(d.path().join(&out).join(f)).unwrap()),
        );
    }
    assert_eq!(outs[0], outs[1], "frames differ between 1 and 2 threads");
}
