//! Far-tail correction of the FFT diffraction blur (issue 17 §5, blur margin).
//!
//! The FFT convolution ([`crate::fft::FftConvolver`]) blurs the periodic tiling of its padded
//! grid: the scene, then its edges replicated over the pad, then — at the wrap — the opposite
//! side of the scene. The diffraction PSF's tail falls only as `1/r³` (edge-spread tail
//! `T(x) = 2λN/(π³x)`, [`crate::airy_edge_tail_fraction`]), so the wrapped side reaches the
//! border pixels (3·10⁻³ of the light level at the border of a slanted edge with a 20 λN pad).
//!
//! The model wanted is the scene's edges replicated to infinity. Both it and the periodic
//! tiling agree on the padded grid `W`; they differ only beyond it, at least the pad's width
//! from every image sample. There the Airy PSF is its ring-averaged envelope
//! `λN/(π³r³)` ([`crate::airy_psf_tail_envelope`]), which is smooth on the scale of a few λN.
//! So the difference `D = replicated − periodic` is taken on a coarse grid of `c × c` sample
//! cells (cell averages of the padded grid; beyond `W` the replicated model is the clamp of
//! the border cells, the periodic one their wrap), over `W` extended until the edge-spread
//! tail beyond the extension is `tail_fraction` at the longest wavelength, convolved with the
//! envelope (cell-centre quadrature, linear convolution by a zero-padded complex FFT) and
//! added to the blurred image by bilinear interpolation from the cell centres.
//!
//! Bound (per band, `E_max` its largest scene value): what lies beyond the extension is
//! ignored, `≤ tail_fraction · E_max` per side of the image (two sides in a corner); the
//! envelope and the cell quadrature are good to about 2 % of the correction itself
//! (`(h/r)²/2` with `r ≥ 5 h`, ring oscillations averaging out over cells of ≥ 2 λN).
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// A planned far-tail correction for a padded grid of `pr × pc` samples whose image occupies
/// rows `top..top + rows`, columns `left..left + cols`.
pub(crate) struct FarTail {
    /// Cell side in samples (divides `pr` and `pc`).
    c: usize,
    /// Cells of the padded grid.
    nr: usize,
    nc: usize,
    /// Extension (cells) beyond the padded grid on each side, rows and columns.
    er: usize,
    ec: usize,
    /// Complex FFT sizes of the linear convolution.
    lr: usize,
    lc: usize,
    fft_r_fwd: Arc<dyn Fft<f32>>,
    fft_r_inv: Arc<dyn Fft<f32>>,
    fft_c_fwd: Arc<dyn Fft<f32>>,
    fft_c_inv: Arc<dyn Fft<f32>>,
    /// Spectrum of the envelope's cell weights at the reference `λN` (transposed layout
    /// `lc × lr`), pre-divided by `lr · lc`.
    kernel: Vec<Complex32>,
    /// Reference `λN` (m) of `kernel`.
    lambda_n_ref_m: f64,
}

/// Per-thread buffers of the correction.
pub(crate) struct FarTailWorkspace {
    cells: Vec<f32>,
    a: Vec<Complex32>,
    b: Vec<Complex32>,
    scratch: Vec<Complex32>,
    delta: Vec<f32>,
}

/// Cell side (samples) for spacing `dx_m` and the longest `λN`: the largest 2^a 3^b 5^c not
/// above `4 λN / dx` (cells of ~2–4 λN).
pub(crate) fn cell_samples(dx_m: f64, lambda_n_max_m: f64) -> usize {
    let target = ((4.0 * lambda_n_max_m / dx_m).floor() as usize).clamp(1, 64);
    (1..=target)
        .rev()
        .find(|&m| crate::fft::next_smooth(m) == m)
        .unwrap_or(1)
}

impl FarTail {
    /// Plan the correction of a padded `pr × pc` grid (multiples of `c`) at spacing `dx_m`,
    /// whose image starts `top`/`left` samples in, for the longest wavelength
    /// `wavelength_max_nm` at working f-number `f_number`, leaving the edge-spread tail
    /// `tail_fraction` beyond the extension.
    #[allow(clippy::too_many_arguments)]
    pub fn plan(
        pr: usize,
        pc: usize,
        top: usize,
        left: usize,
        c: usize,
        dx_m: f64,
        wavelength_max_nm: f64,
        f_number: f64,
        tail_fraction: f64,
    ) -> Self {
        debug_assert!(pr % c == 0 && pc % c == 0);
        let (nr, nc) = (pr / c, pc / c);
        let h = c as f64 * dx_m;
        let reach_m = crate::airy_edge_tail_distance_m(tail_fraction, wavelength_max_nm, f_number);
        let ext = |pad: usize| (((reach_m - pad as f64 * dx_m).max(0.0) / h).ceil() as usize) + 1;
        let (er, ec) = (ext(top), ext(left));
        let lr = crate::fft::next_smooth(2 * (nr + er));
        let lc = crate::fft::next_smooth(2 * (nc + ec));
        let mut planner = FftPlanner::<f32>::new();
        let mut plan = FarTail {
            c,
            nr,
            nc,
            er,
            ec,
            lr,
            lc,
            fft_r_fwd: planner.plan_fft_forward(lc),
            fft_r_inv: planner.plan_fft_inverse(lc),
            fft_c_fwd: planner.plan_fft_forward(lr),
            fft_c_inv: planner.plan_fft_inverse(lr),
            kernel: Vec::new(),
            lambda_n_ref_m: wavelength_max_nm * 1e-9 * f_number,
        };
        // Cell weights of the envelope at offset (i, j) cells (wrapped onto the FFT grid):
        // h² · λN/(π³ r³); the centre cell never meets a non-zero difference (the difference
        // lies beyond the pad), so it is left at 0.
        let signed = |k: usize, l: usize| -> f64 {
            if k <= l / 2 {
                k as f64
            } else {
                k as f64 - l as f64
            }
        };
        let mut ws = plan.workspace();
        for i in 0..lr {
            let y = signed(i, lr) * h;
            for j in 0..lc {
                let x = signed(j, lc) * h;
                let r = (x * x + y * y).sqrt();
                let w = if r < 0.5 * h {
                    0.0
                } else {
                    h * h * crate::airy_psf_tail_envelope(r, wavelength_max_nm, f_number)
                };
                ws.a[i * lc + j] = Complex32::new(w as f32, 0.0);
            }
        }
        plan.forward(&mut ws);
        let norm = 1.0 / (lr * lc) as f32;
        plan.kernel = ws.b.iter().map(|v| v * norm).collect();
        plan
    }

    /// Fresh buffers for one thread.
    pub fn workspace(&self) -> FarTailWorkspace {
        let n = self.lr * self.lc;
        let s = self
            .fft_r_fwd
            .get_inplace_scratch_len()
            .max(self.fft_r_inv.get_inplace_scratch_len())
            .max(self.fft_c_fwd.get_inplace_scratch_len())
            .max(self.fft_c_inv.get_inplace_scratch_len());
        FarTailWorkspace {
            cells: vec![0.0; self.nr * self.nc],
            a: vec![Complex32::default(); n],
            b: vec![Complex32::default(); n],
            scratch: vec![Complex32::default(); s],
            delta: vec![0.0; self.nr * self.nc],
        }
    }

    /// Forward 2-D transform of `ws.a` (`lr × lc`) into `ws.b` (transposed, `lc × lr`).
    fn forward(&self, ws: &mut FarTailWorkspace) {
        self.fft_r_fwd
            .process_with_scratch(&mut ws.a, &mut ws.scratch);
        crate::fft::transpose(&ws.a, self.lr, self.lc, &mut ws.b);
        self.fft_c_fwd
            .process_with_scratch(&mut ws.b, &mut ws.scratch);
    }

    /// Cell averages of the padded grid `padded` (`pr × pc`, as filled before the transform).
    pub fn take_cells(&self, padded: &[f32], ws: &mut FarTailWorkspace) {
        let (c, nc) = (self.c, self.nc);
        let pc = nc * c;
        ws.cells.fill(0.0);
        for (i, row) in padded.chunks_exact(pc).enumerate() {
            let crow = &mut ws.cells[(i / c) * nc..(i / c + 1) * nc];
            for (cell, chunk) in crow.iter_mut().zip(row.chunks_exact(c)) {
                *cell += chunk.iter().sum::<f32>();
            }
        }
        let inv = 1.0 / (c * c) as f32;
        for v in ws.cells.iter_mut() {
            *v *= inv;
        }
    }

    /// The correction on the padded grid's cells for a band of `λN = lambda_n_m` (from the
    /// cells of [`FarTail::take_cells`]) into `ws.delta`.
    pub fn correction(&self, lambda_n_m: f64, ws: &mut FarTailWorkspace) {
        let (nr, nc, er, ec, lr, lc) = (self.nr, self.nc, self.er, self.ec, self.lr, self.lc);
        ws.a.fill(Complex32::default());
        let cells = &ws.cells;
        for ri in 0..nr + 2 * er {
            let i = ri as isize - er as isize;
            let inside_r = i >= 0 && i < nr as isize;
            let ci = i.clamp(0, nr as isize - 1) as usize;
            let wi = i.rem_euclid(nr as isize) as usize;
            let arow = &mut ws.a[ri * lc..ri * lc + nc + 2 * ec];
            for (rj, v) in arow.iter_mut().enumerate() {
                let j = rj as isize - ec as isize;
                if inside_r && j >= 0 && j < nc as isize {
                    continue;
                }
                let cj = j.clamp(0, nc as isize - 1) as usize;
                let wj = j.rem_euclid(nc as isize) as usize;
                v.re = cells[ci * nc + cj] - cells[wi * nc + wj];
            }
        }
        self.forward(ws);
        let scale = (lambda_n_m / self.lambda_n_ref_m) as f32;
        for (v, k) in ws.b.iter_mut().zip(&self.kernel) {
            *v *= k * scale;
        }
        self.fft_c_inv
            .process_with_scratch(&mut ws.b, &mut ws.scratch);
        crate::fft::transpose(&ws.b, lc, lr, &mut ws.a);
        self.fft_r_inv
            .process_with_scratch(&mut ws.a, &mut ws.scratch);
        for (i, drow) in ws.delta.chunks_exact_mut(nc).enumerate() {
            let src = &ws.a[(i + er) * lc + ec..(i + er) * lc + ec + nc];
            for (d, s) in drow.iter_mut().zip(src) {
                *d = s.re;
            }
        }
    }

    /// The correction at padded-grid sample (`pi`, `pj`): bilinear between cell centres.
    #[inline]
    pub fn at(&self, ws: &FarTailWorkspace, pi: usize, pj: usize) -> f32 {
        let coord = |p: usize, n: usize| -> (usize, usize, f32) {
            let u = ((p as f64 + 0.5) / self.c as f64 - 0.5).clamp(0.0, (n - 1) as f64);
            let i0 = (u.floor() as usize).min(n - 1);
            let i1 = (i0 + 1).min(n - 1);
            (i0, i1, (u - i0 as f64) as f32)
        };
        let (r0, r1, fr) = coord(pi, self.nr);
        let (c0, c1, fc) = coord(pj, self.nc);
        let d = &ws.delta;
        let nc = self.nc;
        let top = d[r0 * nc + c0] * (1.0 - fc) + d[r0 * nc + c1] * fc;
        let bot = d[r1 * nc + c0] * (1.0 - fc) + d[r1 * nc + c1] * fc;
        top * (1.0 - fr) + bot * fr
    }
}
