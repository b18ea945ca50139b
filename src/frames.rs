//! Single-channel 16-bit PNG frames (DN as stored, row 0 first), written atomically.
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use camsim_core::RawFrame;
use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

/// Header facts of a PNG frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameInfo {
    /// width (columns)
    pub cols: usize,
    /// height (rows)
    pub rows: usize,
    /// bits per sample
    pub bit_depth: u8,
    /// true for single-channel greyscale
    pub greyscale: bool,
}

/// Read a PNG header.
pub fn png_info(path: &Path) -> Result<FrameInfo, CliError> {
    let f = File::open(path).map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?;
    let dec = png::Decoder::new(BufReader::new(f));
    let r = dec.read_info().map_err(|e| CliError::input(path, format!("not a readable PNG: {e}")))?;
    let i = r.info();
    Ok(FrameInfo {
        cols: i.width as usize,
        rows: i.height as usize,
        bit_depth: i.bit_depth as u8,
        greyscale: i.color_type == png::ColorType::Grayscale,
    })
}

/// Check that a recorded frame is a single-channel 16-bit PNG of the sensor's size.
pub fn check_frame(path: &Path, rows: usize, cols: usize) -> Result<(), CliError> {
    let i = png_info(path)?;
    if !i.greyscale || i.bit_depth != 16 {
        return Err(CliError::input(
            path,
            format!("frame must be a single-channel 16-bit PNG, found {}-bit {}", i.bit_depth, if i.greyscale { "greyscale" } else { "colour" }),
        ));
    }
    if i.rows != rows || i.cols != cols {
        return Err(CliError::input(path, format!("frame is {}×{} (rows×cols) but the sensor is {rows}×{cols}", i.rows, i.cols)));
    }
    Ok(())
}

/// Read a 16-bit greyscale PNG frame.
pub fn read_png16(path: &Path) -> Result<RawFrame, CliError> {
    let f = File::open(path).map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?;
    let mut r = png::Decoder::new(BufReader::new(f))
        .read_info()
        .map_err(|e| CliError::input(path, format!("not a readable PNG: {e}")))?;
    let info = r.info().clone();
    if info.bit_depth != png::BitDepth::Sixteen || info.color_type != png::ColorType::Grayscale {
        return Err(CliError::input(path, "frame must be a single-channel 16-bit PNG"));
    }
    let mut buf = vec![0u8; r.output_buffer_size().unwrap_or(0)];
    r.next_frame(&mut buf).map_err(|e| CliError::input(path, format!("corrupt PNG: {e}")))?;
    let dn = buf.chunks_exact(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect();
    Ok(RawFrame { rows: info.height as usize, cols: info.width as usize, adc_bits: 16, dn })
}

/// Write a frame as a 16-bit greyscale PNG (fast deflate), atomically.
pub fn write_png16(path: &Path, frame: &RawFrame) -> Result<(), CliError> {
    let mut bytes = vec![0u8; frame.dn.len() * 2];
    for (b, v) in bytes.chunks_exact_mut(2).zip(&frame.dn) {
        b.copy_from_slice(&v.to_be_bytes());
    }
    write_atomically(path, |tmp| -> Result<(), std::io::Error> {
        let w = BufWriter::with_capacity(1 << 20, File::create(tmp)?);
        let mut enc = png::Encoder::new(w, frame.cols as u32, frame.rows as u32);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        enc.set_compression(png::Compression::Fastest);
        let mut wr = enc.write_header().map_err(std::io::Error::other)?;
        wr.write_image_data(&bytes).map_err(std::io::Error::other)?;
        wr.finish().map_err(std::io::Error::other)?;
        Ok(())
    })
    .map_err(|e| CliError::output(path, e))
}
