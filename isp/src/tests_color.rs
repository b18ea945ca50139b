//! Tests of the K-channel colour path, the DNG colour transform, tone curves and denoiser.
use super::*;
use crate::dng_color::*;

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// Bradford D65 → D50 against the published matrix (B. Lindbloom, "Chromatic adaptation",
/// brucelindbloom.com, Bradford D65→D50 with the same white points to 4 digits).
#[test]
fn bradford_matches_the_published_d65_to_d50_matrix() {
    let m = bradford(D65_XY, D50_XY);
    let lindbloom = [
        [1.0478112, 0.0228866, -0.0501270],
        [0.0295424, 0.9904844, -0.0170491],
        [-0.0092345, 0.0150436, 0.7521316],
    ];
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                close(m.m[i][j], lindbloom[i][j], 2e-3),
                "{i}{j}: {} vs {}",
                m.m[i][j],
                lindbloom[i][j]
            );
        }
    }
    // and it maps the D65 white onto the D50 white exactly
    let w = m.apply(xy_to_xyz(D65_XY));
    let d50 = xy_to_xyz(D50_XY);
    for k in 0..3 {
        assert!(close(w[k], d50[k], 1e-12));
    }
}

/// McCamy's formula: D65 → 6504 K and illuminant A → 2856 K within its stated ±2 K accuracy
/// near the Planckian locus (McCamy 1992).
#[test]
fn mccamy_cct_of_d65_and_a() {
    assert!(
        close(mccamy_cct_k(D65_XY), 6504.0, 5.0),
        "{}",
        mccamy_cct_k(D65_XY)
    );
    assert!(close(mccamy_cct_k([0.44757, 0.40745]), 2856.0, 5.0));
}

const CM: [[f64; 3]; 3] = [
    [0.8139, -0.2171, -0.0663],
    [-0.8747, 1.6541, 0.2295],
    [-0.1925, 0.2008, 0.8093],
];

/// With the D65 neutral of the ColorMatrix the DNG chain reduces to dcraw/LibRaw's closed form
/// `rgb = (M_xyz→srgb · CM⁻¹) · camera` up to the white normalisation, and white-balanced
/// (1, 1, 1) is sRGB white.
#[test]
fn dng_colour_with_a_d65_neutral_is_the_closed_form() {
    let cm = ColorMatrix { m: CM };
    let n = cm.apply(xy_to_xyz(D65_XY));
    let c = DngColor {
        calibrations: vec![DngCalibration {
            color_matrix: cm,
            forward_matrix: None,
            cct_k: 6504.0,
        }],
        analog_balance: [1.0; 3],
        neutral: n,
    };
    let r = dng_camera_to_srgb(&c).unwrap();
    let white = r.matrix.apply([1.0; 3]);
    // The sRGB matrix's white is D65 XYZ (0.95047, 1, 1.08883); D65 at the 4-decimal xy
    // (0.3127, 0.3290) has Z = 1.089058, 2.1e-4 higher: that difference, and nothing else, can
    // separate white from (1, 1, 1) here (bound 3e-4).
    for k in 0..3 {
        assert!(close(white[k], 1.0, 3e-4), "{white:?}");
    }
    assert!(close(r.white_xy[0], D65_XY[0], 1e-9) && close(r.white_xy[1], D65_XY[1], 1e-9));
    // closed form on an arbitrary camera value
    let cam = [0.2, 0.5, 0.1];
    let ours = r.matrix.apply([0, 1, 2].map(|k| cam[k] * r.gains[k]));
    let closed = ColorMatrix {
        m: XYZ_TO_LINEAR_SRGB,
    }
    .after(&isetcam::invert(&cm).unwrap())
    .apply(cam);
    let nmax = n.iter().cloned().fold(0.0, f64::max);
    for k in 0..3 {
        // the normalisation: neutral n/nmax → Y = 1, i.e. XYZ scaled by nmax
        assert!(
            close(ours[k], closed[k] * nmax, 2e-4 * nmax.max(1.0)),
            "{ours:?} vs {closed:?}"
        );
    }
}

/// Two calibrations: a neutral of illuminant A under the A matrix selects that matrix
/// (weight of calibration 1 = D65 → 0) and finds the A white.
#[test]
fn dng_two_calibrations_interpolate_by_cct() {
    let cm65 = ColorMatrix { m: CM };
    let cm_a = ColorMatrix {
        m: [[0.9, -0.25, -0.1], [-0.8, 1.6, 0.25], [-0.1, 0.3, 0.65]],
    };
    let a_xy = [0.44757, 0.40745];
    let c = DngColor {
        calibrations: vec![
            DngCalibration {
                color_matrix: cm65,
                forward_matrix: None,
                cct_k: 6504.0,
            },
            DngCalibration {
                color_matrix: cm_a,
                forward_matrix: None,
                cct_k: 2856.0,
            },
        ],
        analog_balance: [1.0; 3],
        neutral: cm_a.apply(xy_to_xyz(a_xy)),
    };
    let r = dng_camera_to_srgb(&c).unwrap();
    assert!(r.weight_1 < 0.01, "weight {}", r.weight_1);
    assert!(
        close(r.white_xy[0], a_xy[0], 2e-3) && close(r.white_xy[1], a_xy[1], 2e-3),
        "{:?}",
        r.white_xy
    );
    // white-balanced (1, 1, 1) is still rendered as sRGB white (Bradford A → D65)
    let w = r.matrix.apply([1.0; 3]);
    for k in 0..3 {
        assert!(close(w[k], 1.0, 5e-3), "{w:?}");
    }
}

/// For K = 3 the 3×K least-squares fit is the 3×3 fit.
#[test]
fn channel_matrix_fit_equals_the_3x3_fit_for_rgb() {
    let s: Vec<[f64; 3]> = (0..24)
        .map(|i| {
            let x = i as f64;
            [
                0.1 + 0.03 * x,
                0.5 - 0.01 * x + 0.002 * x * x,
                0.2 + 0.2 * (x * 0.7).sin().abs(),
            ]
        })
        .collect();
    let t: Vec<[f64; 3]> = s
        .iter()
        .map(|v| {
            [
                v[0] * 1.2 - v[1] * 0.1,
                v[1] + 0.05 * v[2],
                v[2] * 0.9 + 0.01,
            ]
        })
        .collect();
    let a = fit_color_correction(&s, &t).unwrap();
    let b = fit_channel_matrix(&s.iter().map(|v| v.to_vec()).collect::<Vec<_>>(), &t).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert!(close(a.m[i][j], b.m[i][j], 1e-10));
        }
    }
}

/// Reinhard Eq. 4 maps Y = Y_white to 1 and keeps hue; filmic maps 0 to 0 and W/2 (the
/// exposure bias is 2) to 1.
#[test]
fn tone_curves_closed_forms() {
    let t = ToneCurve::Reinhard { white: 4.0 };
    let v = t.map([4.0, 4.0, 4.0]);
    assert!(v.iter().all(|&x| close(x, 1.0, 1e-12)), "{v:?}");
    let c = t.map([0.2, 0.4, 0.1]);
    assert!(close(c[0] / c[1], 0.5, 1e-12) && close(c[2] / c[1], 0.25, 1e-12));
    let f = ToneCurve::Filmic;
    assert!(close(f.map([0.0; 3])[0], 0.0, 1e-12));
    assert!(close(f.map([5.6; 3])[0], 1.0, 1e-12));
}

/// The bilateral filter leaves a constant plane alone, blurs noise, and keeps a step whose
/// height is far above σ_r.
#[test]
fn bilateral_keeps_edges_and_flat_fields() {
    let (rows, cols) = (16, 16);
    let step: Vec<f32> = (0..rows * cols)
        .map(|i| if i % cols < 8 { 0.1 } else { 0.9 })
        .collect();
    let mut p = ChannelPlanes {
        rows,
        cols,
        planes: vec![vec![0.37; rows * cols], step.clone()],
        names: vec!["a".into(), "b".into()],
    };
    Bilateral::new(1.5, 0.05).unwrap().apply(&mut p);
    assert!(p.planes[0].iter().all(|&x| (x - 0.37).abs() < 1e-6));
    for (a, b) in p.planes[1].iter().zip(&step) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }
    let mut g = ChannelPlanes {
        rows,
        cols,
        planes: vec![step.clone()],
        names: vec!["a".into()],
    };
    Bilateral::new(1.5, f64::INFINITY).unwrap().apply(&mut g);
    // a Gaussian blurs the step: the pixel next to it moves by more than 0.1
    assert!((g.planes[0][7] - 0.1).abs() > 0.1);
}

/// Per-channel gains: grey world equalises the means, known illuminant makes the illuminant's
/// own response neutral (reference channel g = 1).
#[test]
fn channel_balance_rules() {
    let p = ChannelPlanes {
        rows: 1,
        cols: 2,
        planes: vec![
            vec![0.2, 0.4],
            vec![0.5, 0.5],
            vec![0.1, 0.3],
            vec![0.8, 1.0],
        ],
        names: vec!["b".into(), "g".into(), "r".into(), "w".into()],
    };
    assert_eq!(reference_channel(&p.names), 1);
    let g = ChannelBalance::GreyWorld.gains(&p).unwrap();
    let means = [0.3, 0.5, 0.2, 0.9];
    for k in 0..4 {
        assert!(close(g[k] * means[k], 0.5, 1e-7), "{g:?}");
    }
    let e = ChannelBalance::Gains(vec![1.0, 2.0])
        .gains(&p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("need one per channel (4)"), "{e}");
}

/// dcraw/LibRaw's camera-space adaptation equals the Bradford path for the D65 neutral and
/// differs for a tungsten neutral; in both cases white-balanced (1, 1, 1) is sRGB white.
#[test]
fn camera_space_adaptation_agrees_with_bradford_only_at_d65() {
    let cm = ColorMatrix { m: CM };
    let cal = vec![DngCalibration {
        color_matrix: cm,
        forward_matrix: None,
        cct_k: 6504.0,
    }];
    let d65 = DngColor {
        calibrations: cal.clone(),
        analog_balance: [1.0; 3],
        neutral: cm.apply(xy_to_xyz(D65_XY)),
    };
    let a = dng_camera_to_srgb_with(&d65, WhiteAdaptation::Bradford).unwrap();
    let b = dng_camera_to_srgb_with(&d65, WhiteAdaptation::CameraSpace).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert!(
                close(a.matrix.m[i][j], b.matrix.m[i][j], 1e-3),
                "{:?} vs {:?}",
                a.matrix.m,
                b.matrix.m
            );
        }
    }
    let t = DngColor {
        calibrations: cal,
        analog_balance: [1.0; 3],
        neutral: [0.75, 1.0, 0.42],
    };
    let a = dng_camera_to_srgb_with(&t, WhiteAdaptation::Bradford).unwrap();
    let b = dng_camera_to_srgb_with(&t, WhiteAdaptation::CameraSpace).unwrap();
    let diff: f64 = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| (a.matrix.m[i][j] - b.matrix.m[i][j]).abs())
        .sum();
    assert!(diff > 0.05, "{diff}");
    for r in [a, b] {
        let w = r.matrix.apply([1.0; 3]);
        assert!(w.iter().all(|&x| close(x, 1.0, 5e-3)), "{w:?}");
    }
}
