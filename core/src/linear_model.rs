//! Linear-model compression of spectral images (§2.A of the paper): each pixel's spectrum is
//! approximated by k basis functions found by SVD (the leading eigenvectors of the band
//! Gram matrix XᵀX), and the round-trip error is reported.
use crate::image::{SpectralBasis, SpectralImage};
use crate::spectrum::{Spectrum, WavelengthGrid};
use nalgebra::{DMatrix, SymmetricEigen};

/// A compressed image and how well it reproduces the original.
#[derive(Debug, Clone)]
pub struct CompressedImage {
    /// The image as k basis spectra (piecewise linear on the grid) × k coefficient planes.
    pub image: SpectralImage,
    /// Fraction of the total sum of squares captured by the k basis functions.
    pub variance_explained: f64,
    /// RMS of (reconstruction − original) divided by the RMS of the original.
    pub relative_rms_error: f64,
    /// Largest absolute difference over all pixels and bands.
    pub max_abs_error: f64,
}

/// Compress a band image on `grid` to `k` basis functions (k ≤ number of bands).
pub fn compress(bands: &SpectralImage, grid: &WavelengthGrid, k: usize) -> CompressedImage {
    let cube = bands.to_bands(grid);
    let nb = grid.len();
    let k = k.clamp(1, nb);
    let n = cube.rows * cube.cols;
    // Gram matrix G = XᵀX (bands × bands), X = pixels × bands.
    let mut gram = DMatrix::<f64>::zeros(nb, nb);
    for i in 0..nb {
        for j in i..nb {
            let s: f64 = cube.planes[i]
                .iter()
                .zip(&cube.planes[j])
                .map(|(a, b)| *a as f64 * *b as f64)
                .sum();
            gram[(i, j)] = s;
            gram[(j, i)] = s;
        }
    }
    let eig = SymmetricEigen::new(gram);
    let mut order: Vec<usize> = (0..nb).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].partial_cmp(&eig.eigenvalues[a]).unwrap());
    let total: f64 = eig.eigenvalues.iter().map(|v| v.max(0.0)).sum();
    let kept: f64 = order[..k]
        .iter()
        .map(|&i| eig.eigenvalues[i].max(0.0))
        .sum();
    let basis_vecs: Vec<Vec<f64>> = order[..k]
        .iter()
        .map(|&i| eig.eigenvectors.column(i).iter().copied().collect())
        .collect();
    // Coefficients: projection of each pixel spectrum on the orthonormal basis.
    let planes: Vec<Vec<f32>> = basis_vecs
        .iter()
        .map(|v| {
            (0..n)
                .map(|p| {
                    (0..nb)
                        .map(|b| v[b] * cube.planes[b][p] as f64)
                        .sum::<f64>() as f32
                })
                .collect()
        })
        .collect();
    let basis: Vec<Spectrum> = basis_vecs
        .iter()
        .map(|v| Spectrum::Sampled {
            wavelength_nm: grid.wavelength_nm.clone(),
            values: v.clone(),
        })
        .collect();
    let image = SpectralImage {
        rows: cube.rows,
        cols: cube.cols,
        basis: SpectralBasis::Spectra(basis),
        planes,
    };
    // Round-trip error on the grid.
    let recon = image.to_bands(grid);
    let (mut se, mut ss, mut maxe) = (0.0f64, 0.0f64, 0.0f64);
    for b in 0..nb {
        for p in 0..n {
            let o = cube.planes[b][p] as f64;
            let d = recon.planes[b][p] as f64 - o;
            se += d * d;
            ss += o * o;
            maxe = maxe.max(d.abs());
        }
    }
    CompressedImage {
        image,
        variance_explained: if total > 0.0 { kept / total } else { 1.0 },
        relative_rms_error: if ss > 0.0 { (se / ss).sqrt() } else { 0.0 },
        max_abs_error: maxe,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_two_image_is_recovered_exactly_with_two_terms() {
        let g = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
        let a = Spectrum::sampled(vec![400.0, 700.0], vec![1.0, 0.0]).unwrap();
        let b = Spectrum::sampled(vec![400.0, 550.0, 700.0], vec![0.0, 1.0, 0.2]).unwrap();
        let img = SpectralImage::new(
            8,
            8,
            SpectralBasis::Spectra(vec![a, b]),
            vec![
                (0..64).map(|i| (i % 7) as f32).collect(),
                (0..64).map(|i| (i % 5) as f32 + 1.0).collect(),
            ],
        )
        .unwrap();
        let c1 = compress(&img, &g, 1);
        let c2 = compress(&img, &g, 2);
        assert!(
            c1.relative_rms_error > 1e-2,
            "one term cannot hold a rank-2 image"
        );
        assert!(
            c2.relative_rms_error < 1e-5,
            "two terms are exact: {}",
            c2.relative_rms_error
        );
        assert!((c2.variance_explained - 1.0).abs() < 1e-9);
    }
}
