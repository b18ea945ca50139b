//! Pixel integration (baseline step 2): per channel, the exact spectral integral
//! `∫ QE_c(λ) E(x, λ) dλ` on the irradiance grid, then the area average over each pixel's
//! full p × p square at the pixels of that channel only.
use crate::{ElectronRate, SensorModel};
use camsim_core::SensorIrradiance;
use rayon::prelude::*;

/// Area-overlap weights along one axis.
///
/// The irradiance has `n_cells` square cells of side `cell_pitch_m` and the sensor `n_pixels`
/// pixels of side `pixel_pitch_m`, both grids centred on the optical axis (centres at
/// `(i − (n−1)/2) · pitch`). Entry `k` lists `(cell index, weight)` with weights summing to 1:
/// the fraction of pixel k's extent covered by each cell. Cells beyond the irradiance image
/// count as the nearest border cell (the image continues), so weights of repeated border cells
/// are merged.
pub fn box_weights(
    n_cells: usize,
    cell_pitch_m: f64,
    n_pixels: usize,
    pixel_pitch_m: f64,
) -> Vec<Vec<(usize, f64)>> {
    assert!(n_cells > 0 && cell_pitch_m > 0.0 && pixel_pitch_m > 0.0);
    let ratio = pixel_pitch_m / cell_pitch_m; // pixel width in cell units
    let half_cells = n_cells as f64 / 2.0;
    (0..n_pixels)
        .map(|k| {
            // Pixel k spans [u0, u1] in cell units, where cell j spans [j, j + 1].
            let centre = (k as f64 - (n_pixels as f64 - 1.0) / 2.0) * ratio + half_cells;
            let (u0, u1) = (centre - ratio / 2.0, centre + ratio / 2.0);
            let mut w: Vec<(usize, f64)> = Vec::new();
            let j0 = u0.floor() as i64;
            let j1 = (u1.ceil() as i64 - 1).max(j0);
            for j in j0..=j1 {
                let overlap = (u1.min(j as f64 + 1.0) - u0.max(j as f64)).max(0.0);
                if overlap <= 0.0 {
                    continue;
                }
                let jc = j.clamp(0, n_cells as i64 - 1) as usize; // image continues
                match w.last_mut() {
                    Some(last) if last.0 == jc => last.1 += overlap / ratio,
                    _ => w.push((jc, overlap / ratio)),
                }
            }
            w
        })
        .collect()
}

/// The [`box_weights`] of the sensor's pixel rows and columns over the irradiance grid.
fn pixel_box_weights(
    sensor: &SensorModel,
    irradiance: &SensorIrradiance,
) -> (Vec<Vec<(usize, f64)>>, Vec<Vec<(usize, f64)>>) {
    let img = &irradiance.irradiance;
    let p = irradiance.sample_pitch_m;
    (
        box_weights(img.rows, p, sensor.rows, sensor.pixel_pitch_m),
        box_weights(img.cols, p, sensor.cols, sensor.pixel_pitch_m),
    )
}

/// Mean photo-electron rate per pixel (step 2 without t): `p² · FF · ∫ QE_c(λ) Ē(λ) dλ`,
/// Ē the irradiance (photons/(s·m²·nm)) area-averaged over the pixel's p × p square; with
/// the effect blocks, QE_c is the effective QE (QE shift, IR leakage) and the result is
/// shared by crosstalk ([`crate::effects`]).
///
/// The spectral integral is exact for the piecewise-linear spectra of the image
/// ([`camsim_core::SpectralImage::integrate_against`]); spectra are never expanded.
pub fn electron_rate(sensor: &SensorModel, irradiance: &SensorIrradiance) -> ElectronRate {
    let img = &irradiance.irradiance;
    // Exact spectral integrals ∫ QE_c(λ) B_k(λ) dλ of every channel c and basis term k: the
    // channel's irradiance map is Σ_k w[c][k] a_k(x) (no full-resolution maps are built).
    let weights: Vec<Option<Vec<(usize, f64)>>> = (0..sensor.channel_qe.len())
        .map(|c| {
            let used = sensor.cfa.tile.iter().flatten().any(|&t| t == c);
            used.then(|| {
                // Effective QE: QE shift and IR leakage blocks included.
                crate::effects::channel_term_integrals(sensor, img, c)
                    .into_iter()
                    .enumerate()
                    .filter(|(_, w)| *w != 0.0)
                    .collect()
            })
        })
        .collect();
    let (wy, wx) = pixel_box_weights(sensor, irradiance);
    let k = sensor.pixel_pitch_m * sensor.pixel_pitch_m * sensor.fill_factor;
    let (oi_cols, n_ch) = (img.cols, weights.len());
    let mut out = vec![0f32; sensor.rows * sensor.cols];
    out.par_chunks_mut(sensor.cols).enumerate().for_each_init(
        || vec![Vec::<f64>::new(); n_ch],
        |lines, (r, row_out)| {
            let tile_row = &sensor.cfa.tile[r % sensor.cfa.tile_rows()];
            lines.iter_mut().for_each(|l| l.clear());
            for &c in tile_row {
                if !lines[c].is_empty() {
                    continue;
                }
                let wc = weights[c]
                    .as_ref()
                    .expect("weights of a channel in the tile");
                // Row average over the cells of pixel row r (y box weights), per channel.
                let line = &mut lines[c];
                line.resize(oi_cols, 0.0);
                for &(y, w) in &wy[r] {
                    for &(term, wk) in wc {
                        let src = &img.planes[term][y * oi_cols..(y + 1) * oi_cols];
                        let f = w * wk;
                        line.iter_mut()
                            .zip(src)
                            .for_each(|(l, s)| *l += f * *s as f64);
                    }
                }
            }
            for (col, o) in row_out.iter_mut().enumerate() {
                let line = &lines[tile_row[col % tile_row.len()]];
                let e: f64 = wx[col].iter().map(|&(x, w)| w * line[x]).sum();
                *o = (k * e) as f32;
            }
        },
    );
    let mut rate = ElectronRate {
        rows: sensor.rows,
        cols: sensor.cols,
        electrons_per_s: out,
    };
    // Crosstalk block: shares the mean photo-electrons (before the Poisson draw).
    if let Some(ct) = &sensor.effects.crosstalk {
        crate::effects::apply_crosstalk(ct, &mut rate);
    }
    rate
}

/// The irradiance of one image averaged over every pixel, one plane per spectral basis term:
/// `Ā_k(i)`, the plane of term k area-averaged over pixel i's p × p square (the box weights of
/// [`electron_rate`]).
#[derive(Debug, Clone)]
pub struct PixelTermPlanes {
    /// 1×1 image carrying the basis (for the channels' spectral integrals).
    pub basis: camsim_core::SpectralImage,
    /// Row-major sensor-size planes, one per basis term.
    pub planes: Vec<Vec<f32>>,
}

/// Pixel integration per basis term, before the spectral weighting: with these planes the
/// electron rate of any effective QE is one weighted sum per pixel
/// ([`electron_rate_from_term_planes`]). By linearity, `electron_rate` of the same sensor
/// (without crosstalk) is the same sum taken in another order.
pub fn pixel_term_planes(sensor: &SensorModel, irradiance: &SensorIrradiance) -> PixelTermPlanes {
    let img = &irradiance.irradiance;
    let (wy, wx) = pixel_box_weights(sensor, irradiance);
    let ic = img.cols;
    let planes = img
        .planes
        .iter()
        .map(|p| {
            let mut out = vec![0f32; sensor.rows * sensor.cols];
            out.par_chunks_mut(sensor.cols).enumerate().for_each_init(
                || vec![0f64; ic],
                |line, (r, row)| {
                    line.iter_mut().for_each(|l| *l = 0.0);
                    for &(y, w) in &wy[r] {
                        line.iter_mut()
                            .zip(&p[y * ic..(y + 1) * ic])
                            .for_each(|(l, s)| *l += w * *s as f64);
                    }
                    for (o, wc) in row.iter_mut().zip(&wx) {
                        *o = wc.iter().map(|&(x, w)| w * line[x]).sum::<f64>() as f32;
                    }
                },
            );
            out
        })
        .collect();
    let basis = camsim_core::SpectralImage::new(
        1,
        1,
        img.basis.clone(),
        vec![vec![0f32]; img.planes.len()],
    )
    .expect("one plane per term");
    PixelTermPlanes { basis, planes }
}

/// Mean photo-electron rate of every pixel from its term planes:
/// `p²·FF·Σ_k w_ck Ā_k(i)`, with `w_ck = ∫ QE_c(λ) B_k(λ) dλ` the channel's effective QE (QE
/// shift and IR leakage blocks included) against basis term k. No crosstalk (the caller
/// applies it where wanted).
pub fn electron_rate_from_term_planes(sensor: &SensorModel, pp: &PixelTermPlanes) -> Vec<f32> {
    let weights: Vec<Vec<(usize, f64)>> = (0..sensor.channel_qe.len())
        .map(|c| {
            let used = sensor.cfa.tile.iter().flatten().any(|&t| t == c);
            if !used {
                return Vec::new();
            }
            crate::effects::channel_term_integrals(sensor, &pp.basis, c)
                .into_iter()
                .enumerate()
                .filter(|(_, w)| *w != 0.0)
                .collect()
        })
        .collect();
    let k = sensor.pixel_pitch_m * sensor.pixel_pitch_m * sensor.fill_factor;
    let cols = sensor.cols;
    let mut out = vec![0f32; sensor.rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        for (c, o) in row.iter_mut().enumerate() {
            let i = r * cols + c;
            let e: f64 = weights[sensor.cfa.channel_at(r, c)]
                .iter()
                .map(|&(t, w)| w * pp.planes[t][i] as f64)
                .sum();
            *o = (k * e) as f32;
        }
    });
    out
}

/// The irradiance (or radiance) of one image summed spectrally per sensor channel before the
/// pixel average: `C_c(x) = Σ_k w_ck a_k(x)`, with `w_ck = ∫ QE'_c(λ) B_k(λ) dλ` the
/// weights of [`electron_rate`] (QE shift and IR leakage blocks included), one plane per
/// channel the CFA uses (`channels`, ascending). Pixel integration is linear in the planes,
/// so the pixel average of these planes is [`electron_rate`]'s `∫ QE_c Ē dλ` with the sum
/// taken first; an operator that acts on every plane alike (a wavelength-independent blur or
/// warp, a spatial scale, a mean added) commutes with the sum, so it may act on these planes
/// instead of the basis terms' (Goodman, *Introduction to Fourier Optics*, 2005, §6.1:
/// incoherent imaging is linear in intensity).
#[derive(Debug, Clone)]
pub struct ChannelPlanes {
    /// Channel index of each plane.
    pub channels: Vec<usize>,
    /// Row-major planes of the input image's size, one per entry of `channels`.
    pub planes: Vec<Vec<f32>>,
}

/// [`ChannelPlanes`] of `img` for `sensor`'s channels and effective QE.
pub fn channel_planes(sensor: &SensorModel, img: &camsim_core::SpectralImage) -> ChannelPlanes {
    let w = channel_weights(sensor, &img.basis);
    let planes = w.weights.iter().map(|wc| img.combine(wc)).collect();
    ChannelPlanes {
        channels: w.channels,
        planes,
    }
}

/// The weights `w_ck` of [`ChannelPlanes`] for the terms of `basis`: the planes of an image
/// on that basis are `Σ_k w_ck a_k` ([`channel_planes`]), or a target's render projected
/// onto them ([`camsim_core::scene::render_target_projected_rows`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelWeights {
    /// The channels the CFA uses, ascending.
    pub channels: Vec<usize>,
    /// One row per entry of `channels`, one weight per basis term.
    pub weights: Vec<Vec<f64>>,
}

/// [`ChannelWeights`] of `basis` for `sensor`'s channels and effective QE
/// ([`crate::effects::channel_basis_integrals`]).
pub fn channel_weights(sensor: &SensorModel, basis: &camsim_core::SpectralBasis) -> ChannelWeights {
    let channels: Vec<usize> = (0..sensor.channel_qe.len())
        .filter(|&c| sensor.cfa.tile.iter().flatten().any(|&t| t == c))
        .collect();
    let weights = channels
        .iter()
        .map(|&c| crate::effects::channel_basis_integrals(sensor, basis, c))
        .collect();
    ChannelWeights { channels, weights }
}

/// Mean photo-electron rate of every pixel from its pixel-averaged channel planes
/// (`pixel`: [`pixel_term_planes`] of an irradiance whose planes are [`ChannelPlanes`] in the
/// order of `channels`): `p²·FF·C̄_c(i)`, c pixel i's CFA channel ([`electron_rate`]'s
/// equation with the spectral sum taken before the area average). No crosstalk.
pub fn electron_rate_from_channel_planes(
    sensor: &SensorModel,
    channels: &[usize],
    pixel: &PixelTermPlanes,
) -> Vec<f32> {
    let mut plane_of = vec![usize::MAX; sensor.channel_qe.len()];
    for (j, &c) in channels.iter().enumerate() {
        plane_of[c] = j;
    }
    let k = sensor.pixel_pitch_m * sensor.pixel_pitch_m * sensor.fill_factor;
    let cols = sensor.cols;
    let mut out = vec![0f32; sensor.rows * cols];
    out.par_chunks_mut(cols).enumerate().for_each(|(r, row)| {
        for (c, o) in row.iter_mut().enumerate() {
            let p = &pixel.planes[plane_of[sensor.cfa.channel_at(r, c)]];
            *o = (k * p[r * cols + c] as f64) as f32;
        }
    });
    out
}

pub(crate) fn channel_maps(
    sensor: &SensorModel,
    f: impl Fn(&camsim_core::Spectrum) -> Vec<f32> + Sync,
) -> Vec<Option<Vec<f32>>> {
    (0..sensor.channel_qe.len())
        .into_par_iter()
        .map(|c| {
            let used = sensor.cfa.tile.iter().flatten().any(|&t| t == c);
            used.then(|| f(&sensor.channel_qe[c]))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::mono;
    use crate::Cfa;
    use approx::assert_relative_eq;
    use camsim_core::{SpectralBasis, SpectralImage, Spectrum, WavelengthGrid};

    fn flat_image(rows: usize, cols: usize, plane: Vec<f32>) -> SpectralImage {
        // E(λ) = plane value × 1 on [400, 700] nm → ∫ E dλ = 300 · value for QE = 1.
        SpectralImage::from_single_spectrum(
            rows,
            cols,
            Spectrum::sampled(vec![400.0, 700.0], vec![1.0, 1.0]).unwrap(),
            plane,
        )
    }

    #[test]
    fn weights_sum_to_one_for_odd_ratios() {
        for &(n, s, m, p) in &[
            (7usize, 1.0, 5usize, 1.37),
            (3, 2.0, 11, 0.3),
            (1, 1e3, 4, 1.0),
            (50, 0.7, 9, 2.2),
        ] {
            for w in box_weights(n, s, m, p) {
                let sum: f64 = w.iter().map(|x| x.1).sum();
                assert_relative_eq!(sum, 1.0, epsilon = 1e-12);
                assert!(w.iter().all(|x| x.0 < n && x.1 > 0.0));
            }
        }
    }

    #[test]
    fn uniform_field_single_huge_cell() {
        let mut s = mono(6, 5);
        s.fill_factor = 0.5;
        let irr = SensorIrradiance {
            irradiance: flat_image(1, 1, vec![1e15]),
            sample_pitch_m: 1.0,
        };
        let r = electron_rate(&s, &irr);
        let want = 2e-6f64 * 2e-6 * 0.5 * 300.0 * 1e15;
        for v in r.electrons_per_s {
            assert_relative_eq!(v as f64, want, max_relative = 1e-6);
        }
    }

    #[test]
    fn box_average_matches_brute_force_with_margin_and_odd_ratio() {
        // A ramp in x on a grid with a margin (irradiance larger than the sensor) and a
        // non-integer pitch ratio 2 / 0.37; the reference is a brute-force midpoint average
        // of the piecewise-constant cells over the pixel square.
        let (oi_rows, oi_cols, pitch) = (9usize, 101usize, 0.37e-6);
        let value = |j: usize| 1e14 * (1.0 + 0.1 * j as f64);
        let plane: Vec<f32> = (0..oi_rows * oi_cols)
            .map(|i| value(i % oi_cols) as f32)
            .collect();
        let s = mono(3, 7);
        let irr = SensorIrradiance {
            irradiance: flat_image(oi_rows, oi_cols, plane),
            sample_pitch_m: pitch,
        };
        let r = electron_rate(&s, &irr);
        let n_sub = 200_000;
        for col in 0..7 {
            let x0 = (col as f64 - 3.0) * 2e-6 - 1e-6;
            let mut acc = 0.0;
            for k in 0..n_sub {
                let x = x0 + 2e-6 * (k as f64 + 0.5) / n_sub as f64;
                let j = (x / pitch + oi_cols as f64 / 2.0).floor() as usize;
                acc += value(j) as f32 as f64;
            }
            let want = 4e-12 * 300.0 * acc / n_sub as f64;
            for row in 0..3 {
                assert_relative_eq!(
                    r.electrons_per_s[row * 7 + col] as f64,
                    want,
                    max_relative = 2e-6
                );
            }
        }
    }

    #[test]
    fn channels_are_sampled_at_their_own_pixels_with_exact_integrals() {
        let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
        // Uniform band image whose spectrum is 1 at every band.
        let planes = vec![vec![1e12f32; 4]; g.len()];
        let img = SpectralImage::new(2, 2, SpectralBasis::Bands(g), planes).unwrap();
        let mut s = mono(2, 2);
        s.cfa = Cfa {
            tile: vec![vec![0, 1], vec![1, 0]],
        };
        s.channel_names = vec!["a".into(), "b".into()];
        s.channel_qe = vec![
            Spectrum::sampled(vec![450.0, 550.0, 650.0], vec![0.0, 1.0, 0.0]).unwrap(),
            Spectrum::constant(0.5),
        ];
        let r = electron_rate(
            &s,
            &SensorIrradiance {
                irradiance: img,
                sample_pitch_m: 1e-6,
            },
        );
        let area = 4e-12 * 1e12;
        assert_relative_eq!(
            r.electrons_per_s[0] as f64,
            area * 100.0,
            max_relative = 1e-6
        );
        assert_relative_eq!(
            r.electrons_per_s[1] as f64,
            area * 150.0,
            max_relative = 1e-6
        );
        assert_relative_eq!(
            r.electrons_per_s[2] as f64,
            area * 150.0,
            max_relative = 1e-6
        );
        assert_relative_eq!(
            r.electrons_per_s[3] as f64,
            area * 100.0,
            max_relative = 1e-6
        );
    }

    #[test]
    fn pixel_straddling_two_cells_averages_by_area() {
        // 2 cells of 3 µm: left 0, right 1. A 2 µm pixel centred on the axis sees half/half;
        // a sensor of 2 pixels (centres ±1 µm) sees [−2,0] → all left, [0,2] → all right.
        let img = flat_image(1, 2, vec![0.0, 1e12]);
        let irr = SensorIrradiance {
            irradiance: img,
            sample_pitch_m: 3e-6,
        };
        let r1 = electron_rate(&mono(1, 1), &irr);
        assert_relative_eq!(
            r1.electrons_per_s[0] as f64,
            4e-12 * 300.0 * 0.5e12,
            max_relative = 1e-6
        );
        let r2 = electron_rate(&mono(1, 2), &irr);
        assert_eq!(r2.electrons_per_s[0], 0.0);
        assert_relative_eq!(
            r2.electrons_per_s[1] as f64,
            4e-12 * 300.0 * 1e12,
            max_relative = 1e-6
        );
        // A 4-pixel sensor extends beyond the 6 µm image: border cells continue.
        let r4 = electron_rate(&mono(1, 4), &irr);
        assert_eq!(r4.electrons_per_s[0], 0.0);
        assert_relative_eq!(
            r4.electrons_per_s[3] as f64,
            4e-12 * 300.0 * 1e12,
            max_relative = 1e-6
        );
        // pixel 1 spans [−2, 0] µm: all in the left cell; pixel 2 [0, 2] right.
        assert_eq!(r4.electrons_per_s[1], 0.0);
    }

    /// Term planes + weighted sum give `electron_rate` (same box weights, same exact spectral
    /// integrals, other order of summation): a 2-channel CFA, a non-integer pitch ratio, a
    /// varying band image and a QE-shift block.
    #[test]
    fn term_planes_give_the_electron_rate() {
        let g = WavelengthGrid::regular(400.0, 700.0, 20.0).unwrap();
        let (ir, ic) = (13usize, 17usize);
        let planes: Vec<Vec<f32>> = (0..g.len())
            .map(|k| {
                (0..ir * ic)
                    .map(|i| 1e12 * (1.0 + ((i * 7 + k * 3) % 11) as f32 * 0.1))
                    .collect()
            })
            .collect();
        let img = SpectralImage::new(ir, ic, SpectralBasis::Bands(g), planes).unwrap();
        let mut s = mono(5, 6);
        s.cfa = Cfa {
            tile: vec![vec![0, 1], vec![1, 0]],
        };
        s.channel_names = vec!["a".into(), "b".into()];
        s.channel_qe = vec![
            Spectrum::sampled(vec![450.0, 550.0, 650.0], vec![0.0, 1.0, 0.0]).unwrap(),
            Spectrum::constant(0.5),
        ];
        s.effects.qe_shift = Some(crate::effects::QeShift {
            shift_nm: vec![7.0, -3.0],
        });
        let irr = SensorIrradiance {
            irradiance: img,
            sample_pitch_m: 1.37e-6,
        };
        let want = electron_rate(&s, &irr).electrons_per_s;
        let got = electron_rate_from_term_planes(&s, &pixel_term_planes(&s, &irr));
        assert_eq!(want.len(), got.len());
        for (w, g) in want.iter().zip(&got) {
            assert_relative_eq!(*w as f64, *g as f64, max_relative = 1e-5);
        }
        assert!(want.iter().any(|&w| w != want[0]), "the image varies");
    }
}
