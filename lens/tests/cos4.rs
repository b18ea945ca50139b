//! Relative illumination of an (almost) aberration-free lens follows the cos⁴ law.
//!
//! `LensPrescription::relative_illumination` (analysis.rs) returns
//! `vignetting_factor × cos⁴θ'`, where the vignetting factor is the fraction of the pupil grid
//! transmitted at the field relative to on-axis (with semi-diameter clipping) and θ' is the
//! angle of the real chief ray (aimed at the stop centre) **in image space**, i.e.
//! cos θ' = N, the z direction cosine of the chief ray after the last surface.
//!
//! Test lens: a thin (t = 1 µm) biconvex singlet, f = 200 mm, EPD 4 mm (f/50), stop at the
//! lens, object at infinity. The chief ray crosses the lens at its (flat-normal) vertex and is
//! undeviated, so θ' = θ, the object-space field angle; the expected value is cos⁴θ with θ
//! the field angle for θ = 0…30°. Two statements are checked:
//!
//! 1. the analysis's relative illumination equals cos⁴θ within 1 %, with no vignetting (the
//!    lens has no semi-diameters, then generous ones that clip nothing);
//! 2. an independent radiometric estimate from the real image mapping agrees: for a
//!    rotationally symmetric image y(θ) of a distant Lambertian object, the image irradiance
//!    relative to the axis is E(θ)/E(0) = cos θ · y'(0)² sin θ / (y(θ) y'(θ))
//!    (cos θ: projected entrance-pupil area seen from the field direction; the second factor:
//!    solid angle per image area, dΩ/dA = sin θ/(y y')). With y = f tan θ this is cos⁴θ.
//!    y(θ) is measured with real chief rays and y' by central differences.
use camsim_lens::prescription::{ApertureFile, MaterialFile, PrescriptionFile, SurfaceFile};
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};

fn surf(radius_mm: Option<f64>, thickness_mm: f64, n: Option<f64>, sd: Option<f64>) -> SurfaceFile {
    SurfaceFile {
        radius_mm,
        thickness_mm,
        material: match n {
            None => MaterialFile::Name("air".into()),
            Some(nd) => MaterialFile::Model { nd, vd: 0.0 },
        },
        semi_diameter_mm: sd,
        conic: 0.0,
        aspheric_coeffs: vec![],
        odd_aspheric_coeffs: vec![],
        stop: false,
    }
}

/// Thin biconvex lens, f = 200 mm (n = 1.5, R = ±200 mm), stop at the lens, EPD 4 mm.
fn thin_lens(sd: Option<f64>) -> LensPrescription {
    let (n, r) = (1.5, 200.0);
    let f = 1.0 / ((n - 1.0) * (2.0 / r));
    let mut s = vec![
        surf(Some(r), 1e-6, Some(n), sd),
        surf(Some(-r), f, None, sd),
    ];
    s[0].stop = true;
    let pf = PrescriptionFile {
        name: "thin f/50".into(),
        units: "mm".into(),
        surfaces: s,
        object_distance_mm: None,
        fields_deg: vec![0.0],
        wavelengths_nm: vec![587.5618],
        primary_nm: None,
        aperture: ApertureFile::Epd { epd_mm: 4.0 },
        provenance: None,
        coordinate_breaks: Vec::new(),
    };
    LensPrescription::from_file_form(&pf, &GlassCatalog::bundled()).unwrap()
}

const FIELDS: [f64; 7] = [0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0];

#[test]
fn relative_illumination_is_cos4_of_the_field_angle() {
    for sd in [None, Some(10.0)] {
        let l = thin_lens(sd);
        for f in FIELDS {
            let ri = l.relative_illumination(f, l.primary_nm, 21).unwrap();
            let c4 = f.to_radians().cos().powi(4);
            assert!(
                (ri.vignetting_factor - 1.0).abs() < 1e-12,
                "sd {sd:?} field {f}: vignetting {}",
                ri.vignetting_factor
            );
            assert!(
                (ri.relative_illumination / c4 - 1.0).abs() < 0.01,
                "sd {sd:?} field {f}: RI {} vs cos⁴ {c4}",
                ri.relative_illumination
            );
        }
    }
}

#[test]
fn radiometric_irradiance_from_the_real_image_mapping_is_cos4() {
    let l = thin_lens(None);
    let w = l.primary_nm;
    let fo = l.first_order(w).unwrap();
    // Real chief-ray image height y(θ) (θ in radians).
    let y = |th: f64| -> f64 {
        let aim = l.aim_field(th.to_degrees(), w, &fo).unwrap();
        l.trace(&aim.ray(0.0, 0.0), w, Clipping::None)
            .unwrap()
            .image_mm[1]
    };
    let h = 1e-4;
    let dy = |th: f64| (y(th + h) - y(th - h)) / (2.0 * h);
    let y0p = dy(0.0);
    for f in FIELDS.iter().skip(1) {
        let th = f.to_radians();
        let e_rel = th.cos() * y0p * y0p * th.sin() / (y(th) * dy(th));
        let c4 = th.cos().powi(4);
        assert!(
            (e_rel / c4 - 1.0).abs() < 0.01,
            "field {f}: radiometric {e_rel} vs cos⁴ {c4}"
        );
        let ri = l.relative_illumination(*f, w, 21).unwrap();
        assert!(
            (ri.relative_illumination / e_rel - 1.0).abs() < 0.01,
            "field {f}: analysis {} vs radiometric {e_rel}",
            ri.relative_illumination
        );
    }
}
