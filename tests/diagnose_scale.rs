//! What report.json says about subsampling (issue 23, "Scale"): a sensor larger than the
//! diagnosis's fit-pixel budget (2^15 pixels) is fitted on a subset of rows, which the report
//! names as runs of consecutive rows with their pixel and pixel-shot counts, next to the
//! full-resolution χ²/dof of the believed and the fitted camera; a small sensor is fitted on
//! every row.
use camsim_pipeline::config::load_captures;
use camsim_pipeline::demo::{generate_capture_set, Concealment, DemoSpec};
use camsim_pipeline::diagnose_cmd::{run_diagnose, DiagnoseCmdOptions};
use serde_json::Value;

/// Diagnoses a generated dark/flat set (one illuminant, nothing hidden) of `rows × cols` with
/// the exposure_scale candidate alone (the test reads the subsampling, not the selection);
/// returns report.json, the number of shots and the most frames of a shot.
fn report(rows: usize, cols: usize) -> (Value, usize, usize) {
    let dir = tempfile::tempdir().unwrap();
    let spec = DemoSpec {
        effects: Vec::new(),
        concealment: Concealment::OneIlluminant,
        rows,
        cols,
        seed: 4,
    };
    let t = generate_capture_set(&spec, &dir.path().join("set")).unwrap();
    let set = load_captures(&t.captures_json, None).unwrap();
    let opts = DiagnoseCmdOptions {
        effects: vec!["exposure_scale".into()],
        ..Default::default()
    };
    let r = run_diagnose(&set, &dir.path().join("out"), &opts).unwrap();
    let max_frames = set.shots.iter().map(|s| s.frames.len()).max().unwrap_or(0);
    (r.json, set.shots.len(), max_frames)
}

fn n(v: &Value) -> usize {
    v.as_u64().unwrap_or_else(|| panic!("{v} is not a count")) as usize
}

#[test]
fn report_names_the_fit_rows_and_the_full_resolution_fit() {
    // 640 × 256: the fits keep 128 of the 640 rows, a fifth, so a fit check that used only
    // the fit rows (at most 4 frames, 4 degrees of freedom, per pixel-shot) would have fewer
    // degrees of freedom than 0.9 per pixel-shot of the sensor.
    let (rows, cols) = (640, 256);
    let (r, shots, max_frames) = report(rows, cols);
    let s = &r["subsampled"];
    assert_eq!(s["fits_subsampled"], Value::Bool(true), "{s}");
    assert_eq!(n(&s["sensor_rows"]), rows);
    assert_eq!(n(&s["sensor_pixels"]), rows * cols);
    let runs: Vec<(usize, usize)> = s["fit_row_runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| (n(&x[0]), n(&x[1])))
        .collect();
    // The runs: ascending, disjoint, not touching (else they would be one run), inside the
    // sensor, whole 2-row groups (CFA phases balanced).
    for w in runs.windows(2) {
        assert!(w[0].1 + 1 < w[1].0, "runs {runs:?}");
    }
    for &(a, b) in &runs {
        assert!(
            a <= b && b < rows && a % 2 == 0 && (b - a + 1) % 2 == 0,
            "runs {runs:?}"
        );
    }
    let fit_rows: usize = runs.iter().map(|(a, b)| b - a + 1).sum();
    assert_eq!(n(&s["fit_rows"]), fit_rows);
    assert!(fit_rows < rows, "subsampled but {fit_rows} of {rows} rows");
    assert_eq!(n(&s["fit_pixels"]), fit_rows * cols);
    assert!(fit_rows * cols <= 1 << 15);
    assert_eq!(n(&s["fit_pixel_shots"]), fit_rows * cols * shots);
    assert_eq!(n(&s["sensor_pixel_shots"]), rows * cols * shots);
    // Spread over the field height: from the top row to the last eighth of the sensor.
    assert_eq!(runs[0].0, 0);
    assert!(runs.last().unwrap().1 >= rows - rows / 8, "runs {runs:?}");
    // The confirmation at full resolution is the reported fit.
    let fr = &s["full_resolution"];
    assert_eq!(n(&fr["pixels"]), rows * cols);
    // Every uncensored pixel-shot of F frames adds F degrees of freedom (a censored one its
    // expected deviance): every pixel of the sensor gives at least 0.9 per pixel-shot, the fit
    // rows alone at most F_max per fit pixel-shot, fewer than that here.
    let dof = fr["dof_believed"].as_f64().expect("dof_believed");
    let sensor_pixel_shots = (rows * cols * shots) as f64;
    let fit_rows_bound = (fit_rows * cols * shots * max_frames) as f64;
    assert!(
        fit_rows_bound < 0.9 * sensor_pixel_shots,
        "the check has no power: {fit_rows} fit rows, {max_frames} frames"
    );
    assert!(
        dof >= 0.9 * sensor_pixel_shots,
        "dof {dof} for {sensor_pixel_shots} pixel-shots, fits on {fit_rows} rows"
    );
    assert_eq!(fr["dof_believed"], r["fit_before"]["dof"]);
    assert_eq!(fr["chi2_per_dof_believed"], r["fit_before"]["chi2_per_dof"]);
    assert_eq!(fr["chi2_per_dof_fitted"], r["fit_after"]["chi2_per_dof"]);
    assert!(fr["chi2_per_dof_fitted"].as_f64().unwrap().is_finite());

    // A small sensor: every row, one run.
    let (rows, cols) = (32, 48);
    let (r, shots, _) = report(rows, cols);
    let s = &r["subsampled"];
    assert_eq!(s["fits_subsampled"], Value::Bool(false), "{s}");
    assert_eq!(s["fit_row_runs"], serde_json::json!([[0, rows - 1]]));
    assert_eq!(n(&s["fit_pixel_shots"]), rows * cols * shots);
}
