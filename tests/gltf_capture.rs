//! Capture sets whose shot target is a glTF scene (`"kind": "gltf"`, issue 18: depth-aware
//! image formation in `simulate` and `scene`): the frames of `camsim simulate` agree with
//! `camsim run` on the same scene and camera within the render's Monte Carlo noise, shots of
//! one scene render once, bad input is one line naming the key, and the frames are the same
//! bits at any thread count.
use crate::util::{camsim, camsim_ok};
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

/// Spectral irradiance of a spectral EXR: (bands by wavelength, rows, cols).
fn read_irradiance(p: &Path) -> (Vec<f64>, usize, usize, Vec<Vec<f32>>) {
    let e = camsim_core::exr_io::read_spectral_exr(p).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(e.image.planes.len(), e.grid.len());
    (
        e.grid.wavelength_nm.clone(),
        e.image.rows,
        e.image.cols,
        e.image.planes,
    )
}

/// The sensor pixels of a scene-grid plane ((rows + 2·margin)·os × (cols + 2·margin)·os
/// samples): the margin cropped, os × os samples averaged (what `camsim run` writes).
fn to_pixels(p: &[f32], grid_rows: usize, grid_cols: usize) -> Vec<f64> {
    let os = (grid_cols - grid_rows) / (COLS - ROWS);
    let margin = (grid_rows / os - ROWS) / 2;
    assert_eq!(
        (grid_rows, grid_cols),
        ((ROWS + 2 * margin) * os, (COLS + 2 * margin) * os)
    );
    let mut out = vec![0.0; ROWS * COLS];
    for y in 0..ROWS {
        for x in 0..COLS {
            let mut s = 0.0;
            for dy in 0..os {
                for dx in 0..os {
                    s += p[((y + margin) * os + dy) * grid_cols + (x + margin) * os + dx] as f64;
                }
            }
            out[y * COLS + x] = s / (os * os) as f64;
        }
    }
    out
}

/// High-frequency energy of an image relative to its energy: Σ (neighbour differences)² /
/// Σ value². Defocus (a low-pass filter) lowers it.
fn edge_energy(v: &[f64]) -> f64 {
    let (mut d2, mut e2) = (0.0, 0.0);
    for y in 0..ROWS {
        for x in 0..COLS {
            let a = v[y * COLS + x];
            e2 += a * a;
            if x + 1 < COLS {
                d2 += (v[y * COLS + x + 1] - a).powi(2);
            }
            if y + 1 < ROWS {
                d2 += (v[(y + 1) * COLS + x] - a).powi(2);
            }
        }
    }
    d2 / e2
}

/// `camsim simulate` on a glTF target and `camsim run` on the same scene and camera (both
/// depth-aware: pinhole render + thin-lens defocus by depth through the one chain).
///
/// * Same render seed: the sensor irradiance of the target's shot (`camsim scene`, on the
///   scene grid, cropped and averaged to pixels here) equals run's `sensor_irradiance.exr`
///   to float tolerance (max |Δ| < 1e-4 of the largest value, every band): the same render
///   and the same depth-aware optics. Control: the same shot with `depth_optics: false`
///   (no defocus by depth) differs by more than 5 % of the largest value somewhere and its
///   high-frequency energy ([`edge_energy`]) is over 1.2 × run's, so the comparison sees a
///   missing defocus.
/// * Different render seeds: the block-mean difference of the two raw frames has zero mean
///   (z-test over 96 blocks of 4 × 4 px, |z| < 4; each block's difference carries the render
///   noise and the sensor noise of both frames, so its scatter over the blocks estimates the
///   standard error). With the run's render seed the raw frames differ by the sensor noise.
#[test]
fn simulate_on_a_gltf_target_matches_run() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    // camsim run: the exposure it chooses (auto, half the swing) is used by simulate
    let cfg = json!({"camera": camera(), "render": {"scene": "thinlens.gltf", "spp": 16},
                     "auto_exposure": 0.5, "seed": 3, "simulation": {"oversample": 1}});
    std::fs::write(d.path().join("run.json"), cfg.to_string()).unwrap();
    camsim_ok(
        camsim()
            .args(["run", "run.json", "--out", "run_out"])
            .current_dir(d.path()),
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
                "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 16, "seed": 3}},
               {"id": "c", "exposure_s": t, "frames": ["c.png"],
                "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 16, "seed": 3,
                           "depth_optics": false}}]),
    );
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--out", "sim", "--seed", "5"])
            .current_dir(d.path()),
    );
    // irradiance: simulate's shot b (run's render seed) and c (no depth optics) vs run
    let (run_nm, run_rows, run_cols, run_irr) =
        read_irradiance(&d.path().join("run_out/sensor_irradiance.exr"));
    assert_eq!((run_rows, run_cols), (ROWS, COLS));
    let scene_irr = |id: &str| {
        camsim_ok(
            camsim()
                .args([
                    "scene",
                    "captures.json",
                    "--shot",
                    id,
                    "--out",
                    &format!("sc_{id}"),
                ])
                .current_dir(d.path()),
        );
        read_irradiance(&d.path().join(format!("sc_{id}/{id}_irradiance.exr")))
    };
    let (b_nm, gr, gc, b_irr) = scene_irr("b");
    let (_, _, _, c_irr) = scene_irr("c");
    let peak = run_irr.iter().flatten().fold(0f64, |m, v| m.max(*v as f64));
    assert!(peak > 0.0, "run's irradiance is dark");
    let (mut same_max, mut control_max, mut compared) = (0f64, 0f64, 0);
    let (mut run_sum, mut c_sum) = (vec![0.0; ROWS * COLS], vec![0.0; ROWS * COLS]);
    for (bi, nm) in run_nm.iter().enumerate() {
        let Some(si) = b_nm.iter().position(|w| (w - nm).abs() < 1e-6) else {
            continue;
        };
        compared += 1;
        let (b, c) = (to_pixels(&b_irr[si], gr, gc), to_pixels(&c_irr[si], gr, gc));
        for i in 0..ROWS * COLS {
            let r = run_irr[bi][i] as f64;
            same_max = same_max.max((b[i] - r).abs() / peak);
            control_max = control_max.max((c[i] - r).abs() / peak);
            run_sum[i] += r;
            c_sum[i] += c[i];
        }
    }
    let (e_run, e_c) = (edge_energy(&run_sum), edge_energy(&c_sum));
    eprintln!(
        "gltf target irradiance vs run ({compared} bands): same seed max |Δ|/peak {same_max:.2e}; \
         depth_optics false max |Δ|/peak {control_max:.3}, edge energy {e_c:.4e} vs run {e_run:.4e}"
    );
    assert!(compared >= 10, "only {compared} common bands");
    assert!(
        same_max < 1e-4,
        "simulate's irradiance differs from run's: {same_max}"
    );
    assert!(
        control_max > 0.05,
        "no defocus by depth seen: {control_max}"
    );
    assert!(
        e_c > 1.2 * e_run,
        "edge energy {e_c} (sharp) vs {e_run} (defocused)"
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
    eprintln!(
        "gltf target: run mean {mr:.2} DN, simulate mean {ms:.2} DN, block difference {mean:+.3} ± {:.3} DN (z {z:+.2})",
        sd / n.sqrt()
    );
    assert!(mr > 50.0, "the run frame is dark ({mr} DN)");
    assert!(z.abs() < 4.0, "simulate vs run: z = {z}");
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

/// Shots of the same scene file and render settings render once (the render count of the
/// cache): a second spelling of the path, another exposure and a `mean_luminance_cd_m2`
/// scaling share the render, and the scaled shot's scene radiance is the shared render times
/// one factor (max deviation < 1e-5 of the peak). Another seed renders again, and so does an
/// identical copy of the scene in another folder (its buffers could differ: the cache keys on
/// the file's canonical path, not its content). `camsim scene` writes the scene with
/// depth-aware irradiance.
#[test]
fn gltf_shots_of_one_scene_render_once() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    std::fs::create_dir(d.path().join("copy")).unwrap();
    copy_scene(&d.path().join("copy"));
    let tgt = |file: &str, seed: u64| json!({"kind": "gltf", "file": file, "spp": 2, "seed": seed});
    let mut scaled = tgt("thinlens.gltf", 1);
    scaled["mean_luminance_cd_m2"] = json!(37.0);
    write_captures(
        d.path(),
        json!([
            {"id": "a", "exposure_s": 0.01, "frames": ["a.png"], "target": tgt("thinlens.gltf", 1)},
            {"id": "b", "exposure_s": 0.02, "frames": ["b.png"], "target": tgt("./thinlens.gltf", 1)},
            {"id": "c", "exposure_s": 0.01, "frames": ["c.png"], "target": tgt("thinlens.gltf", 2)},
            {"id": "d", "exposure_s": 0.01, "frames": ["d.png"], "target": scaled},
            {"id": "e", "exposure_s": 0.01, "frames": ["e.png"], "target": tgt("copy/thinlens.gltf", 1)}
        ]),
    );
    let set =
        camsim_pipeline::config::load_captures(&d.path().join("captures.json"), None).unwrap();
    let grid = camsim_pipeline::chain::wavelength_grid(&set);
    let cache = camsim_pipeline::gltf_target::RenderCache::new();
    let scenes: Vec<_> = (0..5)
        .map(|i| {
            camsim_pipeline::simulate::shot_scene_cached(&set, i, &grid, Some(&cache)).unwrap()
        })
        .collect();
    assert_eq!(
        cache.renders(),
        3,
        "five shots, three distinct renders (a = b = d, c, e)"
    );
    assert_eq!(scenes[0].radiance.planes, scenes[1].radiance.planes);
    assert_ne!(scenes[0].radiance.planes, scenes[2].radiance.planes);
    // d: a's render scaled by one factor
    let (a, dd): (Vec<f64>, Vec<f64>) = scenes[0]
        .radiance
        .planes
        .iter()
        .flatten()
        .zip(scenes[3].radiance.planes.iter().flatten())
        .map(|(x, y)| (*x as f64, *y as f64))
        .unzip();
    let k = dd.iter().sum::<f64>() / a.iter().sum::<f64>();
    let peak = dd.iter().fold(0f64, |m, v| m.max(v.abs()));
    let dev = a
        .iter()
        .zip(&dd)
        .fold(0f64, |m, (x, y)| m.max((y - k * x).abs()));
    assert!(
        (k - 1.0).abs() > 1e-3 && dev < 1e-5 * peak,
        "scaled shot: factor {k}, deviation {dev} of peak {peak}"
    );
    assert!(scenes[0].depth_m.is_some());
    // camsim scene: radiance, irradiance and the report for a glTF shot
    camsim_ok(
        camsim()
            .args(["scene", "captures.json", "--shot", "a", "--out", "sc"])
            .current_dir(d.path()),
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
        camsim_ok(
            camsim()
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
                .current_dir(d.path()),
        );
        outs.push(
            ["a0.png", "a1.png"].map(|f| std::fs::read(d.path().join(&out).join(f)).unwrap()),
        );
    }
    assert_eq!(outs[0], outs[1], "frames differ between 1 and 2 threads");
}

/// The render camera policy is `camsim run`'s: with a camera that does not defocus by depth
/// (no `optics.focus_distance_m`), the glTF camera's own `extras.thinlens` renders thin-lens
/// in both. Same render seed: simulate's irradiance (`camsim scene`) equals run's to float
/// tolerance (max |Δ| < 1e-4 of the peak). Control: run with `render.camera = "pinhole"` (same
/// seed) differs by more than 5 % of the peak somewhere, so an always-pinhole target render
/// would fail the comparison.
#[test]
fn gltf_target_renders_with_runs_camera_policy() {
    let d = tempfile::tempdir().unwrap();
    copy_scene(d.path());
    let mut cam = camera();
    cam["optics"]
        .as_object_mut()
        .unwrap()
        .remove("focus_distance_m");
    let run = |name: &str, render: Value, seed: u64| {
        let cfg = json!({"camera": cam, "render": render, "auto_exposure": 0.5, "seed": seed,
                         "simulation": {"oversample": 1}});
        std::fs::write(d.path().join(format!("{name}.json")), cfg.to_string()).unwrap();
        camsim_ok(
            camsim()
                .args(["run", &format!("{name}.json"), "--out", name])
                .current_dir(d.path()),
        );
        read_irradiance(&d.path().join(format!("{name}/sensor_irradiance.exr")))
    };
    let (nm, rows, cols, auto) = run("auto", json!({"scene": "thinlens.gltf", "spp": 8}), 7);
    assert_eq!((rows, cols), (ROWS, COLS));
    let (_, _, _, pinhole) = run(
        "pin",
        json!({"scene": "thinlens.gltf", "spp": 8, "camera": "pinhole"}),
        7,
    );
    std::fs::write(d.path().join("camera.json"), cam.to_string()).unwrap();
    std::fs::write(
        d.path().join("captures.json"),
        json!({"camera": "camera.json", "simulation": {"oversample": 1},
               "shots": [{"id": "a", "exposure_s": 0.01, "frames": ["a.png"],
                          "target": {"kind": "gltf", "file": "thinlens.gltf", "spp": 8,
                                     "seed": 7}}]})
        .to_string(),
    )
    .unwrap();
    camsim_ok(
        camsim()
            .args(["scene", "captures.json", "--shot", "a", "--out", "sc"])
            .current_dir(d.path()),
    );
    let (s_nm, gr, gc, sim) = read_irradiance(&d.path().join("sc/a_irradiance.exr"));
    let peak = auto.iter().flatten().fold(0f64, |m, v| m.max(*v as f64));
    assert!(peak > 0.0, "run's irradiance is dark");
    let (mut same_max, mut control_max, mut compared) = (0f64, 0f64, 0);
    for (bi, w) in nm.iter().enumerate() {
        let Some(si) = s_nm.iter().position(|v| (v - w).abs() < 1e-6) else {
            continue;
        };
        compared += 1;
        let s = to_pixels(&sim[si], gr, gc);
        for i in 0..ROWS * COLS {
            let (a, p) = (auto[bi][i] as f64, pinhole[bi][i] as f64);
            same_max = same_max.max((s[i] - a).abs() / peak);
            control_max = control_max.max((p - a).abs() / peak);
        }
    }
    eprintln!(
        "camera policy ({compared} bands): simulate vs run (glTF thin lens) max |Δ|/peak \
         {same_max:.2e}; pinhole run max |Δ|/peak {control_max:.3}"
    );
    assert!(compared >= 10, "only {compared} common bands");
    assert!(
        same_max < 1e-4,
        "simulate's irradiance differs from run's: {same_max}"
    );
    assert!(
        control_max > 0.05,
        "the pinhole render is the same: {control_max}"
    );
}

/// diagnose's forward model runs only the fit rows' bands when the camera allows it
/// (`chain::band_refusal`); a glTF target with depth-aware optics (defocus by depth over the
/// whole field) must refuse, else every fit-row run of a large gltf capture set fails on
/// `band_irradiance`'s depth check. Without depth optics the same camera runs bands.
#[test]
fn gltf_targets_with_depth_refuse_row_bands() {
    use camsim_pipeline::chain::{band_refusal, RowBand};
    for depth in [true, false] {
        let d = tempfile::tempdir().unwrap();
        copy_scene(d.path());
        let mut cam = camera();
        cam["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 1.2});
        let mut tgt = json!({"kind": "gltf", "file": "thinlens.gltf", "spp": 2, "seed": 1});
        tgt["depth_optics"] = json!(depth);
        std::fs::write(d.path().join("camera.json"), cam.to_string()).unwrap();
        std::fs::write(
            d.path().join("captures.json"),
            json!({"camera": "camera.json", "simulation": {"oversample": 1},
                   "shots": [{"id": "a", "exposure_s": 0.01, "frames": ["a.png"], "target": tgt}]})
            .to_string(),
        )
        .unwrap();
        let set =
            camsim_pipeline::config::load_captures(&d.path().join("captures.json"), None).unwrap();
        let r = band_refusal(&set, RowBand { start: 0, end: 2 });
        assert_eq!(r.is_some(), depth, "depth_optics {depth}: {r:?}");
        if let Some(r) = r {
            assert!(r.contains("glTF"), "{r}");
        }
    }
}
