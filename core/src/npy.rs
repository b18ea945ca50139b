//! Minimal reader for NumPy `.npy` arrays (little-endian f4/f8, C order), used to read
//! reference data such as the ISETCam oracle cases.
use std::path::Path;

/// An array read from a `.npy` file, converted to f64.
#[derive(Debug, Clone)]
pub struct NpyArray {
    /// Shape, outermost first.
    pub shape: Vec<usize>,
    /// Values in C (row-major) order.
    pub data: Vec<f64>,
}

/// Read a little-endian float32/float64, C-ordered `.npy` file.
pub fn read_npy(path: &Path) -> Result<NpyArray, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(format!("{}: not a .npy file", path.display()));
    }
    let (hlen, hstart) = if bytes[6] == 1 {
        (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10)
    } else {
        (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        )
    };
    let header = String::from_utf8_lossy(&bytes[hstart..hstart + hlen]).to_string();
    let fortran = header.contains("'fortran_order': True");
    let descr = header
        .split("'descr':")
        .nth(1)
        .and_then(|s| s.split('\'').nth(1))
        .unwrap_or("");
    let shape_txt = header
        .split("'shape':")
        .nth(1)
        .and_then(|s| s.split('(').nth(1))
        .and_then(|s| s.split(')').next())
        .unwrap_or("");
    let shape: Vec<usize> = shape_txt
        .split(',')
        .filter_map(|t| t.trim().parse().ok())
        .collect();
    let body = &bytes[hstart + hlen..];
    let data: Vec<f64> = match descr {
        "<f8" => body
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect(),
        "<f4" => body
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect(),
        d => return Err(format!("{}: unsupported dtype {d}", path.display())),
    };
    let n: usize = shape.iter().product();
    if n != data.len() {
        return Err(format!(
            "{}: shape {:?} but {} values",
            path.display(),
            shape,
            data.len()
        ));
    }
    let data = if fortran {
        fortran_to_c(&shape, &data)
    } else {
        data
    };
    Ok(NpyArray { shape, data })
}

/// Reorder column-major (Fortran) data into row-major (C) order.
fn fortran_to_c(shape: &[usize], data: &[f64]) -> Vec<f64> {
    let nd = shape.len();
    let mut out = vec![0.0; data.len()];
    let mut idx = vec![0usize; nd];
    for v in out.iter_mut() {
        // idx is the C-order multi-index of this output element
        let mut f = 0usize;
        let mut stride = 1usize;
        for d in 0..nd {
            f += idx[d] * stride;
            stride *= shape[d];
        }
        *v = data[f];
        for d in (0..nd).rev() {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    out
}
