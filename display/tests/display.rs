//! Tests of the display stage against the embedded ISETCam display files (read independently
//! from the raw JSON where that matters).
use approx::assert_relative_eq;
use camsim_core::data;
use camsim_display::{show, DigitalImage, DisplayError, DisplayModel};
use serde_json::Value;

const ALL: [&str; 9] = [
    "lcdExample",
    "LCD-Apple",
    "LCD-Dell",
    "LCD-HP",
    "LCD-Samsung-RGBW",
    "OLED-Samsung",
    "OLED-Sony",
    "CRT-Dell",
    "CRT-HP",
];

fn raw(name: &str) -> Value {
    data::json(&format!("displays/{name}")).unwrap()
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Spatial mean of the displayed spectrum at wavelength `w`.
fn mean_spectrum_at(r: &camsim_display::DisplayRadiance, w: f64) -> f64 {
    let means = r.radiance.plane_means();
    (0..r.radiance.terms())
        .map(|k| means[k] * r.radiance.basis_spectrum(k).eval(w))
        .sum()
}

fn full_drive_image(
    d: &DisplayModel,
    bits: u32,
    rows: usize,
    cols: usize,
    on: &[bool],
) -> DigitalImage {
    let top = ((1u32 << bits) - 1) as u16;
    let v: Vec<u16> = on.iter().map(|&o| if o { top } else { 0 }).collect();
    assert_eq!(v.len(), d.n_primaries());
    DigitalImage::uniform(rows, cols, bits, &v)
}

fn close(a: f64, b: f64, rtol: f64, scale: f64) -> bool {
    (a - b).abs() <= rtol * b.abs().max(1e-9 * scale)
}

#[test]
fn loads_every_embedded_display() {
    let names = DisplayModel::names();
    for n in ALL {
        assert!(names.contains(&n), "{n} missing from {names:?}");
        let d = DisplayModel::load(n).unwrap();
        let v = raw(n);
        assert_eq!(d.name, n);
        assert_eq!(d.n_primaries(), v["spd"].as_array().unwrap().len());
        assert_eq!(d.gamma.levels() as u64, v["gamma_levels"].as_u64().unwrap());
        assert_relative_eq!(d.pixel_pitch_m(), 0.0254 / v["dpi"].as_f64().unwrap());
    }
    assert_eq!(names.len(), ALL.len());
    // OLED-Samsung's tile spans 2 × 2 pixels, so its samples are twice the file's spacing
    let o = DisplayModel::load("OLED-Samsung").unwrap();
    assert_eq!(o.dixel.pixels_per_dixel, [2, 2]);
    assert_relative_eq!(o.dixel_sample_pitch_m()[0], o.pixel_pitch_m() / 40.0);
    // the RGBW maps have mean 0.2 in the file and are renormalised to mean 1
    let w = DisplayModel::load("LCD-Samsung-RGBW").unwrap();
    for m in &w.dixel.file_mean {
        assert_relative_eq!(*m, 0.2, max_relative = 1e-9);
    }
    // case-insensitive lookup
    assert_eq!(DisplayModel::load("lcdexample").unwrap().name, "lcdExample");
}

#[test]
fn displayed_white_is_the_sum_of_primary_spds() {
    for n in ALL {
        let d = DisplayModel::load(n).unwrap();
        let v = raw(n);
        let wl = nums(&v["wavelength_nm"]);
        let spd: Vec<Vec<f64>> = v["spd"].as_array().unwrap().iter().map(nums).collect();
        let sum: Vec<f64> = (0..wl.len())
            .map(|i| spd.iter().map(|s| s[i]).sum())
            .collect();
        let scale = sum.iter().cloned().fold(0.0, f64::max);
        assert!(scale > 0.0);
        let bits = d.gamma.native_bits().unwrap();
        let [pr, pc] = d.dixel.pixels_per_dixel;
        let img = full_drive_image(&d, bits, pr, pc, &vec![true; d.n_primaries()]);
        for spp in [1, 5] {
            let r = show(&d, &img, spp).unwrap();
            for (i, &w) in wl.iter().enumerate() {
                let got = mean_spectrum_at(&r, w);
                assert!(
                    close(got, sum[i], 1e-6, scale),
                    "{n} spp {spp} at {w} nm: displayed {got} vs Σ spd {}",
                    sum[i]
                );
            }
        }
        // white_spd() is the same sum
        for (i, &w) in wl.iter().enumerate() {
            assert!(
                close(d.white_spd().eval(w), sum[i], 1e-12, scale),
                "{n} white_spd at {w}"
            );
        }
    }
}

#[test]
fn gamma_round_trip_is_exact_for_every_level() {
    let mut strict = 0usize;
    for n in ALL {
        let d = DisplayModel::load(n).unwrap();
        let bits = d.gamma.native_bits().unwrap();
        let levels = raw(n)["gamma"].as_array().unwrap().len();
        assert_eq!(levels, 1 << bits);
        for p in 0..d.n_primaries() {
            // the table straight from the JSON, gamma[level][primary]
            let t: Vec<f64> = (0..levels).map(|k| raw_gamma(n, k, p)).collect();
            for k in 0..levels {
                let lin = d.linear_from_digital(p, k as u32, bits).unwrap();
                assert_eq!(lin, t[k], "{n} primary {p} level {k}");
                let back = d.digital_from_linear(p, lin, bits).unwrap() as usize;
                let unique = t.iter().filter(|x| **x == t[k]).count() == 1;
                if unique {
                    strict += 1;
                    assert_eq!(back, k, "{n} primary {p}: level {k} → {lin} → {back}");
                } else {
                    // flat run: the lowest level of the run, with the same intensity
                    let first = t.iter().position(|x| *x == t[k]).unwrap();
                    assert_eq!(back, first, "{n} primary {p} flat level {k}");
                    assert_eq!(d.linear_from_digital(p, back as u32, bits).unwrap(), lin);
                }
            }
        }
    }
    assert!(
        strict > 20_000,
        "only {strict} strictly increasing levels checked"
    );
}

fn raw_gamma(n: &str, k: usize, p: usize) -> f64 {
    thread_local! {
        static CACHE: std::cell::RefCell<Option<(String, Vec<Vec<f64>>)>> = const { std::cell::RefCell::new(None) };
    }
    CACHE.with(|c| {
        let mut c = c.borrow_mut();
        if c.as_ref().map(|(m, _)| m != n).unwrap_or(true) {
            let g = raw(n)["gamma"]
                .as_array()
                .unwrap()
                .iter()
                .map(nums)
                .collect();
            *c = Some((n.to_string(), g));
        }
        c.as_ref().unwrap().1[k][p]
    })
}

#[test]
fn gamma_round_trip_at_other_bit_depths() {
    // 8-bit codes on a 1024-level table and 10-bit codes on a 256-level table (both strictly
    // increasing): proportional mapping with interpolation, inverse exact for every code
    for (n, bits) in [
        ("lcdExample", 8u32),
        ("LCD-Dell", 10),
        ("LCD-Dell", 12),
        ("lcdExample", 12),
    ] {
        let d = DisplayModel::load(n).unwrap();
        for p in 0..d.n_primaries() {
            let mut prev = -1.0;
            for code in 0..(1u32 << bits) {
                let lin = d.linear_from_digital(p, code, bits).unwrap();
                assert!(
                    lin > prev,
                    "{n} {bits}-bit primary {p}: not increasing at {code}"
                );
                prev = lin;
                assert_eq!(
                    d.digital_from_linear(p, lin, bits).unwrap() as u32,
                    code,
                    "{n} {bits}-bit p{p}"
                );
            }
            // end points map to the table ends
            let t = d.gamma.table(p).unwrap();
            assert_eq!(d.linear_from_digital(p, 0, bits).unwrap(), t[0]);
            assert_eq!(
                d.linear_from_digital(p, (1 << bits) - 1, bits).unwrap(),
                t[t.len() - 1]
            );
        }
    }
}

#[test]
fn black_image_gives_the_black_level() {
    let mut nonzero_black = 0;
    for n in ALL {
        let d = DisplayModel::load(n).unwrap();
        let v = raw(n);
        let wl = nums(&v["wavelength_nm"]);
        let spd: Vec<Vec<f64>> = v["spd"].as_array().unwrap().iter().map(nums).collect();
        let g0 = nums(&v["gamma"][0]);
        let black: Vec<f64> = (0..wl.len())
            .map(|i| (0..spd.len()).map(|p| g0[p] * spd[p][i]).sum())
            .collect();
        let scale = spd.iter().flatten().cloned().fold(0.0, f64::max);
        let bits = d.gamma.native_bits().unwrap();
        let [pr, pc] = d.dixel.pixels_per_dixel;
        let img = full_drive_image(&d, bits, 2 * pr, 3 * pc, &vec![false; d.n_primaries()]);
        let r = show(&d, &img, 2).unwrap();
        if black.iter().all(|b| *b == 0.0) {
            // zero radiance at every sample and wavelength (a zero-SPD primary may carry a
            // non-zero plane, like OLED-Samsung's constant 4th primary)
            for (i, &w) in wl.iter().enumerate() {
                for y in 0..r.radiance.rows {
                    for x in 0..r.radiance.cols {
                        let s: f64 = (0..r.radiance.terms())
                            .map(|k| {
                                r.radiance.planes[k][y * r.radiance.cols + x] as f64
                                    * r.radiance.basis_spectrum(k).eval(w)
                            })
                            .sum();
                        assert_eq!(s, 0.0, "{n} black at {w} nm, sample ({y}, {x})");
                    }
                }
                assert_eq!(black[i], 0.0);
            }
        } else {
            nonzero_black += 1;
            for (i, &w) in wl.iter().enumerate() {
                let got = mean_spectrum_at(&r, w);
                assert!(
                    close(got, black[i], 1e-6, scale),
                    "{n} black at {w}: {got} vs {}",
                    black[i]
                );
                assert!(close(d.black_spd().eval(w), black[i], 1e-12, scale));
            }
        }
    }
    // LCD-Dell and LCD-HP have a non-zero first gamma entry
    assert_eq!(nonzero_black, 2);
    let lcd = DisplayModel::load("lcdExample").unwrap();
    let r = show(&lcd, &DigitalImage::uniform(2, 2, 10, &[0, 0, 0]), 3).unwrap();
    assert!(r.radiance.planes.iter().flatten().all(|v| *v == 0.0));
}

#[test]
fn subpixel_map_means_are_preserved() {
    for n in ALL {
        let d = DisplayModel::load(n).unwrap();
        let v = raw(n);
        // the file map's mean (independent of the crate) and the crate's normalisation
        for (p, m) in v["dixel"]["intensitymap"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let vals: Vec<f64> = m.as_array().unwrap().iter().flat_map(nums).collect();
            let mean = vals.iter().sum::<f64>() / vals.len() as f64;
            assert_relative_eq!(d.dixel.file_mean[p], mean, max_relative = 1e-12);
        }
        let bits = d.gamma.native_bits().unwrap();
        let [pr, pc] = d.dixel.pixels_per_dixel;
        for spp in [1usize, 2, 5, 20] {
            let tile = d.dixel.resampled(spp).unwrap();
            assert_eq!((tile.rows, tile.cols), (spp * pr, spp * pc));
            for (p, m) in tile.means().iter().enumerate() {
                assert!(
                    (m - 1.0).abs() < 1e-12,
                    "{n} spp {spp} primary {p}: map mean {m}"
                );
            }
            // through show(): one primary at full drive over one tile → plane mean = top gamma
            for p in 0..d.n_primaries() {
                let mut on = vec![false; d.n_primaries()];
                on[p] = true;
                let r = show(&d, &full_drive_image(&d, bits, pr, pc, &on), spp).unwrap();
                let top = d.gamma.table(p).unwrap()[d.gamma.levels() - 1];
                let mean = r.radiance.plane_means()[p];
                assert!(
                    (mean - top).abs() <= 1e-6 * top,
                    "{n} spp {spp} primary {p}: plane mean {mean} vs {top}"
                );
                assert_relative_eq!(r.sample_pitch_m, d.pixel_pitch_m() / spp as f64);
            }
        }
    }
}

#[test]
fn lcd_example_red_subpixel_sits_where_the_map_says() {
    let d = DisplayModel::load("lcdExample").unwrap();
    let v = raw("lcdExample");
    let red: Vec<Vec<f64>> = v["dixel"]["intensitymap"][0]
        .as_array()
        .unwrap()
        .iter()
        .map(nums)
        .collect();
    let mean = red.iter().flatten().sum::<f64>() / 400.0;
    let map_cols: Vec<usize> = (0..20)
        .filter(|&c| red.iter().any(|r| r[c] > 0.0))
        .collect();
    let map_rows: Vec<usize> = (0..20)
        .filter(|&r| red[r].iter().any(|x| *x > 0.0))
        .collect();
    // the file: a 5-sample-wide stripe in columns 1–5 plus a faint column 7, rows 1–18
    assert_eq!(map_cols, vec![1, 2, 3, 4, 5, 7]);
    assert_eq!(map_rows, (1..=18).collect::<Vec<_>>());

    // two pixels side by side, red at full drive, green and blue off
    let img = DigitalImage::from_rgb(1, 2, 10, &[[1023, 0, 0], [1023, 0, 0]]);
    let r = show(&d, &img, 20).unwrap();
    assert_eq!((r.radiance.rows, r.radiance.cols), (20, 40));
    let plane = &r.radiance.planes[0];
    for y in 0..20 {
        for x in 0..40 {
            let want = red[y][x % 20] / mean;
            let got = plane[y * 40 + x] as f64;
            assert!(
                (got - want).abs() <= 1e-6 * want.max(1e-30),
                "({y}, {x}): {got} vs {want}"
            );
        }
    }
    let lit: Vec<usize> = (0..40)
        .filter(|&x| (0..20).any(|y| plane[y * 40 + x] > 0.0))
        .collect();
    let expected: Vec<usize> = map_cols
        .iter()
        .flat_map(|&c| [c, c + 20])
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    assert_eq!(lit, expected);
    assert!(r.radiance.planes[1]
        .iter()
        .chain(&r.radiance.planes[2])
        .all(|v| *v == 0.0));
    // with 2 samples per pixel the stripe (cols 1–7) falls in the left half
    let r2 = show(&d, &img, 2).unwrap();
    let p = &r2.radiance.planes[0];
    assert!(
        p[0] > 0.0 && p[2] > 0.0 && p[1] == 0.0 && p[3] == 0.0,
        "{p:?}"
    );
}

#[test]
fn unknown_display_error_names_it_and_lists_the_displays() {
    let e = DisplayModel::load("LCD-Nonexistent").unwrap_err();
    assert!(matches!(e, DisplayError::UnknownDisplay { .. }));
    let msg = e.to_string();
    assert!(msg.contains("LCD-Nonexistent"), "{msg}");
    for n in ALL {
        assert!(msg.contains(n), "{n} not listed in: {msg}");
    }
}

#[test]
fn bad_inputs_are_rejected_with_the_value() {
    let d = DisplayModel::load("lcdExample").unwrap();
    let e = show(&d, &DigitalImage::uniform(1, 1, 8, &[300, 0, 0]), 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("300"), "{e}");
    let e = show(&d, &DigitalImage::uniform(1, 1, 8, &[1, 0]), 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("2 channels"), "{e}");
    assert!(show(&d, &DigitalImage::uniform(1, 1, 8, &[1, 0, 0]), 0).is_err());
    let e = d.linear_from_digital(0, 1024, 10).unwrap_err().to_string();
    assert!(e.contains("1024"), "{e}");
    let e = d.linear_from_digital(5, 0, 10).unwrap_err().to_string();
    assert!(e.contains('5'), "{e}");

    let mut v = raw("lcdExample");
    v["gamma"][7][1] = Value::from(-1.0);
    let e = DisplayModel::from_json(&v).unwrap_err().to_string();
    assert!(e.contains("gamma[7][1]") && e.contains("-1"), "{e}");
    let mut v = raw("lcdExample");
    v["dpi"] = Value::from(-96.0);
    assert!(DisplayModel::from_json(&v)
        .unwrap_err()
        .to_string()
        .contains("-96"));

    // a 3-channel image on a 4-primary display drives the 4th primary at code 0
    let w = DisplayModel::load("LCD-Samsung-RGBW").unwrap();
    let r = show(&w, &DigitalImage::uniform(1, 1, 10, &[1023, 1023, 1023]), 1).unwrap();
    assert_eq!(r.radiance.planes[3][0], 0.0);
}

#[test]
fn colorimetry_and_units() {
    let d = DisplayModel::load("lcdExample").unwrap();
    let xyz = d.primaries_xyz();
    let y: f64 = xyz.iter().map(|c| c.y).sum();
    assert_relative_eq!(d.peak_luminance_cd_per_m2(), y, max_relative = 1e-9);
    assert!(y > 10.0 && y < 1000.0, "white luminance {y} cd/m²");
    // red primary is reddish, blue bluish
    assert!(xyz[0].x > xyz[0].z && xyz[2].z > xyz[2].x);
    // photon conversion: L_q = L_e λ / (h c)
    let r = show(&d, &DigitalImage::uniform(1, 1, 10, &[1023, 1023, 1023]), 1).unwrap();
    let c = camsim_core::constants::SI;
    let q = r.radiance_photons(&c);
    let (w, e) = (550.0, mean_spectrum_at(&r, 550.0));
    let qv: f64 = (0..q.terms())
        .map(|k| q.planes[k][0] as f64 * q.basis_spectrum(k).eval(w))
        .sum();
    assert_relative_eq!(
        qv,
        e * w * 1e-9 / (c.planck_j_s * c.light_speed_m_per_s),
        max_relative = 1e-6
    );
}
