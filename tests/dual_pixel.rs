//! Dual pixel through the pipeline (issue 21): the disparity-versus-defocus study
//! (examples/study_dual_pixel/spec_ci.json) against the thin-lens closed form computed here
//! independently, its sign flip through focus, the phase-detection AF loop landing within the
//! depth of focus; the two half-photodiodes summing to the normal depth-aware pixel; an
//! imperfect split scaling the disparity by 2s − 1; an absent block changing nothing; and
//! the `sensor.dual_pixel` key's one-line errors.
use crate::util::{num, repo, study_rows};
use camsim_core::image::Plane;
use camsim_pipeline::config::{
    camera_from_file, captures_with_camera, CameraFile, CaptureSet, CapturesFile,
};
use serde_json::{json, Value};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// The example camera (4.4 mm f/1.8 focused at 1 m, 1.4 µm mono pixels, ideal split).
fn example_camera() -> Value {
    serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_dual_pixel/camera.json")).unwrap(),
    )
    .unwrap()
}

/// Thin-lens disparity (px), written out independently of the library: the blur disc of a
/// point at Z through a lens of aperture radius A = f/(2N) focused on D, the sensor at
/// v = fD/(D − f), has radius r = A v (1/Z − 1/D) (signed; similar triangles); the two
/// half-disc centroids lie 4r/(3π) either side of its centre.
fn thin_lens_disparity_px(z_m: f64) -> f64 {
    let (f, n, d, p) = (4.4e-3, 1.8, 1.0, 1.4e-6);
    let a = f / (2.0 * n);
    let v = f * d / (d - f);
    let r_px = a * v * (1.0 / z_m - 1.0 / d) / p;
    8.0 * r_px / (3.0 * PI)
}

#[test]
fn dual_pixel_study_disparity_follows_thin_lens_and_pdaf_focuses() {
    let dir = tempfile::tempdir().unwrap();
    let spec = repo().join("examples/study_dual_pixel/spec_ci.json");
    let rows = &study_rows(&spec, dir.path());
    assert_eq!(rows.len(), 5, "five object distances");
    let mut signs = Vec::new();
    for r in rows {
        let z = num(r, "object_distance_m");
        // The closed form reported is the thin-lens one.
        let e = num(r, "disparity_px_expected");
        let indep = thin_lens_disparity_px(z);
        assert!(
            (e - indep).abs() < 1e-9 * (1.0 + indep.abs()),
            "Z {z}: {e} vs {indep}"
        );
        // Noise-free: the measured edge disparity is exactly the x-centroid difference of the
        // sampled half-disc kernels the chain applies (a step edge's centroid shift; f32 sums).
        let (m, sampled) = (
            num(r, "disparity_px_measured"),
            num(r, "disparity_px_sampled"),
        );
        assert!(
            (m - sampled).abs() < 2e-3,
            "Z {z}: measured {m}, kernels' {sampled}"
        );
        // The kernels converge to the half-disc closed form: each sample cell counts at its
        // centre, so the centre column (light fraction ≈ 2/(πr) of a half disc of r samples)
        // sits ¼ sample off: a bias below 1/(π r) samples on the disparity, plus the
        // sub-sample quadrature (0.02 px + 2 %, optics test).
        let coc = num(r, "coc_radius_px");
        let tol = num(r, "disparity_px_tolerance");
        assert!(
            (tol - (0.02 + 0.02 * e.abs() + (sampled - e).abs())).abs() < 1e-12,
            "{tol}"
        );
        // Measured against the closed form directly, with the bound from first principles
        // (cell-centre bias + quadrature + the f32 edge sums), not with the reported tolerance
        // (which contains |sampled − expected| and so could not fail).
        if coc.abs() > 1.0 {
            let bound = 1.0 / (PI * coc.abs()) + 0.02 + 0.02 * e.abs();
            assert!(
                (sampled - e).abs() <= bound,
                "Z {z}: kernels' {sampled} vs closed form {e} (r = {coc} px)"
            );
            assert!(
                (m - e).abs() <= bound + 2e-3,
                "Z {z}: measured {m} vs closed form {e} (r = {coc} px, bound {bound})"
            );
        }
        // One noisy readout: within 5 standard errors (row scatter) plus the sampling bound.
        let (nz, se) = (
            num(r, "disparity_px_noisy"),
            num(r, "disparity_px_noisy_std_error"),
        );
        assert!(se > 0.0 && se < 0.3, "Z {z}: standard error {se}");
        assert!(
            (nz - e).abs() <= 5.0 * se + tol,
            "Z {z}: noisy {nz} expected {e}, SE {se}"
        );
        if e.abs() > tol {
            signs.push((z, m.signum()));
        } else {
            assert!(m.abs() <= tol, "in focus: {m}");
        }
        // Calibrated slope against α = 8 A v / (3π p) at the 1 m calibration focus.
        let (sc, se_) = (
            num(r, "slope_px_m_calibrated"),
            num(r, "slope_px_m_expected"),
        );
        let alpha = thin_lens_disparity_px(1.0 / 2.0);
        assert!((se_ - alpha).abs() < 1e-9 * alpha, "{se_} vs {alpha}");
        assert!((sc - se_).abs() < 0.05 * se_, "calibrated {sc} vs {se_}");
        // PDAF from 1 m onto Z: converged within the depth of focus, in a few measurements.
        let (err, dof) = (
            num(r, "pdaf_focus_error_per_m"),
            num(r, "depth_of_focus_per_m"),
        );
        assert_eq!(num(r, "pdaf_within_depth_of_focus"), 1.0, "Z {z}: {r}");
        assert!(
            err <= dof,
            "Z {z}: focus error {err} 1/m beyond the depth of focus {dof}"
        );
        let it = num(r, "pdaf_iterations");
        assert!((1.0..=4.0).contains(&it), "Z {z}: {it} measurements");
    }
    // Sign flip through focus: nearer than 1 m positive, farther negative.
    for (z, s) in &signs {
        assert_eq!(*s, if *z < 1.0 { 1.0 } else { -1.0 }, "sign at Z = {z}");
    }
    assert!(signs.iter().any(|(z, _)| *z < 1.0) && signs.iter().any(|(z, _)| *z > 1.0));
    assert!(dir.path().join("report.html").exists());
}

/// The dual-pixel study through a real lens (examples/study_dual_pixel/spec_ci_lens.json: the
/// 50 mm double Gauss at f/8, focused 2 m from its first vertex, paraxial criterion, 6 µm
/// pixels), issue 21's "PDAF loop that focuses the lens of the focus work": the measured edge
/// disparity follows the traced half-pupil kernels the chain applies (0.15 px + 3 %: the edge
/// is measured on the sensor's spectral weighting, the kernels' centroids are averaged over the
/// lens's three wavelengths with equal weights), the kernels follow the paraxial thin-lens form
/// 8r/(3π) (4 % + 0.15 px, spherical aberration and pupil distortion; render test
/// `dual_pixel_lens`), the sign flips through focus, the calibrated slope is within 5 % of the
/// paraxial one, and the PDAF loop, refocusing the lens by its focus model, lands within the
/// depth of focus in at most four measurements.
#[test]
fn dual_pixel_study_through_a_real_lens_focuses_the_lens() {
    let dir = tempfile::tempdir().unwrap();
    let spec = repo().join("examples/study_dual_pixel/spec_ci_lens.json");
    let rows = &study_rows(&spec, dir.path());
    assert_eq!(rows.len(), 2);
    for r in rows {
        let u = num(r, "object_vergence_per_m");
        let (e, m, k) = (
            num(r, "disparity_px_expected"),
            num(r, "disparity_px_measured"),
            num(r, "disparity_px_sampled"),
        );
        assert!(e.abs() > 2.0, "1/Z {u}: defocused enough ({e} px)");
        assert!(
            (m - k).abs() < 0.15 + 0.03 * k.abs(),
            "1/Z {u}: measured {m} vs kernels {k}"
        );
        assert!(
            (k - e).abs() < 0.15 + 0.04 * e.abs(),
            "1/Z {u}: kernels {k} vs paraxial {e}"
        );
        // focus ≈ 0.49 1/m from the entrance pupil: nearer positive, farther negative
        assert_eq!(
            m.signum(),
            if u > 0.5 { 1.0 } else { -1.0 },
            "sign at 1/Z = {u}"
        );
        let (sc, se) = (
            num(r, "slope_px_m_calibrated"),
            num(r, "slope_px_m_expected"),
        );
        assert!((sc - se).abs() < 0.05 * se, "calibrated {sc} vs {se}");
        let (err, dof) = (
            num(r, "pdaf_focus_error_per_m"),
            num(r, "depth_of_focus_per_m"),
        );
        assert_eq!(num(r, "pdaf_within_depth_of_focus"), 1.0, "1/Z {u}: {r}");
        assert!(
            err <= dof,
            "1/Z {u}: focus error {err} beyond the depth of focus {dof}"
        );
        let it = num(r, "pdaf_iterations");
        assert!((1.0..=4.0).contains(&it), "1/Z {u}: {it} measurements");
    }
}

/// One-shot capture set of the example edge at `z_m` through `camera`.
fn edge_set(camera: Value, z_m: f64) -> CaptureSet {
    let f: CameraFile = serde_json::from_value(camera).unwrap();
    let cam = camera_from_file(Path::new("camera.json"), f).unwrap();
    let captures = json!({
        "camera": "camera.json",
        "shots": [{
            "id": "edge",
            "target": {"kind": "slanted_edge", "dark": 3e15, "light": 3e16, "angle_deg": 0.0,
                       "radiance_unit": "photons", "distance_m": z_m},
            "exposure_s": 0.001,
            "frames": ["edge.png"],
        }],
    });
    let raw: CapturesFile = serde_json::from_value(captures).unwrap();
    captures_with_camera(
        Path::new("captures.json"),
        raw,
        cam,
        PathBuf::from("camera.json"),
    )
    .unwrap()
}

#[test]
fn dual_pixel_halves_sum_to_the_depth_aware_pixel() {
    use camsim_pipeline::chain;
    let set = edge_set(example_camera(), 0.4);
    let grid = chain::wavelength_grid(&set);
    let mut scene = chain::shot_scene(&set, 0, &grid).unwrap();
    let n = scene.radiance.rows * scene.radiance.cols;
    // The same plane as a depth map: the normal path then defocuses it as a thin lens.
    scene.depth_m = Some(Plane {
        rows: scene.radiance.rows,
        cols: scene.radiance.cols,
        data: vec![0.4; n],
    });
    let normal = camsim_sensor::electron_rate(
        &set.camera.sensor,
        &chain::irradiance_and_blur_of(&set, &scene, &grid)
            .unwrap()
            .irradiance,
    );
    let halves = chain::dual_pixel_rates(&set.camera, &set.camera_path, &scene, &grid)
        .unwrap()
        .sum();
    let peak = normal.electrons_per_s.iter().cloned().fold(0f32, f32::max);
    assert!(peak > 0.0);
    for (a, b) in normal.electrons_per_s.iter().zip(&halves.electrons_per_s) {
        assert!((a - b).abs() <= 1e-5 * peak, "{a} vs {b}");
    }
    // and the halves differ (the edge is 2.5 1/m out of focus)
    let rates = chain::dual_pixel_rates(&set.camera, &set.camera_path, &scene, &grid).unwrap();
    assert_ne!(rates.left, rates.right);
}

#[test]
fn imperfect_split_scales_the_disparity() {
    use camsim_pipeline::pdaf::{measure_disparity, DisparityFrames, DisparityOptions};
    let mut c = example_camera();
    c["sensor"]["dual_pixel"] = json!({"separation": 0.75});
    let set = edge_set(c, 0.4);
    let grid = camsim_pipeline::chain::wavelength_grid(&set);
    let scene = camsim_pipeline::chain::shot_scene(&set, 0, &grid).unwrap();
    let s = &set.camera.sensor;
    let shot = camsim_sensor::Shot::new(s, 0.001);
    let opts = DisparityOptions {
        region: camsim_core::stats::Rect {
            row0: 0,
            row1: s.rows,
            col0: 0,
            col1: s.cols,
        },
        ref_cols: 12,
        frames: DisparityFrames::Expected,
    };
    let d = measure_disparity(
        &set.camera,
        &set.camera_path,
        &scene,
        &grid,
        &shot,
        &opts,
        0,
    )
    .unwrap()
    .disparity_px;
    let e = (2.0 * 0.75 - 1.0) * thin_lens_disparity_px(0.4);
    let tol = 0.02 + 0.02 * e.abs();
    assert!((d - e).abs() <= tol, "separation 0.75: {d} vs {e} ± {tol}");
}

#[test]
fn dual_pixel_block_absent_or_present_keeps_the_normal_frame() {
    let mut with = example_camera();
    let mut without = with.clone();
    without["sensor"]
        .as_object_mut()
        .unwrap()
        .remove("dual_pixel");
    with["optics"]
        .as_object_mut()
        .unwrap()
        .remove("focus_distance_m");
    without["optics"]
        .as_object_mut()
        .unwrap()
        .remove("focus_distance_m");
    let frame = |c: Value| {
        let set = edge_set(c, 0.4);
        let mut out = Vec::new();
        camsim_pipeline::simulate::simulate_each(&set, 7, true, &mut |_, _| {}, &mut |o| {
            if let camsim_pipeline::simulate::SimOutput::Expected { dn, .. } = o {
                out = dn.data.clone();
            }
            Ok(())
        })
        .unwrap();
        out
    };
    let (a, b) = (frame(with), frame(without));
    assert!(!a.is_empty());
    assert_eq!(
        a, b,
        "sensor.dual_pixel must not change the normal chain's frame"
    );
}

#[test]
fn dual_pixel_key_errors_are_one_line() {
    for (block, needle) in [
        (
            json!({"separation": 0.3}),
            "sensor.dual_pixel.separation = 0.3",
        ),
        (
            json!({"separation": 1.5}),
            "sensor.dual_pixel.separation = 1.5",
        ),
        (json!({"split": "vertical"}), "split"),
    ] {
        let mut c = example_camera();
        c["sensor"]["dual_pixel"] = block;
        let err = match serde_json::from_value::<CameraFile>(c) {
            Err(e) => e.to_string(),
            Ok(f) => camera_from_file(Path::new("camera.json"), f)
                .unwrap_err()
                .one_line(),
        };
        assert!(err.contains(needle), "{err}");
        assert!(!err.contains('\n'), "{err}");
    }
    // A valid camera whose halves do not split (s = ½) cannot be a dual_pixel study point:
    // the error names the key instead of failing later on a zero disparity.
    let mut c = example_camera();
    c["sensor"]["dual_pixel"] = json!({"separation": 0.5});
    let mut doc = json!({
        "kind": "dual_pixel",
        "camera": c,
        "target": {"kind": "slanted_edge", "dark": 3e15, "light": 3e16, "angle_deg": 0.0,
                   "radiance_unit": "photons"},
        "object_vergence_per_m": 1.5,
        "exposure_s": 0.001
    });
    let err = camsim_pipeline::study::dual_pixel::validate(&doc).unwrap_err();
    assert!(
        err.contains("camera.sensor.dual_pixel.separation") && err.contains("0.5"),
        "{err}"
    );
    doc["camera"]["sensor"]["dual_pixel"] = json!({"separation": 0.51});
    camsim_pipeline::study::dual_pixel::validate(&doc).unwrap();
}
