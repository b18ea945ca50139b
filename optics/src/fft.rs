//! 2-D FFT convolution on a padded grid (paper Eqs. 4–6: Ẽ = H · F{E}, E = F⁻¹{Ẽ}).
//!
//! Layout: the padded real image is `pr × pc`; its row transforms (length `pc/2+1`) are
//! transposed so that every column of the spectrum is contiguous (`nfc × pr`), which lets the
//! column FFTs and the transfer-function product run over contiguous memory.
use crate::formulas::otf_of_u;
use crate::kernels::SampledPsf;
use crate::Padding;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// What to do with the real result after the inverse transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Finish {
    /// Keep the values (linear-model coefficients may be negative).
    Keep,
    /// Clamp at 0 (band planes: irradiance is non-negative; removes FFT ringing/round-off).
    NonNegative,
    /// Absolute value (ISETCam `abs(ifft2(...))`).
    Abs,
}

/// The transfer function multiplying the spectrum.
pub(crate) enum Transfer<'a> {
    /// Diffraction-limited OTF with `λ N` (m) (Eq. 3), evaluated on the frequency grid.
    Diffraction { lambda_n_m: f64 },
    /// A precomputed spectrum in the transposed layout (from [`FftConvolver::kernel_spectrum`]).
    Spectrum(&'a [Complex32]),
}

pub(crate) use camsim_core::fft_size::next_smooth;

/// MATLAB `round` (half away from zero) of `n / 8`.
pub(crate) fn isetcam_pad(n: usize) -> usize {
    (n as f64 / 8.0).round() as usize
}

/// Per-thread buffers of one convolution.
pub(crate) struct Workspace {
    real: Vec<f32>,
    a: Vec<Complex32>,
    b: Vec<Complex32>,
    row_scratch: Vec<Complex32>,
    col_scratch: Vec<Complex32>,
    /// Buffers of the far-tail correction (when planned).
    far: Option<crate::far_tail::FarTailWorkspace>,
}

/// A planned convolution of `rows × cols` planes on a padded `pr × pc` grid.
pub(crate) struct FftConvolver {
    rows: usize,
    cols: usize,
    pr: usize,
    pc: usize,
    nfc: usize,
    top: usize,
    left: usize,
    zero_pad: bool,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    /// Squared column frequencies fx² (cycles/m)², one per spectrum column (len nfc).
    fx2: Vec<f64>,
    /// Squared row frequencies fy², one per FFT row index (len pr).
    fy2: Vec<f64>,
    /// Sample-aperture compensation `(gx per spectrum column, gy per row)`, see
    /// [`FftConvolver::compensate_sample_aperture`].
    aperture_gain: Option<(Vec<f32>, Vec<f32>)>,
    /// Sample spacing (m).
    dx: f64,
    /// Far-tail correction of the diffraction transfer ([`crate::far_tail`]), if planned.
    far_tail: Option<crate::far_tail::FarTail>,
}

/// `sin(πx)/(πx)`.
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-12 {
        1.0
    } else {
        let px = std::f64::consts::PI * x;
        px.sin() / px
    }
}

/// Signed frequency (cycles/m) of FFT index `k` of an `n`-point transform at spacing `dx`.
/// ISETCam (`unitFrequencyList`) scales odd sizes by `1/((n−1) dx)` instead of `1/(n dx)`.
fn freq(k: usize, n: usize, dx: f64, isetcam: bool) -> f64 {
    let j = if k <= (n - 1) / 2 {
        k as f64
    } else {
        k as f64 - n as f64
    };
    // For even n, index n/2 is −n/2 (fftshift convention, as ISETCam's grid).
    let denom = if isetcam && n % 2 == 1 && n > 1 {
        (n - 1) as f64
    } else {
        n as f64
    };
    j / (denom * dx)
}

impl FftConvolver {
    /// Plan a convolution. `Padding::Replicate`: edge-replicate by at least `margin_r`/`margin_c`
    /// on every side and round the size up to 2^a3^b5^c. `Padding::Zero` (ISETCam): zeros,
    /// `round(n/8)` each side, FFT at exactly that size with ISETCam's frequency grid.
    pub fn new(
        rows: usize,
        cols: usize,
        dx: f64,
        padding: Padding,
        margin_r: usize,
        margin_c: usize,
    ) -> Self {
        let (pr, pc, top, left, zero_pad) = match padding {
            Padding::Zero => {
                let (tr, tc) = (isetcam_pad(rows), isetcam_pad(cols));
                (rows + 2 * tr, cols + 2 * tc, tr, tc, true)
            }
            Padding::Replicate => {
                let pr = next_smooth(rows + 2 * margin_r);
                let pc = next_smooth(cols + 2 * margin_c);
                (pr, pc, (pr - rows) / 2, (pc - cols) / 2, false)
            }
        };
        Self::build(rows, cols, dx, (pr, pc, top, left, zero_pad))
    }

    /// Plan a `Padding::Replicate` convolution for the diffraction transfer with the far-tail
    /// correction ([`crate::far_tail`]): the scene's edges replicated to infinity instead of
    /// the FFT's wrap, up to the edge-spread tail `tail_fraction` of the longest wavelength
    /// `wavelength_max_nm` at working f-number `f_number`. The padded size is rounded to whole
    /// cells of the correction.
    pub fn new_far_tail(
        rows: usize,
        cols: usize,
        dx: f64,
        margin: usize,
        wavelength_max_nm: f64,
        f_number: f64,
        tail_fraction: f64,
    ) -> Self {
        let lambda_n_m = wavelength_max_nm * 1e-9 * f_number;
        let c = crate::far_tail::cell_samples(dx, lambda_n_m);
        let size = |n: usize| c * next_smooth((n + 2 * margin).div_ceil(c));
        let (pr, pc) = (size(rows), size(cols));
        let (top, left) = ((pr - rows) / 2, (pc - cols) / 2);
        let mut conv = Self::build(rows, cols, dx, (pr, pc, top, left, false));
        conv.far_tail = Some(crate::far_tail::FarTail::plan(
            pr,
            pc,
            top,
            left,
            c,
            dx,
            wavelength_max_nm,
            f_number,
            tail_fraction,
        ));
        conv
    }

    /// Plan a convolution of planes already zero-padded the ISETCam way (the uncropped
    /// optical image, [`crate::form_image_uncropped`]): the FFT at exactly `rows × cols` with
    /// ISETCam's frequency grid and no further padding — the same transform as
    /// `new(.., Padding::Zero, ..)` on the unpadded planes.
    pub fn prepadded_zero(rows: usize, cols: usize, dx: f64) -> Self {
        Self::build(rows, cols, dx, (rows, cols, 0, 0, true))
    }

    /// Plan on the padded grid `(pr, pc, top, left, zero_pad)`.
    fn build(
        rows: usize,
        cols: usize,
        dx: f64,
        (pr, pc, top, left, zero_pad): (usize, usize, usize, usize, bool),
    ) -> Self {
        let nfc = pc / 2 + 1;
        let mut rp = RealFftPlanner::<f32>::new();
        let mut cp = FftPlanner::<f32>::new();
        let fx2 = (0..nfc)
            .map(|k| freq(k, pc, dx, zero_pad).powi(2))
            .collect();
        let fy2 = (0..pr).map(|k| freq(k, pr, dx, zero_pad).powi(2)).collect();
        FftConvolver {
            rows,
            cols,
            pr,
            pc,
            nfc,
            top,
            left,
            zero_pad,
            r2c: rp.plan_fft_forward(pc),
            c2r: rp.plan_fft_inverse(pc),
            col_fwd: cp.plan_fft_forward(pr),
            col_inv: cp.plan_fft_inverse(pr),
            fx2,
            fy2,
            aperture_gain: None,
            dx,
            far_tail: None,
        }
    }

    /// Make every transfer act on samples of aperture order `n` and give cell averages: the
    /// transfer is multiplied by `[sinc(d fx) sinc(d fy)]^(1 − n)` (divide by the samples'
    /// B-spline transfer `sincⁿ`, multiply by the output cell's `sinc`;
    /// [`camsim_core::sample_aperture`]). Exact for transfers that vanish beyond the grid's
    /// Nyquist frequency (the caller's duty). `n = 1` (cell averages in and out) is the identity.
    pub fn compensate_sample_aperture(&mut self, order: u32) {
        if order <= 1 {
            self.aperture_gain = None;
            return;
        }
        let e = 1 - order as i32;
        let g = |f2: &f64| sinc(self.dx * f2.sqrt()).powi(e) as f32;
        let gx = self.fx2.iter().map(g).collect();
        let gy = self.fy2.iter().map(g).collect();
        self.aperture_gain = Some((gx, gy));
    }

    /// Fresh buffers for one thread.
    pub fn workspace(&self) -> Workspace {
        let n = self.pr * self.nfc;
        Workspace {
            real: vec![0.0; self.pr * self.pc],
            a: vec![Complex32::default(); n],
            b: vec![Complex32::default(); n],
            row_scratch: vec![
                Complex32::default();
                self.r2c.get_scratch_len().max(self.c2r.get_scratch_len())
            ],
            col_scratch: vec![
                Complex32::default();
                self.col_fwd
                    .get_inplace_scratch_len()
                    .max(self.col_inv.get_inplace_scratch_len())
            ],
            far: self.far_tail.as_ref().map(|f| f.workspace()),
        }
    }

    /// Copy `plane` into the padded buffer (replicated edges or zeros).
    fn fill_padded(&self, plane: &[f32], real: &mut [f32]) {
        let (pc, top, left, rows, cols) = (self.pc, self.top, self.left, self.rows, self.cols);
        for (pi, prow) in real.chunks_exact_mut(pc).enumerate() {
            let inside = pi >= top && pi < top + rows;
            if self.zero_pad && !inside {
                prow.fill(0.0);
                continue;
            }
            let si = (pi as isize - top as isize).clamp(0, rows as isize - 1) as usize;
            let src = &plane[si * cols..(si + 1) * cols];
            let (lo, rest) = prow.split_at_mut(left);
            let (mid, hi) = rest.split_at_mut(cols);
            mid.copy_from_slice(src);
            if self.zero_pad {
                lo.fill(0.0);
                hi.fill(0.0);
            } else {
                lo.fill(src[0]);
                hi.fill(src[cols - 1]);
            }
        }
    }

    /// Forward 2-D transform of `ws.real` into `ws.b` (transposed layout).
    fn forward(&self, ws: &mut Workspace) {
        for (r_in, r_out) in ws
            .real
            .chunks_exact_mut(self.pc)
            .zip(ws.a.chunks_exact_mut(self.nfc))
        {
            self.r2c
                .process_with_scratch(r_in, r_out, &mut ws.row_scratch)
                .expect("row FFT sizes");
        }
        transpose(&ws.a, self.pr, self.nfc, &mut ws.b);
        self.col_fwd
            .process_with_scratch(&mut ws.b, &mut ws.col_scratch);
    }

    /// Inverse 2-D transform of `ws.b` into `ws.real` (unnormalised).
    fn inverse(&self, ws: &mut Workspace) {
        self.col_inv
            .process_with_scratch(&mut ws.b, &mut ws.col_scratch);
        transpose(&ws.b, self.nfc, self.pr, &mut ws.a);
        let even = self.pc % 2 == 0;
        for (r_in, r_out) in
            ws.a.chunks_exact_mut(self.nfc)
                .zip(ws.real.chunks_exact_mut(self.pc))
        {
            // Hermitian symmetry: DC (and Nyquist) bins of a real row are real.
            r_in[0].im = 0.0;
            if even {
                r_in[self.nfc - 1].im = 0.0;
            }
            self.c2r
                .process_with_scratch(r_in, r_out, &mut ws.row_scratch)
                .expect("row inverse FFT sizes");
        }
    }

    /// The spectrum (transposed layout) of a centred PSF, wrapped onto the padded grid so its
    /// centre sits at index (0, 0).
    pub fn kernel_spectrum(&self, psf: &SampledPsf, ws: &mut Workspace) -> Vec<Complex32> {
        ws.real.fill(0.0);
        let (hr, hc) = (psf.half_rows as isize, psf.half_cols as isize);
        let w = 2 * psf.half_cols + 1;
        for (i, row) in psf.data.chunks_exact(w).enumerate() {
            let y = (i as isize - hr).rem_euclid(self.pr as isize) as usize;
            for (j, &v) in row.iter().enumerate() {
                let x = (j as isize - hc).rem_euclid(self.pc as isize) as usize;
                ws.real[y * self.pc + x] += v as f32;
            }
        }
        self.forward(ws);
        ws.b.clone()
    }

    /// Convolve one plane: pad, transform, multiply by the transfer function, invert, crop.
    pub fn convolve(
        &self,
        plane: &[f32],
        transfer: &Transfer,
        finish: Finish,
        ws: &mut Workspace,
        out: &mut [f32],
    ) {
        self.fill_padded(plane, &mut ws.real);
        // The far-tail correction of the diffraction transfer, from the padded grid's cells.
        let far = match (&self.far_tail, transfer, ws.far.as_mut()) {
            (Some(f), Transfer::Diffraction { lambda_n_m }, Some(fw)) => {
                f.take_cells(&ws.real, fw);
                f.correction(*lambda_n_m, fw);
                Some(f)
            }
            _ => None,
        };
        self.forward(ws);
        match transfer {
            Transfer::Diffraction { lambda_n_m } => {
                // Eq. 3 on the grid: u = ρ λN, ρ² = fx² + fy².
                let ln2 = lambda_n_m * lambda_n_m;
                for (col, &fx2) in ws.b.chunks_exact_mut(self.pr).zip(&self.fx2) {
                    for (v, &fy2) in col.iter_mut().zip(&self.fy2) {
                        let u2 = (fx2 + fy2) * ln2;
                        if u2 >= 1.0 {
                            *v = Complex32::default();
                        } else {
                            *v *= otf_of_u(u2.sqrt()) as f32;
                        }
                    }
                }
            }
            Transfer::Spectrum(h) => {
                for (v, hv) in ws.b.iter_mut().zip(h.iter()) {
                    *v *= *hv;
                }
            }
        }
        if let Some((gx, gy)) = &self.aperture_gain {
            for (col, &a) in ws.b.chunks_exact_mut(self.pr).zip(gx) {
                for (v, &b) in col.iter_mut().zip(gy) {
                    *v *= a * b;
                }
            }
        }
        self.inverse(ws);
        let norm = 1.0 / (self.pr * self.pc) as f32;
        for (i, orow) in out.chunks_exact_mut(self.cols).enumerate() {
            let start = (self.top + i) * self.pc + self.left;
            let src = &ws.real[start..start + self.cols];
            for (j, (o, &s)) in orow.iter_mut().zip(src).enumerate() {
                let mut v = s * norm;
                if let (Some(f), Some(fw)) = (far, ws.far.as_ref()) {
                    v += f.at(fw, self.top + i, self.left + j);
                }
                *o = match finish {
                    Finish::Keep => v,
                    Finish::NonNegative => v.max(0.0),
                    Finish::Abs => v.abs(),
                };
            }
        }
    }
}

/// Blocked transpose of a `rows × cols` row-major matrix into `cols × rows`.
pub(crate) fn transpose(src: &[Complex32], rows: usize, cols: usize, dst: &mut [Complex32]) {
    const B: usize = 32;
    for rb in (0..rows).step_by(B) {
        let re = (rb + B).min(rows);
        for cb in (0..cols).step_by(B) {
            let ce = (cb + B).min(cols);
            for r in rb..re {
                let srow = &src[r * cols..];
                for c in cb..ce {
                    dst[c * rows + r] = srow[c];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_sizes() {
        assert_eq!(next_smooth(1), 1);
        assert_eq!(next_smooth(7), 8);
        assert_eq!(next_smooth(1088), 1125);
        assert_eq!(next_smooth(1025), 1080);
        assert_eq!(isetcam_pad(64), 8);
        assert_eq!(isetcam_pad(96), 12);
        assert_eq!(isetcam_pad(20), 3); // 2.5 rounds away from zero
    }

    #[test]
    fn frequency_grid_matches_isetcam_unit_frequency_list() {
        // even n: standard grid, index n/2 = -n/2
        assert_eq!(freq(0, 8, 1.0, true), 0.0);
        assert_eq!(freq(3, 8, 1.0, true), 3.0 / 8.0);
        assert_eq!(freq(4, 8, 1.0, true), -4.0 / 8.0);
        assert_eq!(freq(7, 8, 1.0, false), -1.0 / 8.0);
        // odd n: ISETCam scale (n-1), baseline n
        assert_eq!(freq(2, 5, 1.0, true), 2.0 / 4.0);
        assert_eq!(freq(3, 5, 1.0, true), -2.0 / 4.0);
        assert_eq!(freq(2, 5, 1.0, false), 2.0 / 5.0);
    }

    #[test]
    fn delta_kernel_is_identity_and_shift_kernel_shifts() {
        let (rows, cols) = (9, 13);
        let plane: Vec<f32> = (0..rows * cols).map(|i| (i * 7 % 11) as f32).collect();
        let c = FftConvolver::new(rows, cols, 1.0, Padding::Replicate, 2, 2);
        let mut ws = c.workspace();
        let delta = SampledPsf {
            half_rows: 1,
            half_cols: 1,
            pitch_m: 1.0,
            data: {
                let mut d = vec![0.0; 9];
                d[4] = 1.0;
                d
            },
        };
        let h = c.kernel_spectrum(&delta, &mut ws);
        let mut out = vec![0.0; rows * cols];
        c.convolve(
            &plane,
            &Transfer::Spectrum(&h),
            Finish::Keep,
            &mut ws,
            &mut out,
        );
        for (a, b) in out.iter().zip(&plane) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
        // kernel with its mass one sample to the right of centre: out(x) = in(x - 1)
        let shift = SampledPsf {
            half_rows: 1,
            half_cols: 1,
            pitch_m: 1.0,
            data: {
                let mut d = vec![0.0; 9];
                d[5] = 1.0;
                d
            },
        };
        let h = c.kernel_spectrum(&shift, &mut ws);
        c.convolve(
            &plane,
            &Transfer::Spectrum(&h),
            Finish::Keep,
            &mut ws,
            &mut out,
        );
        for i in 0..rows {
            for j in 1..cols {
                assert!((out[i * cols + j] - plane[i * cols + j - 1]).abs() < 1e-4);
            }
            // replicate padding: left neighbour of column 0 is column 0 itself
            assert!((out[i * cols] - plane[i * cols]).abs() < 1e-4);
        }
    }
}
