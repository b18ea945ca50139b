//! Tests of the any-CFA path: constant colour through every tile and method, and PSNR on a
//! natural multispectral test image (dead leaves) against its ground truth.
use super::*;
use crate::cfa_generic::{bin_quad_bayer, demosaic_planes, remosaic_quad_bayer};
use camsim_core::{data, Spectrum};

fn names(s: &str) -> Vec<String> {
    s.chars().map(|c| c.to_string()).collect()
}

/// Tiles of the CFAs the issue names, as (label, channel letters, tile rows of letters).
fn cfas() -> Vec<(&'static str, Vec<String>, Vec<&'static str>)> {
    vec![
        ("Bayer RGGB", names("rgb"), vec!["rg", "gb"]),
        ("RGBW", names("rgbw"), vec!["rg", "wb"]),
        ("RCCB", names("rcb"), vec!["rc", "cb"]),
        ("RCCC", names("rc"), vec!["rc", "cc"]),
        (
            "quad Bayer",
            names("rgb"),
            vec!["rrgg", "rrgg", "ggbb", "ggbb"],
        ),
        ("mono", names("m"), vec!["m"]),
        (
            "4×4 multispectral",
            names("abcdefghijklmnop"),
            vec!["abcd", "efgh", "ijkl", "mnop"],
        ),
    ]
}

fn tile_of(ch: &[String], rows: &[&str]) -> Vec<Vec<usize>> {
    rows.iter()
        .map(|r| {
            r.chars()
                .map(|c| ch.iter().position(|n| n == &c.to_string()).unwrap())
                .collect()
        })
        .collect()
}

/// Sample full planes through a tile.
fn sample(
    planes: &[Vec<f32>],
    rows: usize,
    cols: usize,
    tile: &[Vec<usize>],
    ch: &[String],
) -> Mosaic {
    let (tr, tc) = (tile.len(), tile[0].len());
    let data = (0..rows * cols)
        .map(|i| planes[tile[(i / cols) % tr][(i % cols) % tc]][i])
        .collect();
    Mosaic::new(rows, cols, data, tile.to_vec(), ch.to_vec()).unwrap()
}

fn methods_for(label: &str) -> Vec<DemosaicMethod> {
    match label {
        "Bayer RGGB" => vec![
            DemosaicMethod::Bilinear,
            DemosaicMethod::Malvar,
            DemosaicMethod::EdgeAdaptive,
            DemosaicMethod::Lmmse,
        ],
        "quad Bayer" => vec![
            DemosaicMethod::Bilinear,
            DemosaicMethod::Lmmse,
            DemosaicMethod::QuadRemosaic,
            DemosaicMethod::QuadBinning,
        ],
        _ => vec![DemosaicMethod::Bilinear, DemosaicMethod::Lmmse],
    }
}

#[test]
fn constant_colour_is_reproduced_exactly_for_every_cfa_and_method() {
    for (label, ch, rows_s) in cfas() {
        let tile = tile_of(&ch, &rows_s);
        let colour: Vec<f32> = (0..ch.len())
            .map(|k| 0.1 + 0.8 * (k as f32 + 0.5) / ch.len() as f32)
            .collect();
        for (rows, cols) in [(8, 8), (9, 13), (17, 10)] {
            let planes: Vec<Vec<f32>> = colour.iter().map(|&v| vec![v; rows * cols]).collect();
            let m = sample(&planes, rows, cols, &tile, &ch);
            for method in methods_for(label) {
                let out = demosaic_planes(&m, method).unwrap();
                for (k, p) in out.planes.iter().enumerate() {
                    for (i, &v) in p.iter().enumerate() {
                        assert!(
                            (v - colour[k]).abs() <= 2e-6,
                            "{label} {} {rows}×{cols} pixel {i} channel {}: {v} ≠ {}",
                            method.name(),
                            ch[k],
                            colour[k]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn non_quad_tiles_are_refused_by_the_quad_methods_with_the_reason() {
    let ch = names("rgb");
    let m = sample(
        &vec![vec![0.5; 64]; 3],
        8,
        8,
        &tile_of(&ch, &["rg", "gb"]),
        &ch,
    );
    let e = bin_quad_bayer(&m).unwrap_err().to_string();
    assert!(e.contains("4×4 tile"), "{e}");
    let e = remosaic_quad_bayer(&m).unwrap_err().to_string();
    assert!(e.contains("quad_remosaic"), "{e}");
}

/// SplitMix64 (Steele, Lea & Flood 2014), enough for a reproducible test image.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn gaussian_band(centre_nm: f64, sigma_nm: f64) -> Spectrum {
    let w: Vec<f64> = (380..=780).step_by(5).map(|x| x as f64).collect();
    let v = w
        .iter()
        .map(|&x| 0.5 * (-(x - centre_nm).powi(2) / (2.0 * sigma_nm * sigma_nm)).exp())
        .collect();
    Spectrum::sampled(w, v).unwrap()
}

/// Channel QE for a channel letter: r/g/b Gaussian bands (600/540/460 nm, σ 35 nm), w/c clear
/// (the sum of the three), m a panchromatic mono pixel (same as clear), and a..p 16 narrow
/// bands (σ 15 nm) at 400 + 20·k nm.
fn qe(letter: &str, multispectral: bool) -> Spectrum {
    let band = |c| gaussian_band(c, 35.0);
    if multispectral {
        let k = (letter.as_bytes()[0] - b'a') as f64;
        return gaussian_band(400.0 + 20.0 * k, 15.0);
    }
    match letter {
        "r" => band(600.0),
        "g" => band(540.0),
        "b" => band(460.0),
        _ => {
            let w: Vec<f64> = (380..=780).step_by(5).map(|x| x as f64).collect();
            let v = w
                .iter()
                .map(|&x| band(600.0).eval(x) + band(540.0).eval(x) + band(460.0).eval(x))
                .collect();
            Spectrum::sampled(w, v).unwrap()
        }
    }
}

/// Dead-leaves image (Lee, Mumford & Huang, "Occlusion models for natural images", IJCV 2001;
/// the texture chart of IEEE 1858 / ISO 19567-2): discs with radii ∝ r⁻³ on [1, 48] px, each
/// a Macbeth reflectance times a brightness in [0.25, 1], under D65, blurred by a Gaussian
/// PSF of σ = 0.7 px. Returns one ground-truth plane per channel, normalised to peak 1.
fn dead_leaves(rows: usize, cols: usize, ch: &[String], multispectral: bool) -> Vec<Vec<f32>> {
    let d65 = data::illuminant("D65").unwrap();
    let refl = data::macbeth_reflectances_row_major().unwrap();
    let qes: Vec<Spectrum> = ch.iter().map(|n| qe(n, multispectral)).collect();
    let resp: Vec<Vec<f64>> = refl
        .iter()
        .map(|r| {
            let rad = Spectrum::multiply(r, &d65);
            qes.iter()
                .map(|q| Spectrum::integrate_product(&rad, q).unwrap())
                .collect()
        })
        .collect();
    let mut rng = Rng(20261126);
    let mut label = vec![usize::MAX; rows * cols];
    let mut bright = vec![0f64; rows * cols];
    let (rmin, rmax) = (1.0f64, 48.0f64);
    let mut left = rows * cols;
    let mut n = 0;
    while left > 0 && n < 200_000 {
        n += 1;
        // inverse CDF of p(r) ∝ r⁻³ on [rmin, rmax]
        let u = rng.next();
        let r =
            1.0 / (1.0 / (rmin * rmin) - u * (1.0 / (rmin * rmin) - 1.0 / (rmax * rmax))).sqrt();
        let (cy, cx) = (rng.next() * rows as f64, rng.next() * cols as f64);
        let patch = (rng.next() * 24.0) as usize % 24;
        let b = 0.25 + 0.75 * rng.next();
        // later leaves fall *under* earlier ones: fill only uncovered pixels
        let (r0, r1) = (
            (cy - r).floor().max(0.0) as usize,
            ((cy + r).ceil() as usize).min(rows),
        );
        let (c0, c1) = (
            (cx - r).floor().max(0.0) as usize,
            ((cx + r).ceil() as usize).min(cols),
        );
        for y in r0..r1 {
            for x in c0..c1 {
                let i = y * cols + x;
                if label[i] == usize::MAX
                    && (y as f64 + 0.5 - cy).powi(2) + (x as f64 + 0.5 - cx).powi(2) <= r * r
                {
                    label[i] = patch;
                    bright[i] = b;
                    left -= 1;
                }
            }
        }
    }
    let planes: Vec<Vec<f64>> = (0..ch.len())
        .map(|k| {
            (0..rows * cols)
                .map(|i| {
                    if label[i] == usize::MAX {
                        0.0
                    } else {
                        bright[i] * resp[label[i]][k]
                    }
                })
                .collect()
        })
        .collect();
    // separable Gaussian blur, σ = 0.7 px, mirrored borders
    let s = 0.7f64;
    let taps: Vec<f64> = (-3..=3)
        .map(|d: i32| (-(d * d) as f64 / (2.0 * s * s)).exp())
        .collect();
    let tsum: f64 = taps.iter().sum();
    let mir = |i: isize, n: usize| -> usize {
        let p = 2 * (n as isize - 1);
        let m = i.rem_euclid(p);
        if m < n as isize {
            m as usize
        } else {
            (p - m) as usize
        }
    };
    let blurred: Vec<Vec<f64>> = planes
        .iter()
        .map(|p| {
            let mut h = vec![0.0; rows * cols];
            for y in 0..rows {
                for x in 0..cols {
                    h[y * cols + x] = (0..7)
                        .map(|t| taps[t] * p[y * cols + mir(x as isize + t as isize - 3, cols)])
                        .sum::<f64>()
                        / tsum;
                }
            }
            let mut v = vec![0.0; rows * cols];
            for y in 0..rows {
                for x in 0..cols {
                    v[y * cols + x] = (0..7)
                        .map(|t| taps[t] * h[mir(y as isize + t as isize - 3, rows) * cols + x])
                        .sum::<f64>()
                        / tsum;
                }
            }
            v
        })
        .collect();
    let peak = blurred.iter().flatten().cloned().fold(0.0, f64::max);
    blurred
        .iter()
        .map(|p| p.iter().map(|&x| (x / peak) as f32).collect())
        .collect()
}

/// PSNR (dB, peak 1) over all channels, excluding a border of `b` pixels.
fn psnr(truth: &[Vec<f32>], est: &[Vec<f32>], rows: usize, cols: usize, b: usize) -> f64 {
    let (mut se, mut n) = (0.0f64, 0.0f64);
    for (t, e) in truth.iter().zip(est) {
        for y in b..rows - b {
            for x in b..cols - b {
                let d = (t[y * cols + x] - e[y * cols + x]) as f64;
                se += d * d;
                n += 1.0;
            }
        }
    }
    10.0 * (1.0 / (se / n)).log10()
}

/// 2×2 block means of full planes (the ground truth of binning).
fn bin_truth(p: &[Vec<f32>], rows: usize, cols: usize) -> Vec<Vec<f32>> {
    let (r2, c2) = (rows / 2, cols / 2);
    p.iter()
        .map(|v| {
            (0..r2 * c2)
                .map(|i| {
                    let (y, x) = (2 * (i / c2), 2 * (i % c2));
                    0.25 * (v[y * cols + x]
                        + v[y * cols + x + 1]
                        + v[(y + 1) * cols + x]
                        + v[(y + 1) * cols + x + 1])
                })
                .collect()
        })
        .collect()
}

/// The PSNR table of docs/isp.md. The generic (lmmse) method must beat the generic bilinear
/// normalised convolution on every CFA; on Bayer it is compared with the Bayer-specific
/// methods (printed; run with `--nocapture` to see the table).
#[test]
fn psnr_on_dead_leaves_generic_against_bilinear_and_bayer_methods() {
    let (rows, cols) = (160, 160);
    let mut table = vec![];
    for (label, ch, rows_s) in cfas() {
        let tile = tile_of(&ch, &rows_s);
        let truth = dead_leaves(rows, cols, &ch, label.contains("multispectral"));
        let m = sample(&truth, rows, cols, &tile, &ch);
        let mut row = vec![];
        for method in methods_for(label) {
            let out = demosaic_planes(&m, method).unwrap();
            let p = if method == DemosaicMethod::QuadBinning {
                psnr(
                    &bin_truth(&truth, rows, cols),
                    &out.planes,
                    rows / 2,
                    cols / 2,
                    4,
                )
            } else {
                psnr(&truth, &out.planes, rows, cols, 8)
            };
            row.push((method.name(), p));
        }
        table.push((label, row));
    }
    println!("| CFA | method: PSNR (dB) |");
    for (label, row) in &table {
        let cells: Vec<String> = row.iter().map(|(n, p)| format!("{n} {p:.2}")).collect();
        println!("| {label} | {} |", cells.join(" · "));
    }
    for (label, row) in &table {
        let get = |n: &str| row.iter().find(|r| r.0 == n).map(|r| r.1);
        if *label == "mono" {
            // a mono tile has no missing samples: every method returns the input exactly
            assert!(row.iter().all(|r| r.1 > 100.0), "{label}: {row:?}");
            continue;
        }
        let (b, l) = (get("bilinear").unwrap(), get("lmmse").unwrap());
        assert!(
            l > b + 0.5,
            "{label}: lmmse {l:.2} dB is not above bilinear {b:.2} dB"
        );
    }
}
