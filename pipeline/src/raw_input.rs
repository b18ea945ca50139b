//! Reading recorded frames: the spec's 16-bit PNG mosaics, plus 8/16-bit greyscale TIFF
//! (real cameras' exports), uncompressed DNG ([`dng`]) and headerless raw — each as a
//! [`RawFrame`] of DN as stored.
pub mod dng;

use crate::error::CliError;
use camsim_core::RawFrame;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

/// Read a 16-bit greyscale PNG frame.
pub fn read_png16(path: &Path) -> Result<RawFrame, CliError> {
    crate::staging::protect_input(path);
    let f =
        File::open(path).map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?;
    let mut r = png::Decoder::new(BufReader::new(f))
        .read_info()
        .map_err(|e| CliError::input(path, format!("not a readable PNG: {e}")))?;
    let info = r.info().clone();
    if info.bit_depth != png::BitDepth::Sixteen || info.color_type != png::ColorType::Grayscale {
        return Err(CliError::input(
            path,
            "frame must be a single-channel 16-bit PNG",
        ));
    }
    let mut buf = vec![0u8; r.output_buffer_size().unwrap_or(0)];
    r.next_frame(&mut buf)
        .map_err(|e| CliError::input(path, format!("corrupt PNG: {e}")))?;
    let dn = buf
        .chunks_exact(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    Ok(RawFrame {
        rows: info.height as usize,
        cols: info.width as usize,
        adc_bits: 16,
        dn,
        layout: None,
    })
}

/// Layout of a headerless raw frame file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawFormat {
    /// rows
    pub rows: usize,
    /// columns
    pub cols: usize,
    /// 1 or 2
    pub bytes_per_sample: usize,
    /// byte order of 16-bit samples
    pub little_endian: bool,
    /// bytes skipped at the start
    pub header_bytes: u64,
}

fn is_raw(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("raw") | Some("bin")
    )
}

/// Read a headerless raw mosaic laid out as `fmt` says (row 0 first).
pub fn read_raw(path: &Path, fmt: &RawFormat) -> Result<RawFrame, CliError> {
    crate::staging::protect_input(path);
    let bytes = std::fs::read(path)
        .map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?;
    // Checked: a header of 2^64 - 1 bytes or an absurd size is a size mismatch, not an
    // overflow (the file's real length bounds everything read below).
    let need = fmt
        .rows
        .checked_mul(fmt.cols)
        .and_then(|n| n.checked_mul(fmt.bytes_per_sample))
        .and_then(|n| usize::try_from(fmt.header_bytes).ok()?.checked_add(n));
    if need != Some(bytes.len()) {
        let need = need.map_or("more than 2^64".to_string(), |n| n.to_string());
        return Err(CliError::input(
            path,
            format!(
                "raw frame has {} bytes; raw_format ({}×{}, {} bit, {} header bytes) needs {need}",
                bytes.len(),
                fmt.rows,
                fmt.cols,
                fmt.bytes_per_sample * 8,
                fmt.header_bytes
            ),
        ));
    }
    let body = &bytes[fmt.header_bytes as usize..];
    let dn: Vec<u16> = if fmt.bytes_per_sample == 1 {
        body.iter().map(|&b| b as u16).collect()
    } else if fmt.little_endian {
        body.chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect()
    } else {
        body.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    };
    Ok(RawFrame {
        rows: fmt.rows,
        cols: fmt.cols,
        adc_bits: (fmt.bytes_per_sample * 8) as u32,
        dn,
        layout: None,
    })
}

/// Read one recorded frame; `.raw`/`.bin` files need the capture set's `raw_format`.
pub fn read_frame_with(path: &Path, raw_format: Option<&RawFormat>) -> Result<RawFrame, CliError> {
    crate::guard::guarded(path, || read_frame_with_unguarded(path, raw_format))
}

fn read_frame_with_unguarded(
    path: &Path,
    raw_format: Option<&RawFormat>,
) -> Result<RawFrame, CliError> {
    if is_raw(path) {
        let fmt = raw_format.ok_or_else(|| {
            CliError::input(path, "a headerless raw frame needs \"raw_format\" in captures.json (rows, cols, bits_per_sample, endianness)")
        })?;
        return read_raw(path, fmt);
    }
    read_frame_unguarded(path)
}

/// Read one recorded frame (PNG: 16-bit greyscale; TIFF: 8- or 16-bit greyscale; DNG: the
/// active area of the CFA image, see [`dng::read_dng`]).
pub fn read_frame(path: &Path) -> Result<RawFrame, CliError> {
    crate::guard::guarded(path, || read_frame_unguarded(path))
}

fn read_frame_unguarded(path: &Path) -> Result<RawFrame, CliError> {
    crate::staging::protect_input(path);
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "png" => read_png16(path),
        "dng" => dng::read_dng(path).map(|d| d.frame),
        "tif" | "tiff" => {
            let img = image::ImageReader::open(path)
                .map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?
                .decode()
                .map_err(|e| CliError::input(path, format!("not a readable TIFF: {e}")))?;
            let (cols, rows) = (img.width() as usize, img.height() as usize);
            let (dn, bits) = match img {
                image::DynamicImage::ImageLuma8(b) => {
                    (b.into_raw().into_iter().map(u16::from).collect(), 8)
                }
                image::DynamicImage::ImageLuma16(b) => (b.into_raw(), 16),
                other => {
                    return Err(CliError::input(
                        path,
                        format!(
                            "frame must be a single-channel greyscale mosaic, found {:?}",
                            other.color()
                        ),
                    ))
                }
            };
            Ok(RawFrame {
                rows,
                cols,
                adc_bits: bits,
                dn,
                layout: None,
            })
        }
        other => Err(CliError::input(
            path,
            format!("unsupported frame format \".{other}\" (expected .png, .tif, .dng, or .raw/.bin with raw_format)"),
        )),
    }
}

/// Where the patches of a chart are in the recorded frames: a label image of the sensor's
/// size in which pixel value k ≥ 1 marks patch k − 1 (row-major chart order) and 0 marks no
/// patch (camsim's `labels` extension of `patches` targets; docs/calibrate.md).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PatchLabels {
    /// rows
    pub rows: usize,
    /// columns
    pub cols: usize,
    /// label per pixel, row-major
    pub label: Vec<u16>,
}

/// Read a patch label image (8- or 16-bit greyscale PNG or TIFF) for a `rows × cols` sensor
/// and a chart of `n_patches` patches.
pub fn read_patch_labels(
    path: &Path,
    rows: usize,
    cols: usize,
    n_patches: usize,
) -> Result<PatchLabels, CliError> {
    let img = image::ImageReader::open(path)
        .map_err(|e| CliError::input(path, format!("cannot open label image: {e}")))?
        .with_guessed_format()
        .map_err(|e| CliError::input(path, format!("cannot read label image: {e}")))?
        .decode()
        .map_err(|e| CliError::input(path, format!("not a readable label image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let label: Vec<u16> = match img {
        image::DynamicImage::ImageLuma8(b) => b.into_raw().into_iter().map(u16::from).collect(),
        image::DynamicImage::ImageLuma16(b) => b.into_raw(),
        other => {
            return Err(CliError::input(
                path,
                format!(
                    "a label image must be single-channel greyscale (pixel value = patch number), found {:?}",
                    other.color()
                ),
            ))
        }
    };
    if (h, w) != (rows, cols) {
        return Err(CliError::input(
            path,
            format!("label image is {h}×{w} (rows×cols) but the sensor is {rows}×{cols}"),
        ));
    }
    if let Some(i) = label.iter().position(|&v| v as usize > n_patches) {
        return Err(CliError::input(
            path,
            format!(
                "pixel (row {}, col {}) has label {} but the chart has {n_patches} patches (labels 1–{n_patches}, 0 = none)",
                i / cols,
                i % cols,
                label[i]
            ),
        ));
    }
    if label.iter().all(|&v| v == 0) {
        return Err(CliError::input(path, "label image marks no patch (all 0)"));
    }
    Ok(PatchLabels { rows, cols, label })
}
