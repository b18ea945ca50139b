//! On-axis MTF of strongly aberrated lenses (5–20 waves p-v) against Optiland with a 512²
//! pupil, at the paraxial focus and at the MTF best focus (issue 17 §2).
//!
//! References: lens/tests/data/optics_ref/mtf_*.mtf.ref.json, made by
//! `tools/optics_ref_run.sh mtf_singlet_planoconvex_f3 mtf_singlet_biconvex_f4`
//! (tools/optics_ref_extra.py mtf: optiland's OPD map on a 512² grid through ref_lens.py's
//! mtf_from_opd; the best focus by the same merit and search as camsim_lens::focus).
use camsim_lens::focus::MtfMerit;
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};
use serde_json::Value;
use std::path::Path;

fn data(name: &str) -> (LensPrescription, Value, Value) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/optics_ref");
    let input: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap())
            .unwrap();
    let r: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join(format!("{name}.mtf.ref.json"))).unwrap(),
    )
    .unwrap();
    let lens = LensPrescription::from_json_file(
        dir.join(format!("{name}.json")),
        &GlassCatalog::bundled(),
    )
    .unwrap();
    let lens = lens.focused(lens.primary_nm).unwrap();
    (lens, input, r["results"].clone())
}

fn mtf_of(lens: &LensPrescription, freqs: &[f64], n_min: usize, n_max: usize) -> (Vec<f64>, bool) {
    let (wo, s) = lens
        .wave_optics_sampled(0.0, lens.primary_nm, n_min, n_max, 2, freqs)
        .unwrap();
    (
        wo.mtf
            .iter()
            .map(|p| 0.5 * (p.tangential + p.sagittal))
            .collect(),
        s.alias_free,
    )
}

fn ref_mtf(r: &Value, freqs: &[f64]) -> Vec<f64> {
    freqs
        .iter()
        .map(|f| {
            let v = &r["mtf"][format!("{f}")];
            0.5 * (v["tangential"].as_f64().unwrap() + v["sagittal"].as_f64().unwrap())
        })
        .collect()
}

fn check(name: &str) {
    let (lens, input, r) = data(name);
    let freqs: Vec<f64> = input["mtf_freqs_lpmm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let merit_f: Vec<f64> = input["merit_freqs_lpmm"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let wl = lens.primary_nm;
    // the lens is in the regime of the issue: 5–20 waves p-v at paraxial focus
    let pv = r["paraxial"]["opd_pv_waves"].as_f64().unwrap();
    let ours_pv = lens.opd_map(0.0, wl, 256).unwrap().pv_waves;
    assert!((5.0..=20.0).contains(&pv), "{name}: {pv} waves p-v");
    assert!(
        (ours_pv - pv).abs() < 0.01 * pv,
        "{name}: p-v {ours_pv} vs {pv}"
    );

    // paraxial focus
    let (ours, ok) = mtf_of(&lens, &freqs, 64, 1024);
    assert!(ok, "{name}: sampling not alias free");
    let want = ref_mtf(&r["paraxial"], &freqs);
    for ((f, a), b) in freqs.iter().zip(&ours).zip(&want) {
        assert!(
            (a - b).abs() < 0.03,
            "{name} paraxial {f} lp/mm: {a} vs Optiland {b}"
        );
    }
    // a fixed 64² grid aliases here (what the sampling rule fixes)
    let (coarse, _) = mtf_of(&lens, &freqs, 64, 64);
    let worst = coarse
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst > 0.03, "{name}: 64² is already within {worst}");

    // best focus: the plane maximising the mean (T+S)/2 over merit_f
    let fans: Vec<_> = lens
        .wavelengths_nm
        .iter()
        .map(|&w| {
            lens.ray_fan(
                0.0,
                w,
                wl,
                &camsim_lens::analysis::pupil_grid(33),
                Clipping::None,
            )
            .unwrap()
        })
        .collect();
    let dz_rms = lens.best_focus_shift_mm(&fans, 0.02 * lens.first_order(wl).unwrap().efl_mm);
    let want_rms = r["best_rms"]["image_shift_mm"].as_f64().unwrap();
    assert!(
        (dz_rms - want_rms).abs() < 1e-4,
        "{name}: RMS best focus {dz_rms} vs {want_rms}"
    );
    let (lo, hi) = lens.focus_search_interval_mm(wl, dz_rms).unwrap();
    let merit = MtfMerit::on_axis(wl, &merit_f);
    let best = lens.best_focus_mtf(&merit, lo, hi).unwrap();
    assert!(best.alias_free);
    assert!(best.merit >= best.merit_at_zero);
    let want_dz = r["best_mtf"]["image_shift_mm"].as_f64().unwrap();
    let nw = lens.first_order(wl).unwrap().working_f_number;
    let dof = 2.0 * wl * 1e-6 * nw * nw;
    let d0 = lens.surfaces.last().unwrap().thickness_mm;
    let want = ref_mtf(&r["best_mtf"], &freqs);
    // plane for plane: our MTF on Optiland's best-focus plane
    let at_ref = lens.with_image_distance(d0 + want_dz);
    let (ours, _) = mtf_of(&at_ref, &freqs, 64, 1024);
    for ((f, a), b) in freqs.iter().zip(&ours).zip(&want) {
        assert!(
            (a - b).abs() < 0.03,
            "{name} on Optiland's best focus, {f} lp/mm: {a} vs {b}"
        );
    }
    // our search finds a plane at least as good, within the depth of focus of Optiland's
    let (merit_at_ref, _) = at_ref.mtf_merit(&merit).unwrap();
    assert!(
        best.merit >= merit_at_ref - 0.005,
        "{name}: merit {} vs {merit_at_ref}",
        best.merit
    );
    assert!(
        (best.image_shift_mm - want_dz).abs() < 1.5 * dof,
        "{name}: best focus {} vs Optiland {want_dz} (depth of focus {dof})",
        best.image_shift_mm
    );
    // and the best-focus MTF of each tool agrees
    let (ours, _) = mtf_of(
        &lens.with_image_distance(d0 + best.image_shift_mm),
        &freqs,
        64,
        1024,
    );
    for ((f, a), b) in freqs.iter().zip(&ours).zip(&want) {
        assert!(
            (a - b).abs() < 0.03,
            "{name} best focus {f} lp/mm: {a} vs Optiland {b}"
        );
    }
}

#[test]
fn planoconvex_singlet_mtf_matches_optiland_512() {
    check("mtf_singlet_planoconvex_f3");
}

#[test]
fn biconvex_singlet_mtf_matches_optiland_512() {
    check("mtf_singlet_biconvex_f4");
}
