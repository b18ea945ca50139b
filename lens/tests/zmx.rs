//! Zemax `.zmx` reader against the rayoptics patent files (shared/data/real/lens/prescriptions).
use camsim_lens::readers::{decode_text, read_zmx, read_zmx_file, ZmxOptions};
use camsim_lens::{GlassCatalog, LensPrescription};
use std::path::PathBuf;

fn pres(f: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/real/lens/prescriptions")
        .join(f)
}

/// Substitutions for glasses absent from the bundled catalogue (documented in lenses/README.md).
fn opts() -> ZmxOptions {
    ZmxOptions::default()
        .substitute("J-LAK14", "S-LAL14", "ohara")
        .substitute("L-TIM28_MOLD", "L-TIM28", "ohara")
        .substitute("SILICA", "LITHOSIL-Q", "schott")
}

fn load(f: &str) -> LensPrescription {
    let pf = read_zmx_file(pres(f), &opts()).unwrap();
    LensPrescription::from_file_form(&pf, &GlassCatalog::bundled()).unwrap()
}

#[test]
fn us583336_double_gauss_efl_matches_the_files_efly_target() {
    // The file's merit function has `EFLY 2 13 … 4.94E+1`: target EFL 49.4 mm, written to 3
    // significant digits → tolerance ±0.05 mm. FNUM 4.5 is the file's aperture (F/# = 4.5).
    let l = load("rayoptics_US00583336-2-scaled.zmx");
    assert_eq!(l.surfaces.len(), 12); // SURF 1…12 (0 = object, 13 = image)
    assert_eq!(l.stop_index, 6); // SURF 7
    assert!(l.object_distance_mm.is_none());
    assert_eq!(l.fields_deg, vec![0.0, 17.0, 24.0]); // FTYP 0: angles
    assert_eq!(l.wavelengths_nm.len(), 3);
    assert!((l.primary_nm - 587.5618).abs() < 1e-9); // PWAV 2
    let fo = l.first_order(l.primary_nm).unwrap();
    assert!((fo.efl_mm - 49.4).abs() < 0.05, "EFL {}", fo.efl_mm);
    assert!((fo.f_number - 4.5).abs() < 1e-9);
    // Surface 2: CURV 7.0613988631e-2 → R = 14.1615 mm, DISZ 1.386, N-BAK1 (Schott).
    let s = &l.surfaces[1];
    assert!((1.0 / s.curvature_per_mm - 1.0 / 7.061398863114783e-2).abs() < 1e-9);
    assert!((s.thickness_mm - 1.386).abs() < 1e-12);
    assert!((s.semi_diameter_mm.unwrap() - 6.3).abs() < 1e-12);
    // Schott data sheet N-BAK1: n_d = 1.57250 (also the file's GLAS line: 1.572500121386).
    assert!((s.medium.index(587.5618) - 1.5725).abs() < 2e-5);
}

#[test]
fn us5831776_lithography_lens_is_a_quarter_reduction() {
    // Finite conjugate (object DISZ 110.86 mm), OBNA 0.15, 248 nm, all fused silica. The design
    // is a 1/4 reduction lens: paraxial magnification −0.25. The surface data are given to 4–5
    // digits, so the magnification holds to ~1e-4; tolerance 1e-3.
    let l = load("rayoptics_US05831776-1.zmx");
    assert_eq!(l.surfaces.len(), 42);
    assert_eq!(l.wavelengths_nm, vec![248.0]);
    assert!((l.object_distance_mm.unwrap() - 110.8588354359).abs() < 1e-9);
    let fo = l.first_order(248.0).unwrap();
    assert!(
        (fo.magnification + 0.25).abs() < 1e-3,
        "m = {}",
        fo.magnification
    );
    // Object-space NA 0.15 → image-space NA 0.15/|m| = 0.6 (Lagrange invariant); paraxially
    // NA' = 1/(2 N_w) with tan vs sin of 0.15 differing by 1.1 % → tolerance 2 %.
    let na_img = 1.0 / (2.0 * fo.working_f_number);
    assert!((na_img / 0.6 - 1.0).abs() < 0.02, "image NA {na_img}");
}

#[test]
fn us8427765_even_asphere_and_f_number() {
    let l = load("rayoptics_US08427765-1.ZMX");
    assert_eq!(l.surfaces.len(), 11);
    assert_eq!(l.stop_index, 4); // SURF 5
                                 // SURF 4 EVENASPH: CONI 0.02, PARM 2 = 1.10721e-5 (r⁴), PARM 3 = 1.837e-7 (r⁶).
    let s = &l.surfaces[3];
    assert_eq!(s.conic, 0.02);
    assert_eq!(s.aspheric_coeffs, vec![1.10721e-5, 1.837e-7]);
    let fo = l.first_order(l.primary_nm).unwrap();
    assert!((fo.f_number - 2.1).abs() < 1e-9); // FNUM 2.1
                                               // Glasses: SF11 from Schott (data sheet n_d 1.78472), TAFD30 from Hoya (n_d 1.88300).
    assert!((l.surfaces[5].medium.index(587.5618) - 1.78472).abs() < 2e-5);
    assert!((l.surfaces[9].medium.index(587.5618) - 1.883).abs() < 2e-5);
}

#[test]
fn reflective_files_load_with_their_mirrors_and_coordinate_break() {
    // US5331467 (catadioptric: two Mangin mirrors) and US8011793 (off-axis four-mirror
    // system whose image plane is decentred by a coordinate break).
    let l = load("rayoptics_US05331467-1.zmx");
    let mirrors: Vec<usize> = (0..l.surfaces.len())
        .filter(|&j| l.surfaces[j].is_mirror())
        .collect();
    assert_eq!(mirrors, vec![3, 6]); // Zemax surfaces 4 and 7
    let l = load("rayoptics_US08011793-1.zmx");
    assert_eq!(l.surfaces.iter().filter(|s| s.is_mirror()).count(), 4);
    assert_eq!(l.coordinate_breaks.len(), 1);
    let cb = l.coordinate_breaks[0];
    assert_eq!(
        (cb.surface, cb.decenter_y_mm, cb.tilt_x_deg),
        (5, 140.0, 0.0)
    );
}

const MINI: &str = "VERS 1\nMODE SEQ\nUNIT MM X W X CM MR CPMM\nENPD 10\nFTYP 0 0 1 1 0 0 0\n\
YFLN 0 5\nWAVM 1 0.55 1\nSURF 0\n  TYPE STANDARD\n  CURV 0.0\n  DISZ INFINITY\n\
SURF 1\n  STOP\n  TYPE STANDARD\n  CURV 0.02\n  DISZ 5\n  GLAS N-BK7 0 0 1.5 40\n\
SURF 2\n  TYPE TYPEX\n  CURV -0.02\n  DISZ 45\nSURF 3\n  TYPE STANDARD\n  CURV 0\n  DISZ 0\n";

#[test]
fn unsupported_types_and_unknown_glasses_are_clear_errors() {
    let o = ZmxOptions::default();
    let e = read_zmx(MINI.replace("TYPEX", "TOROIDAL").as_bytes(), "t", &o)
        .unwrap_err()
        .to_string();
    assert!(e.contains("surface 2") && e.contains("TOROIDAL"), "{e}");
    let e = read_zmx(
        MINI.replace("TYPEX", "STANDARD")
            .replace("N-BK7", "UNOBTAINIUM")
            .as_bytes(),
        "t",
        &o,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("surface 1") && e.contains("UNOBTAINIUM"), "{e}");
}

#[test]
fn utf16_and_latin1_files_read_like_utf8() {
    let text = MINI.replace("TYPEX", "STANDARD");
    let a = read_zmx(text.as_bytes(), "t", &ZmxOptions::default()).unwrap();
    // UTF-16LE with BOM (Zemax's default), UTF-16BE with BOM, UTF-16LE without BOM.
    let mut le = vec![0xFF, 0xFE];
    let mut be = vec![0xFE, 0xFF];
    let mut le_nobom = Vec::new();
    for u in text.encode_utf16() {
        le.extend(u.to_le_bytes());
        be.extend(u.to_be_bytes());
        le_nobom.extend(u.to_le_bytes());
    }
    for bytes in [le, be, le_nobom] {
        assert_eq!(decode_text(&bytes), text);
        assert_eq!(read_zmx(&bytes, "t", &ZmxOptions::default()).unwrap(), a);
    }
    // latin-1 (a NOTE with 'é' = 0xE9, invalid UTF-8) decodes byte-for-code-point.
    let mut l1 = b"NOTE 0 caf\xE9\n".to_vec();
    l1.extend(text.as_bytes());
    assert!(decode_text(&l1).starts_with("NOTE 0 café"));
    assert_eq!(read_zmx(&l1, "t", &ZmxOptions::default()).unwrap(), a);
    // Closed form for this singlet: thick lens, R1 = 50, R2 = −50, d = 5, N-BK7 at 550 nm.
    let l = LensPrescription::from_file_form(&a, &GlassCatalog::bundled()).unwrap();
    let n = l.surfaces[0].medium.index(550.0);
    let phi = (n - 1.0) * (2.0 / 50.0 - (n - 1.0) * 5.0 / (n * 50.0 * 50.0));
    let fo = l.first_order(550.0).unwrap();
    assert!((fo.efl_mm - 1.0 / phi).abs() < 1e-9);
    assert!((fo.entrance_pupil_diameter_mm - 10.0).abs() < 1e-12);
}
