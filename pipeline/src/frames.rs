//! Single-channel 16-bit PNG frames (DN as stored, row 0 first), written atomically.
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use camsim_core::RawFrame;
use std::fs::File;
use std::io::{BufReader, Write};
use std::path::Path;

pub use crate::raw_input::read_png16;

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
    crate::staging::protect_input(path);
    let f =
        File::open(path).map_err(|e| CliError::input(path, format!("cannot open frame: {e}")))?;
    let dec = png::Decoder::new(BufReader::new(f));
    let r = dec
        .read_info()
        .map_err(|e| CliError::input(path, format!("not a readable PNG: {e}")))?;
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
            format!(
                "frame must be a single-channel 16-bit PNG, found {}-bit {}",
                i.bit_depth,
                if i.greyscale { "greyscale" } else { "colour" }
            ),
        ));
    }
    if i.rows != rows || i.cols != cols {
        return Err(CliError::input(
            path,
            format!(
                "frame is {}×{} (rows×cols) but the sensor is {rows}×{cols}",
                i.rows, i.cols
            ),
        ));
    }
    Ok(())
}

/// Write a frame as a 16-bit greyscale PNG, atomically ([`encode_png16`]).
pub fn write_png16(path: &Path, frame: &RawFrame) -> Result<(), CliError> {
    let bytes = encode_png16(frame);
    write_atomically(path, |tmp| -> Result<(), std::io::Error> {
        let mut f = File::create(tmp)?;
        f.write_all(&bytes)?;
        Ok(())
    })
    .map_err(|e| CliError::output(path, e))
}

/// Deflate "stored" block payload limit (bytes).
const STORED_MAX: usize = 65_535;

/// A frame as a single-channel 16-bit PNG (big-endian samples, filter type 0 on every row)
/// whose zlib stream holds stored (uncompressed) deflate blocks, one per IDAT chunk.
///
/// Noisy 10–16-bit frames compress poorly (fast deflate saves ~25 %), while compressing costs
/// more than the rest of a 12 MP simulation; stored blocks make the encoder a parallel copy:
/// the chunks are filled, their Adler-32 parts and CRCs computed on all threads, and the
/// Adler-32 parts combined. Any PNG reader accepts the result.
pub fn encode_png16(frame: &RawFrame) -> Vec<u8> {
    use rayon::prelude::*;
    let (rows, cols) = (frame.rows, frame.cols);
    assert_eq!(frame.dn.len(), rows * cols, "frame size");
    let row_len = 1 + 2 * cols; // filter byte + big-endian samples
    let raw_len = rows * row_len;
    let n_blocks = raw_len.div_ceil(STORED_MAX).max(1);
    let payload = |i: usize| STORED_MAX.min(raw_len - i * STORED_MAX);
    // IDAT chunk i: [zlib header (first)] + stored-block header + payload + [Adler-32 (last)].
    let data_len =
        |i: usize| (i == 0) as usize * 2 + 5 + payload(i) + (i + 1 == n_blocks) as usize * 4;
    let head = 8 + 25; // signature + IHDR
    let total = head + (0..n_blocks).map(|i| 12 + data_len(i)).sum::<usize>() + 12;
    let mut out = vec![0u8; total];
    // Signature and IHDR.
    out[..8].copy_from_slice(b"\x89PNG\r\n\x1a\n");
    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&(cols as u32).to_be_bytes());
    ihdr.extend_from_slice(&(rows as u32).to_be_bytes());
    ihdr.extend_from_slice(&[16, 0, 0, 0, 0]); // 16-bit, greyscale, deflate, adaptive filters, no interlace
    write_chunk(&mut out[8..head], b"IHDR", &ihdr);
    let (body, iend) = out[head..].split_at_mut(total - head - 12);
    write_chunk(iend, b"IEND", &[]);
    // Split the body into the IDAT chunks.
    let mut chunks: Vec<&mut [u8]> = Vec::with_capacity(n_blocks);
    let mut rest = body;
    for i in 0..n_blocks {
        let (c, r) = rest.split_at_mut(12 + data_len(i));
        chunks.push(c);
        rest = r;
    }
    // Fill every chunk but the CRC; Adler-32 (a, b) of each payload.
    let parts: Vec<(u32, u32, usize)> = chunks
        .par_iter_mut()
        .enumerate()
        .map(|(i, c)| {
            let len = data_len(i);
            c[..4].copy_from_slice(&(len as u32).to_be_bytes());
            c[4..8].copy_from_slice(b"IDAT");
            let mut d = &mut c[8..8 + len];
            if i == 0 {
                d[..2].copy_from_slice(&[0x78, 0x01]); // deflate, 32 K window, no dictionary
                d = &mut d[2..];
            }
            let p = payload(i);
            d[0] = (i + 1 == n_blocks) as u8; // BFINAL, BTYPE = 00 (stored)
            d[1..3].copy_from_slice(&(p as u16).to_le_bytes());
            d[3..5].copy_from_slice(&(!(p as u16)).to_le_bytes());
            let dst = &mut d[5..5 + p];
            fill_scanlines(dst, i * STORED_MAX, row_len, &frame.dn, cols);
            let (a, b) = adler32_parts(dst);
            (a, b, p)
        })
        .collect();
    // Adler-32 of the whole raw stream, into the last chunk.
    let (mut a, mut b) = (1u32, 0u32);
    for &(a2, b2, n) in &parts {
        (a, b) = adler32_combine(a, b, a2, b2, n);
    }
    let last = chunks.last_mut().expect("at least one block");
    let l = last.len();
    last[l - 8..l - 4].copy_from_slice(&((b << 16) | a).to_be_bytes());
    // CRC-32 of type + data of every chunk.
    chunks.par_iter_mut().for_each(|c| {
        let l = c.len();
        let crc = crc32(&c[4..l - 4]);
        c[l - 4..].copy_from_slice(&crc.to_be_bytes());
    });
    out
}

/// A PNG chunk (length, type, data, CRC) into `dst` (exactly 12 + data bytes).
fn write_chunk(dst: &mut [u8], kind: &[u8; 4], data: &[u8]) {
    dst[..4].copy_from_slice(&(data.len() as u32).to_be_bytes());
    dst[4..8].copy_from_slice(kind);
    dst[8..8 + data.len()].copy_from_slice(data);
    let crc = crc32(&dst[4..8 + data.len()]);
    dst[8 + data.len()..].copy_from_slice(&crc.to_be_bytes());
}

/// Bytes `start..start + dst.len()` of the raw PNG scanlines (per row: filter byte 0, then the
/// samples big-endian) of a `cols`-wide frame.
fn fill_scanlines(dst: &mut [u8], start: usize, row_len: usize, dn: &[u16], cols: usize) {
    let (mut o, mut d) = (start, 0);
    while d < dst.len() {
        let (row, mut pos) = (o / row_len, o % row_len);
        let n = (row_len - pos).min(dst.len() - d);
        let end = pos + n;
        let line = &dn[row * cols..(row + 1) * cols];
        let seg = &mut dst[d..d + n];
        let mut j = 0;
        if pos == 0 {
            seg[0] = 0;
            j = 1;
            pos = 1;
        }
        // Byte pos ≥ 1 is byte (pos − 1) % 2 of sample (pos − 1) / 2.
        if pos < end && (pos - 1) % 2 == 1 {
            seg[j] = line[(pos - 1) / 2] as u8;
            j += 1;
            pos += 1;
        }
        let pairs = (end - pos) / 2;
        let k0 = (pos - 1) / 2;
        for (b, v) in seg[j..j + 2 * pairs]
            .chunks_exact_mut(2)
            .zip(&line[k0..k0 + pairs])
        {
            b.copy_from_slice(&v.to_be_bytes());
        }
        j += 2 * pairs;
        pos += 2 * pairs;
        if pos < end {
            seg[j] = (line[(pos - 1) / 2] >> 8) as u8;
        }
        o += n;
        d += n;
    }
}

const ADLER_MOD: u32 = 65_521;

/// Adler-32 sums (a, b) of `data` from the initial a = 1, b = 0.
fn adler32_parts(data: &[u8]) -> (u32, u32) {
    let (mut a, mut b) = (1u32, 0u32);
    // 5552 bytes keep b below 2^32 before the reduction (zlib's NMAX).
    for block in data.chunks(5552) {
        for &x in block {
            a += x as u32;
            b += a;
        }
        a %= ADLER_MOD;
        b %= ADLER_MOD;
    }
    (a, b)
}

/// Adler-32 sums of a concatenation from those of its parts (the second part, of `n2` bytes,
/// summed from a = 1, b = 0): a = a1 + a2 − 1, b = b1 + n2·a1 + b2 − n2 (mod 65521).
fn adler32_combine(a1: u32, b1: u32, a2: u32, b2: u32, n2: usize) -> (u32, u32) {
    let m = ADLER_MOD as u64;
    let n = n2 as u64 % m;
    let a = (a1 as u64 + a2 as u64 + m - 1) % m;
    let b = (b1 as u64 + n * a1 as u64 + b2 as u64 + m - n) % m;
    (a as u32, b as u32)
}

/// CRC-32 (ISO-HDLC, as PNG uses), slicing by 8 bytes.
fn crc32(data: &[u8]) -> u32 {
    static TABLES: std::sync::OnceLock<[[u32; 256]; 8]> = std::sync::OnceLock::new();
    let t = TABLES.get_or_init(|| {
        let mut t = [[0u32; 256]; 8];
        for i in 0..256u32 {
            let mut c = i;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
            t[0][i as usize] = c;
        }
        for i in 0..256 {
            for k in 1..8 {
                let prev = t[k - 1][i];
                t[k][i] = (prev >> 8) ^ t[0][(prev & 0xff) as usize];
            }
        }
        t
    });
    let mut crc = !0u32;
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        let lo = crc ^ u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        let hi = u32::from_le_bytes([c[4], c[5], c[6], c[7]]);
        crc = t[7][(lo & 0xff) as usize]
            ^ t[6][((lo >> 8) & 0xff) as usize]
            ^ t[5][((lo >> 16) & 0xff) as usize]
            ^ t[4][(lo >> 24) as usize]
            ^ t[3][(hi & 0xff) as usize]
            ^ t[2][((hi >> 8) & 0xff) as usize]
            ^ t[1][((hi >> 16) & 0xff) as usize]
            ^ t[0][(hi >> 24) as usize];
    }
    for &b in chunks.remainder() {
        crc = t[0][((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_and_adler32_known_values() {
        // Check values of the standard test string.
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        let (a, b) = adler32_parts(b"Wikipedia");
        assert_eq!((b << 16) | a, 0x11E6_0398);
        // Combining parts equals the sum over the whole, also across the 5552-byte blocks.
        let data: Vec<u8> = (0..40_000u32).map(|i| (i * 7919 % 251) as u8).collect();
        for split in [0, 1, 5552, 12_345, 39_999, 40_000] {
            let (a1, b1) = adler32_parts(&data[..split]);
            let (a2, b2) = adler32_parts(&data[split..]);
            assert_eq!(
                adler32_combine(a1, b1, a2, b2, data.len() - split),
                adler32_parts(&data)
            );
        }
    }

    #[test]
    fn png16_round_trips_through_a_reference_decoder() {
        // Sizes around the stored-block limit (rows straddling blocks, a row longer than a
        // block, a single pixel), extreme values.
        for &(rows, cols) in &[
            (1usize, 1usize),
            (3, 5),
            (97, 331),
            (40, 32_768),
            (2, 40_000),
        ] {
            let dn: Vec<u16> = (0..rows * cols)
                .map(|i| (i as u32).wrapping_mul(2_654_435_761) as u16)
                .collect();
            let mut dn = dn;
            dn[0] = 0xFFFF;
            let frame = RawFrame {
                rows,
                cols,
                adc_bits: 16,
                layout: None,
                dn,
            };
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("f.png");
            write_png16(&p, &frame).unwrap();
            // The png crate checks every CRC and the Adler-32.
            let f = File::open(&p).unwrap();
            let mut dec = png::Decoder::new(BufReader::new(f));
            dec.ignore_checksums(false);
            let mut r = dec.read_info().unwrap();
            let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
            r.next_frame(&mut buf).unwrap();
            let back: Vec<u16> = buf
                .chunks_exact(2)
                .map(|c| u16::from_be_bytes([c[0], c[1]]))
                .collect();
            assert_eq!(back, frame.dn, "{rows}×{cols}");
            assert_eq!(read_png16(&p).unwrap().dn, frame.dn);
            let info = png_info(&p).unwrap();
            assert_eq!(
                (info.rows, info.cols, info.bit_depth, info.greyscale),
                (rows, cols, 16, true)
            );
        }
    }
}

/// Write a frame in the format its path names: 16-bit greyscale TIFF for `.tif`/`.tiff`,
/// otherwise the spec's 16-bit PNG (same format as the recording).
pub fn write_frame(path: &Path, frame: &RawFrame) -> Result<(), CliError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext != "png" && ext != "tif" && ext != "tiff" {
        return Err(CliError::output(
            path,
            format!(
                "frames are written as .png, .tif/.tiff or (with raw_format) .raw/.bin; \
                 \"{}\" is not one of them",
                if ext.is_empty() {
                    "no extension".to_string()
                } else {
                    format!(".{ext}")
                }
            ),
        ));
    }
    if ext == "tif" || ext == "tiff" {
        let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_raw(
            frame.cols as u32,
            frame.rows as u32,
            frame.dn.clone(),
        )
        .ok_or_else(|| CliError::output(path, "frame size does not match its data"))?;
        write_atomically(path, |tmp| -> Result<(), std::io::Error> {
            let f = std::io::BufWriter::new(File::create(tmp)?);
            img.write_with_encoder(image::codecs::tiff::TiffEncoder::new(f))
                .map_err(std::io::Error::other)
        })
        .map_err(|e| CliError::output(path, e))
    } else {
        write_png16(path, frame)
    }
}

/// Write a frame in its recording's format, headerless raw (`.raw`/`.bin`) included.
pub fn write_frame_with(
    path: &Path,
    frame: &RawFrame,
    raw_format: Option<&crate::raw_input::RawFormat>,
) -> Result<(), CliError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    if ext != "raw" && ext != "bin" {
        return write_frame(path, frame);
    }
    let fmt = raw_format.ok_or_else(|| {
        CliError::output(
            path,
            "a headerless raw frame needs \"raw_format\" in captures.json",
        )
    })?;
    let mut bytes = vec![0u8; fmt.header_bytes as usize];
    for &v in &frame.dn {
        match (fmt.bytes_per_sample, fmt.little_endian) {
            (1, _) => bytes.push(v.min(255) as u8),
            (_, true) => bytes.extend_from_slice(&v.to_le_bytes()),
            (_, false) => bytes.extend_from_slice(&v.to_be_bytes()),
        }
    }
    write_atomically(path, |tmp| std::fs::write(tmp, &bytes)).map_err(|e| CliError::output(path, e))
}

/// How [`write_dng`] lays out a DNG.
#[derive(Debug, Clone, PartialEq)]
pub struct DngLayout {
    /// CFA tile from the active area's top-left, one string per row (letters r g b c m y w).
    pub cfa: Vec<String>,
    /// Black level repeat cell (rows, cols) and its values (row-major, DN).
    pub black_repeat: (usize, usize),
    /// Black levels of the cell.
    pub black_level_dn: Vec<f64>,
    /// Optional BlackLevelDeltaH (per active-area column) and DeltaV (per row).
    pub black_delta_h: Vec<f64>,
    /// BlackLevelDeltaV.
    pub black_delta_v: Vec<f64>,
    /// WhiteLevel (DN).
    pub white_level: u32,
    /// Masked border (top, left, bottom, right pixels) stored around the frame, filled with
    /// the black level; the frame becomes the ActiveArea.
    pub border: [usize; 4],
    /// Raw image in a SubIFD of IFD 0 (with a small preview in IFD 0), as cameras and the
    /// Adobe converter write it; else the raw image is IFD 0 itself.
    pub raw_in_subifd: bool,
    /// Bits per stored sample: 8 or 16.
    pub bits_per_sample: u16,
}

impl DngLayout {
    /// A plain layout for a camera: its CFA and black level, WhiteLevel 2^bits − 1, 16-bit
    /// samples, raw image in a SubIFD.
    pub fn for_sensor(s: &camsim_sensor::SensorModel) -> Self {
        let cfa = s
            .cfa
            .tile
            .iter()
            .map(|row| {
                row.iter()
                    .map(|&k| {
                        s.channel_names[k]
                            .chars()
                            .next()
                            .unwrap_or('g')
                            .to_ascii_lowercase()
                    })
                    .collect()
            })
            .collect();
        DngLayout {
            cfa,
            black_repeat: (1, 1),
            black_level_dn: vec![s.black_level_dn],
            black_delta_h: Vec::new(),
            black_delta_v: Vec::new(),
            white_level: s.max_dn() as u32,
            border: [0; 4],
            raw_in_subifd: true,
            bits_per_sample: 16,
        }
    }
}

/// Write a mosaic as an uncompressed DNG (what [`crate::raw_input::dng::read_dng`] reads),
/// atomically, with the `tiff` crate: DNGVersion 1.4, CFARepeatPatternDim/CFAPattern,
/// BlackLevelRepeatDim/BlackLevel (RATIONAL: fractional pedestals survive), optional
/// BlackLevelDeltaH/V, WhiteLevel and ActiveArea.
pub fn write_dng(path: &Path, frame: &RawFrame, layout: &DngLayout) -> Result<(), CliError> {
    use crate::raw_input::dng::tags as t;
    use tiff::encoder::{Rational, TiffEncoder};
    use tiff::tags::Tag;
    let bad = |m: String| CliError::output(path, m);
    let codes: Vec<u8> = layout
        .cfa
        .iter()
        .flat_map(|r| r.chars())
        .map(|c| {
            "rgbcmyw"
                .find(c.to_ascii_lowercase())
                .map(|i| i as u8)
                .ok_or_else(|| {
                    bad(format!(
                        "CFA letter '{c}' has no DNG colour code (r g b c m y w)"
                    ))
                })
        })
        .collect::<Result<_, _>>()?;
    let (pr, pc) = (
        layout.cfa.len(),
        layout.cfa.first().map_or(0, |r| r.chars().count()),
    );
    if pr == 0 || pc == 0 || codes.len() != pr * pc {
        return Err(bad("the CFA tile must be a non-empty rectangle".into()));
    }
    let (br, bc) = layout.black_repeat;
    if br * bc != layout.black_level_dn.len() || br == 0 {
        return Err(bad("black level cell size does not match its values".into()));
    }
    if layout.bits_per_sample != 8 && layout.bits_per_sample != 16 {
        return Err(bad("bits_per_sample must be 8 or 16".into()));
    }
    let [bt, bl, bb, brr] = layout.border;
    let (rows, cols) = (frame.rows + bt + bb, frame.cols + bl + brr);
    let black_at = |r: usize, c: usize| -> f64 {
        layout.black_level_dn[(r % br) * bc + c % bc]
            + layout.black_delta_v.get(r).copied().unwrap_or(0.0)
            + layout.black_delta_h.get(c).copied().unwrap_or(0.0)
    };
    let mut stored = vec![0u16; rows * cols];
    for r in 0..rows {
        for c in 0..cols {
            let inside = r >= bt && r < bt + frame.rows && c >= bl && c < bl + frame.cols;
            stored[r * cols + c] = if inside {
                frame.dn[(r - bt) * frame.cols + c - bl]
            } else {
                // masked pixels read the black level of the nearest active pixel's cell
                let (ar, ac) = (
                    r.saturating_sub(bt).min(frame.rows - 1),
                    c.saturating_sub(bl).min(frame.cols - 1),
                );
                black_at(ar, ac).round().max(0.0) as u16
            };
        }
    }
    let rational = |v: f64| -> Rational {
        // 1/1000 DN resolution
        Rational {
            n: (v.max(0.0) * 1000.0).round() as u32,
            d: 1000,
        }
    };
    let srational = |v: f64| tiff::encoder::SRational {
        n: (v * 1000.0).round() as i32,
        d: 1000,
    };
    let write = |tmp: &Path| -> Result<(), tiff::TiffError> {
        let f = std::io::BufWriter::new(File::create(tmp)?);
        // the tiff encoder writes the platform's byte order (the reader handles both)
        let mut enc = TiffEncoder::new(f)?;
        let tag = Tag::from_u16_exhaustive;
        let raw_tags =
            |dir: &mut tiff::encoder::DirectoryEncoder<'_, _, _>| -> Result<(), tiff::TiffError> {
                let off = if layout.bits_per_sample == 8 {
                    let b: Vec<u8> = stored.iter().map(|&v| v.min(255) as u8).collect();
                    dir.write_data(&b[..])?
                } else {
                    dir.write_data(&stored[..])?
                };
                dir.write_tag(tag(t::NEW_SUBFILE_TYPE), 0u32)?;
                dir.write_tag(Tag::ImageWidth, cols as u32)?;
                dir.write_tag(Tag::ImageLength, rows as u32)?;
                dir.write_tag(Tag::BitsPerSample, layout.bits_per_sample)?;
                dir.write_tag(Tag::Compression, 1u16)?;
                dir.write_tag(Tag::PhotometricInterpretation, t::PHOTOMETRIC_CFA)?;
                dir.write_tag(Tag::StripOffsets, off as u32)?;
                dir.write_tag(Tag::SamplesPerPixel, 1u16)?;
                dir.write_tag(Tag::RowsPerStrip, rows as u32)?;
                dir.write_tag(
                    Tag::StripByteCounts,
                    (rows * cols * layout.bits_per_sample as usize / 8) as u32,
                )?;
                dir.write_tag(Tag::PlanarConfiguration, 1u16)?;
                dir.write_tag(tag(t::CFA_REPEAT_PATTERN_DIM), &[pr as u16, pc as u16][..])?;
                dir.write_tag(tag(t::CFA_PATTERN), &codes[..])?;
                dir.write_tag(tag(t::CFA_LAYOUT), 1u16)?;
                dir.write_tag(tag(t::BLACK_LEVEL_REPEAT_DIM), &[br as u16, bc as u16][..])?;
                let levels: Vec<Rational> =
                    layout.black_level_dn.iter().map(|&v| rational(v)).collect();
                dir.write_tag(tag(t::BLACK_LEVEL), &levels[..])?;
                if !layout.black_delta_h.is_empty() {
                    let v: Vec<_> = layout.black_delta_h.iter().map(|&x| srational(x)).collect();
                    dir.write_tag(tag(t::BLACK_LEVEL_DELTA_H), &v[..])?;
                }
                if !layout.black_delta_v.is_empty() {
                    let v: Vec<_> = layout.black_delta_v.iter().map(|&x| srational(x)).collect();
                    dir.write_tag(tag(t::BLACK_LEVEL_DELTA_V), &v[..])?;
                }
                dir.write_tag(tag(t::WHITE_LEVEL), layout.white_level)?;
                if layout.border != [0; 4] {
                    let aa = [
                        bt as u32,
                        bl as u32,
                        (bt + frame.rows) as u32,
                        (bl + frame.cols) as u32,
                    ];
                    dir.write_tag(tag(t::ACTIVE_AREA), &aa[..])?;
                }
                Ok(())
            };
        let dng_tags =
            |dir: &mut tiff::encoder::DirectoryEncoder<'_, _, _>| -> Result<(), tiff::TiffError> {
                dir.write_tag(tag(t::DNG_VERSION), &[1u8, 4, 0, 0][..])?;
                dir.write_tag(tag(t::UNIQUE_CAMERA_MODEL), "camsim")?;
                Ok(())
            };
        if layout.raw_in_subifd {
            let mut sub = enc.extra_directory()?;
            raw_tags(&mut sub)?;
            let sub_off = sub.finish_with_offsets()?;
            // IFD 0: an 8 × 8 grey preview (NewSubFileType 1) pointing at the raw SubIFD
            let mut ifd0 = enc.image_directory()?;
            let preview = [128u8; 64];
            let off = ifd0.write_data(&preview[..])?;
            ifd0.write_tag(tag(t::NEW_SUBFILE_TYPE), 1u32)?;
            ifd0.write_tag(Tag::ImageWidth, 8u32)?;
            ifd0.write_tag(Tag::ImageLength, 8u32)?;
            ifd0.write_tag(Tag::BitsPerSample, 8u16)?;
            ifd0.write_tag(Tag::Compression, 1u16)?;
            ifd0.write_tag(Tag::PhotometricInterpretation, 1u16)?;
            ifd0.write_tag(Tag::StripOffsets, off as u32)?;
            ifd0.write_tag(Tag::SamplesPerPixel, 1u16)?;
            ifd0.write_tag(Tag::RowsPerStrip, 8u32)?;
            ifd0.write_tag(Tag::StripByteCounts, 64u32)?;
            ifd0.write_tag(Tag::SubIfd, &[sub_off.offset][..])?;
            dng_tags(&mut ifd0)?;
            ifd0.finish()?;
        } else {
            let mut ifd0 = enc.image_directory()?;
            raw_tags(&mut ifd0)?;
            dng_tags(&mut ifd0)?;
            ifd0.finish()?;
        }
        Ok(())
    };
    write_atomically(path, |tmp| {
        write(tmp).map_err(|e| std::io::Error::other(e.to_string()))
    })
    .map_err(|e| CliError::output(path, e))
}
