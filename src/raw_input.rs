//! Reading recorded frames: the spec's 16-bit PNG mosaics, plus 8/16-bit greyscale TIFF
//! (real cameras' exports) — each as a [`RawFrame`] of DN as stored.
use crate::error::CliError;
use crate::frames::read_png16;
use camsim_core::RawFrame;
use std::path::Path;

/// Read one recorded frame (PNG: 16-bit greyscale; TIFF: 8- or 16-bit greyscale).
pub fn read_frame(path: &Path) -> Result<RawFrame, CliError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "png" => read_png16(path),
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
            })
        }
        other => Err(CliError::input(
            path,
            format!("unsupported frame format \".{other}\" (expected .png or .tif)"),
        )),
    }
}
