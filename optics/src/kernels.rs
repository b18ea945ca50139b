//! Sampled point-spread functions: Gaussian (separable), pillbox disk, and the wavefront PSF
//! with Zernike defocus; plus direct separable convolution of planes.
use crate::error::{check_positive, OpticsError};
use crate::Padding;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

/// A centred PSF sampled on a square grid of pitch `pitch_m`: `(2·half_rows+1) ×
/// (2·half_cols+1)` samples, row-major, the centre sample on the optical axis of the PSF.
/// Constructors normalise it to sum 1 (so its OTF is 1 at zero frequency).
#[derive(Debug, Clone, PartialEq)]
pub struct SampledPsf {
    /// Samples above (and below) the centre.
    pub half_rows: usize,
    /// Samples left (and right) of the centre.
    pub half_cols: usize,
    /// Sample pitch (m).
    pub pitch_m: f64,
    /// Row-major samples.
    pub data: Vec<f64>,
}

impl SampledPsf {
    /// Number of rows `2·half_rows + 1`.
    pub fn rows(&self) -> usize {
        2 * self.half_rows + 1
    }
    /// Number of columns `2·half_cols + 1`.
    pub fn cols(&self) -> usize {
        2 * self.half_cols + 1
    }
    /// Sample at offset (dy, dx) from the centre (0 outside).
    pub fn at(&self, dy: isize, dx: isize) -> f64 {
        let (i, j) = (dy + self.half_rows as isize, dx + self.half_cols as isize);
        if i < 0 || j < 0 || i >= self.rows() as isize || j >= self.cols() as isize {
            0.0
        } else {
            self.data[i as usize * self.cols() + j as usize]
        }
    }
    /// Sum of the samples.
    pub fn sum(&self) -> f64 {
        self.data.iter().sum()
    }
    /// Divide by the sum (the sum must be > 0).
    pub(crate) fn normalise(&mut self) {
        let s = self.sum();
        self.data.iter_mut().for_each(|v| *v /= s);
    }
}

/// Normalised 1-D Gaussian kernel `exp(−x²/(2σ²))` sampled at `k · pitch` for
/// `|k| ≤ ceil(4σ/pitch)` (point samples keep the discrete variance ≈ σ² for σ ≳ pitch/2).
/// σ = 0 gives the identity `[1]`.
pub fn gaussian_kernel_1d(sigma_m: f64, pitch_m: f64) -> Vec<f64> {
    if sigma_m <= 0.0 {
        return vec![1.0];
    }
    let h = (4.0 * sigma_m / pitch_m).ceil() as usize;
    let mut k: Vec<f64> = (0..=2 * h)
        .map(|i| {
            let x = (i as f64 - h as f64) * pitch_m;
            (-x * x / (2.0 * sigma_m * sigma_m)).exp()
        })
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// Rows per parallel piece of [`separable_convolve`]'s passes.
const CONVOLVE_ROWS: usize = 16;

/// Convolve every plane (`rows × cols`) with the separable kernel `k ⊗ k` (odd length,
/// centred). Outside the image: edge replication or zeros, per `padding`. Parallel over
/// planes and, within a plane, over pieces of [`CONVOLVE_ROWS`] rows (a whole-sensor image
/// of one to four planes keeps every thread busy); each output sample is the same sum in the
/// same order whatever the split.
pub(crate) fn separable_convolve(
    planes: &mut [Vec<f32>],
    rows: usize,
    cols: usize,
    k: &[f64],
    padding: Padding,
) {
    if k.len() <= 1 {
        return;
    }
    let h = k.len() / 2;
    let kf: Vec<f32> = k.iter().map(|v| *v as f32).collect();
    if rows == 0 || cols == 0 {
        return;
    }
    let piece = CONVOLVE_ROWS * cols;
    planes.par_iter_mut().for_each(|p| {
        // Horizontal pass through an extended row buffer.
        let mut tmp = vec![0f32; rows * cols];
        p.par_chunks(piece)
            .zip(tmp.par_chunks_mut(piece))
            .for_each(|(src_rows, dst_rows)| {
                let mut ext = vec![0f32; cols + 2 * h];
                for (src, dst) in src_rows
                    .chunks_exact(cols)
                    .zip(dst_rows.chunks_exact_mut(cols))
                {
                    let (lo, hi) = match padding {
                        Padding::Replicate => (src[0], src[cols - 1]),
                        Padding::Zero => (0.0, 0.0),
                    };
                    ext[..h].fill(lo);
                    ext[h..h + cols].copy_from_slice(src);
                    ext[h + cols..].fill(hi);
                    for (j, d) in dst.iter_mut().enumerate() {
                        *d = ext[j..j + 2 * h + 1]
                            .iter()
                            .zip(&kf)
                            .map(|(a, b)| a * b)
                            .sum();
                    }
                }
            });
        // Vertical pass: accumulate whole rows (vectorises over columns).
        let tmp = &tmp;
        p.par_chunks_mut(piece).enumerate().for_each(|(c, out)| {
            out.fill(0.0);
            for (k, orow) in out.chunks_exact_mut(cols).enumerate() {
                let i = c * CONVOLVE_ROWS + k;
                for (t, &w) in kf.iter().enumerate() {
                    let si = i as isize + t as isize - h as isize;
                    let si = match padding {
                        Padding::Replicate => si.clamp(0, rows as isize - 1) as usize,
                        Padding::Zero => {
                            if si < 0 || si >= rows as isize {
                                continue;
                            }
                            si as usize
                        }
                    };
                    let srow = &tmp[si * cols..(si + 1) * cols];
                    orow.iter_mut().zip(srow).for_each(|(o, s)| *o += w * s);
                }
            }
        });
    });
}

/// A disc of radius `r_m` (centred on a sample) area-sampled at `pitch_m`: per sample cell,
/// the count of its 8×8 sub-samples inside the disc for which `keep(x_m)` holds (x the
/// sub-sample's signed offset along the columns; none lies on x = 0). Unnormalised; the
/// half-width is the fewest samples that hold the disc.
pub(crate) fn disc_subsample_counts(
    r_m: f64,
    pitch_m: f64,
    keep: impl Fn(f64) -> bool,
) -> SampledPsf {
    let h = (r_m / pitch_m - 0.5 - 1e-9).ceil().max(0.0) as usize;
    let n = 2 * h + 1;
    const S: usize = 8;
    let mut data = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let mut c = 0usize;
            for a in 0..S {
                for b in 0..S {
                    let y = (i as f64 - h as f64 - 0.5 + (a as f64 + 0.5) / S as f64) * pitch_m;
                    let x = (j as f64 - h as f64 - 0.5 + (b as f64 + 0.5) / S as f64) * pitch_m;
                    if x * x + y * y <= r_m * r_m && keep(x) {
                        c += 1;
                    }
                }
            }
            data[i * n + j] = c as f64;
        }
    }
    SampledPsf {
        half_rows: h,
        half_cols: h,
        pitch_m,
        data,
    }
}

/// A uniform disk ("pillbox") of diameter `width_m`, area-sampled (8×8 sub-samples per
/// sample cell) at `pitch_m` and normalised to sum 1. A disk narrower than a sample is the
/// identity.
pub fn pillbox_psf(width_m: f64, pitch_m: f64) -> SampledPsf {
    let mut p = disc_subsample_counts(width_m / 2.0, pitch_m, |_| true);
    let h = p.half_rows;
    let n = 2 * h + 1;
    if p.sum() == 0.0 {
        p.data[h * n + h] = 1.0;
    }
    p.normalise();
    p
}

/// Diffraction PSF of a circular pupil with Zernike defocus, sampled at `pitch_m`.
///
/// The pupil (normalised radius ρ ≤ 1, `pupil_samples` across the diameter) carries the phase
/// `2π W(ρ)/λ` with `W = c √3 (2ρ² − 1)` (Zernike Z(2,0), `c = defocus_um` = RMS wavefront
/// error). The PSF is `|F{P}|²`, evaluated exactly at the image-plane samples by a matrix
/// Fourier transform (image coordinate x ↔ pupil ξ via the kernel `exp(−iπ x ξ / (λN))`, so
/// zero defocus gives the Airy pattern with its first zero at 1.22 λN), truncated to a radius
/// of `10 λN + 2 · 8√3 N |c|` (≤ 0.45 λN · pupil_samples, inside the alias-free period of the
/// sampled pupil) and normalised to sum 1.
pub fn wavefront_psf(
    wavelength_nm: f64,
    f_number: f64,
    defocus_um: f64,
    pupil_samples: usize,
    pitch_m: f64,
) -> Result<SampledPsf, OpticsError> {
    check_positive("wavelength_nm", wavelength_nm, false)?;
    check_positive("f_number", f_number, false)?;
    check_positive("sample_pitch_m", pitch_m, false)?;
    if !defocus_um.is_finite() {
        return Err(OpticsError::InvalidParameter {
            name: "defocus_um",
            value: defocus_um,
            reason: "must be finite",
        });
    }
    if !(16..=4096).contains(&pupil_samples) {
        return Err(OpticsError::InvalidParameter {
            name: "pupil_samples",
            value: pupil_samples as f64,
            reason: "must be between 16 and 4096",
        });
    }
    let lambda_m = wavelength_nm * 1e-9;
    let ln = lambda_m * f_number;
    let blur_m = 2.0 * 8.0 * 3f64.sqrt() * f_number * defocus_um.abs() * 1e-6;
    let np = pupil_samples;
    let xi: Vec<f64> = (0..np)
        .map(|k| -1.0 + (k as f64 + 0.5) * 2.0 / np as f64)
        .collect();
    // Pupil function P(ξ, η) with the defocus phase.
    let lambda_um = wavelength_nm * 1e-3;
    let mut pupil = vec![Complex64::new(0.0, 0.0); np * np];
    for (a, &eta) in xi.iter().enumerate() {
        for (b, &x) in xi.iter().enumerate() {
            let rho2 = x * x + eta * eta;
            if rho2 <= 1.0 {
                let w_um = defocus_um * 3f64.sqrt() * (2.0 * rho2 - 1.0);
                pupil[a * np + b] = Complex64::from_polar(1.0, 2.0 * PI * w_um / lambda_um);
            }
        }
    }
    Ok(pupil_psf(&pupil, np, &xi, ln, 10.0 * ln + blur_m, pitch_m))
}

/// The normalised PSF `|F{P}|²` of a sampled pupil (`np × np`, coordinates `xi` across the
/// unit diameter, `ln` = λN in m) over a radius of `reach_m`, capped at `0.45 λN · np` (inside
/// the alias-free period of the sampled pupil) and at 2048 samples of `pitch_m`.
pub(crate) fn pupil_psf(
    pupil: &[Complex64],
    np: usize,
    xi: &[f64],
    ln: f64,
    reach_m: f64,
    pitch_m: f64,
) -> SampledPsf {
    let radius_m = reach_m.min(0.45 * ln * np as f64);
    let h = ((radius_m / pitch_m).ceil() as usize).min(2048);
    let data = pupil_mft_intensity(pupil, np, xi, ln, h, pitch_m);
    let mut p = SampledPsf {
        half_rows: h,
        half_cols: h,
        pitch_m,
        data,
    };
    p.normalise();
    p
}

/// `|F{P}|²` of the `np × np` pupil `pupil` (coordinates `xi` across the unit diameter) at the
/// `(2h+1)²` image samples `(i − h)·pitch_m`, by the matrix Fourier transform with the kernel
/// `exp(−iπ x ξ / (λN))` (`ln` = λN in m). Unnormalised; row-major.
pub(crate) fn pupil_mft_intensity(
    pupil: &[Complex64],
    np: usize,
    xi: &[f64],
    ln: f64,
    h: usize,
    pitch_m: f64,
) -> Vec<f64> {
    let n_out = 2 * h + 1;
    // DFT matrix E[x][k] = exp(−iπ x ξ_k / (λN)) for the output samples x = (i − h)·pitch.
    let e: Vec<Complex64> = (0..n_out)
        .flat_map(|i| {
            let x = (i as f64 - h as f64) * pitch_m;
            xi.iter()
                .map(move |&k| Complex64::from_polar(1.0, -PI * x * k / ln))
        })
        .collect();
    // T[a][x] = Σ_b P[a][b] E[x][b]; F[y][x] = Σ_a E[y][a] T[a][x].
    let t: Vec<Complex64> = (0..np)
        .into_par_iter()
        .flat_map_iter(|a| {
            let prow = &pupil[a * np..(a + 1) * np];
            let e = &e;
            (0..n_out).map(move |x| {
                prow.iter()
                    .zip(&e[x * np..(x + 1) * np])
                    .map(|(p, q)| p * q)
                    .sum::<Complex64>()
            })
        })
        .collect();
    (0..n_out)
        .into_par_iter()
        .flat_map_iter(|y| {
            let mut row = vec![Complex64::new(0.0, 0.0); n_out];
            for a in 0..np {
                let w = e[y * np + a];
                for (r, tv) in row.iter_mut().zip(&t[a * n_out..(a + 1) * n_out]) {
                    *r += w * tv;
                }
            }
            row.into_iter().map(|f| f.norm_sqr())
        })
        .collect()
}

#[cfg(test)]
mod separable_tests {
    use super::{separable_convolve, CONVOLVE_ROWS};
    use crate::Padding;

    /// The convolution one plane at a time, rows in order (the rule before the passes were
    /// split into row pieces).
    fn serial(p: &mut [f32], rows: usize, cols: usize, k: &[f64], padding: Padding) {
        let h = k.len() / 2;
        let kf: Vec<f32> = k.iter().map(|v| *v as f32).collect();
        let mut ext = vec![0f32; cols + 2 * h];
        let mut tmp = vec![0f32; rows * cols];
        for (src, dst) in p.chunks_exact(cols).zip(tmp.chunks_exact_mut(cols)) {
            let (lo, hi) = match padding {
                Padding::Replicate => (src[0], src[cols - 1]),
                Padding::Zero => (0.0, 0.0),
            };
            ext[..h].fill(lo);
            ext[h..h + cols].copy_from_slice(src);
            ext[h + cols..].fill(hi);
            for (j, d) in dst.iter_mut().enumerate() {
                *d = ext[j..j + 2 * h + 1]
                    .iter()
                    .zip(&kf)
                    .map(|(a, b)| a * b)
                    .sum();
            }
        }
        p.fill(0.0);
        for i in 0..rows {
            for (t, &w) in kf.iter().enumerate() {
                let si = i as isize + t as isize - h as isize;
                let si = match padding {
                    Padding::Replicate => si.clamp(0, rows as isize - 1) as usize,
                    Padding::Zero if si < 0 || si >= rows as isize => continue,
                    Padding::Zero => si as usize,
                };
                for c in 0..cols {
                    p[i * cols + c] += w * tmp[si * cols + c];
                }
            }
        }
    }

    /// Split into row pieces and run in parallel, every plane is bit for bit the serial
    /// convolution, for heights below, at and across the piece size, both paddings, and a
    /// kernel wider than the image.
    #[test]
    fn row_pieces_give_the_serial_convolution() {
        let k = [0.05, 0.1, 0.2, 0.3, 0.2, 0.1, 0.05];
        for (rows, cols) in [
            (1, 5),
            (3, 2),
            (CONVOLVE_ROWS, 7),
            (2 * CONVOLVE_ROWS + 5, 9),
        ] {
            for padding in [Padding::Replicate, Padding::Zero] {
                let plane = |s: u32| -> Vec<f32> {
                    (0..rows * cols)
                        .map(|i| ((i as u32 * 2_654_435_761 ^ s) % 1000) as f32 * 0.37)
                        .collect()
                };
                let mut planes = vec![plane(1), plane(7), plane(13)];
                let mut want = planes.clone();
                separable_convolve(&mut planes, rows, cols, &k, padding);
                for w in &mut want {
                    serial(w, rows, cols, &k, padding);
                }
                for (a, b) in planes.iter().zip(&want) {
                    assert!(
                        a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "{rows}x{cols} {padding:?}"
                    );
                }
            }
        }
    }
}
