//! Convolution of one image plane with a square kernel, edges replicated, by the direct sum or
//! by the convolution theorem (FFT), whichever costs fewer operations for the plane and kernel
//! sizes (a deterministic choice: the same sizes always take the same path).
//!
//! The FFT path computes exactly the direct sum's value (up to floating-point rounding, in
//! f64): the plane is continued by edge replication r pixels on every side (r the kernel's
//! radius), and the linear convolution of that padded plane with the kernel is taken on a
//! periodic grid of at least `w + 2r` × `h + 2r` samples. The outputs used, padded indices
//! [2r, w + 2r) × [2r, h + 2r), never wrap: each reads padded samples t − j with
//! 0 ≤ t − j < w + 2r (Oppenheim & Schafer, "Discrete-Time Signal Processing", §8.7, linear
//! convolution by the DFT). Real-to-complex FFTs along rows (`realfft`), complex FFTs along
//! columns (`rustfft`); plans are cached per thread.
use crate::depth_path::Kernel;
use realfft::num_complex::Complex;
use realfft::RealFftPlanner;
use rustfft::FftPlanner;
use std::cell::RefCell;

thread_local! {
    static PLANNERS: RefCell<(RealFftPlanner<f64>, FftPlanner<f64>)> =
        RefCell::new((RealFftPlanner::new(), FftPlanner::new()));
}

use camsim_core::fft_size::next_smooth as smooth_size;

/// A kernel prepared for convolving `w × h` planes: the direct sum for small kernels, else
/// the kernel's spectrum on the FFT grid.
pub struct PlaneConvolver {
    w: usize,
    h: usize,
    kernel: Kernel,
    fft: Option<FftGrid>,
}

struct FftGrid {
    /// FFT grid (columns, rows).
    mx: usize,
    my: usize,
    /// Kernel spectrum, column-major over the `mx/2 + 1` half-spectrum columns.
    spectrum: Vec<Complex<f64>>,
}

impl PlaneConvolver {
    /// Prepare `k` for `w × h` planes. The FFT is used when its operation count, about
    /// 2 · 5 · M log₂ M for the forward and inverse transforms of M = mx · my samples, is below
    /// the direct sum's w · h · (2r + 1)².
    pub fn new(w: usize, h: usize, k: &Kernel) -> PlaneConvolver {
        Self::with_choice(w, h, k, None)
    }

    /// [`PlaneConvolver::new`] with the path forced (`Some(true)`: FFT whenever r > 0).
    fn with_choice(w: usize, h: usize, k: &Kernel, force_fft: Option<bool>) -> PlaneConvolver {
        let r = k.radius;
        let n = 2 * r + 1;
        let (mx, my) = (smooth_size(w + 2 * r), smooth_size(h + 2 * r));
        let m = (mx * my) as f64;
        let direct = (w * h) as f64 * (n * n) as f64;
        let use_fft = force_fft.unwrap_or(10.0 * m * m.log2() < direct);
        let fft = if r > 0 && use_fft {
            Some(FftGrid::kernel(k, mx, my))
        } else {
            None
        };
        PlaneConvolver {
            w,
            h,
            kernel: k.clone(),
            fft,
        }
    }

    /// The convolution of the `w × h` plane `img` with the kernel (edges replicated).
    pub fn apply(&self, img: &[f32]) -> Vec<f32> {
        let (w, h) = (self.w, self.h);
        let k = &self.kernel;
        if k.radius == 0 {
            return img.iter().map(|v| v * k.values[0]).collect();
        }
        let Some(g) = &self.fft else {
            return direct(img, w, h, k);
        };
        let r = k.radius;
        let (mx, my) = (g.mx, g.my);
        let hx = mx / 2 + 1;
        // padded plane (edge replication by r), zero beyond w + 2r / h + 2r
        let mut spec = vec![Complex::new(0.0, 0.0); hx * my];
        PLANNERS.with(|p| {
            let (rp, cp) = &mut *p.borrow_mut();
            let r2c = rp.plan_fft_forward(mx);
            let mut row = vec![0f64; mx];
            let mut out = vec![Complex::new(0.0, 0.0); hx];
            for y in 0..h + 2 * r {
                let sy = (y as isize - r as isize).clamp(0, h as isize - 1) as usize;
                let src = &img[sy * w..(sy + 1) * w];
                row.iter_mut().for_each(|v| *v = 0.0);
                for (x, v) in row.iter_mut().enumerate().take(w + 2 * r) {
                    let sx = (x as isize - r as isize).clamp(0, w as isize - 1) as usize;
                    *v = src[sx] as f64;
                }
                r2c.process(&mut row, &mut out).expect("row FFT sizes");
                for (c, v) in out.iter().enumerate() {
                    spec[c * my + y] = *v;
                }
            }
            let col = cp.plan_fft_forward(my);
            let icol = cp.plan_fft_inverse(my);
            for (c, column) in spec.chunks_mut(my).enumerate() {
                col.process(column);
                for (v, kv) in column.iter_mut().zip(&g.spectrum[c * my..(c + 1) * my]) {
                    *v *= kv;
                }
                icol.process(column);
            }
            let c2r = rp.plan_fft_inverse(mx);
            let scale = 1.0 / (mx * my) as f64;
            let mut res = vec![0f32; w * h];
            let mut row_in = vec![Complex::new(0.0, 0.0); hx];
            let mut row_out = vec![0f64; mx];
            for y in 0..h {
                let py = y + 2 * r;
                for (c, v) in row_in.iter_mut().enumerate() {
                    *v = spec[c * my + py];
                }
                // the spectrum of a real row: DC and (even mx) Nyquist bins are real
                row_in[0].im = 0.0;
                if mx % 2 == 0 {
                    row_in[hx - 1].im = 0.0;
                }
                c2r.process(&mut row_in, &mut row_out)
                    .expect("row inverse FFT sizes");
                for (x, o) in res[y * w..(y + 1) * w].iter_mut().enumerate() {
                    *o = (row_out[x + 2 * r] * scale) as f32;
                }
            }
            res
        })
    }
}

impl FftGrid {
    fn kernel(k: &Kernel, mx: usize, my: usize) -> FftGrid {
        let n = 2 * k.radius + 1;
        let hx = mx / 2 + 1;
        let mut spectrum = vec![Complex::new(0.0, 0.0); hx * my];
        PLANNERS.with(|p| {
            let (rp, cp) = &mut *p.borrow_mut();
            let r2c = rp.plan_fft_forward(mx);
            let mut row = vec![0f64; mx];
            let mut out = vec![Complex::new(0.0, 0.0); hx];
            for j in 0..n {
                row.iter_mut().for_each(|v| *v = 0.0);
                for i in 0..n {
                    row[i] = k.values[j * n + i] as f64;
                }
                r2c.process(&mut row, &mut out).expect("kernel FFT sizes");
                for (c, v) in out.iter().enumerate() {
                    spectrum[c * my + j] = *v;
                }
            }
            let col = cp.plan_fft_forward(my);
            for column in spectrum.chunks_mut(my) {
                col.process(column);
            }
        });
        FftGrid { mx, my, spectrum }
    }
}

/// The direct sum (edge replication) over an edge-replicated copy of the plane, row by row
/// (each kernel tap adds a scaled row slice: vectorisable). Every output sums its taps in
/// the same (dy, dx) order as a per-pixel loop, so the result is that loop's to the bit.
fn direct(img: &[f32], w: usize, h: usize, k: &Kernel) -> Vec<f32> {
    let r = k.radius;
    let n = 2 * r + 1;
    let pw = w + 2 * r;
    let mut padded = vec![0f32; pw * (h + 2 * r)];
    for y in 0..h + 2 * r {
        let sy = (y as isize - r as isize).clamp(0, h as isize - 1) as usize;
        let src = &img[sy * w..(sy + 1) * w];
        for (x, v) in padded[y * pw..(y + 1) * pw].iter_mut().enumerate() {
            *v = src[(x as isize - r as isize).clamp(0, w as isize - 1) as usize];
        }
    }
    let mut out = vec![0f32; w * h];
    for (y, acc) in out.chunks_mut(w).enumerate() {
        // tap (dy, dx) reads img[y − dy][x − dx] = padded[y + r − dy][x + r − dx]
        for j in 0..n {
            let prow = &padded[(y + 2 * r - j) * pw..(y + 2 * r - j + 1) * pw];
            for i in 0..n {
                let kv = k.values[j * n + i];
                let src = &prow[2 * r - i..2 * r - i + w];
                for (a, p) in acc.iter_mut().zip(src) {
                    *a += p * kv;
                }
            }
        }
    }
    out
}

/// The plane `img` (`w × h`) convolved with `k` where it is non-zero only inside
/// `bbox = (row0, row1, col0, col1)` (half-open): only the window of the box grown by the
/// kernel radius (clamped to the plane) is convolved, the rest of the output is exactly 0.
/// Equal to the whole-plane convolution: outside the grown box every tap reads a zero (or,
/// through edge replication, a border sample outside the box), and inside the window the
/// samples beyond it are zero, as are the window's own replicated edges where it is interior.
pub fn convolve_window(
    img: &[f32],
    w: usize,
    h: usize,
    bbox: (usize, usize, usize, usize),
    conv: &PlaneConvolver,
) -> Vec<f32> {
    let (r0, r1, c0, c1) = bbox;
    let (ww, wh) = (c1 - c0, r1 - r0);
    debug_assert_eq!((conv.w, conv.h), (ww, wh));
    let crop: Vec<f32> = (r0..r1)
        .flat_map(|r| img[r * w + c0..r * w + c1].iter().copied())
        .collect();
    let res = conv.apply(&crop);
    let mut out = vec![0f32; w * h];
    for (r, row) in (r0..r1).zip(res.chunks(ww)) {
        out[r * w + c0..r * w + c1].copy_from_slice(row);
    }
    out
}

/// The bounding box (row0, row1, col0, col1; half-open) of the non-zero samples of a `w × h`
/// plane grown by `margin` and clamped to the plane; `None` when all are zero.
pub fn grown_support(
    img: &[f32],
    w: usize,
    h: usize,
    margin: usize,
) -> Option<(usize, usize, usize, usize)> {
    let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
    for (r, row) in img.chunks(w).enumerate().take(h) {
        if let Some(a) = row.iter().position(|v| *v != 0.0) {
            let b = row.iter().rposition(|v| *v != 0.0).unwrap_or(a);
            r0 = r0.min(r);
            r1 = r;
            c0 = c0.min(a);
            c1 = c1.max(b);
        }
    }
    (r0 != usize::MAX).then(|| {
        (
            r0.saturating_sub(margin),
            (r1 + 1 + margin).min(h),
            c0.saturating_sub(margin),
            (c1 + 1 + margin).min(w),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The FFT path equals the direct sum (edge replication included) to f32 rounding, on
    /// random planes, asymmetric kernels and odd, even and prime sizes.
    #[test]
    fn fft_convolution_equals_the_direct_sum() {
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) as f64 / (1u64 << 31) as f64) as f32
        };
        for (w, h, r) in [(37, 23, 5), (64, 48, 9), (31, 61, 12), (17, 17, 8)] {
            let img: Vec<f32> = (0..w * h).map(|_| rnd()).collect();
            let n = 2 * r + 1;
            let mut values: Vec<f32> = (0..n * n).map(|_| rnd()).collect();
            let sum: f32 = values.iter().sum();
            values.iter_mut().for_each(|v| *v /= sum);
            let k = Kernel { radius: r, values };
            let c = PlaneConvolver::with_choice(w, h, &k, Some(true));
            assert!(c.fft.is_some());
            let a = c.apply(&img);
            let b = direct(&img, w, h, &k);
            let worst = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0f32, f32::max);
            assert!(worst < 2e-6, "{w}×{h}, r {r}: max |FFT − direct| {worst}");
            // a zero plane stays exactly zero far from nothing: FFT noise stays below the
            // 1e-6 coverage thresholds of the layer composite
            let mut one = vec![0f32; w * h];
            one[(h / 2) * w + w / 2] = 1.0;
            let a = c.apply(&one);
            let far = a
                .iter()
                .enumerate()
                .filter(|(q, _)| {
                    let (y, x) = ((q / w) as isize, (q % w) as isize);
                    (y - (h / 2) as isize).abs() > r as isize
                        || (x - (w / 2) as isize).abs() > r as isize
                })
                .map(|(_, v)| v.abs())
                .fold(0f32, f32::max);
            assert!(far < 1e-9, "{w}×{h}, r {r}: leakage {far}");
        }
    }

    /// The per-pixel loop the row-slice direct sum must equal to the bit.
    fn per_pixel(img: &[f32], w: usize, h: usize, k: &Kernel) -> Vec<f32> {
        let r = k.radius as isize;
        let n = 2 * k.radius + 1;
        let mut out = vec![0f32; w * h];
        for y in 0..h as isize {
            for x in 0..w as isize {
                let mut s = 0f32;
                for dy in -r..=r {
                    let yy = (y - dy).clamp(0, h as isize - 1) as usize;
                    for dx in -r..=r {
                        let xx = (x - dx).clamp(0, w as isize - 1) as usize;
                        s += img[yy * w + xx] * k.values[(dy + r) as usize * n + (dx + r) as usize];
                    }
                }
                out[y as usize * w + x as usize] = s;
            }
        }
        out
    }

    #[test]
    fn direct_sum_and_windows_equal_the_per_pixel_loop() {
        let mut s = 99u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) as f64 / (1u64 << 31) as f64) as f32
        };
        for (w, h, r) in [(13, 9, 3), (40, 33, 6), (8, 21, 7)] {
            let n = 2 * r + 1;
            let values: Vec<f32> = (0..n * n).map(|_| rnd()).collect();
            let k = Kernel { radius: r, values };
            let img: Vec<f32> = (0..w * h).map(|_| rnd()).collect();
            assert_eq!(direct(&img, w, h, &k), per_pixel(&img, w, h, &k));
            // a sparse plane: a block touching the left border
            let mut sparse = vec![0f32; w * h];
            for y in h / 3..h / 2 + 1 {
                for x in 0..w / 3 + 1 {
                    sparse[y * w + x] = rnd();
                }
            }
            let bb = grown_support(&sparse, w, h, r).unwrap();
            let conv = PlaneConvolver::with_choice(bb.3 - bb.2, bb.1 - bb.0, &k, Some(false));
            let a = convolve_window(&sparse, w, h, bb, &conv);
            assert_eq!(a, per_pixel(&sparse, w, h, &k), "{w}×{h} r {r}");
        }
        assert_eq!(grown_support(&[0.0; 12], 4, 3, 1), None);
    }

    #[test]
    fn small_kernels_take_the_direct_path() {
        let k = Kernel::pillbox(1.5);
        assert!(PlaneConvolver::new(256, 256, &k).fft.is_none());
        assert!(PlaneConvolver::new(256, 256, &Kernel::pillbox(20.0))
            .fft
            .is_some());
    }
}
