//! Fast reading of 16-bit greyscale PNGs whose zlib stream holds only stored (uncompressed)
//! deflate blocks and whose rows all use filter type 0 — what [`crate::frames::encode_png16`]
//! writes, and what any PNG writer produces at compression level 0 without filtering.
//!
//! For such a file decoding is a byte-swapping copy, so [`decode_stored_gray16`] reads the
//! samples straight from the file's bytes into a caller's (reused) buffer: no inflater, no
//! intermediate image, no allocation per frame. It checks what a full decoder checks
//! (signature, IHDR, the CRC of every chunk, the zlib header, LEN against NLEN of every
//! stored block, the exact amount of image data, the Adler-32 of the zlib stream) and
//! returns `None` for anything else — another bit depth, colour type, interlacing, a
//! compressed block, a filtered row, a bad checksum — so that the caller decodes the file
//! with the general decoder, which either reads it or reports what is wrong with it.
//!
//! Formats: PNG (ISO/IEC 15948:2004 §5 chunk layout and CRC, §11.2.2 IHDR, §9.2 filter
//! type 0), zlib (RFC 1950: header, Adler-32), deflate stored blocks (RFC 1951 §3.2.4).

const SIGNATURE: &[u8; 8] = b"\x89PNG\r\n\x1a\n";

/// One chunk after `rest` (length, type, data, CRC); `None` if truncated or its CRC is wrong.
fn next_chunk<'a>(rest: &mut &'a [u8]) -> Option<([u8; 4], &'a [u8])> {
    let r = *rest;
    if r.len() < 12 {
        return None;
    }
    let len = u32::from_be_bytes(r[..4].try_into().ok()?) as usize;
    if len > 0x7fff_ffff || r.len() - 12 < len {
        return None;
    }
    let kind: [u8; 4] = r[4..8].try_into().ok()?;
    let crc = u32::from_be_bytes(r[8 + len..12 + len].try_into().ok()?);
    if crc32fast::hash(&r[4..8 + len]) != crc {
        return None;
    }
    *rest = &r[12 + len..];
    Some((kind, &r[8..8 + len]))
}

/// The zlib stream: the data of the consecutive IDAT chunks, read across chunk boundaries.
struct Stream<'a> {
    parts: Vec<&'a [u8]>,
    part: usize,
    offset: usize,
}

impl<'a> Stream<'a> {
    /// The next contiguous run of at most `max` (> 0) bytes; `None` at the end of the data.
    fn run(&mut self, max: usize) -> Option<&'a [u8]> {
        loop {
            let p = *self.parts.get(self.part)?;
            if self.offset < p.len() {
                let n = (p.len() - self.offset).min(max);
                let r = &p[self.offset..self.offset + n];
                self.offset += n;
                return Some(r);
            }
            self.part += 1;
            self.offset = 0;
        }
    }

    /// The next `N` bytes.
    fn bytes<const N: usize>(&mut self) -> Option<[u8; N]> {
        let mut b = [0u8; N];
        for x in b.iter_mut() {
            *x = self.run(1)?[0];
        }
        Some(b)
    }

    /// Whether every byte has been read.
    fn at_end(&self) -> bool {
        self.parts
            .iter()
            .enumerate()
            .skip(self.part)
            .all(|(i, p)| p.len() == if i == self.part { self.offset } else { 0 })
    }
}

/// The decompressed scanlines (filter byte + big-endian samples per row) as they arrive,
/// written as samples into `out`.
struct Scanlines<'o> {
    out: &'o mut [u16],
    row_len: usize,
    /// Position in the current row (0 = its filter byte is next).
    in_row: usize,
    /// Sample bytes written so far.
    sample_bytes: usize,
}

impl Scanlines<'_> {
    /// Takes the next bytes of the scanline stream; `None` if a row is filtered or the data
    /// exceed the image.
    fn feed(&mut self, mut run: &[u8]) -> Option<()> {
        while !run.is_empty() {
            if self.in_row == 0 {
                if run[0] != 0 || self.sample_bytes == 2 * self.out.len() {
                    return None;
                }
                run = &run[1..];
                self.in_row = 1;
                continue;
            }
            let n = (self.row_len - self.in_row).min(run.len());
            self.put(&run[..n]);
            self.in_row = if self.in_row + n == self.row_len {
                0
            } else {
                self.in_row + n
            };
            run = &run[n..];
        }
        Some(())
    }

    /// Big-endian sample bytes at `sample_bytes` (a run may start or end inside a sample).
    fn put(&mut self, mut b: &[u8]) {
        let mut p = self.sample_bytes;
        self.sample_bytes += b.len();
        if p % 2 == 1 {
            // The low byte of a sample whose high byte ended the previous run.
            self.out[p / 2] |= b[0] as u16;
            b = &b[1..];
            p += 1;
        }
        let pairs = b.len() / 2;
        let dst = &mut self.out[p / 2..p / 2 + pairs];
        for (d, s) in dst.iter_mut().zip(b.chunks_exact(2)) {
            *d = u16::from_be_bytes([s[0], s[1]]);
        }
        if b.len() % 2 == 1 {
            self.out[p / 2 + pairs] = (b[b.len() - 1] as u16) << 8;
        }
    }
}

/// Decodes a whole PNG file held in `png` into `out` (row-major samples, resized to
/// width × height) if it is a 16-bit greyscale, non-interlaced PNG of stored deflate blocks
/// with unfiltered rows and every checksum right; returns (width, height). `None` means
/// "not this kind of file, or damaged": decode it with a general decoder. `out` is
/// unspecified after `None`.
pub fn decode_stored_gray16(png: &[u8], out: &mut Vec<u16>) -> Option<(usize, usize)> {
    let mut rest = png.strip_prefix(SIGNATURE)?;
    let (kind, ihdr) = next_chunk(&mut rest)?;
    if &kind != b"IHDR" || ihdr.len() != 13 {
        return None;
    }
    let width = u32::from_be_bytes(ihdr[0..4].try_into().ok()?) as usize;
    let height = u32::from_be_bytes(ihdr[4..8].try_into().ok()?) as usize;
    // 16-bit, greyscale, deflate, adaptive filtering (method 0), no interlace.
    if ihdr[8..] != [16, 0, 0, 0, 0] || width == 0 || height == 0 {
        return None;
    }
    let mut stream = Stream {
        parts: Vec::new(),
        part: 0,
        offset: 0,
    };
    let mut idat_ended = false;
    loop {
        let (kind, data) = next_chunk(&mut rest)?;
        match &kind {
            b"IDAT" => {
                if idat_ended {
                    return None; // IDAT chunks must be consecutive
                }
                stream.parts.push(data);
            }
            b"IEND" => break,
            // Any other critical chunk (PLTE, a second IHDR, unknown) is left to the decoder.
            k if k[0] & 0x20 == 0 => return None,
            _ => idat_ended |= !stream.parts.is_empty(),
        }
    }
    let pixels = width.checked_mul(height)?;
    let row_len = width.checked_mul(2)?.checked_add(1)?;
    row_len.checked_mul(height)?;
    // Every sample is written below (the image data must be complete), so a buffer of the
    // right size is reused as it is.
    if out.len() != pixels {
        out.clear();
        out.resize(pixels, 0);
    }
    // zlib header: deflate with a window of at most 32 KiB, no preset dictionary.
    let [cmf, flg] = stream.bytes::<2>()?;
    if cmf & 0x0f != 8 || cmf >> 4 > 7 || (u16::from(cmf) * 256 + u16::from(flg)) % 31 != 0 {
        return None;
    }
    if flg & 0x20 != 0 {
        return None;
    }
    let mut lines = Scanlines {
        out,
        row_len,
        in_row: 0,
        sample_bytes: 0,
    };
    let mut adler = simd_adler32::Adler32::new();
    loop {
        // Block header: BFINAL, BTYPE (00 = stored), then padding to the byte boundary.
        let [head] = stream.bytes::<1>()?;
        if (head >> 1) & 3 != 0 {
            return None;
        }
        let [l0, l1, n0, n1] = stream.bytes::<4>()?;
        let len = u16::from_le_bytes([l0, l1]);
        if len != !u16::from_le_bytes([n0, n1]) {
            return None;
        }
        let mut left = len as usize;
        while left > 0 {
            let run = stream.run(left)?;
            adler.write(run);
            lines.feed(run)?;
            left -= run.len();
        }
        if head & 1 == 1 {
            break;
        }
    }
    let check = u32::from_be_bytes(stream.bytes::<4>()?);
    let complete = lines.sample_bytes == 2 * pixels && lines.in_row == 0;
    (check == adler.finish() && complete && stream.at_end()).then_some((width, height))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::encode_png16;
    use camsim_core::RawFrame;

    fn frame(rows: usize, cols: usize) -> RawFrame {
        RawFrame {
            rows,
            cols,
            adc_bits: 16,
            dn: (0..rows * cols)
                .map(|i| (i as u64 * 2_654_435_761 % 65_536) as u16)
                .collect(),
            layout: None,
        }
    }

    /// The same file with its IDAT data re-cut into chunks of `size` bytes (so that block
    /// headers, samples and the Adler-32 straddle chunk boundaries).
    fn recut(png: &[u8], size: usize) -> Vec<u8> {
        let mut rest = &png[8..];
        let mut zlib = Vec::new();
        let mut out = png[..8].to_vec();
        let chunk = |out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]| {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let start = out.len();
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
            let crc = crc32fast::hash(&out[start..]);
            out.extend_from_slice(&crc.to_be_bytes());
        };
        while let Some((kind, data)) = next_chunk(&mut rest) {
            match &kind {
                b"IDAT" => zlib.extend_from_slice(data),
                b"IEND" => {
                    for c in zlib.chunks(size) {
                        chunk(&mut out, b"IDAT", c);
                    }
                    chunk(&mut out, b"tEXt", b"Comment\0ancillary chunks are skipped");
                    chunk(&mut out, b"IEND", &[]);
                }
                _ => chunk(&mut out, &kind, data),
            }
        }
        out
    }

    /// Samples as the general decoder (the `png` crate) reads them.
    fn reference(png: &[u8]) -> Vec<u16> {
        let mut r = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .unwrap();
        let mut buf = vec![0u8; r.output_buffer_size().unwrap()];
        r.next_frame(&mut buf).unwrap();
        buf.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    }

    #[test]
    fn reads_what_the_writer_writes_and_what_the_png_crate_reads() {
        // 300 × 301: rows of 603 bytes, several 65 535-byte blocks ending inside a sample.
        for (rows, cols) in [(1, 1), (3, 5), (300, 301)] {
            let f = frame(rows, cols);
            let png = encode_png16(&f);
            let mut out = vec![7; 3];
            assert_eq!(decode_stored_gray16(&png, &mut out), Some((cols, rows)));
            assert_eq!(out, f.dn);
            for size in [1, 2, 3, 1000, 65_537] {
                let cut = recut(&png, size);
                assert_eq!(reference(&cut), f.dn, "png crate, chunks of {size}");
                let mut again = Vec::new();
                assert_eq!(decode_stored_gray16(&cut, &mut again), Some((cols, rows)));
                assert_eq!(again, f.dn, "chunks of {size}");
            }
        }
    }

    /// A 16-bit greyscale PNG of `width` × `height` from raw scanlines (filter bytes
    /// included), as stored deflate blocks of at most `block` bytes in one IDAT chunk.
    fn stored_png(width: u32, height: u32, scanlines: &[u8], block: usize) -> Vec<u8> {
        let mut zlib = vec![0x78, 0x01];
        let blocks: Vec<&[u8]> = scanlines.chunks(block).collect();
        for (i, b) in blocks.iter().enumerate() {
            zlib.push((i + 1 == blocks.len()) as u8);
            zlib.extend_from_slice(&(b.len() as u16).to_le_bytes());
            zlib.extend_from_slice(&(!(b.len() as u16)).to_le_bytes());
            zlib.extend_from_slice(b);
        }
        let mut a = simd_adler32::Adler32::new();
        a.write(scanlines);
        zlib.extend_from_slice(&a.finish().to_be_bytes());
        let mut out = SIGNATURE.to_vec();
        let mut chunk = |kind: &[u8; 4], data: &[u8]| {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let start = out.len();
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
            let crc = crc32fast::hash(&out[start..]);
            out.extend_from_slice(&crc.to_be_bytes());
        };
        let mut ihdr = width.to_be_bytes().to_vec();
        ihdr.extend_from_slice(&height.to_be_bytes());
        ihdr.extend_from_slice(&[16, 0, 0, 0, 0]);
        chunk(b"IHDR", &ihdr);
        chunk(b"IDAT", &zlib);
        chunk(b"IEND", &[]);
        out
    }

    #[test]
    fn leaves_every_other_or_damaged_file_to_the_general_decoder() {
        let (rows, cols) = (40usize, 30usize);
        let f = frame(rows, cols);
        let png = encode_png16(&f);
        let mut out = Vec::new();
        let refused = |bytes: &[u8]| decode_stored_gray16(bytes, &mut Vec::new()).is_none();
        assert!(decode_stored_gray16(&png, &mut out).is_some());
        // The png crate's encoder: uncompressed 16-bit is this kind of file (read); a
        // compressed one and an 8-bit one are not.
        let encode = |depth: png::BitDepth, compression| {
            let mut v = Vec::new();
            let mut e = png::Encoder::new(&mut v, cols as u32, rows as u32);
            e.set_color(png::ColorType::Grayscale);
            e.set_depth(depth);
            e.set_compression(compression);
            let bytes: Vec<u8> = match depth {
                png::BitDepth::Sixteen => f.dn.iter().flat_map(|v| v.to_be_bytes()).collect(),
                _ => f.dn.iter().map(|&v| (v >> 8) as u8).collect(),
            };
            e.write_header().unwrap().write_image_data(&bytes).unwrap();
            v
        };
        use png::{BitDepth, Compression};
        let plain = encode(BitDepth::Sixteen, Compression::NoCompression);
        let mut again = Vec::new();
        assert_eq!(decode_stored_gray16(&plain, &mut again), Some((cols, rows)));
        assert_eq!(again, f.dn);
        assert!(refused(&encode(BitDepth::Sixteen, Compression::Balanced)));
        assert!(refused(&encode(
            BitDepth::Eight,
            Compression::NoCompression
        )));
        // Hand-made stored files: the scanlines as they are (read), a row with the Sub
        // filter (a real decoder reads other samples: refused), a row too many or a byte short.
        let lines: Vec<u8> =
            f.dn.chunks(cols)
                .flat_map(|r| std::iter::once(0).chain(r.iter().flat_map(|v| v.to_be_bytes())))
                .collect();
        let made = stored_png(cols as u32, rows as u32, &lines, 777);
        assert_eq!(reference(&made), f.dn);
        assert_eq!(decode_stored_gray16(&made, &mut again), Some((cols, rows)));
        assert_eq!(again, f.dn);
        let mut sub = lines.clone();
        sub[2 * (1 + 2 * cols)] = 1; // row 2: Sub
        let filtered = stored_png(cols as u32, rows as u32, &sub, 777);
        assert_ne!(reference(&filtered), f.dn);
        assert!(refused(&filtered));
        let mut long = lines.clone();
        long.extend_from_slice(&lines[..1 + 2 * cols]);
        assert!(refused(&stored_png(cols as u32, rows as u32, &long, 777)));
        let short = &lines[..lines.len() - 1];
        assert!(refused(&stored_png(cols as u32, rows as u32, short, 777)));
        // Every single damaged byte after the signature (every 7th): refused.
        for i in (8..png.len()).step_by(7) {
            let mut bad = png.clone();
            bad[i] ^= 0x10;
            assert!(refused(&bad), "byte {i} damaged, still accepted");
        }
        // Truncated files.
        for n in [0, 8, 40, png.len() / 2, png.len() - 1] {
            assert!(refused(&png[..n]));
        }
        assert_eq!(out, f.dn);
    }
}
