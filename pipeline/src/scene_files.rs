//! File formats of scenes from the world: hyperspectral cubes (ENVI `.hdr` + raw data, NumPy
//! `.npy`) and RGB pictures (8/16-bit PNG or TIFF) for [`camsim_core::scene_import`].
//!
//! Every reader is safe on hostile input: sizes come from the header, are checked against the
//! file's length (a header that claims more or fewer bytes than the file holds is refused)
//! and against the memory budget ([`crate::budget`]) **before** anything is allocated; every
//! error is one line naming the file, the key and the value.
//!
//! ## ENVI
//!
//! A text header (`NAME.hdr`, first line `ENVI`, then `key = value` lines; `{…}` values may
//! span lines; keys are case-insensitive) next to a headerless binary file. Keys read:
//!
//! | key | meaning |
//! |---|---|
//! | `samples`, `lines`, `bands` | columns, rows, bands (required, ≥ 1) |
//! | `interleave` | `bsq` (band after band), `bil` (per row, band after band), `bip` (per pixel, all bands) — required |
//! | `data type` | 1 u8, 2 i16, 3 i32, 4 f32, 5 f64, 12 u16, 13 u32 (required) |
//! | `byte order` | 0 little-endian (default), 1 big-endian |
//! | `header offset` | bytes to skip at the start of the data file (default 0) |
//! | `wavelength` | `{λ1, λ2, …}`, one per band, strictly increasing (required) |
//! | `wavelength units` | `nanometers`/`nm` or `micrometers`/`microns`/`um`/`µm`; when absent the values must look like nm (all ≥ 100) |
//!
//! The data file is the header's name without `.hdr`, or with `.raw`, `.img`, `.dat`, `.bsq`,
//! `.bil`, `.bip` in its place (first that exists), unless the target names it (`data_file`).
//! Its length must be exactly `header offset + samples · lines · bands · bytes per value`.
//!
//! ## NumPy `.npy`
//!
//! Format versions 1–3, a 3-D array `rows × cols × bands` of `<f4`, `>f4`, `<f8` or `>f8`,
//! C or Fortran order. The file holds no wavelengths: they come from the target
//! (`wavelength_nm`, a list, or `wavelength_file`, a JSON list or whitespace/comma-separated
//! numbers).
use crate::budget;
use camsim_core::scene_import::RgbCodes;
use std::path::{Path, PathBuf};

/// A hyperspectral cube as read: `planes[band][row · cols + col]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralCube {
    /// Rows (ENVI `lines`).
    pub rows: usize,
    /// Columns (ENVI `samples`).
    pub cols: usize,
    /// One wavelength per band (nm), strictly increasing.
    pub wavelength_nm: Vec<f64>,
    /// One row-major plane per band.
    pub planes: Vec<Vec<f32>>,
}

/// Storage types of ENVI and npy values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Sample {
    U8,
    I16,
    I32,
    F32,
    F64,
    U16,
    U32,
}

impl Sample {
    fn bytes(self) -> usize {
        match self {
            Sample::U8 => 1,
            Sample::I16 | Sample::U16 => 2,
            Sample::I32 | Sample::U32 | Sample::F32 => 4,
            Sample::F64 => 8,
        }
    }
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().expect("length checked");
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Sample::U8 => b[0] as f64,
            Sample::I16 => num!(i16, 2),
            Sample::U16 => num!(u16, 2),
            Sample::I32 => num!(i32, 4),
            Sample::U32 => num!(u32, 4),
            Sample::F32 => num!(f32, 4),
            Sample::F64 => num!(f64, 8),
        }
    }
}

/// How values are ordered in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Layout {
    /// band, row, col (ENVI bsq; npy Fortran order is handled separately)
    Bsq,
    /// row, band, col
    Bil,
    /// row, col, band (ENVI bip; npy C order)
    Bip,
    /// npy Fortran order of a rows × cols × bands array: row fastest, then col, then band
    Fortran,
}

fn err(path: &Path, msg: impl std::fmt::Display) -> String {
    format!("{}: {msg}", path.display())
}

/// Check the memory a cube of `n_values` f32 values plus `file_bytes` of file needs.
fn check_cube_budget(path: &Path, key: &str, n_values: f64, file_bytes: f64) -> Result<(), String> {
    budget::check_memory(
        Some(path),
        key,
        budget::f32_bytes(n_values, 2.0) + file_bytes,
        &format!("{n_values:.3e} values as f32 (the cube and one working copy) + the file"),
    )
    .map_err(|e| e.one_line())
}

/// Decode `n = rows·cols·bands` values of `data` laid out as `layout` into band planes,
/// refusing non-finite and negative values (one error naming the first).
#[allow(clippy::too_many_arguments)]
fn decode_planes(
    path: &Path,
    data: &[u8],
    ty: Sample,
    big: bool,
    layout: Layout,
    rows: usize,
    cols: usize,
    bands: usize,
) -> Result<Vec<Vec<f32>>, String> {
    let bpv = ty.bytes();
    let mut planes = vec![vec![0f32; rows * cols]; bands];
    for (b, plane) in planes.iter_mut().enumerate() {
        for r in 0..rows {
            for c in 0..cols {
                let idx = match layout {
                    Layout::Bsq => (b * rows + r) * cols + c,
                    Layout::Bil => (r * bands + b) * cols + c,
                    Layout::Bip => (r * cols + c) * bands + b,
                    Layout::Fortran => (b * cols + c) * rows + r,
                };
                let v = ty.decode(&data[idx * bpv..(idx + 1) * bpv], big);
                if !v.is_finite() || v < 0.0 {
                    return Err(err(
                        path,
                        format!(
                            "value {v} at row {r}, column {c}, band {b}: radiance must be a \
                             finite number ≥ 0"
                        ),
                    ));
                }
                plane[r * cols + c] = v as f32;
            }
        }
    }
    Ok(planes)
}

/// Read a file of exactly `expected` bytes (checked against its length first).
fn read_exact_len(path: &Path, expected: u128, what: &str) -> Result<Vec<u8>, String> {
    crate::staging::protect_input(path);
    let len = std::fs::metadata(path)
        .map_err(|e| err(path, format!("cannot read: {e}")))?
        .len() as u128;
    if len != expected {
        return Err(err(
            path,
            format!(
                "the file has {len} bytes but {what} needs exactly {expected}; the header and the \
                 data do not match (truncated file, or wrong samples/lines/bands/data type)"
            ),
        ));
    }
    std::fs::read(path).map_err(|e| err(path, format!("cannot read: {e}")))
}

/// The `key = value` pairs of an ENVI header (keys lower-cased, braces joined).
fn envi_pairs(path: &Path, text: &str) -> Result<Vec<(String, String)>, String> {
    let mut lines = text.lines();
    match lines.next() {
        Some(l) if l.trim_start_matches('\u{feff}').trim().starts_with("ENVI") => {}
        _ => {
            return Err(err(
                path,
                "not an ENVI header (the first line must be `ENVI`)",
            ))
        }
    }
    let mut out = Vec::new();
    let mut pending: Option<(String, String)> = None;
    for line in lines {
        if let Some((k, mut v)) = pending.take() {
            v.push(' ');
            v.push_str(line.trim());
            if v.contains('}') {
                out.push((k, v));
            } else {
                if v.len() > 10_000_000 {
                    return Err(err(path, format!("{k}: unterminated `{{` value")));
                }
                pending = Some((k, v));
            }
            continue;
        }
        let t = line.trim();
        if t.is_empty() || t.starts_with(';') {
            continue;
        }
        let Some((k, v)) = t.split_once('=') else {
            continue;
        };
        let (k, v) = (k.trim().to_ascii_lowercase(), v.trim().to_string());
        if v.starts_with('{') && !v.contains('}') {
            pending = Some((k, v));
        } else {
            out.push((k, v));
        }
    }
    if let Some((k, _)) = pending {
        return Err(err(
            path,
            format!("{k}: `{{` value without its closing `}}`"),
        ));
    }
    Ok(out)
}

fn envi_get<'a>(pairs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    pairs
        .iter()
        .rev()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

fn envi_count(path: &Path, pairs: &[(String, String)], key: &str) -> Result<usize, String> {
    let v = envi_get(pairs, key).ok_or_else(|| err(path, format!("`{key}`: required")))?;
    match v.parse::<u64>() {
        Ok(n) if n >= 1 && n <= u32::MAX as u64 => Ok(n as usize),
        _ => Err(err(
            path,
            format!(
                "`{key}` = {v}: expected a whole number from 1 to {}",
                u32::MAX
            ),
        )),
    }
}

/// Parse a list of wavelengths (`{a, b, …}` or bare) in `unit_scale` nm per unit.
fn number_list(path: &Path, key: &str, v: &str) -> Result<Vec<f64>, String> {
    v.trim()
        .trim_start_matches('{')
        .trim_end_matches('}')
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|t| !t.is_empty())
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(path, format!("`{key}`: `{t}` is not a number")))
        })
        .collect()
}

/// Check wavelengths: one per band, positive, strictly increasing.
fn check_wavelengths(path: &Path, key: &str, w: &[f64], bands: usize) -> Result<(), String> {
    if w.len() != bands {
        return Err(err(
            path,
            format!("`{key}` lists {} wavelengths for {bands} bands", w.len()),
        ));
    }
    if let Some(i) = w.iter().position(|x| !(*x > 0.0 && x.is_finite())) {
        return Err(err(path, format!("`{key}`[{i}] = {}: must be > 0", w[i])));
    }
    if let Some(i) = w.windows(2).position(|p| p[1] <= p[0]) {
        return Err(err(
            path,
            format!(
                "`{key}`: wavelengths must increase, but {} follows {}",
                w[i + 1],
                w[i]
            ),
        ));
    }
    Ok(())
}

/// The data file of an ENVI header: `data_file` when given, else the first of NAME, NAME.raw,
/// NAME.img, NAME.dat, NAME.bsq, NAME.bil, NAME.bip that exists.
fn envi_data_file(hdr: &Path, data_file: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(d) = data_file {
        return Ok(d.to_path_buf());
    }
    let stem = hdr.with_extension("");
    let mut tried = Vec::new();
    for ext in ["", "raw", "img", "dat", "bsq", "bil", "bip"] {
        let p = if ext.is_empty() {
            stem.clone()
        } else {
            stem.with_extension(ext)
        };
        if p.is_file() && p != hdr {
            return Ok(p);
        }
        tried.push(p.display().to_string());
    }
    Err(err(
        hdr,
        format!(
            "no data file beside the header (tried {}); name it with `data_file`",
            tried.join(", ")
        ),
    ))
}

/// Read an ENVI cube (see the module documentation). `data_file` overrides the data file's
/// name; the memory budget is checked before the data are read.
pub fn read_envi(hdr: &Path, data_file: Option<&Path>) -> Result<SpectralCube, String> {
    crate::staging::protect_input(hdr);
    let meta = std::fs::metadata(hdr).map_err(|e| err(hdr, format!("cannot read: {e}")))?;
    if meta.len() > 64 << 20 {
        return Err(err(
            hdr,
            format!("{} bytes is too large for an ENVI header", meta.len()),
        ));
    }
    let text = std::fs::read_to_string(hdr).map_err(|e| err(hdr, format!("cannot read: {e}")))?;
    let pairs = envi_pairs(hdr, &text)?;
    let cols = envi_count(hdr, &pairs, "samples")?;
    let rows = envi_count(hdr, &pairs, "lines")?;
    let bands = envi_count(hdr, &pairs, "bands")?;
    let layout = match envi_get(&pairs, "interleave").map(|s| s.to_ascii_lowercase()) {
        Some(s) if s == "bsq" => Layout::Bsq,
        Some(s) if s == "bil" => Layout::Bil,
        Some(s) if s == "bip" => Layout::Bip,
        Some(s) => {
            return Err(err(
                hdr,
                format!("`interleave` = {s}: expected bsq, bil or bip"),
            ))
        }
        None => return Err(err(hdr, "`interleave`: required (bsq, bil or bip)")),
    };
    let ty = match envi_get(&pairs, "data type") {
        Some("1") => Sample::U8,
        Some("2") => Sample::I16,
        Some("3") => Sample::I32,
        Some("4") => Sample::F32,
        Some("5") => Sample::F64,
        Some("12") => Sample::U16,
        Some("13") => Sample::U32,
        Some(v) => {
            return Err(err(
                hdr,
                format!(
                    "`data type` = {v}: expected 1 (u8), 2 (i16), 3 (i32), 4 (f32), 5 (f64), \
                     12 (u16) or 13 (u32)"
                ),
            ))
        }
        None => return Err(err(hdr, "`data type`: required")),
    };
    let big = match envi_get(&pairs, "byte order") {
        None | Some("0") => false,
        Some("1") => true,
        Some(v) => return Err(err(hdr, format!("`byte order` = {v}: expected 0 or 1"))),
    };
    let offset: u64 = match envi_get(&pairs, "header offset") {
        None => 0,
        Some(v) => v.parse().map_err(|_| {
            err(
                hdr,
                format!("`header offset` = {v}: expected a byte count ≥ 0"),
            )
        })?,
    };
    let wl_text =
        envi_get(&pairs, "wavelength").ok_or_else(|| err(hdr, "`wavelength`: required"))?;
    let mut wl = number_list(hdr, "wavelength", wl_text)?;
    let scale = match envi_get(&pairs, "wavelength units").map(|s| s.to_ascii_lowercase()) {
        Some(u) if ["nanometers", "nanometer", "nm"].contains(&u.as_str()) => 1.0,
        Some(u)
            if ["micrometers", "micrometer", "microns", "micron", "um", "µm"]
                .contains(&u.as_str()) =>
        {
            1000.0
        }
        Some(u) => {
            return Err(err(
                hdr,
                format!("`wavelength units` = {u}: expected nanometers or micrometers"),
            ))
        }
        None if wl.iter().all(|w| *w >= 100.0) => 1.0,
        None => {
            return Err(err(
                hdr,
                "`wavelength units`: missing, and the wavelengths are not all ≥ 100 (nm); \
                 state `wavelength units = micrometers` or nanometers",
            ))
        }
    };
    wl.iter_mut().for_each(|w| *w *= scale);
    check_wavelengths(hdr, "wavelength", &wl, bands)?;
    let n = rows as u128 * cols as u128 * bands as u128;
    let bytes = offset as u128 + n * ty.bytes() as u128;
    check_cube_budget(hdr, "samples × lines × bands", n as f64, bytes as f64)?;
    let data_path = envi_data_file(hdr, data_file)?;
    let data = read_exact_len(
        &data_path,
        bytes,
        &format!(
            "the header ({cols} samples × {rows} lines × {bands} bands × {} bytes + {offset} \
             header bytes)",
            ty.bytes()
        ),
    )?;
    let planes = decode_planes(
        &data_path,
        &data[offset as usize..],
        ty,
        big,
        layout,
        rows,
        cols,
        bands,
    )?;
    Ok(SpectralCube {
        rows,
        cols,
        wavelength_nm: wl,
        planes,
    })
}

/// The value of `'key':` in an npy header dict, up to the next top-level comma.
fn npy_field<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let k = format!("'{key}'");
    let at = header.find(&k)? + k.len();
    let rest = header[at..].trim_start().strip_prefix(':')?.trim_start();
    if rest.starts_with('(') {
        let end = rest.find(')')?;
        Some(&rest[..=end])
    } else {
        let end = rest.find([',', '}']).unwrap_or(rest.len());
        Some(rest[..end].trim())
    }
}

/// Read a 3-D `.npy` cube (rows × cols × bands, float32/float64) with the given wavelengths
/// (one per band, nm).
pub fn read_npy_cube(path: &Path, wavelength_nm: &[f64]) -> Result<SpectralCube, String> {
    crate::staging::protect_input(path);
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| err(path, format!("cannot read: {e}")))?;
    let len = f
        .metadata()
        .map_err(|e| err(path, format!("cannot read: {e}")))?
        .len() as u128;
    let mut pre = [0u8; 12];
    let got = f
        .read(&mut pre)
        .map_err(|e| err(path, format!("cannot read: {e}")))?;
    if got < 10 || &pre[..6] != b"\x93NUMPY" {
        return Err(err(path, "not a NumPy .npy file (no \\x93NUMPY magic)"));
    }
    let (hlen, hstart) = match pre[6] {
        1 => (u16::from_le_bytes([pre[8], pre[9]]) as u128, 10u128),
        2 | 3 if got >= 12 => (
            u32::from_le_bytes([pre[8], pre[9], pre[10], pre[11]]) as u128,
            12,
        ),
        v => {
            return Err(err(
                path,
                format!("npy format version {v} (expected 1, 2 or 3)"),
            ))
        }
    };
    if hstart + hlen > len || hlen > 1 << 20 {
        return Err(err(
            path,
            format!("the npy header claims {hlen} bytes but the file has {len} bytes in all"),
        ));
    }
    let mut head = vec![0u8; (hstart + hlen) as usize];
    drop(f);
    {
        let mut f =
            std::fs::File::open(path).map_err(|e| err(path, format!("cannot read: {e}")))?;
        f.read_exact(&mut head)
            .map_err(|e| err(path, format!("cannot read the header: {e}")))?;
    }
    let header = String::from_utf8_lossy(&head[hstart as usize..]).to_string();
    let descr = npy_field(&header, "descr")
        .ok_or_else(|| err(path, "npy header: no 'descr'"))?
        .trim_matches(|c| c == '\'' || c == '"');
    let (ty, big) = match descr {
        "<f4" => (Sample::F32, false),
        ">f4" => (Sample::F32, true),
        "<f8" => (Sample::F64, false),
        ">f8" => (Sample::F64, true),
        d => {
            return Err(err(
                path,
                format!("npy 'descr' = {d}: expected float32 or float64 (<f4, >f4, <f8, >f8)"),
            ))
        }
    };
    let fortran = match npy_field(&header, "fortran_order") {
        Some("False") => false,
        Some("True") => true,
        v => {
            return Err(err(
                path,
                format!("npy 'fortran_order' = {v:?}: expected True or False"),
            ))
        }
    };
    let shape_txt =
        npy_field(&header, "shape").ok_or_else(|| err(path, "npy header: no 'shape'"))?;
    let dims: Vec<u64> = shape_txt
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<u64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            err(
                path,
                format!("npy 'shape' = {shape_txt}: not whole numbers"),
            )
        })?;
    let [rows, cols, bands] = dims[..] else {
        return Err(err(
            path,
            format!("npy 'shape' = {shape_txt}: expected 3 axes (rows, columns, bands)"),
        ));
    };
    if rows == 0
        || cols == 0
        || bands == 0
        || [rows, cols, bands].iter().any(|&d| d > u32::MAX as u64)
    {
        return Err(err(
            path,
            format!(
                "npy 'shape' = {shape_txt}: every axis must be 1 to {}",
                u32::MAX
            ),
        ));
    }
    let (rows, cols, bands) = (rows as usize, cols as usize, bands as usize);
    check_wavelengths(path, "wavelength_nm", wavelength_nm, bands)?;
    let n = rows as u128 * cols as u128 * bands as u128;
    let bytes = hstart + hlen + n * ty.bytes() as u128;
    check_cube_budget(path, "shape", n as f64, bytes as f64)?;
    let data = read_exact_len(
        path,
        bytes,
        &format!("the npy header (shape {shape_txt}, {descr})"),
    )?;
    let layout = if fortran {
        Layout::Fortran
    } else {
        Layout::Bip
    };
    let planes = decode_planes(
        path,
        &data[(hstart + hlen) as usize..],
        ty,
        big,
        layout,
        rows,
        cols,
        bands,
    )?;
    Ok(SpectralCube {
        rows,
        cols,
        wavelength_nm: wavelength_nm.to_vec(),
        planes,
    })
}

/// Wavelengths from a side file: a JSON list, or numbers separated by whitespace or commas.
pub fn read_wavelength_file(path: &Path) -> Result<Vec<f64>, String> {
    crate::staging::protect_input(path);
    let len = std::fs::metadata(path)
        .map_err(|e| err(path, format!("cannot read: {e}")))?
        .len();
    if len > 16 << 20 {
        return Err(err(
            path,
            format!("{len} bytes is too large for a wavelength list"),
        ));
    }
    let t = std::fs::read_to_string(path).map_err(|e| err(path, format!("cannot read: {e}")))?;
    let t = t.trim();
    if t.starts_with('[') {
        serde_json::from_str::<Vec<f64>>(t)
            .map_err(|e| err(path, format!("not a JSON list of numbers: {e}")))
    } else {
        number_list(path, "wavelengths", t)
    }
}

/// Read an 8/16-bit grey, RGB or RGBA PNG or TIFF as DAC codes (alpha is dropped). The pixel
/// count is checked against the memory budget from the header, before decoding.
pub fn read_rgb_picture(path: &Path) -> Result<RgbCodes, String> {
    crate::staging::protect_input(path);
    let reader = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| err(path, format!("cannot read: {e}")))?;
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| err(path, format!("not a PNG or TIFF picture: {e}")))?;
    let n = w as f64 * h as f64;
    // decoded RGBA16 + the codes + 3 f32 planes
    budget::check_memory(
        Some(path),
        "file",
        n * (8.0 + 6.0 + 12.0),
        &format!("{w}×{h} pixels"),
    )
    .map_err(|e| e.one_line())?;
    let img = crate::guard::guarded(path, || {
        image::ImageReader::open(path)
            .and_then(|r| r.with_guessed_format())
            .map_err(|e| crate::error::CliError::Other(e.to_string()))?
            .decode()
            .map_err(|e| crate::error::CliError::Other(e.to_string()))
    })
    .map_err(|e| err(path, format!("cannot decode: {}", e.one_line())))?;
    use image::DynamicImage as D;
    let (rows, cols) = (img.height() as usize, img.width() as usize);
    let (channels, bits, codes): (usize, u32, Vec<u16>) = match img {
        D::ImageLuma8(b) => (1, 8, b.into_raw().into_iter().map(u16::from).collect()),
        D::ImageLumaA8(b) => (1, 8, b.pixels().map(|p| u16::from(p.0[0])).collect()),
        D::ImageRgb8(b) => (3, 8, b.into_raw().into_iter().map(u16::from).collect()),
        D::ImageRgba8(b) => (
            3,
            8,
            b.pixels()
                .flat_map(|p| [p.0[0], p.0[1], p.0[2]].map(u16::from))
                .collect(),
        ),
        D::ImageLuma16(b) => (1, 16, b.into_raw()),
        D::ImageLumaA16(b) => (1, 16, b.pixels().map(|p| p.0[0]).collect()),
        D::ImageRgb16(b) => (3, 16, b.into_raw()),
        D::ImageRgba16(b) => (
            3,
            16,
            b.pixels().flat_map(|p| [p.0[0], p.0[1], p.0[2]]).collect(),
        ),
        other => {
            return Err(err(
                path,
                format!(
                    "{:?} pictures are not DAC codes; expected 8- or 16-bit grey or RGB",
                    other.color()
                ),
            ))
        }
    };
    Ok(RgbCodes {
        rows,
        cols,
        channels,
        bits,
        codes,
    })
}
