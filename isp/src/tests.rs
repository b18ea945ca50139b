//! Tests of the image processor, including the ISETCam `ip_default_pipeline` oracle.
use super::*;
use crate::isetcam::{self, SampledSpectra};
use camsim_core::constants::SI;
use camsim_core::npy::read_npy;
use camsim_core::{data, RawFrame, Spectrum};
use std::path::Path;

const ORACLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/oracles/isetcam");

fn names() -> Vec<String> {
    vec!["r".into(), "g".into(), "b".into()]
}

/// The four Bayer tiles with channels r = 0, g = 1, b = 2.
fn bayer_tiles() -> Vec<(&'static str, Vec<Vec<usize>>)> {
    vec![
        ("RGGB", vec![vec![0, 1], vec![1, 2]]),
        ("GRBG", vec![vec![1, 0], vec![2, 1]]),
        ("GBRG", vec![vec![1, 2], vec![0, 1]]),
        ("BGGR", vec![vec![2, 1], vec![1, 0]]),
    ]
}

const METHODS: [DemosaicMethod; 3] = [
    DemosaicMethod::Bilinear,
    DemosaicMethod::Malvar,
    DemosaicMethod::EdgeAdaptive,
];

#[test]
fn constant_colour_is_reproduced_everywhere_by_every_method() {
    let colour = [0.3f32, 0.55, 0.8];
    for (rows, cols) in [(3, 4), (5, 6), (7, 9), (16, 11)] {
        let img = RgbImage::filled(rows, cols, colour);
        for (name, tile) in bayer_tiles() {
            let m = Mosaic::sample_rgb(&img, tile, names()).unwrap();
            assert_eq!(m.bayer_layout().unwrap().name(), name);
            for method in METHODS {
                let out = demosaic(&m, method).unwrap();
                for (i, p) in out.data.iter().enumerate() {
                    for k in 0..3 {
                        assert!(
                            (p[k] - colour[k]).abs() <= 1e-7,
                            "{name} {method:?} {rows}×{cols} pixel ({}, {}) channel {k}: {} ≠ {}",
                            i / cols,
                            i % cols,
                            p[k],
                            colour[k]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn bilinear_handles_non_bayer_tiles_and_others_refuse_them() {
    // a 3×3 diagonal-stripe tile (no checkerboard channel) and an RGBW-like 2×2 tile
    let stripes = vec![vec![0, 1, 2], vec![1, 2, 0], vec![2, 0, 1]];
    let colour = [0.25f32, 0.5, 0.75];
    let img = RgbImage::filled(10, 13, colour);
    let m = Mosaic::sample_rgb(&img, stripes, names()).unwrap();
    let out = demosaic(&m, DemosaicMethod::Bilinear).unwrap();
    for p in &out.data {
        for k in 0..3 {
            assert!((p[k] - colour[k]).abs() < 1e-6, "{p:?}");
        }
    }
    let e = demosaic(&m, DemosaicMethod::Malvar).unwrap_err();
    assert!(matches!(e, IspError::NotBayer { .. }), "{e}");
    assert!(e.to_string().contains("3×3"), "{e}");

    // RGBW: 4 channels, w is ignored by the RGB output but interpolated by demosaic_channels
    let rgbw = Mosaic::new(
        6,
        8,
        (0..48)
            .map(|i| [0.2, 0.4, 0.6, 0.9][(i / 8 % 2) * 2 + i % 8 % 2])
            .collect(),
        vec![vec![0, 1], vec![2, 3]],
        vec!["r".into(), "g".into(), "b".into(), "w".into()],
    )
    .unwrap();
    let planes = demosaic_channels(&rgbw, DemosaicMethod::Bilinear).unwrap();
    for (ch, want) in [0.2f32, 0.4, 0.6, 0.9].iter().enumerate() {
        assert!(
            planes[ch].iter().all(|v| (v - want).abs() < 1e-6),
            "channel {ch}"
        );
    }
    let e = demosaic(&rgbw, DemosaicMethod::EdgeAdaptive).unwrap_err();
    assert!(e.to_string().contains("'w'"), "{e}");
}

#[test]
fn demosaic_names_parse_and_unknown_names_list_the_valid_ones() {
    for m in METHODS {
        assert_eq!(m.name().parse::<DemosaicMethod>().unwrap(), m);
    }
    let e = "ahd".parse::<DemosaicMethod>().unwrap_err().to_string();
    assert!(
        e.contains("'ahd'")
            && e.contains("bilinear")
            && e.contains("malvar")
            && e.contains("edge_adaptive"),
        "{e}"
    );
}

/// A deterministic "natural" test image (192×256): a smooth, slowly varying colour field
/// multiplied by a luminance map with sharp-edged discs, a slanted rectangle and a patch of
/// fine oriented grating, plus one disc of a different hue (a colour edge). Channels share
/// most of the high-frequency structure, as in natural images.
fn natural_test_image() -> RgbImage {
    let (rows, cols) = (192usize, 256usize);
    let tau = std::f64::consts::TAU;
    let mut data = Vec::with_capacity(rows * cols);
    for y in 0..rows {
        for x in 0..cols {
            let (xf, yf) = (x as f64, y as f64);
            let mut base = [0usize, 1, 2].map(|k| {
                let ph = k as f64 * 0.31;
                0.45 + 0.22
                    * (tau * (xf / 170.0 + ph)).sin()
                    * (tau * (yf / 130.0 + 0.5 * ph)).cos()
            });
            let mut lum = 1.0;
            let disc = |cx: f64, cy: f64, r: f64| (xf - cx).powi(2) + (yf - cy).powi(2) < r * r;
            if disc(60.0, 50.0, 28.0) {
                lum *= 0.45;
            }
            if disc(190.0, 140.0, 35.0) {
                lum *= 1.5;
            }
            // slanted rectangle (edges at ~5° to the axes)
            let (u, v) = (0.996 * xf + 0.087 * yf, -0.087 * xf + 0.996 * yf);
            if (110.0..170.0).contains(&u) && (20.0..70.0).contains(&v) {
                lum *= 0.6;
            }
            // fine grating (period 7 px, oriented at 30°)
            if (20.0..100.0).contains(&xf) && (110.0..180.0).contains(&yf) {
                lum *= 1.0 + 0.3 * (tau * (0.866 * xf + 0.5 * yf) / 7.0).sin();
            }
            // a disc of another hue: a colour edge
            if disc(200.0, 45.0, 22.0) {
                base = [0.75, 0.3, 0.15];
            }
            data.push(base.map(|b| (b * lum).clamp(0.0, 1.0) as f32));
        }
    }
    RgbImage { rows, cols, data }
}

fn psnr(a: &RgbImage, b: &RgbImage) -> f64 {
    let mse: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .flat_map(|(p, q)| (0..3).map(move |k| ((p[k] - q[k]) as f64).powi(2)))
        .sum::<f64>()
        / (3 * a.data.len()) as f64;
    10.0 * (1.0 / mse).log10()
}

#[test]
fn malvar_and_edge_adaptive_beat_bilinear_on_a_natural_image() {
    let truth = natural_test_image();
    for (name, tile) in bayer_tiles() {
        let m = Mosaic::sample_rgb(&truth, tile, names()).unwrap();
        let p: Vec<f64> = METHODS
            .iter()
            .map(|&me| psnr(&demosaic(&m, me).unwrap(), &truth))
            .collect();
        eprintln!(
            "{name}: PSNR bilinear {:.2} dB, malvar {:.2} dB, edge-adaptive {:.2} dB",
            p[0], p[1], p[2]
        );
        assert!(
            p[1] > p[0] + 0.5,
            "{name}: malvar {} vs bilinear {}",
            p[1],
            p[0]
        );
        assert!(
            p[2] > p[0] + 0.5,
            "{name}: edge-adaptive {} vs bilinear {}",
            p[2],
            p[0]
        );
    }
}

#[test]
fn srgb_curve_round_trips_and_matches_the_standard() {
    for i in 0..=20000 {
        let v = i as f64 / 10000.0 - 0.5; // includes negatives (odd extension) and > 1
        let back = srgb_decode(srgb_encode(v));
        assert!((back - v).abs() <= 1e-12 * (1.0 + v.abs()), "{v} → {back}");
    }
    assert_eq!(srgb_encode(0.0), 0.0);
    assert!((srgb_encode(1.0) - 1.0).abs() < 1e-15);
    // the two pieces meet (to the 4-digit precision of the standard's constants)
    assert!((srgb_encode(0.003_130_8) - 0.040_45).abs() < 1e-5);
    assert!((srgb_encode(0.5) - 0.735_356_983_052_11).abs() < 1e-9);
    assert!((srgb_decode(0.5) - 0.214_041_140_482_232_5).abs() < 1e-9);
}

#[test]
fn quantisation_round_trips_every_8_bit_code_and_sampled_16_bit_codes() {
    let codes8: Vec<[f32; 3]> = (0..256)
        .map(|k| [srgb_decode(k as f64 / 255.0) as f32; 3])
        .collect();
    let img = RgbImage {
        rows: 16,
        cols: 16,
        data: codes8,
    };
    let q = to_srgb8(&img);
    for k in 0..256 {
        assert_eq!(&q[3 * k..3 * k + 3], &[k as u8; 3], "code {k}");
    }
    let codes16: Vec<u16> = (0..65536u32).step_by(97).map(|k| k as u16).collect();
    let img16 = RgbImage {
        rows: 1,
        cols: codes16.len(),
        data: codes16
            .iter()
            .map(|&k| [srgb_decode(k as f64 / 65535.0) as f32; 3])
            .collect(),
    };
    let q16 = to_srgb16(&img16);
    for (i, &k) in codes16.iter().enumerate() {
        // f32 storage of the linear value limits the round trip to ±1 code near black
        assert!(
            (q16[3 * i] as i32 - k as i32).abs() <= 1,
            "code {k} → {}",
            q16[3 * i]
        );
    }
    // out-of-range values clip
    let clip = RgbImage {
        rows: 1,
        cols: 1,
        data: vec![[-0.5, 2.0, f32::NAN]],
    };
    assert_eq!(to_srgb8(&clip), vec![0, 255, 0]);
}

#[test]
fn color_correction_fit_recovers_a_known_matrix() {
    let truth = ColorMatrix {
        m: [[1.7, -0.5, -0.2], [-0.3, 1.6, -0.3], [0.05, -0.6, 1.55]],
    };
    let mut state = 12345u64;
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let sensor: Vec<[f64; 3]> = (0..24).map(|_| [rnd(), rnd(), rnd()]).collect();
    let target: Vec<[f64; 3]> = sensor.iter().map(|s| truth.apply(*s)).collect();
    let fit = fit_color_correction(&sensor, &target).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert!((fit.m[i][j] - truth.m[i][j]).abs() < 1e-12, "{:?}", fit.m);
        }
    }
    // too few samples, degenerate samples
    assert!(fit_color_correction(&sensor[..2], &target[..2])
        .unwrap_err()
        .to_string()
        .contains("2 samples"));
    let grey: Vec<[f64; 3]> = (0..5).map(|i| [i as f64; 3]).collect();
    assert!(matches!(
        fit_color_correction(&grey, &grey),
        Err(IspError::Fit(_))
    ));
}

#[test]
fn grey_world_makes_a_grey_scene_neutral() {
    // a grey scene with spatial shading, seen by a sensor with unequal channel sensitivities
    let sens = [0.6f32, 1.0, 0.45];
    let (rows, cols) = (40, 50);
    let data = (0..rows * cols)
        .map(|i| {
            let shade =
                0.2 + 0.6 * ((i % cols) as f32 / cols as f32) * ((i / cols) as f32 / rows as f32);
            sens.map(|s| s * shade)
        })
        .collect();
    let mut img = RgbImage { rows, cols, data };
    let gains = WhiteBalance::GreyWorld.apply(&mut img).unwrap();
    assert!(
        (gains[0] - 1.0 / 0.6).abs() < 1e-5
            && gains[1] == 1.0
            && (gains[2] - 1.0 / 0.45).abs() < 1e-5,
        "{gains:?}"
    );
    for p in &img.data {
        assert!(
            (p[0] - p[1]).abs() < 1e-5 * p[1] && (p[2] - p[1]).abs() < 1e-5 * p[1],
            "{p:?}"
        );
    }
    // the same through develop() from a Bayer mosaic, with white patch too
    let img0 = RgbImage::filled(12, 12, [0.3, 0.5, 0.2]);
    let m = Mosaic::sample_rgb(&img0, bayer_tiles()[0].1.clone(), names()).unwrap();
    for wb in [WhiteBalance::GreyWorld, WhiteBalance::WhitePatch] {
        let p = IspPipeline {
            demosaic: DemosaicMethod::Malvar,
            white_balance: wb,
            ccm: None,
            exposure_gain: 1.0,
            clip_negative: false,
        };
        let out = develop(&p, &m).unwrap();
        assert!(out
            .linear
            .data
            .iter()
            .all(|q| (q[0] - 0.5).abs() < 1e-6 && (q[2] - 0.5).abs() < 1e-6));
        assert!(out.srgb8.chunks(3).all(|c| c[0] == c[1] && c[1] == c[2]));
    }
    let bad = WhiteBalance::Gains([1.0, -2.0, 1.0])
        .gains(&img)
        .unwrap_err()
        .to_string();
    assert!(bad.contains("-2"), "{bad}");
}

fn rgb_filters() -> Vec<Spectrum> {
    data::spectral("sensor/colorfilters/RGB").unwrap().spectra
}

#[test]
fn known_illuminant_gains_neutralise_the_illuminant_and_the_grey_patches() {
    let qe = rgb_filters();
    let d65 = data::illuminant("D65").unwrap().energy_to_photons(&SI);
    let g = illuminant_gains(&qe, &d65).unwrap();
    let resp: Vec<f64> = qe
        .iter()
        .map(|q| Spectrum::integrate_product(q, &d65).unwrap())
        .collect();
    for k in 0..3 {
        assert!((g[k] * resp[k] - resp[1]).abs() < 1e-12 * resp[1]);
    }
    // a spectrally flat grey surface is exactly neutral after the gains
    let grey = Spectrum::multiply(&Spectrum::constant(0.18), &d65);
    let b: Vec<f64> = (0..3)
        .map(|k| g[k] * Spectrum::integrate_product(&qe[k], &grey).unwrap())
        .collect();
    assert!(
        (b[0] / b[1] - 1.0).abs() < 1e-4 && (b[2] / b[1] - 1.0).abs() < 1e-4,
        "{b:?}"
    );
    // the Macbeth neutral series (yellowish in the ISETCam data) is closer to neutral with
    // the gains than without
    let mcc = macbeth_sensor_rgb(&qe, &d65).unwrap();
    let off = |p: [f64; 3]| (p[0] / p[1]).ln().abs() + (p[2] / p[1]).ln().abs();
    for p in &mcc[18..24] {
        let b = [p[0] * g[0], p[1], p[2] * g[2]];
        assert!(off(b) < 0.5 * off(*p), "{b:?} vs {p:?}");
    }
    // a tungsten light needs a much larger blue gain than D65
    let a = data::illuminant("A").unwrap().energy_to_photons(&SI);
    assert!(illuminant_gains(&qe, &a).unwrap()[2] > 2.0 * g[2]);
    assert!(illuminant_gains(&qe[..2], &a)
        .unwrap_err()
        .to_string()
        .contains("2 spectra"));
}

#[test]
fn macbeth_target_and_fitted_ccm_render_the_chart() {
    let d65 = data::illuminant("D65").unwrap();
    let target = macbeth_target_linear_srgb(&d65, 0.9).unwrap();
    assert_eq!(target.len(), 24);
    let xyz = macbeth_xyz(&d65).unwrap();
    // white patch Y is the chosen level; the XYZ → sRGB matrix maps D65 white to R = G = B
    let w = target[MACBETH_WHITE_INDEX];
    let wy = 0.2126 * w[0] + 0.7152 * w[1] + 0.0722 * w[2];
    assert!((wy - 0.9).abs() < 2e-3, "{w:?}");
    // a spectrally flat reflector under D65 renders neutral (checks data + matrix); the
    // ISETCam Macbeth "white 9.5" is yellowish (reflectance 0.51 at 400 nm, 0.85 at 600 nm)
    let cmf = data::cie1931_xyz().unwrap();
    let flat = [0, 1, 2].map(|k| Spectrum::integrate_product(&d65, &cmf[k]).unwrap());
    let flat_rgb = ColorMatrix {
        m: XYZ_TO_LINEAR_SRGB,
    }
    .apply(flat.map(|x| x / flat[1]));
    assert!(
        flat_rgb.iter().all(|v| (v - 1.0).abs() < 1e-3),
        "{flat_rgb:?}"
    );
    assert!(w[0] > w[1] && w[1] > w[2] && w[2] > 0.8 * w[1], "{w:?}");
    // red patch (row 3, col 3) is red, blue (row 3, col 1) is blue
    assert!(target[14][0] > 2.0 * target[14][1] && target[12][2] > 2.0 * target[12][0]);
    assert!(xyz[MACBETH_WHITE_INDEX][1] > xyz[23][1] * 20.0);
    // agreement with ISETCam's stored linear-sRGB chart (file order = column-major chart,
    // scaled to max 1): compare chromaticity-independent ratios loosely
    let lrgb = data::json("surfaces/charts/macbethChartLinearRGB").unwrap();
    let vals = lrgb["values"].as_array().unwrap();
    let file = |i: usize| -> [f64; 3] {
        let a = vals[i].as_array().unwrap();
        [
            a[0].as_f64().unwrap(),
            a[1].as_f64().unwrap(),
            a[2].as_f64().unwrap(),
        ]
    };
    // patch "red" is row 3 col 3 (row-major 14) = file index 4·2 + 2 = 10
    let (ours, theirs) = (target[14], file(10));
    assert!(
        (ours[0] / ours[1] / (theirs[0] / theirs[1]) - 1.0).abs() < 0.35,
        "{ours:?} {theirs:?}"
    );
    // (ISETCam's stored chart is of undocumented derivation — "you should really create them
    // on the fly", its comment says — and differs from a recomputation by 0.79–1.07 in R/G over
    // the patches, so it can only be a loose check.) The tight check is a recomputed reference:
    // the same reflectances, D65 and CIE 1931 data integrated by a separate path (midpoint sum
    // on a 0.05 nm grid of the three-way product over 380–830 nm, where all three are defined)
    // and the IEC 61966-2-1 matrix at
    // its published 4 digits, white patch scaled to Y = 0.9. Tolerance: the 4-digit matrix
    // (±5·10⁻⁵ per coefficient on XYZ ≤ 1) and the quadrature (≲ 10⁻⁵) move each channel by
    // ≤ 3·10⁻⁴ absolute; 10⁻³ absolute, or 10⁻³ relative on the larger values, per channel.
    let refl = data::macbeth_reflectances_row_major().unwrap();
    let xyz_ref: Vec<[f64; 3]> = refl
        .iter()
        .map(|r| {
            let h = 0.05;
            let n = ((830.0 - 380.0) / h) as usize;
            let mut acc = [0.0; 3];
            for i in 0..n {
                let l = 380.0 + (i as f64 + 0.5) * h;
                let rl = r.eval(l) * d65.eval(l);
                for k in 0..3 {
                    acc[k] += rl * cmf[k].eval(l) * h;
                }
            }
            acc
        })
        .collect();
    const IEC: [[f64; 3]; 3] = [
        [3.2406, -1.5372, -0.4986],
        [-0.9689, 1.8758, 0.0415],
        [0.0557, -0.2040, 1.0570],
    ];
    let wy_ref = xyz_ref[MACBETH_WHITE_INDEX][1];
    for (i, x) in xyz_ref.iter().enumerate() {
        let x = x.map(|v| v * 0.9 / wy_ref);
        let rgb = [0, 1, 2].map(|r| IEC[r][0] * x[0] + IEC[r][1] * x[1] + IEC[r][2] * x[2]);
        for k in 0..3 {
            let tol = 1e-3 * rgb[k].abs().max(1.0);
            assert!(
                (target[i][k] - rgb[k]).abs() <= tol,
                "patch {i} channel {k}: {} vs recomputed {} ({:?} vs {rgb:?})",
                target[i][k],
                rgb[k],
                target[i]
            );
        }
    }
    // and so the red patch's R/G, the ratio compared with ISETCam above, to its propagated
    // tolerance (G of the red patch is small: the ratio carries its relative error).
    let x = xyz_ref[14].map(|v| v * 0.9 / wy_ref);
    let rg_ref = (IEC[0][0] * x[0] + IEC[0][1] * x[1] + IEC[0][2] * x[2])
        / (IEC[1][0] * x[0] + IEC[1][1] * x[1] + IEC[1][2] * x[2]);
    let rg_tol = rg_ref * (1e-3 / ours[0].abs() + 1e-3 / ours[1].abs());
    assert!(
        (ours[0] / ours[1] - rg_ref).abs() <= rg_tol,
        "red patch R/G {} vs recomputed {rg_ref} (± {rg_tol})",
        ours[0] / ours[1]
    );

    // fit sensor → target on the chart: the white patch lands within 8 % of its target (the
    // default RGB filters are not colorimetric; red is the worst channel)
    let d65_photons = d65.energy_to_photons(&SI);
    let sensor = macbeth_sensor_rgb(&rgb_filters(), &d65_photons).unwrap();
    let ccm = fit_color_correction(&sensor, &target).unwrap();
    let wc = ccm.apply(sensor[MACBETH_WHITE_INDEX]);
    assert!(
        (0..3).all(|k| (wc[k] / w[k] - 1.0).abs() < 0.08),
        "{wc:?} vs {w:?}"
    );
    let rms = (sensor
        .iter()
        .zip(&target)
        .map(|(s, t)| {
            (0..3)
                .map(|k| (ccm.apply(*s)[k] - t[k]).powi(2))
                .sum::<f64>()
        })
        .sum::<f64>()
        / 72.0)
        .sqrt();
    eprintln!("Macbeth CCM fit rms residual {rms:.4} (white Y 0.9)");
    assert!(rms < 0.05, "rms {rms}");
}

#[test]
fn from_raw_subtracts_black_and_normalises() {
    let raw = RawFrame {
        rows: 2,
        cols: 2,
        adc_bits: 10,
        dn: vec![64, 1023, 543, 0],
        layout: None,
    };
    let m = Mosaic::from_raw(&raw, vec![vec![0, 1], vec![1, 2]], names(), 64.0, 1023.0).unwrap();
    assert_eq!(m.data[0], 0.0);
    assert_eq!(m.data[1], 1.0);
    assert!((m.data[2] - 479.0 / 959.0).abs() < 1e-7);
    assert!(m.data[3] < 0.0);
    let e = Mosaic::from_raw(&raw, vec![vec![0]], names(), 64.0, 10.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("white_dn = 10"), "{e}");
    let e = Mosaic::from_raw(&raw, vec![vec![0, 5]], names(), 64.0, 1023.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("tile[0][1] = 5"), "{e}");
    let p = IspPipeline {
        exposure_gain: 0.0,
        ..Default::default()
    };
    assert!(develop(&p, &m)
        .unwrap_err()
        .to_string()
        .contains("exposure_gain = 0"));
}

// ---------------------------------------------------------------------------------------
// ISETCam oracle: ../shared/oracles/isetcam/cases/ip_default_pipeline.json

fn oracle_mosaic() -> Mosaic {
    let a = read_npy(Path::new(&format!(
        "{ORACLE}/data/ip_default_pipeline__input.npy"
    )))
    .unwrap();
    assert_eq!(a.shape, vec![72, 88]);
    // GRBG: [[G, R], [B, G]]
    Mosaic::new(
        72,
        88,
        a.data.iter().map(|&v| v as f32).collect(),
        vec![vec![1, 0], vec![2, 1]],
        names(),
    )
    .unwrap()
}

fn oracle_rgb(which: &str) -> Vec<f64> {
    let a = read_npy(Path::new(&format!(
        "{ORACLE}/data/ip_default_pipeline__{which}.npy"
    )))
    .unwrap();
    assert_eq!(a.shape, vec![72, 88, 3]);
    a.data
}

fn assert_close(ours: &RgbImage, expected: &[f64], rtol: f64, what: &str) {
    let mx = expected.iter().fold(0f64, |a, &b| a.max(b.abs()));
    let mut worst = (0.0, 0);
    for (i, p) in ours.data.iter().enumerate() {
        for k in 0..3 {
            let (o, e) = (p[k] as f64, expected[3 * i + k]);
            let err = (o - e).abs() / (e.abs() + 1e-6 * mx);
            if err > worst.0 {
                worst = (err, 3 * i + k);
            }
        }
    }
    let j = worst.1;
    assert!(
        worst.0 <= rtol,
        "{what}: worst relative error {:.3e} at pixel ({}, {}) channel {}: ours {} expected {}",
        worst.0,
        j / 3 / ours.cols,
        j / 3 % ours.cols,
        j % 3,
        ours.data[j / 3][j % 3],
        expected[j]
    );
}

#[test]
fn isetcam_oracle_bilinear_demosaic_matches_sensorspace() {
    let m = oracle_mosaic();
    assert_eq!(m.bayer_layout().unwrap().name(), "GRBG");
    let ours = demosaic(&m, DemosaicMethod::Bilinear).unwrap();
    assert_close(&ours, &oracle_rgb("sensorspace"), 1e-6, "sensorspace");
}

struct CommonSpectra {
    wave: Vec<f64>,
    d65: Vec<f64>,
    cmf: Vec<[f64; 3]>,
    macbeth: Vec<Vec<f64>>,
    filters: Vec<[f64; 3]>,
}

fn common_spectra() -> CommonSpectra {
    let txt =
        std::fs::read_to_string(format!("{ORACLE}/common/spectra_400_700_10nm.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&txt).unwrap();
    let vec1 = |x: &serde_json::Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|y| y.as_f64().unwrap())
            .collect()
    };
    let rows3 = |x: &serde_json::Value| -> Vec<[f64; 3]> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let r = vec1(r);
                [r[0], r[1], r[2]]
            })
            .collect()
    };
    let wave = vec1(&v["wave_nm"]);
    let refl_rows: Vec<Vec<f64>> = v["macbeth_reflectance"]["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(vec1)
        .collect();
    // rows = wavelength, cols = patch (file order); transpose to one spectrum per patch
    let macbeth = (0..24)
        .map(|p| refl_rows.iter().map(|r| r[p]).collect())
        .collect();
    CommonSpectra {
        wave,
        d65: vec1(&v["D65_energy"]["values"]),
        cmf: rows3(&v["XYZ_cmf_energy"]["values"]),
        macbeth,
        filters: rows3(&v["sensor_RGB_filters"]["values"]),
    }
}

/// The combined sensor → display matrix of ISETCam's default ip (column convention), up to
/// the final scalar; the display primaries are resampled to `display_wave`.
fn isetcam_combined(c: &CommonSpectra, display_wave: Option<&[f64]>) -> ColorMatrix {
    let xyzq = data::spectral("human/xyzQuanta").unwrap();
    let xyz_quanta = SampledSpectra {
        wavelength_nm: c.wave.clone(),
        values: c
            .wave
            .iter()
            .map(|&w| [0, 1, 2].map(|k| xyzq.spectra[k].eval(w)))
            .collect(),
    };
    let qe = SampledSpectra {
        wavelength_nm: c.wave.clone(),
        values: c.filters.clone(),
    };
    let s2xyz = isetcam::mcc_sensor_to_xyz(&qe, &c.d65, &c.macbeth, &xyz_quanta).unwrap();
    let prim = isetcam::display_primaries("displays/lcdExample").unwrap();
    let (prim, cmf) = match display_wave {
        Some(w) => {
            let cmf = SampledSpectra {
                wavelength_nm: c.wave.clone(),
                values: c.cmf.clone(),
            };
            (isetcam::resample(&prim, w), isetcam::resample(&cmf, w))
        }
        None => {
            let cie = data::cie1931_xyz().unwrap();
            let w = prim.wavelength_nm.clone();
            let cmf = SampledSpectra {
                values: w
                    .iter()
                    .map(|&x| [0, 1, 2].map(|k| cie[k].eval(x)))
                    .collect(),
                wavelength_nm: w,
            };
            (prim, cmf)
        }
    };
    let rgb2xyz = isetcam::display_rgb_to_xyz(&prim, &cmf).unwrap();
    isetcam::invert(&rgb2xyz).unwrap().after(&s2xyz)
}

#[test]
fn isetcam_oracle_combined_transform_direction() {
    // The oracle states a least-squares fit of result = sensorspace · M (row convention).
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(format!("{ORACLE}/cases/ip_default_pipeline.json")).unwrap(),
    )
    .unwrap();
    let d: Vec<f64> = v["expected"]["derived_combined_transform"]["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let expected = ColorMatrix {
        m: [[d[0], d[1], d[2]], [d[3], d[4], d[5]], [d[6], d[7], d[8]]],
    }
    .transpose();
    let c = common_spectra();
    let ours = isetcam_combined(&c, Some(&c.wave.clone()));
    let k = expected.m[1][1] / ours.m[1][1];
    let worst = (0..9)
        .map(|i| (ours.m[i / 3][i % 3] * k - expected.m[i / 3][i % 3]).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "ours×{k:.6e} = {:?}\nexpected = {:?}\nworst abs diff {worst:.3e}",
        ours.scaled(k).m,
        expected.m
    );
    assert!(worst < 1e-4, "combined transform differs by {worst}");
}

#[test]
fn isetcam_oracle_result_is_reproduced() {
    let c = common_spectra();
    let m = oracle_mosaic();
    let sensorspace = demosaic(&m, DemosaicMethod::Bilinear).unwrap();
    let pipeline = IspPipeline {
        demosaic: DemosaicMethod::Bilinear,
        white_balance: WhiteBalance::None,
        ccm: Some(isetcam_combined(&c, Some(&c.wave.clone()))),
        exposure_gain: 1.0,
        clip_negative: false,
    };
    let mut out = develop(&pipeline, &m).unwrap().linear;
    // ISETCam: max(result) = max(sensor data) / voltage swing; here the swing is 1 V
    isetcam::scale_to_max(&mut out, sensorspace.max_value() as f64).unwrap();
    assert_close(&out, &oracle_rgb("result"), 1e-4, "result");
}

/// The clip-below-zero option (ISETCam convention): a colour matrix with a negative
/// coefficient drives a pure-red pixel negative in G; with the option, exactly those values
/// become 0 and every other value is unchanged; without it the negative value is kept.
#[test]
fn clip_negative_option_zeroes_only_negative_values() {
    let img0 = RgbImage::filled(8, 8, [0.6, 0.0, 0.0]);
    let m = Mosaic::sample_rgb(&img0, bayer_tiles()[0].1.clone(), names()).unwrap();
    let ccm = ColorMatrix {
        m: [[1.0, 0.0, 0.0], [-0.25, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };
    let base = IspPipeline {
        demosaic: DemosaicMethod::Bilinear,
        ccm: Some(ccm),
        ..Default::default()
    };
    let keep = develop(&base, &m).unwrap();
    let clip = develop(
        &IspPipeline {
            clip_negative: true,
            ..base.clone()
        },
        &m,
    )
    .unwrap();
    let mut negatives = 0;
    for (a, b) in keep.linear.data.iter().zip(&clip.linear.data) {
        for c in 0..3 {
            if a[c] < 0.0 {
                negatives += 1;
                assert_eq!(b[c], 0.0);
            } else {
                assert_eq!(a[c], b[c]);
            }
        }
    }
    // G = −0.25 · 0.6 = −0.15 at every pixel of the uniform red field
    assert_eq!(negatives, 64, "{:?}", keep.linear.data[0]);
    assert!((keep.linear.data[27][1] + 0.15).abs() < 1e-6);
    assert_eq!(
        keep.srgb8, clip.srgb8,
        "the sRGB codes are clipped either way"
    );
}
