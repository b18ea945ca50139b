//! Every prescription in lenses/ loads and has its published EFL / F-number / magnification.
use camsim_lens::{GlassCatalog, LensPrescription};
use serde_json::Value;

#[test]
fn every_bundled_lens_matches_its_published_numbers() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let l = LensPrescription::from_json_file(&p, &GlassCatalog::bundled())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            l.provenance.as_deref().is_some_and(|s| s.len() > 40),
            "{name}"
        );
        let fo = l.first_order(l.primary_nm).unwrap();
        // In focus: the image plane is the paraxial image (1e-4 mm).
        assert!(
            (fo.paraxial_image_distance_mm - l.surfaces.last().unwrap().thickness_mm).abs() < 1e-4,
            "{name}: not at paraxial focus"
        );
        let v: Value = serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        let Some(pb) = v.get("published") else {
            // The two optics_ref double Gauss lenses are checked in tests/readers.rs.
            assert!(
                name.starts_with("double_gauss_"),
                "{name}: no \"published\" block"
            );
            n += 1;
            continue;
        };
        let g = |k: &str| pb.get(k).and_then(|x| x.as_f64());
        if let Some(efl) = g("efl_mm") {
            let tol = g("efl_abs_tol_mm").unwrap_or_else(|| g("efl_rel_tol").unwrap() * efl);
            assert!(
                (fo.efl_mm - efl).abs() <= tol,
                "{name}: EFL {} vs {efl}",
                fo.efl_mm
            );
        }
        if let Some(fno) = g("f_number") {
            let tol = g("f_number_rel_tol").unwrap() * fno;
            assert!(
                (fo.f_number - fno).abs() <= tol,
                "{name}: F/# {} vs {fno}",
                fo.f_number
            );
        }
        if let Some(m) = g("magnification") {
            let tol = g("magnification_abs_tol").unwrap();
            assert!(
                (fo.magnification - m).abs() <= tol,
                "{name}: m {}",
                fo.magnification
            );
        }
        assert!(g("efl_mm").is_some() || g("f_number").is_some() || g("magnification").is_some());
        n += 1;
    }
    assert!(n >= 12, "only {n} lenses");
}
