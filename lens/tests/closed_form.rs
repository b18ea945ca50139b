//! Paraxial and real-ray results against closed forms (Smith, "Modern Optical Engineering";
//! Welford, "Aberrations of Optical Systems"; Goodman, "Introduction to Fourier Optics").
use camsim_lens::prescription::{ApertureFile, MaterialFile, PrescriptionFile, SurfaceFile};
use camsim_lens::trace::Ray;
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};

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

fn lens(
    mut surfaces: Vec<SurfaceFile>,
    stop: usize,
    epd_mm: f64,
    object_distance_mm: Option<f64>,
) -> LensPrescription {
    surfaces[stop].stop = true;
    let f = PrescriptionFile {
        name: "test".into(),
        units: "mm".into(),
        surfaces,
        object_distance_mm,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![587.5618],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap()
}

#[test]
fn thin_lens_limit_lensmaker() {
    // 1/f = (n − 1)(1/R1 − 1/R2) for t → 0.
    let (n, r1, r2) = (1.5, 80.0, -120.0);
    let l = lens(
        vec![surf(Some(r1), 1e-6, Some(n)), surf(Some(r2), 50.0, None)],
        0,
        10.0,
        None,
    );
    let fo = l.first_order(587.5618).unwrap();
    let f = 1.0 / ((n - 1.0) * (1.0 / r1 - 1.0 / r2));
    assert!((fo.efl_mm - f).abs() < 1e-6, "{} vs {f}", fo.efl_mm);
    assert!((fo.bfl_mm - f).abs() < 1e-5);
    assert!((fo.ffl_mm - f).abs() < 1e-5);
    // Stop at the lens: entrance and exit pupils at the lens, F/# = f/D.
    assert!(fo.entrance_pupil_z_mm.abs() < 1e-9);
    assert!((fo.f_number - f / 10.0).abs() < 1e-6);
}

#[test]
fn thick_lens_formulas() {
    // Smith §2.4 (thick lens): 1/f = (n−1)[1/R1 − 1/R2 + (n−1) t/(n R1 R2)],
    // BFL = f (1 − (n−1) t/(n R1)), FFL = f (1 + (n−1) t/(n R2)),
    // principal planes: δ1 = −f (n−1) t/(n R2) from V1, δ2 = −f (n−1) t/(n R1) from V2.
    let (n, r1, r2, t) = (1.6, 40.0, -60.0, 8.0);
    let l = lens(
        vec![surf(Some(r1), t, Some(n)), surf(Some(r2), 60.0, None)],
        0,
        10.0,
        None,
    );
    let fo = l.first_order(587.5618).unwrap();
    let f = 1.0 / ((n - 1.0) * (1.0 / r1 - 1.0 / r2 + (n - 1.0) * t / (n * r1 * r2)));
    assert!((fo.efl_mm - f).abs() < 1e-10 * f);
    assert!((fo.bfl_mm - f * (1.0 - (n - 1.0) * t / (n * r1))).abs() < 1e-10 * f);
    assert!((fo.ffl_mm - f * (1.0 + (n - 1.0) * t / (n * r2))).abs() < 1e-10 * f);
    let d1 = -f * (n - 1.0) * t / (n * r2);
    let d2 = -f * (n - 1.0) * t / (n * r1);
    assert!((fo.front_principal_z_mm - d1).abs() < 1e-10 * f);
    assert!((fo.rear_principal_z_mm - (t + d2)).abs() < 1e-10 * f);

    // Focusing (Gauss equation from the principal planes): 1/s' = 1/f − 1/s.
    let d = 500.0; // object 500 mm in front of V1
    let lf = l.focus_at(Some(d)).unwrap();
    let fo2 = lf.first_order(587.5618).unwrap();
    let s = d + d1;
    let s_img = 1.0 / (1.0 / f - 1.0 / s);
    assert!((lf.surfaces[1].thickness_mm - (s_img + d2)).abs() < 1e-9 * f);
    assert!((fo2.magnification - (-s_img / s)).abs() < 1e-10);
    // Working F/# for a finite conjugate: N_w ≈ (1 − m) f/D with the pupils at the principal
    // planes only when the stop is there; here check the Lagrange-invariant form instead:
    // N_w = 1/(2 u') with u' = (D/2)/s' when the stop (EP) is at the first vertex and H ≈ V.
    assert!(fo2.working_f_number > fo.working_f_number);
}

#[test]
fn single_surface_real_ray_intercept() {
    // A ray parallel to the axis at height h refracts at a sphere R (air → n) and crosses the
    // axis at z = R + R sin r / sin(i − r), sin i = h/R, sin r = sin i / n (triangle at the
    // centre of curvature).
    let (n, r) = (1.5, 50.0);
    let l = lens(vec![surf(Some(r), 400.0, Some(n))], 0, 40.0, None);
    for h in [1.0, 10.0, 20.0, 30.0] {
        let ray = Ray {
            origin_mm: [0.0, h, -10.0],
            direction: [0.0, 0.0, 1.0],
            opl_mm: 0.0,
        };
        let t = l.trace(&ray, 587.5618, Clipping::None).unwrap();
        let z_cross = t.image_mm[2] - t.image_mm[1] * t.direction[2] / t.direction[1];
        let i = (h / r).asin();
        let rr = (i.sin() / n).asin();
        let want = r + r * rr.sin() / (i - rr).sin();
        assert!((z_cross - want).abs() < 1e-9, "h {h}: {z_cross} vs {want}");
    }
}

fn ellipsoid_lens(n: f64, r: f64, epd: f64) -> LensPrescription {
    // Cartesian oval for an object at infinity: k = −1/n² images to z = n R/(n−1) exactly.
    let mut s = surf(Some(r), n * r / (n - 1.0), Some(n));
    s.conic = -1.0 / (n * n);
    lens(vec![s], 0, epd, None)
}

#[test]
fn conic_cartesian_oval_is_stigmatic() {
    let (n, r) = (1.5, 50.0);
    let l = ellipsoid_lens(n, r, 60.0);
    for h in [1.0, 10.0, 20.0, 29.0] {
        let ray = Ray {
            origin_mm: [0.0, h, -5.0],
            direction: [0.0, 0.0, 1.0],
            opl_mm: 0.0,
        };
        let t = l.trace(&ray, 587.5618, Clipping::None).unwrap();
        assert!(t.image_mm[1].abs() < 1e-9, "h {h}: y = {}", t.image_mm[1]);
    }
}

#[test]
fn even_asphere_series_of_a_sphere_traces_like_the_sphere() {
    // Paraboloid (k = −1) base + A4.. from the series of a sphere
    // z = r²/2R + r⁴/8R³ + r⁶/16R⁵ + 5r⁸/128R⁷ + 7r¹⁰/256R⁹ + 21r¹²/1024R¹¹ (+ O(r¹⁴/R¹³)).
    let (n, r) = (1.5, 50.0);
    let sphere = lens(vec![surf(Some(r), 120.0, Some(n))], 0, 16.0, None);
    let mut s = surf(Some(r), 120.0, Some(n));
    s.conic = -1.0;
    s.aspheric_coeffs = vec![
        1.0 / (8.0 * r.powi(3)),
        1.0 / (16.0 * r.powi(5)),
        5.0 / (128.0 * r.powi(7)),
        7.0 / (256.0 * r.powi(9)),
        21.0 / (1024.0 * r.powi(11)),
    ];
    let asph = lens(vec![s], 0, 16.0, None);
    for (h, ang) in [(2.0, 0.0), (7.5, 0.0), (5.0, 0.1), (-6.0, -0.2)] {
        let d = [0.0, f64::sin(ang), f64::cos(ang)];
        let ray = Ray {
            origin_mm: [1.0, h, -5.0],
            direction: d,
            opl_mm: 0.0,
        };
        let a = sphere.trace(&ray, 587.5618, Clipping::None).unwrap();
        let b = asph.trace(&ray, 587.5618, Clipping::None).unwrap();
        for k in 0..3 {
            assert!(
                (a.image_mm[k] - b.image_mm[k]).abs() < 1e-7,
                "h {h}: {:?} vs {:?}",
                a.image_mm,
                b.image_mm
            );
        }
        assert!((a.opl_mm - b.opl_mm).abs() < 1e-8);
    }
}

#[test]
fn total_internal_reflection_loses_the_ray() {
    // In glass (n = 1.5) a ray parallel to the axis meets the convex rear sphere |R| = 10 at
    // incidence sin i = h/|R|; critical sin i_c = 1/n = 0.667: h = 8 → TIR, h = 6 → passes.
    let l = lens(
        vec![surf(None, 5.0, Some(1.5)), surf(Some(-10.0), 20.0, None)],
        0,
        18.0,
        None,
    );
    let ray = |h: f64| Ray {
        origin_mm: [0.0, h, -1.0],
        direction: [0.0, 0.0, 1.0],
        opl_mm: 0.0,
    };
    assert!(l.trace(&ray(8.0), 587.5618, Clipping::None).is_none());
    assert!(l.trace(&ray(6.0), 587.5618, Clipping::None).is_some());
}

#[test]
fn vignetting_by_a_front_aperture_is_the_circle_overlap() {
    // Collimated beam of radius a (EP = stop, no optics in front) clipped by an aperture of the
    // same radius a at distance L in front: transmitted fraction = lens-shaped overlap of two
    // circles of radius a at centre distance d = L tan θ:
    // A = 2a² acos(d/2a) − (d/2)√(4a² − d²), fraction = A/(π a²).
    let a = 5.0;
    let big = 1000.0;
    let mut s0 = surf(None, 20.0, None);
    s0.semi_diameter_mm = Some(a);
    let mut s1 = surf(None, 2.0, None);
    s1.semi_diameter_mm = Some(big);
    let mut s2 = surf(Some(50.0), 5.0, Some(1.5));
    s2.semi_diameter_mm = Some(big);
    let mut s3 = surf(None, 95.0, None);
    s3.semi_diameter_mm = Some(big);
    let l = lens(vec![s0, s1, s2, s3], 1, 2.0 * a, None);
    for th in [3.0f64, 6.0, 10.0] {
        let ri = l.relative_illumination(th, l.primary_nm, 201).unwrap();
        let d = 20.0 * th.to_radians().tan();
        let area = 2.0 * a * a * (d / (2.0 * a)).acos() - d / 2.0 * (4.0 * a * a - d * d).sqrt();
        let want = area / (std::f64::consts::PI * a * a);
        // 201² grid: edge sampling error ~ perimeter·pitch/area ≈ 1 %.
        assert!(
            (ri.vignetting_factor - want).abs() < 0.01,
            "{th}°: {} vs {want}",
            ri.vignetting_factor
        );
        assert!(ri.cos4_factor <= 1.0 && ri.relative_illumination <= ri.vignetting_factor);
    }
}

#[test]
fn perfect_lens_mtf_is_the_diffraction_limit() {
    // The Cartesian oval is aberration-free on axis: OPD ≈ 0 and the MTF is the incoherent
    // diffraction limit (2/π)[acos ν − ν√(1 − ν²)], ν = f/ν_c, ν_c = 1/(λ N_w) (Goodman §6.4).
    let (n, r) = (1.5, 50.0);
    let l = ellipsoid_lens(n, r, 8.0);
    let fo = l.first_order(587.5618).unwrap();
    let nu_c = 1.0 / (587.5618e-6 * fo.working_f_number);
    let freqs: Vec<f64> = [0.1, 0.25, 0.5, 0.75].iter().map(|x| x * nu_c).collect();
    let wo = l.wave_optics(0.0, 587.5618, 64, 4, &freqs).unwrap();
    assert!(wo.opd.rms_waves < 1e-4, "OPD rms {}", wo.opd.rms_waves);
    assert!((wo.psf.values.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    for p in &wo.mtf {
        let v = p.freq_cyc_per_mm / nu_c;
        let want = 2.0 / std::f64::consts::PI * (v.acos() - v * (1.0 - v * v).sqrt());
        // 64-sample pupil: the discrete disc's autocorrelation deviates by ≲ 1 %.
        assert!(
            (p.tangential - want).abs() < 0.015,
            "ν {v}: {} vs {want}",
            p.tangential
        );
        assert!((p.sagittal - want).abs() < 0.015);
    }
}

#[test]
fn validation_names_the_bad_value() {
    let mut s = vec![surf(Some(0.0), 5.0, Some(1.5)), surf(None, 10.0, None)];
    s[1].stop = true;
    let f = PrescriptionFile {
        name: String::new(),
        units: "mm".into(),
        surfaces: s,
        object_distance_mm: None,
        fields_deg: vec![],
        wavelengths_nm: vec![],
        primary_nm: None,
        aperture: ApertureFile::FNumber { f_number: 2.0 },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    let e = LensPrescription::from_file_form(&f, &GlassCatalog::bundled())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("surface 0") && e.contains("radius_mm = 0"),
        "{e}"
    );
    let mut f2 = f.clone();
    f2.surfaces[0].radius_mm = Some(20.0);
    f2.surfaces[1].stop = false;
    let e = LensPrescription::from_file_form(&f2, &GlassCatalog::bundled())
        .unwrap_err()
        .to_string();
    assert!(e.contains("stop"), "{e}");
}
