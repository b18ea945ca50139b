//! Field curvature and astigmatism (sagittal / tangential foci) against closed forms and an
//! independent ray-pair computation.
use camsim_lens::prescription::{ApertureFile, MaterialFile, PrescriptionFile, SurfaceFile};
use camsim_lens::{GlassCatalog, LensPrescription};

const WL: f64 = 587.5618;

fn surf(radius_mm: Option<f64>, thickness_mm: f64, n: Option<f64>) -> SurfaceFile {
    SurfaceFile {
        radius_mm,
        thickness_mm,
        material: match n {
            None => MaterialFile::Name("air".into()),
            Some(nd) => MaterialFile::Model { nd, vd: 0.0 },
        },
        semi_diameter_mm: None,
        conic: 0.0,
        aspheric_coeffs: vec![],
        odd_aspheric_coeffs: vec![],
        stop: false,
    }
}

fn lens(mut surfaces: Vec<SurfaceFile>, stop: usize, epd_mm: f64) -> LensPrescription {
    surfaces[stop].stop = true;
    let f = PrescriptionFile {
        name: "test".into(),
        units: "mm".into(),
        surfaces,
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![WL],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap()
}

fn bundled(name: &str) -> LensPrescription {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses")
        .join(name);
    let l = LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap();
    l.focused(l.primary_nm).unwrap()
}

#[test]
fn thin_lens_with_the_stop_at_the_lens_has_the_third_order_field_curves() {
    // Third-order theory of a thin lens with the stop in contact (Smith, "Modern Optical
    // Engineering" §6.3; Jenkins & White §9.9): whatever its bending, the sagittal and
    // tangential image surfaces have sags x_s = −h²(n+1)/(2nf) and x_t = −h²(3n+1)/(2nf) at
    // image height h (Petzval x_p = −h²/(2nf), with x_t − x_p = 3(x_s − x_p)).
    let n = 1.5;
    for (r1, r2) in [(100.0, -100.0), (60.0, -300.0), (-400.0, -42.857)] {
        let mut s0 = surf(Some(r1), 1e-4, Some(n));
        s0.stop = false;
        let l = lens(vec![s0, surf(Some(r2), 100.0, None)], 0, 2.0);
        let l = l.focused(WL).unwrap();
        let f = l.first_order(WL).unwrap().efl_mm;
        for th in [0.5f64, 1.0, 2.0] {
            let fc = l.field_curvature(th, WL).unwrap();
            let h = fc.chief_height_mm;
            let xs = -h * h * (n + 1.0) / (2.0 * n * f);
            let xt = -h * h * (3.0 * n + 1.0) / (2.0 * n * f);
            // Fifth-order terms are O(θ²) ≈ 1e-3 relative at 2°.
            assert!(
                (fc.sagittal_mm - xs).abs() < 2e-3 * xs.abs(),
                "R {r1}/{r2} {th}°: s {} vs {xs}",
                fc.sagittal_mm
            );
            assert!(
                (fc.tangential_mm - xt).abs() < 2e-3 * xt.abs(),
                "R {r1}/{r2} {th}°: t {} vs {xt}",
                fc.tangential_mm
            );
        }
    }
}

#[test]
fn refracting_sphere_with_the_stop_at_its_centre_images_on_a_concentric_sphere() {
    // Every chief ray passes through the centre of curvature C undeviated and is an axis of
    // symmetry, so there is no astigmatism and both foci lie on the sphere about C of radius
    // ρ = f' − R = R/(n − 1) (f' = nR/(n − 1) from the vertex): exactly, at any field,
    // Δz = ρ (cos θ − 1) from the paraxial image plane.
    let (n, r) = (1.6, 20.0);
    let rho = r / (n - 1.0);
    let l = lens(
        vec![surf(Some(r), r, Some(n)), surf(None, rho, Some(n))],
        1,
        1.0,
    );
    let l = l.focused(WL).unwrap();
    assert!((l.surfaces[1].thickness_mm - rho).abs() < 1e-9);
    for th in [5.0f64, 15.0, 30.0, 45.0] {
        let fc = l.field_curvature(th, WL).unwrap();
        let want = rho * (th.to_radians().cos() - 1.0);
        assert!(
            (fc.sagittal_mm - want).abs() < 1e-9 && (fc.tangential_mm - want).abs() < 1e-9,
            "{th}°: s {} t {} vs {want}",
            fc.sagittal_mm,
            fc.tangential_mm
        );
    }
}

#[test]
fn on_axis_foci_are_the_paraxial_foci_of_each_wavelength() {
    // On the axis both foci are the paraxial image: at the primary wavelength the lens is
    // focused (0), at another the longitudinal colour BFL(λ) − BFL(primary).
    let l = bundled("double_gauss_50mm_f2.json");
    let b0 = l.first_order(l.primary_nm).unwrap().bfl_mm;
    for &w in &l.wavelengths_nm {
        let fc = l.field_curvature(0.0, w).unwrap();
        let want = l.first_order(w).unwrap().bfl_mm - b0;
        assert!(
            (fc.sagittal_mm - want).abs() < 1e-9 && (fc.tangential_mm - want).abs() < 1e-9,
            "{w} nm: {fc:?} vs {want}"
        );
    }
}

#[test]
fn coddington_agrees_with_traced_ray_pairs() {
    // Two independent computations of the same foci: Coddington's differential equations
    // along the chief ray, and finite ray pairs intersected after the lens (Richardson
    // extrapolated). Includes an even asphere (principal curvatures of the asphere) and a
    // fisheye at 77°.
    for (name, fracs) in [
        ("double_gauss_50mm_f2.json", vec![0.3, 0.7, 1.0]),
        ("zmx_us8427765_aspheric.json", vec![0.5, 1.0]),
        ("pbrt_fisheye_10mm_f4.json", vec![0.5, 1.0]),
        ("iset_tessar_50mm.json", vec![1.0]),
    ] {
        let l = bundled(name);
        let max = l.fields_deg.iter().cloned().fold(0.0, f64::max);
        for f in fracs {
            let th = f * max;
            for &w in &l.wavelengths_nm {
                let a = l.field_curvature(th, w).unwrap();
                let b = l.field_curvature_from_ray_pairs(th, w, 1e-3).unwrap();
                let scale = 1.0 + a.sagittal_mm.abs().max(a.tangential_mm.abs());
                assert!(
                    (a.sagittal_mm - b.sagittal_mm).abs() < 2e-6 * scale
                        && (a.tangential_mm - b.tangential_mm).abs() < 2e-6 * scale,
                    "{name} {th}° {w} nm: Coddington {a:?} vs rays {b:?}"
                );
            }
        }
    }
}
