//! Foreign-format readers against published data.
use camsim_lens::readers::read_iset_dat;
use camsim_lens::{GlassCatalog, LensPrescription};

#[test]
fn pbrt_dgauss_dat_is_a_50mm_lens() {
    // Smith, "Modern Lens Design" p. 312: US 2,673,491 double Gauss, scaled to 50 mm
    // (file header); patent data are rounded, so the nominal EFL holds to ~1 %.
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/real/lens/prescriptions/pbrt_dgauss.50mm.dat");
    let f = read_iset_dat(&std::fs::read_to_string(p).unwrap(), "dgauss 50mm").unwrap();
    assert_eq!(f.surfaces.len(), 11);
    assert!(f.surfaces[5].stop && f.surfaces[5].radius_mm.is_none());
    let l = LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap();
    let fo = l.first_order(l.primary_nm).unwrap();
    assert!((fo.efl_mm - 50.0).abs() < 0.5, "EFL {}", fo.efl_mm);
    // The stop is filled: marginal ray height at the stop = 17.1/2.
    assert!((fo.stop_semi_diameter_mm - 8.55).abs() < 1e-9);
}

#[test]
fn dat_errors_name_the_line() {
    let e = read_iset_dat("# c\n10 2 1.5 10\n10 2 x 10\n", "bad")
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 3") && e.contains("'x'"), "{e}");
    let e = read_iset_dat("10 2 1.5 10\n-10 20 1 10\n", "nostop")
        .unwrap_err()
        .to_string();
    assert!(e.contains("no stop"), "{e}");
}

#[test]
fn bundled_lenses_load_and_have_their_published_efl() {
    // Published (optics_ref / Optiland & rayoptics) EFLs, F/2.000.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses");
    for (file, efl) in [
        ("double_gauss_50mm_f2.json", 50.001879),
        ("double_gauss_100mm_f2.json", 100.003760),
    ] {
        let l = LensPrescription::from_json_file(dir.join(file), &GlassCatalog::bundled()).unwrap();
        let fo = l.first_order(l.primary_nm).unwrap();
        assert!((fo.efl_mm - efl).abs() < 1e-5, "{file}: {}", fo.efl_mm);
        assert!((fo.f_number - 2.0).abs() < 1e-4);
        assert!(l.provenance.is_some());
        // The last thickness is the paraxial BFL, so the lens is in focus.
        assert!(
            (fo.paraxial_image_distance_mm - l.surfaces.last().unwrap().thickness_mm).abs() < 1e-4
        );
    }
}
