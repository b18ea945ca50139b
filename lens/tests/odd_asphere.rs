//! The Zemax odd asphere (`TYPE ODDASPHE`): sag z = c r²/(1 + √(1 − (1+k) c² r²)) + Σ β_i r^i,
//! i = 1, 2, … (`Surface::odd_aspheric_coeffs`). Its analytic derivatives (dz/d(r²), used for
//! the ray-surface intersection and the normal, and d²z/d(r²)², used for the principal
//! curvatures) are checked against central finite differences of the sag; the `.zmx` reader
//! against the file's PARM lines (unit scaling included) and hostile input. The traced lens
//! with odd aspheres is checked against Optiland and rayoptics in optics_ref_literature.rs.
use camsim_lens::prescription::{MaterialFile, Medium, Surface};
use camsim_lens::readers::{read_zmx, ZmxOptions};
use camsim_lens::trace::normal;

fn surface(c: f64, k: f64, even: Vec<f64>, odd: Vec<f64>) -> Surface {
    Surface {
        curvature_per_mm: c,
        thickness_mm: 1.0,
        medium: Medium::Air,
        material: MaterialFile::Name("air".into()),
        semi_diameter_mm: None,
        conic: k,
        aspheric_coeffs: even,
        odd_aspheric_coeffs: odd,
    }
}

/// The first surface of US 7,535,658 (tests/data/zmx_literature): c = 1/1.962, k = 1.153,
/// β3…β10, plus an even A4 and β1, β2 terms to exercise every branch.
fn test_surface() -> Surface {
    surface(
        1.0 / 1.962,
        1.153,
        vec![3e-3],
        vec![
            2e-3, -4e-3, -1.895e-2, 2.426e-2, -5.123e-2, 8.371e-4, 7.850e-3, 4.091e-3, -7.732e-3,
            -4.265e-3,
        ],
    )
}

#[test]
fn odd_asphere_sag_is_the_zemax_polynomial() {
    let s = test_surface();
    let (c, k) = (s.curvature_per_mm, s.conic);
    for &r in &[0.0, 0.1, 0.37, 0.8, 1.1] {
        let r2: f64 = r * r;
        let conic = c * r2 / (1.0 + (1.0 - (1.0 + k) * c * c * r2).sqrt());
        let odd: f64 = (1..=10)
            .map(|i| s.odd_aspheric_coeffs[i - 1] * r.powi(i as i32))
            .sum();
        let want = conic + 3e-3 * r2 * r2 + odd;
        let got = s.sag_mm(r2).unwrap();
        assert!((got - want).abs() < 1e-15, "r {r}: {got} vs {want}");
    }
    // Without odd terms the sag is the even asphere's.
    let even = surface(c, k, vec![3e-3], vec![]);
    let z = even.sag_mm(0.25).unwrap();
    let conic = c * 0.25 / (1.0 + (1.0 - (1.0 + k) * c * c * 0.25).sqrt());
    assert!((z - conic - 3e-3 * 0.0625).abs() < 1e-16);
    assert!(!test_surface().is_conic_only());
    assert!(surface(c, k, vec![], vec![0.0, 0.0]).is_conic_only());
}

#[test]
fn odd_asphere_derivatives_match_finite_differences() {
    let s = test_surface();
    // z as a function of r (not r²), for the finite differences.
    let z = |r: f64| s.sag_mm(r * r).unwrap();
    let h = 1e-4;
    for &r in &[0.05, 0.2, 0.5, 0.8, 1.1] {
        let dz_dr = (z(r + h) - z(r - h)) / (2.0 * h);
        let d2z_dr2 = (z(r + h) - 2.0 * z(r) + z(r - h)) / (h * h);
        let g = s.dsag_dr2(r * r).unwrap();
        let g2 = s.d2sag_dr2(r * r).unwrap();
        // dz/dr = 2r·g; d²z/dr² = 2g + 4r²·g2 (chain rule through r²).
        let a1 = 2.0 * r * g;
        let a2 = 2.0 * g + 4.0 * r * r * g2;
        assert!(
            (a1 - dz_dr).abs() < 1e-8 * (1.0 + dz_dr.abs()),
            "r {r}: dz/dr {a1} vs finite difference {dz_dr}"
        );
        assert!(
            (a2 - d2z_dr2).abs() < 1e-5 * (1.0 + d2z_dr2.abs()),
            "r {r}: d²z/dr² {a2} vs finite difference {d2z_dr2}"
        );
        // The traced normal is (−∂z/∂x, −∂z/∂y, 1) normalised: check it off the meridian,
        // against the finite-difference gradient of z(√(x² + y²)).
        let (x, y) = (0.6 * r, 0.8 * r);
        let zxy = |x: f64, y: f64| z(x.hypot(y));
        let zx = (zxy(x + h, y) - zxy(x - h, y)) / (2.0 * h);
        let zy = (zxy(x, y + h) - zxy(x, y - h)) / (2.0 * h);
        let nrm = (zx * zx + zy * zy + 1.0).sqrt();
        let want = [-zx / nrm, -zy / nrm, 1.0 / nrm];
        let got = normal(&s, [x, y, zxy(x, y)]).unwrap();
        for j in 0..3 {
            assert!(
                (got[j] - want[j]).abs() < 1e-8,
                "r {r}: normal {got:?} vs {want:?}"
            );
        }
    }
    // On the axis: the β1·r cone is left out of the normal (the symmetric limit), which is
    // then the axis; the principal curvatures are finite and equal (c + 2β2: z = β2 r² adds
    // 2β2 to the vertex curvature).
    let n0 = normal(&s, [0.0, 0.0, 0.0]).unwrap();
    assert_eq!(n0, [0.0, 0.0, 1.0]);
    let [m, a] = s.principal_curvatures_per_mm(0.0).unwrap();
    let want = s.curvature_per_mm + 2.0 * s.odd_aspheric_coeffs[1];
    assert!(
        (m - want).abs() < 1e-12 && (a - want).abs() < 1e-12,
        "{m} {a} vs {want}"
    );
}

fn zmx(unit: &str, parm: &str) -> String {
    format!(
        "MODE SEQ\nUNIT {unit}\nENPD 1\nSURF 0\n  DISZ INFINITY\nSURF 1\n  STOP\n  DISZ 0\n\
         SURF 2\n  TYPE ODDASPHE\n  CURV 0.5\n  CONI -1.5\n{parm}  DISZ 1\n  GLAS ___BLANK 1 0 \
         1.5 56 0 0 0 0 0 0\nSURF 3\n  DISZ 4\nSURF 4\n  DISZ 0\n"
    )
}

#[test]
fn zmx_oddasphe_parms_are_read_in_mm() {
    let opts = ZmxOptions::default();
    let p = "  PARM 1 0.001\n  PARM 3 -0.02\n  PARM 10 4e-5\n";
    let f = read_zmx(zmx("MM", p).as_bytes(), "t", &opts).unwrap();
    let s = &f.surfaces[1];
    assert_eq!(s.conic, -1.5);
    assert_eq!(
        s.odd_aspheric_coeffs,
        vec![0.001, 0.0, -0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 4e-5]
    );
    assert!(s.aspheric_coeffs.is_empty());
    // In inches: z_mm = 25.4·β·(r_mm/25.4)^k, so β_mm = β·25.4^(1−k); the same sag in mm.
    let f_in = read_zmx(zmx("IN", p).as_bytes(), "t", &opts).unwrap();
    let s_in = &f_in.surfaces[1];
    for (k, (b_in, b)) in s_in
        .odd_aspheric_coeffs
        .iter()
        .zip(&s.odd_aspheric_coeffs)
        .enumerate()
    {
        let want = b * 25.4f64.powi(-(k as i32));
        assert!((b_in - want).abs() <= 1e-15 * want.abs(), "β{}", k + 1);
    }
    // Trailing zero terms are dropped; ODDASPH (7-letter) is accepted too.
    let f = read_zmx(
        zmx("MM", "  PARM 2 0.01\n  PARM 4 0\n")
            .replace("ODDASPHE", "ODDASPH")
            .as_bytes(),
        "t",
        &opts,
    )
    .unwrap();
    assert_eq!(f.surfaces[1].odd_aspheric_coeffs, vec![0.0, 0.01]);
}

#[test]
fn zmx_oddasphe_hostile_parm_is_one_clear_error() {
    let opts = ZmxOptions::default();
    let e = read_zmx(zmx("MM", "  PARM 100000000 1\n").as_bytes(), "t", &opts)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ODDASPHE PARM 100000000") && e.contains("1…240"),
        "{e}"
    );
    let e = read_zmx(zmx("MM", "  PARM 3 abc\n").as_bytes(), "t", &opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("PARM") && e.contains("abc"), "{e}");
}
