//! `camsim diagnose` on concealed-effect capture sets (issue 6, acceptance 1–3).
//!
//! Every set comes from the project's generator (`camsim_pipeline::demo::generate_capture_set`, the
//! library path of `camsim demo diagnose`), whose effect shapes differ from the fitted models
//! (docs/effects.md, "forms"); the diagnosis runs through `camsim_pipeline::diagnose_cmd::run_diagnose`
//! (the library path of `camsim diagnose`) and is judged from its report.json against the
//! generator's truth.json.
//!
//! Tolerances:
//! * magnitude: within 30 % of the truth (issue 6), or an absolute floor where the truth is
//!   near zero (stated per case);
//! * χ²/dof after the fit: |χ²/dof − 1| ≤ 5·√(2/dof) (the χ² of `dof` independent unit terms
//!   has σ = √(2·dof); 5σ), with dof from the report (≈ 2·10⁴ on these sets, so ≈ 0.05).
use camsim_pipeline::config::load_captures;
use camsim_pipeline::demo::{generate_capture_set, Concealment, DemoSpec};
use camsim_pipeline::diagnose_cmd::{run_diagnose, DiagnoseCmdOptions};
use serde_json::Value;
use std::path::Path;

const ROWS: usize = 32;
const COLS: usize = 48;

/// What one diagnosis of a generated set returned.
struct Outcome {
    /// (effect id, true magnitude) from the generator.
    truth: Vec<(String, f64)>,
    /// report.json.
    report: Value,
    /// The set and the output folder live here.
    dir: tempfile::TempDir,
}

fn spec(effects: &[(&str, f64)], concealment: Concealment, seed: u64) -> DemoSpec {
    DemoSpec {
        effects: effects.iter().map(|(i, m)| (i.to_string(), *m)).collect(),
        concealment,
        rows: ROWS,
        cols: COLS,
        seed,
    }
}

fn diagnose_generated(effects: &[(&str, f64)], concealment: Concealment, seed: u64) -> Outcome {
    diagnose_generated_with(effects, concealment, seed, Candidates::All)
}

/// Which candidate effects a diagnosis searches.
#[derive(Clone, Copy, Debug)]
enum Candidates {
    /// Every effect id (the full matrix; `camsim diagnose`'s default).
    All,
    /// CI size: the sensor-side candidates (cheap: no re-render of the optics) plus these
    /// optics-side ids (the truth and its optics look-alikes of docs/diagnose.md).
    Ci(&'static [&'static str]),
}

/// The sensor-side effect ids: their candidates refit the sensor stage on the believed
/// irradiance. The optics-side ids (relative_illumination, veiling_glare, defocus,
/// distortion, lateral_color) re-render the optics for every trial value, which is what
/// makes the chart/edge/point sets slow; CI sets name the ones they need.
const SENSOR_SIDE: [&str; 14] = [
    "exposure_scale",
    "conversion_gain",
    "black_level",
    "dark_current",
    "read_noise",
    "dsnu",
    "prnu",
    "column_fpn",
    "hot_pixels",
    "nonlinearity",
    "full_well",
    "crosstalk",
    "ir_leakage",
    "qe_shift",
];

fn options_for(c: Candidates) -> DiagnoseCmdOptions {
    match c {
        Candidates::All => DiagnoseCmdOptions::default(),
        Candidates::Ci(optics) => DiagnoseCmdOptions {
            effects: SENSOR_SIDE
                .iter()
                .chain(optics)
                .map(|s| s.to_string())
                .collect(),
            ..Default::default()
        },
    }
}

fn diagnose_generated_with(
    effects: &[(&str, f64)],
    concealment: Concealment,
    seed: u64,
    candidates: Candidates,
) -> Outcome {
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("set");
    let truth = generate_capture_set(&spec(effects, concealment, seed), &set_dir)
        .unwrap_or_else(|e| panic!("{effects:?}: generator: {e}"));
    let set = load_captures(&truth.captures_json, None).unwrap();
    let report = run_diagnose(&set, &dir.path().join("out"), &options_for(candidates))
        .unwrap_or_else(|e| panic!("{effects:?}: diagnose: {e}"));
    // The typed summary agrees with its report.
    assert_eq!(report.findings.len(), findings(&report.json).len());
    let report = report.json;
    // The written report.json is the returned one.
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("out/report.json")).unwrap())
            .unwrap();
    // (serde_json's float parsing may differ from the written value in the last bit)
    assert_eq!(findings(&written).len(), findings(&report).len());
    for (a, b) in findings(&written).iter().zip(findings(&report)) {
        assert!(a.0 == b.0 && (a.1 - b.1).abs() <= 1e-12 * b.1.abs());
    }
    // One line per diagnosis (shown with --nocapture; docs/diagnose.md's matrix is made from
    // these lines).
    eprintln!(
        "diagnose-outcome {effects:?} {concealment:?} seed {seed} ({candidates:?}): findings {:?}, undecided {:?}, chi2/dof {:.4} -> {:.4} (dof {})",
        findings(&report),
        undecided(&report),
        report["fit_before"]["chi2_per_dof"].as_f64().unwrap_or(f64::NAN),
        report["fit_after"]["chi2_per_dof"].as_f64().unwrap_or(f64::NAN),
        report["fit_after"]["dof"]
    );
    Outcome {
        truth: truth
            .effects
            .iter()
            .map(|e| (e.effect.clone(), e.magnitude))
            .collect(),
        report,
        dir,
    }
}

fn findings(r: &Value) -> Vec<(String, f64)> {
    r["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["effect"].as_str().unwrap().to_string(),
                f["magnitude"].as_f64().unwrap_or(f64::NAN),
            )
        })
        .collect()
}

fn undecided(r: &Value) -> Vec<Vec<String>> {
    r["undecided"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| {
            u["effects"]
                .as_array()
                .unwrap()
                .iter()
                .map(|e| e.as_str().unwrap().to_string())
                .collect()
        })
        .collect()
}

/// χ²/dof after the fit is 1 within 5σ of a χ² with the report's dof.
fn assert_fit_after(o: &Outcome, what: &str) {
    let c = o.report["fit_after"]["chi2_per_dof"].as_f64().unwrap();
    let dof = o.report["fit_after"]["dof"].as_f64().unwrap();
    let tol = 5.0 * (2.0 / dof).sqrt();
    assert!(
        (c - 1.0).abs() <= tol,
        "{what}: χ²/dof after = {c:.4} (dof {dof}), expected 1 ± {tol:.4}; report findings {:?}",
        findings(&o.report)
    );
}

/// Every true effect is found (magnitude within 30 % or `floor`), nothing else is reported,
/// nothing is left undecided, and the fit ends at χ²/dof ≈ 1.
fn assert_found_exactly(o: &Outcome, floor: f64, what: &str) {
    let found = findings(&o.report);
    for (id, truth) in &o.truth {
        let Some((_, m)) = found.iter().find(|f| &f.0 == id) else {
            panic!(
                "{what}: {id} (truth {truth}) not found; findings {found:?}, undecided {:?}",
                undecided(&o.report)
            );
        };
        let tol = (0.3 * truth.abs()).max(floor);
        assert!(
            (m - truth).abs() <= tol,
            "{what}: {id} magnitude {m} vs truth {truth} (tolerance {tol})"
        );
    }
    let extra: Vec<_> = found
        .iter()
        .filter(|f| !o.truth.iter().any(|t| t.0 == f.0))
        .collect();
    assert!(extra.is_empty(), "{what}: spurious findings {extra:?}");
    assert!(
        undecided(&o.report).is_empty(),
        "{what}: undecided {:?}",
        undecided(&o.report)
    );
    let before = o.report["fit_before"]["chi2_per_dof"].as_f64().unwrap();
    let after = o.report["fit_after"]["chi2_per_dof"].as_f64().unwrap();
    assert!(
        after < before,
        "{what}: fit did not improve ({before} → {after})"
    );
    assert_fit_after(o, what);
}

fn single(id: &str, magnitude: f64, conceal: Concealment, floor: f64) {
    single_with(id, magnitude, conceal, floor, Candidates::All);
}

fn single_with(id: &str, magnitude: f64, conceal: Concealment, floor: f64, c: Candidates) {
    let o = diagnose_generated_with(&[(id, magnitude)], conceal, 1, c);
    assert_found_exactly(&o, floor, &format!("{id}={magnitude} ({conceal:?}, {c:?})"));
}

/// A matrix case in two sizes: the CI test searches the CI candidates (sensor side + the
/// listed optics ids), the `_full` twin (ignored in CI; docs/testing.md) every candidate,
/// with the same set and the same assertions.
macro_rules! ci_and_full {
    ($(#[$doc:meta])* $ci:ident, $full:ident, $optics:expr, |$c:ident| $body:block) => {
        $(#[$doc])*
        #[test]
        fn $ci() {
            let $c = Candidates::Ci($optics);
            $body
        }
        $(#[$doc])*
        #[test]
        #[ignore = "full diagnose matrix (every candidate): docs/testing.md"]
        fn $full() {
            let $c = Candidates::All;
            $body
        }
    };
}

// ---------------------------------------------------------------------------------------
// Acceptance 1: every effect id, concealed.
//
// Concealments: `Mimicked` builds the set around the effect's look-alike (the evidence that
// separates them is present); `BelowNoise` uses a magnitude under one frame's noise and more
// repeats; `UnderScene` has no flat field (charts, edge, points, ramp). See docs/diagnose.md
// for the matrix with results.

#[test]
fn exposure_scale_default_set() {
    // `none`: the other concealments of exposure_scale are true ambiguities, tested below
    // (mimicked: flats only, where added uniform light = more light; below-noise: a 1 %
    // change, where the photon-transfer slope that separates conversion_gain is not
    // resolved).
    single("exposure_scale", 1.08, Concealment::None, 0.0);
}

/// 1 % more light with 6 repeats per flat: the photon-transfer slope over the set is known
/// to ≈ √(2/(5·6·1536)) ≈ 0.7 %, so a conversion-gain error of 1 % (same means, slope 1 %
/// off) cannot be excluded — the right answer is "cannot tell", with the fitted camera
/// explaining the recording either way.
#[test]
fn exposure_scale_below_noise_is_undecided_against_conversion_gain() {
    let o = diagnose_generated(&[("exposure_scale", 1.01)], Concealment::BelowNoise, 1);
    let u = undecided(&o.report);
    assert!(
        u.iter().any(|g| g.contains(&"exposure_scale".to_string())
            && g.contains(&"conversion_gain".to_string())),
        "expected exposure_scale/conversion_gain undecided, got {u:?}, findings {:?}",
        findings(&o.report)
    );
    // The kept effect has the right size (within 30 % of the 1 % change).
    let g = o.report["undecided"]
        .as_array()
        .unwrap()
        .iter()
        .find(|g| g["effects"][0] == "exposure_scale" || g["effects"][0] == "conversion_gain")
        .unwrap();
    let m = g["magnitudes"][0].as_f64().unwrap();
    // (more light and more volts per electron scale the mean alike: both ratios are 1.01)
    assert!(((m - 1.01) / 0.01).abs() <= 0.3, "{g}");
    assert_fit_after(&o, "exposure_scale 1 % below noise");
}

#[test]
fn conversion_gain_mimicking_exposure() {
    single("conversion_gain", 0.9, Concealment::Mimicked, 0.0);
}

#[test]
fn black_level_mimicking_dsnu_and_dark_current() {
    single("black_level", 6.5, Concealment::Mimicked, 0.0);
}

#[test]
fn dark_current_mimicking_black_level() {
    single("dark_current", 0.02, Concealment::Mimicked, 0.0);
}

#[test]
fn read_noise_mimicking_fixed_pattern() {
    single("read_noise", 2.0e-3, Concealment::Mimicked, 0.0);
}

#[test]
fn dsnu_mimicking_black_level() {
    single("dsnu", 2.0e-3, Concealment::Mimicked, 0.0);
}

#[test]
fn prnu_mimicking_shot_noise() {
    single("prnu", 2.0, Concealment::Mimicked, 0.0);
}

ci_and_full!(
    column_fpn_below_noise,
    column_fpn_below_noise_full,
    &[],
    |c| {
        single_with("column_fpn", 1.0e-3, Concealment::BelowNoise, 0.0, c);
    }
);

ci_and_full!(
    hot_pixels_under_scene,
    hot_pixels_under_scene_full,
    &[],
    |c| {
        single_with("hot_pixels", 0.004, Concealment::UnderScene, 0.0, c);
    }
);

ci_and_full!(
    nonlinearity_under_scene,
    nonlinearity_under_scene_full,
    &[],
    |c| {
        single_with("nonlinearity", 0.06, Concealment::UnderScene, 0.0, c);
    }
);

ci_and_full!(
    full_well_under_scene,
    full_well_under_scene_full,
    &[],
    |c| {
        single_with("full_well", 7000.0, Concealment::UnderScene, 0.0, c);
    }
);

#[test]
fn full_well_mimicking_prnu() {
    // Flats reaching 80 % and 95 % of the believed scale with a 70 % well: the clipped
    // pixels' lost noise and flattened means look like fixed pattern until the well is fitted.
    single("full_well", 7000.0, Concealment::Mimicked, 0.0);
}

#[test]
fn relative_illumination_with_flats() {
    // `none`: relative illumination concealed under scene content cannot be told from the
    // scene's own shading without a flat field; that case is the "cannot tell" test below.
    single("relative_illumination", 0.25, Concealment::None, 0.0);
}

#[test]
fn relative_illumination_below_noise_with_flats() {
    // Mechanical (two-circle) vignetting, 5 % at the corner, on the below-noise set (flats at
    // six levels, more repeats); fitted as an even polynomial.
    single("relative_illumination", 0.05, Concealment::BelowNoise, 0.0);
}

ci_and_full!(
    veiling_glare_under_scene,
    veiling_glare_under_scene_full,
    &["veiling_glare"],
    |c| {
        single_with("veiling_glare", 0.03, Concealment::UnderScene, 0.0, c);
    }
);

ci_and_full!(
    defocus_under_scene,
    defocus_under_scene_full,
    &["defocus"],
    |c| {
        single_with("defocus", 1.5, Concealment::UnderScene, 0.0, c);
    }
);

#[test]
fn crosstalk_mimicking_qe() {
    single("crosstalk", 0.05, Concealment::Mimicked, 0.0);
}

#[test]
fn ir_leakage_mimicking_qe() {
    single("ir_leakage", 0.03, Concealment::Mimicked, 0.0);
}

#[test]
fn qe_shift_mimicking_crosstalk() {
    single("qe_shift", -6.0, Concealment::Mimicked, 0.0);
}

ci_and_full!(
    distortion_under_scene,
    distortion_under_scene_full,
    &["distortion", "lateral_color"],
    |c| {
        single_with("distortion", -0.04, Concealment::UnderScene, 0.0, c);
    }
);

ci_and_full!(
    lateral_color_under_scene,
    lateral_color_under_scene_full,
    &["lateral_color", "distortion"],
    |c| {
        single_with("lateral_color", 2.5, Concealment::UnderScene, 0.0, c);
    }
);

// Identifiability (issue 23): a candidate the shots cannot tell from the baseline
// (exposure, conversion gain, black level; per channel for the colour candidates) is reported
// as "cannot tell", never as a finding. Sets: darks + six flats up to 85 % of full scale under
// one illuminant (3200 K), and the same flats under a second one (6500 K).

/// The effects the report says it cannot tell from these shots.
fn cannot_tell(r: &Value) -> Vec<String> {
    r["cannot_tell"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["effect"].as_str().unwrap().to_string())
        .collect()
}

/// The variance inflation the report gives a candidate (∞ as a string when exactly
/// degenerate).
fn variance_inflation(r: &Value, id: &str) -> f64 {
    let c = r["identifiability"]["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["effect"] == id)
        .unwrap_or_else(|| panic!("{id} missing from the identifiability table"));
    c["variance_inflation"].as_f64().unwrap_or(f64::INFINITY)
}

#[test]
fn nonlinearity_on_one_illuminant_flats_is_found_and_qe_shift_cannot_tell() {
    let o = diagnose_generated_with(
        &[("nonlinearity", 0.03)],
        Concealment::OneIlluminant,
        1,
        Candidates::Ci(&[]),
    );
    let what = "nonlinearity=0.03 (one illuminant)";
    let ct = cannot_tell(&o.report);
    eprintln!(
        "{what}: cannot tell {ct:?}; variance inflation qe_shift {:.3e}, nonlinearity {:.3e}",
        variance_inflation(&o.report, "qe_shift"),
        variance_inflation(&o.report, "nonlinearity")
    );
    assert!(
        ct.iter().any(|e| e == "qe_shift"),
        "{what}: qe_shift not in cannot_tell {ct:?}"
    );
    assert!(
        o.report["cannot_tell"][0]["would_separate"]
            .as_str()
            .unwrap()
            .contains("illuminant"),
        "{what}: the separating shot should name a second illuminant"
    );
    assert!(!ct.iter().any(|e| e == "nonlinearity"), "{what}: {ct:?}");
    // The nonlinearity is found (within 30 %) and nothing else is reported as a finding.
    // (An exposure/gain pair may be left undecided and kept in the fitted camera: the
    // generator's tanh bends as −v³/3s², the fitted quadratic as −a·v², and the slope that
    // the quadratic form cannot follow is a change of gain or exposure, which these flats
    // cannot tell apart. Undecided groups are not findings.)
    let found = findings(&o.report);
    let ids: Vec<&str> = found.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(ids, ["nonlinearity"], "{what}: findings {found:?}");
    let (truth, m) = (o.truth[0].1, found[0].1);
    assert!(
        (m - truth).abs() <= 0.3 * truth,
        "{what}: magnitude {m} vs truth {truth}"
    );
    for u in undecided(&o.report) {
        assert!(
            u.iter()
                .all(|e| e == "exposure_scale" || e == "conversion_gain"),
            "{what}: undecided {u:?}"
        );
    }
    assert_fit_after(&o, what);
}

#[test]
fn qe_shift_with_a_second_illuminant_is_found() {
    let o = diagnose_generated_with(
        &[("qe_shift", -6.0)],
        Concealment::TwoIlluminants,
        1,
        Candidates::Ci(&[]),
    );
    let what = "qe_shift=-6 (two illuminants)";
    let ct = cannot_tell(&o.report);
    eprintln!(
        "{what}: cannot tell {ct:?}; variance inflation qe_shift {:.3e}",
        variance_inflation(&o.report, "qe_shift")
    );
    assert!(!ct.iter().any(|e| e == "qe_shift"), "{what}: {ct:?}");
    assert_found_exactly(&o, 0.0, what);
}

#[test]
fn qe_shift_on_one_illuminant_flats_is_never_a_finding() {
    let o = diagnose_generated_with(
        &[("qe_shift", -6.0)],
        Concealment::OneIlluminant,
        1,
        Candidates::Ci(&[]),
    );
    let what = "qe_shift=-6 (one illuminant)";
    let ct = cannot_tell(&o.report);
    assert!(ct.iter().any(|e| e == "qe_shift"), "{what}: {ct:?}");
    assert!(
        !findings(&o.report).iter().any(|f| f.0 == "qe_shift"),
        "{what}: reported as a finding"
    );
}

// Null sets: the believed camera made the frames; the right answer is nothing.

fn null_set(conceal: Concealment, seed: u64) {
    let o = diagnose_generated(&[], conceal, seed);
    assert!(o.truth.is_empty());
    let what = format!("null set ({conceal:?}, seed {seed})");
    assert!(
        findings(&o.report).is_empty(),
        "{what}: findings {:?}",
        findings(&o.report)
    );
    assert!(undecided(&o.report).is_empty(), "{what}");
    // Before = after: the believed model already explains the recording.
    let before = o.report["fit_before"]["chi2_per_dof"].as_f64().unwrap();
    let after = o.report["fit_after"]["chi2_per_dof"].as_f64().unwrap();
    assert_eq!(before, after, "{what}");
    assert_fit_after(&o, &what);
}

#[test]
fn null_sets_have_no_findings() {
    null_set(Concealment::Mimicked, 1);
    null_set(Concealment::Mimicked, 2);
    null_set(Concealment::BelowNoise, 3);
}

// Two-effect sets, including look-alike pairs.

#[test]
fn two_effects_exposure_scale_and_black_level() {
    let o = diagnose_generated(
        &[("exposure_scale", 1.08), ("black_level", 6.5)],
        Concealment::BelowNoise,
        1,
    );
    assert_found_exactly(&o, 0.0, "exposure_scale + black_level");
}

#[test]
fn two_effects_prnu_and_dsnu() {
    let o = diagnose_generated(&[("prnu", 2.0), ("dsnu", 2.0e-3)], Concealment::Mimicked, 1);
    assert_found_exactly(&o, 0.0, "prnu + dsnu");
}

#[test]
fn two_effects_dark_current_and_black_level() {
    let o = diagnose_generated(
        &[("dark_current", 0.02), ("black_level", 6.5)],
        Concealment::Mimicked,
        1,
    );
    assert_found_exactly(&o, 0.0, "dark_current + black_level");
}

#[test]
fn two_effects_relative_illumination_and_veiling_glare() {
    let o = diagnose_generated(
        &[("relative_illumination", 0.25), ("veiling_glare", 0.03)],
        Concealment::None,
        1,
    );
    assert_found_exactly(&o, 0.0, "relative_illumination + veiling_glare");
}

/// A set that truly cannot separate a look-alike pair: more light (exposure_scale) and
/// light added evenly (veiling_glare) scale a uniform flat field identically, and the
/// `mimicked` exposure_scale set holds only flats and darks. The engine must say it cannot
/// tell instead of naming one, and the fitted camera (which keeps one of them) still
/// explains the recording.
#[test]
fn ambiguous_set_is_reported_undecided() {
    let o = diagnose_generated(&[("exposure_scale", 1.08)], Concealment::Mimicked, 1);
    let u = undecided(&o.report);
    assert!(
        u.iter().any(|g| g.contains(&"exposure_scale".to_string())
            && g.contains(&"veiling_glare".to_string())),
        "expected an undecided exposure_scale/veiling_glare group, got {u:?}, findings {:?}",
        findings(&o.report)
    );
    assert!(
        findings(&o.report).is_empty(),
        "an undecided effect must not also be a finding: {:?}",
        findings(&o.report)
    );
    let g = &o.report["undecided"][0];
    assert!(g["explanation"].as_str().unwrap().contains("cannot tell"));
    assert!(!g["would_separate"].as_array().unwrap().is_empty());
    assert_fit_after(&o, "ambiguous exposure_scale/veiling_glare");
}

// ---------------------------------------------------------------------------------------
// Acceptance 2: the fitted camera simulates the recording's mean.

/// Per-pixel z of the recorded frame mean against an expected image:
/// z = (mean − expected) / √(s²/F + σ_fixed²), s² the recorded temporal variance over the F
/// frames, σ_fixed² the camera's fixed-pattern variance of that pixel (DSNU and PRNU of the
/// camera file: the expected image carries no drawn pattern, the recording does). Pixels
/// with a frame at an ADC rail are left out. Returns (mean z, mean z², pixels).
fn z_stats(
    set: &camsim_pipeline::config::CaptureSet,
    set_dir: &Path,
    shot: usize,
    expected_exr: &Path,
    camera: &Value,
) -> (f64, f64, usize) {
    let sh = &set.shots[shot];
    let frames: Vec<Vec<u16>> = sh
        .frames
        .iter()
        .map(|f| {
            camsim_pipeline::raw_input::read_frame_with(&set_dir.join(f), None)
                .unwrap()
                .dn
        })
        .collect();
    let n_f = frames.len() as f64;
    assert!(n_f >= 2.0);
    let (_, _, chans, _) = camsim_core::exr_io::read_channels(expected_exr).unwrap();
    let expected = &chans.iter().find(|c| c.0 == "Y").unwrap().1;
    let s = &camera["sensor"];
    let bits = s["adc_bits"].as_f64().unwrap();
    let max_dn = 2f64.powf(bits) - 1.0;
    let k = max_dn / s["voltage_swing_v"].as_f64().unwrap();
    let black = s["black_level_dn"].as_f64().unwrap();
    let dsnu_dn = k * s["dsnu_sigma_v"].as_f64().unwrap_or(0.0);
    let prnu = s["prnu_sigma_percent"].as_f64().unwrap_or(0.0) / 100.0;
    let (mut sz, mut sz2, mut n) = (0.0, 0.0, 0usize);
    for (i, &e) in expected.iter().enumerate() {
        if frames.iter().any(|f| f[i] == 0 || f[i] as f64 >= max_dn) {
            continue;
        }
        let m = frames.iter().map(|f| f[i] as f64).sum::<f64>() / n_f;
        let v = frames
            .iter()
            .map(|f| (f[i] as f64 - m).powi(2))
            .sum::<f64>()
            / (n_f - 1.0);
        let fixed = dsnu_dn * dsnu_dn + (prnu * (e as f64 - black)).powi(2);
        let z = (m - e as f64) / (v / n_f + fixed).sqrt();
        sz += z;
        sz2 += z * z;
        n += 1;
    }
    (sz / n as f64, sz2 / n as f64, n)
}

#[test]
fn fitted_camera_simulates_the_recorded_mean() {
    use camsim_pipeline::simulate::{simulate, SimulateOptions};
    let o = diagnose_generated(&[("conversion_gain", 0.9)], Concealment::Mimicked, 2);
    assert!(findings(&o.report).iter().any(|f| f.0 == "conversion_gain"));
    let set_dir = o.dir.path().join("set");
    let captures = set_dir.join("captures.json");
    let fitted = o.dir.path().join("out/fitted_camera.json");
    let fitted_json: Value =
        serde_json::from_str(&std::fs::read_to_string(&fitted).unwrap()).unwrap();
    let believed_path = set_dir.join("camera.json");
    let believed_json: Value =
        serde_json::from_str(&std::fs::read_to_string(&believed_path).unwrap()).unwrap();
    let run = |camera: &Path, out: &Path| {
        let set = load_captures(&captures, Some(camera)).unwrap();
        simulate(
            &set,
            &SimulateOptions {
                out_dir: out.to_path_buf(),
                seed: 0,
                expected: true,
                progress: false,
            },
        )
        .unwrap();
        set
    };
    let out_fit = o.dir.path().join("expected_fitted");
    let out_bel = o.dir.path().join("expected_believed");
    let set = run(&fitted, &out_fit);
    run(&believed_path, &out_bel);
    let mut worst_believed: f64 = 0.0;
    for (s, shot) in set.shots.iter().enumerate() {
        let (mz, mz2, n) = z_stats(
            &set,
            &set_dir,
            s,
            &out_fit.join(format!("{}.exr", shot.id)),
            &fitted_json,
        );
        assert!(n > 100, "{}: {n} usable pixels", shot.id);
        // z over n pixels: mean 0 ± 1/√n, mean z² 1 ± √(2/n) (5σ each). The fixed pattern
        // is Gaussian in the model; the z² bound adds the 1/(F−1) inflation of a z built
        // with the sample variance (F = 2 frames in darks: Student-t tails), hence the
        // looser factor there.
        let f = shot.frames.len() as f64;
        let infl = if f > 3.0 { (f - 1.0) / (f - 3.0) } else { 3.0 };
        let nf = n as f64;
        assert!(
            mz.abs() <= 5.0 / nf.sqrt(),
            "{}: fitted camera's expected image is off the recorded mean: mean z {mz:.3} over {n} pixels",
            shot.id
        );
        assert!(
            mz2 <= infl * (1.0 + 5.0 * (2.0 / nf).sqrt()),
            "{}: mean z² {mz2:.3} over {n} pixels (bound {:.3})",
            shot.id,
            infl * (1.0 + 5.0 * (2.0 / nf).sqrt())
        );
        let (mzb, _, _) = z_stats(
            &set,
            &set_dir,
            s,
            &out_bel.join(format!("{}.exr", shot.id)),
            &believed_json,
        );
        worst_believed = worst_believed.max(mzb.abs());
    }
    // The test can fail: the believed camera's expected images miss the recording.
    assert!(
        worst_believed > 10.0 / ((ROWS * COLS) as f64).sqrt(),
        "the believed camera already matched (worst mean z {worst_believed})"
    );
}

// ---------------------------------------------------------------------------------------
// Acceptance 3: every output; bad sets give one clear error.

#[test]
fn every_output_of_the_spec_is_written() {
    let o = diagnose_generated(&[("black_level", 6.5)], Concealment::Mimicked, 1);
    let r = &o.report;
    // report.json keys exactly as in effects.md (extra keys allowed after them).
    for k in ["fit_before", "findings", "fit_after", "fitted_camera"] {
        assert!(r.get(k).is_some(), "report.json lacks {k}");
    }
    for k in ["fit_before", "fit_after"] {
        assert!(r[k]["chi2_per_dof"].as_f64().unwrap().is_finite());
        assert!(r[k]["dof"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(r["fitted_camera"], "fitted_camera.json");
    let f = &r["findings"][0];
    for k in [
        "effect",
        "magnitude",
        "where",
        "explanation",
        "evidence",
        "fit_after",
    ] {
        assert!(f.get(k).is_some(), "finding lacks {k}: {f}");
    }
    assert!(f["evidence"]["delta_bic"].as_f64().unwrap() < -10.0);
    assert!(f["fit_after"]["chi2_per_dof"].as_f64().is_some());
    assert!(!f["where"].as_str().unwrap().is_empty());
    // fitted_camera.json is a camera `camsim simulate` reads, with the finding in it.
    let out = o.dir.path().join("out");
    let cam = camsim_pipeline::config::load_camera(&out.join("fitted_camera.json")).unwrap();
    let believed =
        camsim_pipeline::config::load_camera(&o.dir.path().join("set/camera.json")).unwrap();
    let dbl = cam.sensor.black_level_dn - believed.sensor.black_level_dn;
    assert!(
        (dbl - 6.5).abs() < 0.3 * 6.5,
        "fitted black level off by {dbl}"
    );
    // report.html with residual maps before/after, photon-transfer curves, radial
    // profiles, the ranked candidates; every image it names exists.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    for needle in [
        "residual_0_before.png",
        "residual_0_after.png",
        "ptc_0.png",
        "radial_before.png",
        "radial_after.png",
        "Ranked candidates",
        "Findings",
    ] {
        assert!(html.contains(needle), "report.html lacks {needle}");
    }
    for cap in html.split("src=\"").skip(1) {
        let name = &cap[..cap.find('"').unwrap()];
        assert!(out.join(name).is_file(), "report.html names missing {name}");
    }
    // No staging folder is left behind.
    let names: Vec<String> = std::fs::read_dir(o.dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
}

#[test]
fn edge_shots_give_an_mtf_figure() {
    // The figure comes from the edge shots whatever the candidates: CI candidates (the full
    // search of this set is defocus_under_scene_full's).
    let o = diagnose_generated_with(
        &[("defocus", 1.5)],
        Concealment::UnderScene,
        2,
        Candidates::Ci(&["defocus"]),
    );
    let html = std::fs::read_to_string(o.dir.path().join("out/report.html")).unwrap();
    assert!(html.contains("mtf_0.png"), "no MTF figure");
    assert!(o.dir.path().join("out/mtf_0.png").is_file());
}

/// A small valid set to break.
fn base_set() -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let t = generate_capture_set(
        &spec(&[("dark_current", 0.02)], Concealment::Mimicked, 5),
        &dir.path().join("set"),
    )
    .unwrap();
    (dir, t.captures_json)
}

/// Loading + diagnosing gives one error (never a panic), whose text names `what`.
fn expect_error(captures: &Path, out: &Path, what: &[&str]) {
    let r = std::panic::catch_unwind(|| {
        load_captures(captures, None)
            .and_then(|set| run_diagnose(&set, out, &DiagnoseCmdOptions::default()))
    });
    let msg = match r {
        Err(_) => panic!("diagnose panicked on a bad set ({what:?})"),
        Ok(Ok(_)) => panic!("diagnose accepted a bad set ({what:?})"),
        Ok(Err(e)) => e.to_string(),
    };
    assert!(!msg.contains('\n'), "not one line: {msg}");
    for w in what {
        assert!(msg.contains(w), "error \"{msg}\" does not name {w}");
    }
    assert!(!out.exists(), "output written despite the error: {msg}");
}

fn edit_captures(captures: &Path, f: impl FnOnce(&mut Value)) {
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(captures).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(captures, serde_json::to_string(&v).unwrap()).unwrap();
}

#[test]
fn bad_sets_give_one_clear_error() {
    // missing frame
    let (d, c) = base_set();
    let frame = {
        let v: Value = serde_json::from_str(&std::fs::read_to_string(&c).unwrap()).unwrap();
        v["shots"][0]["frames"][1].as_str().unwrap().to_string()
    };
    std::fs::remove_file(d.path().join("set").join(&frame)).unwrap();
    expect_error(&c, &d.path().join("out"), &[&frame]);

    // a frame of the wrong size
    let (d, c) = base_set();
    let p = d.path().join("set").join(&frame);
    image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(7, 5, image::Luma([100]))
        .save(&p)
        .unwrap();
    expect_error(&c, &d.path().join("out"), &[&frame, "5×7"]);

    // no shots
    let (d, c) = base_set();
    edit_captures(&c, |v| v["shots"] = serde_json::json!([]));
    let r = std::panic::catch_unwind(|| {
        load_captures(&c, None).and_then(|set| {
            run_diagnose(&set, &d.path().join("out"), &DiagnoseCmdOptions::default())
        })
    });
    let msg = r
        .expect("no panic")
        .expect_err("no shots accepted")
        .to_string();
    assert!(msg.contains("shot"), "{msg}");
    assert!(!d.path().join("out").exists());

    // shots without frames only
    let (d, c) = base_set();
    edit_captures(&c, |v| {
        for s in v["shots"].as_array_mut().unwrap() {
            s["frames"] = serde_json::json!([]);
        }
    });
    let r = std::panic::catch_unwind(|| {
        load_captures(&c, None).and_then(|set| {
            run_diagnose(&set, &d.path().join("out"), &DiagnoseCmdOptions::default())
        })
    });
    let msg = r
        .expect("no panic")
        .expect_err("frameless set accepted")
        .to_string();
    assert!(msg.contains("frames"), "{msg}");
    assert!(!d.path().join("out").exists());

    // corrupt captures.json and corrupt camera.json
    let (d, c) = base_set();
    std::fs::write(&c, "{\"camera\": \"camera.json\", \"shots\": [").unwrap();
    expect_error(&c, &d.path().join("out"), &["captures.json"]);
    let (d, c) = base_set();
    std::fs::write(d.path().join("set/camera.json"), "{ not json").unwrap();
    expect_error(&c, &d.path().join("out"), &["camera.json"]);

    // a frame that is not an image
    let (d, c) = base_set();
    std::fs::write(d.path().join("set").join(&frame), b"garbage").unwrap();
    expect_error(&c, &d.path().join("out"), &[&frame]);

    // unknown effect id / bad threshold
    let (d, c) = base_set();
    let set = load_captures(&c, None).unwrap();
    let opts = DiagnoseCmdOptions {
        effects: vec!["vignetting".into()],
        ..Default::default()
    };
    let msg = run_diagnose(&set, &d.path().join("out"), &opts)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("vignetting") && msg.contains("relative_illumination"),
        "{msg}"
    );
    let opts = DiagnoseCmdOptions {
        bic_threshold: -1.0,
        ..Default::default()
    };
    let msg = run_diagnose(&set, &d.path().join("out"), &opts)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("--bic-threshold"), "{msg}");
}

/// Determinism: the same set gives the same report.json (findings, magnitudes, χ², candidate
/// table, every number) on 1 and on 3 threads — the likelihood's parallel sums are over fixed
/// blocks, combined in order.
#[test]
fn diagnosis_is_the_same_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let set_dir = dir.path().join("set");
    let truth = generate_capture_set(
        &spec(&[("conversion_gain", 0.9)], Concealment::Mimicked, 5),
        &set_dir,
    )
    .unwrap();
    let set = load_captures(&truth.captures_json, None).unwrap();
    let run = |threads: usize| -> String {
        let out = dir.path().join(format!("out{threads}"));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let t0 = std::time::Instant::now();
        pool.install(|| run_diagnose(&set, &out, &DiagnoseCmdOptions::default()).unwrap());
        eprintln!(
            "diagnose on {threads} thread(s): {:.1} s",
            t0.elapsed().as_secs_f64()
        );
        std::fs::read_to_string(out.join("report.json")).unwrap()
    };
    let (one, three) = (run(1), run(3));
    let r: Value = serde_json::from_str(&one).unwrap();
    assert!(!findings(&r).is_empty(), "the set should give findings");
    assert_eq!(one, three, "report.json differs between 1 and 3 threads");
}

// Noise the field has measured since the paper (issue 21): row noise, RTN pixels, black-level
// drift, dark current against temperature. Each is concealed next to its look-alike
// (docs/diagnose.md: read_noise, hot_pixels, black_level, dark_current) and searched with the
// CI candidates plus the four new ids; the same sets without the effect (magnitude 0: the
// same shots, the believed camera) must give no finding at all.

/// The issue-21 candidate ids, searched on top of the sensor-side ones.
const NOISE_IDS: [&str; 4] = ["row_noise", "rtn", "black_level_drift", "dark_temperature"];

fn noise_null(id: &str, c: Candidates) {
    let o = diagnose_generated_with(&[(id, 0.0)], Concealment::Mimicked, 1, c);
    let what = format!("{id}=0 (mimicked, the effect's shots without it)");
    assert!(
        findings(&o.report).is_empty(),
        "{what}: findings {:?}",
        findings(&o.report)
    );
    assert!(
        undecided(&o.report).is_empty(),
        "{what}: undecided {:?}",
        undecided(&o.report)
    );
    assert_fit_after(&o, &what);
}

ci_and_full!(
    /// Row noise 0.4 mV (≈ 1.6 DN per row and frame; read noise 4.1 DN per pixel) in the
    /// repeated flats and darks that separate read noise from fixed pattern; the same shots
    /// without it give no finding.
    row_noise_mimicking_read_noise,
    row_noise_mimicking_read_noise_full,
    &NOISE_IDS,
    |c| {
        single_with("row_noise", 4e-4, Concealment::Mimicked, 0.0, c);
        noise_null("row_noise", c);
    }
);

ci_and_full!(
    /// RTN in 0.6 % of the pixels (steps lognormal about 8 mV, switching 0.4 per frame) in
    /// the hot-pixel set (darks at three exposures, flats at four levels, 4 repeats).
    rtn_mimicking_hot_pixels,
    rtn_mimicking_hot_pixels_full,
    &NOISE_IDS,
    |c| {
        single_with("rtn", 0.006, Concealment::Mimicked, 0.0, c);
        noise_null("rtn", c);
    }
);

ci_and_full!(
    /// A 6 DN drift of the pedestal over the set (14 frames) in the black-level set.
    black_level_drift_mimicking_black_level,
    black_level_drift_mimicking_black_level_full,
    &NOISE_IDS,
    |c| {
        single_with("black_level_drift", 6.0, Concealment::Mimicked, 0.0, c);
        noise_null("black_level_drift", c);
    }
);

ci_and_full!(
    /// Dark current doubling every 6 °C, darks at 10, 20, 30, 40 °C (two exposures each);
    /// the null twin has the same temperature series and no law.
    dark_temperature_mimicking_dark_current,
    dark_temperature_mimicking_dark_current_full,
    &NOISE_IDS,
    |c| {
        single_with("dark_temperature", 6.0, Concealment::Mimicked, 0.0, c);
        noise_null("dark_temperature", c);
    }
);
