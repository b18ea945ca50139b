//! Recorded-frame formats read back exactly: DNG (written here with the `tiff` crate's encoder
//! in the machine's byte order, and with a small hand-made TIFF writer for big-endian files
//! and for malformed directories) and headerless raw. Bad files give one error that names the
//! file and the offending tag or size. A `captures.json` whose frames are `.dng` calibrates to
//! the same numbers as the same frames stored as PNG.
use crate::cli::{camera, write_set};
use crate::util::{camsim, camsim_ok};
use camsim_pipeline::raw_input::{dng::read_dng, read_frame, read_raw, RawFormat};
use serde_json::{json, Value};
use std::io::Cursor;
use std::path::Path;
use tiff::encoder::{colortype, TiffEncoder};
use tiff::tags::Tag;

/// What a test DNG holds (stored image, before the active-area crop).
#[derive(Clone)]
struct Spec {
    rows: u32,
    cols: u32,
    bits: u16,
    dn: Vec<u16>,
    /// CFARepeatPatternDim and CFAPattern (DNG colour codes 0 = R, 1 = G, 2 = B)
    cfa_dim: [u16; 2],
    cfa: Vec<u8>,
    black_dim: Option<[u16; 2]>,
    black: Option<Vec<u32>>,
    white: Option<u32>,
    active_area: Option<[u32; 4]>,
}

/// A deterministic test pattern that uses the whole code range of `bits`.
fn pattern(rows: u32, cols: u32, bits: u16) -> Vec<u16> {
    let max = (1u64 << bits) - 1;
    (0..(rows * cols) as u64)
        .map(|i| ((i * 2654435761 + 17) % (max + 1)) as u16)
        .collect()
}

fn bayer_spec(rows: u32, cols: u32, bits: u16) -> Spec {
    Spec {
        rows,
        cols,
        bits,
        dn: pattern(rows, cols, bits),
        cfa_dim: [2, 2],
        cfa: vec![1, 2, 0, 1], // GBRG
        black_dim: None,
        black: None,
        white: None,
        active_area: None,
    }
}

const DNG_VERSION: [u8; 4] = [1, 4, 0, 0];

/// Write `s` as IFD 0 with the `tiff` crate's encoder (native byte order); `extra` tags are
/// written last and replace any written before (e.g. Compression, PhotometricInterpretation).
fn write_dng_tiff(path: &Path, s: &Spec, extra: &[(u16, u16)]) {
    let mut buf = Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut buf).unwrap();
        macro_rules! tags {
            ($img:expr) => {{
                let e = $img.encoder();
                e.write_tag(Tag::PhotometricInterpretation, 32803u16)
                    .unwrap();
                e.write_tag(Tag::Unknown(50706), &DNG_VERSION[..]).unwrap();
                e.write_tag(Tag::Unknown(33421), &s.cfa_dim[..]).unwrap();
                e.write_tag(Tag::Unknown(33422), &s.cfa[..]).unwrap();
                if let Some(d) = s.black_dim {
                    e.write_tag(Tag::Unknown(50713), &d[..]).unwrap();
                }
                if let Some(b) = &s.black {
                    e.write_tag(Tag::Unknown(50714), &b[..]).unwrap();
                }
                if let Some(w) = s.white {
                    e.write_tag(Tag::Unknown(50717), w).unwrap();
                }
                if let Some(a) = s.active_area {
                    e.write_tag(Tag::Unknown(50829), &a[..]).unwrap();
                }
                for &(t, v) in extra {
                    e.write_tag(Tag::from_u16_exhaustive(t), v).unwrap();
                }
            }};
        }
        if s.bits == 8 {
            let mut img = enc.new_image::<colortype::Gray8>(s.cols, s.rows).unwrap();
            tags!(img);
            let d8: Vec<u8> = s.dn.iter().map(|&v| v as u8).collect();
            img.write_data(&d8).unwrap();
        } else {
            let mut img = enc.new_image::<colortype::Gray16>(s.cols, s.rows).unwrap();
            tags!(img);
            // small strips: exercises the multi-strip path
            img.rows_per_strip(3).unwrap();
            img.write_data(&s.dn).unwrap();
        }
    }
    std::fs::write(path, buf.into_inner()).unwrap();
}

/// One IFD entry for the hand-made writer: tag, TIFF type (1 BYTE, 3 SHORT, 4 LONG), values.
type Entry = (u16, u16, Vec<u32>);

/// A minimal classic-TIFF writer for either byte order: IFD 0 right after the header, then the
/// entries' out-of-line values, then the sample data (so truncating the file cuts the data).
/// `StripOffsets` (273) is filled in by the writer; `image` is the sample bytes in file order.
fn write_tiff_by_hand(path: &Path, big_endian: bool, entries: &[Entry], image: &[u8]) {
    let u16b = |v: u16| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let u32b = |v: u32| {
        if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        }
    };
    let mut entries: Vec<Entry> = entries.to_vec();
    entries.push((273, 4, vec![0]));
    entries.sort_by_key(|e| e.0);
    let ifd_len = 2 + 12 * entries.len() + 4;
    let size = |ty: u16| {
        if ty == 1 {
            1
        } else if ty == 3 {
            2
        } else {
            4
        }
    };
    let mut extra_at = 8 + ifd_len;
    let extra_len: usize = entries
        .iter()
        .map(|(_, ty, v)| {
            let n = size(*ty) * v.len();
            if n > 4 {
                n + n % 2
            } else {
                0
            }
        })
        .sum();
    let data_at = (8 + ifd_len + extra_len) as u32;
    let mut out: Vec<u8> = if big_endian {
        b"MM\0\x2a".to_vec()
    } else {
        b"II\x2a\0".to_vec()
    };
    out.extend(u32b(8));
    let mut extra = Vec::new();
    out.extend(u16b(entries.len() as u16));
    for (tag, ty, vals) in &entries {
        let vals = if *tag == 273 {
            vec![data_at]
        } else {
            vals.clone()
        };
        let mut bytes = Vec::new();
        for v in &vals {
            match ty {
                1 => bytes.push(*v as u8),
                3 => bytes.extend(u16b(*v as u16)),
                _ => bytes.extend(u32b(*v)),
            }
        }
        out.extend(u16b(*tag));
        out.extend(u16b(*ty));
        out.extend(u32b(vals.len() as u32));
        if bytes.len() <= 4 {
            bytes.resize(4, 0);
            out.extend(bytes);
        } else {
            out.extend(u32b(extra_at as u32));
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            extra_at += bytes.len();
            extra.extend(bytes);
        }
    }
    out.extend(u32b(0));
    out.extend(extra);
    assert_eq!(out.len() as u32, data_at);
    out.extend_from_slice(image);
    std::fs::write(path, out).unwrap();
}

/// The DNG entries of `s` for the hand-made writer (one strip).
fn dng_entries(s: &Spec) -> Vec<Entry> {
    let bps = (s.bits / 8) as u32;
    let mut e: Vec<Entry> = vec![
        (254, 4, vec![0]),
        (256, 4, vec![s.cols]),
        (257, 4, vec![s.rows]),
        (258, 3, vec![s.bits as u32]),
        (259, 3, vec![1]),
        (262, 3, vec![32803]),
        (277, 3, vec![1]),
        (278, 4, vec![s.rows]),
        (279, 4, vec![s.rows * s.cols * bps]),
        (33421, 3, s.cfa_dim.iter().map(|&v| v as u32).collect()),
        (33422, 1, s.cfa.iter().map(|&v| v as u32).collect()),
        (50706, 1, DNG_VERSION.iter().map(|&v| v as u32).collect()),
    ];
    if let Some(d) = s.black_dim {
        e.push((50713, 3, d.iter().map(|&v| v as u32).collect()));
    }
    if let Some(b) = &s.black {
        e.push((50714, 4, b.clone()));
    }
    if let Some(w) = s.white {
        e.push((50717, 4, vec![w]));
    }
    if let Some(a) = s.active_area {
        e.push((50829, 4, a.to_vec()));
    }
    e
}

fn sample_bytes(s: &Spec, big_endian: bool) -> Vec<u8> {
    let mut b = Vec::new();
    for &v in &s.dn {
        if s.bits == 8 {
            b.push(v as u8);
        } else if big_endian {
            b.extend(v.to_be_bytes());
        } else {
            b.extend(v.to_le_bytes());
        }
    }
    b
}

/// The active area of `s` (row-major), as the reader must return it.
fn active(s: &Spec) -> (usize, usize, Vec<u16>) {
    let [t, l, b, r] = s.active_area.unwrap_or([0, 0, s.rows, s.cols]);
    let mut v = Vec::new();
    for row in t..b {
        for col in l..r {
            v.push(s.dn[(row * s.cols + col) as usize]);
        }
    }
    ((b - t) as usize, (r - l) as usize, v)
}

#[test]
fn dng_written_by_the_tiff_encoder_reads_back_exactly() {
    let d = tempfile::tempdir().unwrap();
    // 16 bit, 2×2 black-level cell, white level, active area at an odd offset (the CFA and
    // black patterns start at the active area's corner, DNG spec).
    let mut s = bayer_spec(13, 17, 16);
    s.white = Some(60000);
    s.black_dim = Some([2, 2]);
    s.black = Some(vec![510, 512, 514, 516]);
    s.active_area = Some([1, 3, 12, 16]);
    s.dn = s.dn.iter().map(|&v| v.min(60000)).collect();
    let p = d.path().join("a16.dng");
    write_dng_tiff(&p, &s, &[]);
    let f = read_dng(&p).unwrap();
    let (ar, ac, want) = active(&s);
    assert_eq!((f.frame.rows, f.frame.cols), (ar, ac));
    assert_eq!(f.frame.dn, want);
    assert_eq!(f.frame.adc_bits, 16, "60000 needs 16 bits");
    assert_eq!(f.info.cfa, vec!["gb".to_string(), "rg".to_string()]);
    assert_eq!(f.info.black_level_dn, vec![510.0, 512.0, 514.0, 516.0]);
    assert_eq!(f.info.black_level_at(1, 1), 516.0);
    assert_eq!(f.info.black_level_at(2, 3), 512.0);
    assert_eq!(f.info.mean_black_level_dn(), 513.0);
    assert_eq!(f.info.white_level, 60000);
    assert_eq!(f.info.active_area, [1, 3, 12, 16]);
    assert_eq!((f.info.stored_rows, f.info.stored_cols), (13, 17));
    assert_eq!(f.info.bits_per_sample, 16);
    // the generic frame reader dispatches on the extension
    assert_eq!(read_frame(&p).unwrap().dn, want);

    // 8 bit, RGGB, one black level, no white level: white = 255.
    let mut s8 = bayer_spec(6, 10, 8);
    s8.cfa = vec![0, 1, 1, 2];
    s8.black = Some(vec![16]);
    let p8 = d.path().join("a8.dng");
    write_dng_tiff(&p8, &s8, &[]);
    let f8 = read_dng(&p8).unwrap();
    assert_eq!(f8.frame.dn, s8.dn);
    assert_eq!(f8.frame.adc_bits, 8);
    assert_eq!(f8.info.white_level, 255);
    assert_eq!(f8.info.cfa, vec!["rg".to_string(), "gb".to_string()]);
    assert_eq!(f8.info.black_level_dn, vec![16.0]);
    assert_eq!(f8.info.black_level_at(3, 7), 16.0);
    // a 12-bit camera in 16-bit containers: WhiteLevel 4095 → 12 ADC bits
    let mut s12 = bayer_spec(4, 6, 16);
    s12.dn = pattern(4, 6, 12);
    s12.white = Some(4095);
    let p12 = d.path().join("a12.dng");
    write_dng_tiff(&p12, &s12, &[]);
    let f12 = read_dng(&p12).unwrap();
    assert_eq!(f12.frame.adc_bits, 12);
    assert_eq!(f12.frame.dn, s12.dn);
}

#[test]
fn dng_big_and_little_endian_by_hand_read_back_exactly() {
    let d = tempfile::tempdir().unwrap();
    for big in [false, true] {
        for bits in [8u16, 16] {
            let mut s = bayer_spec(7, 9, bits);
            s.cfa = vec![2, 1, 1, 0]; // BGGR
            s.active_area = Some([0, 1, 7, 9]);
            s.black = Some(vec![bits as u32 * 4]);
            let p = d.path().join(format!("h{bits}{big}.dng"));
            write_tiff_by_hand(&p, big, &dng_entries(&s), &sample_bytes(&s, big));
            let f = read_dng(&p).unwrap_or_else(|e| panic!("{e}"));
            let (ar, ac, want) = active(&s);
            assert_eq!(
                (f.frame.rows, f.frame.cols),
                (ar, ac),
                "{bits} bit, big {big}"
            );
            assert_eq!(f.frame.dn, want, "{bits} bit, big-endian {big}");
            // the CFA pattern starts at the active area's corner: column 1 of BGGR is "gb"
            assert_eq!(f.info.cfa, vec!["bg".to_string(), "gr".to_string()]);
            assert_eq!(f.info.black_level_dn, vec![bits as f64 * 4.0]);
        }
    }
}

fn err_of(p: &Path) -> String {
    match read_dng(p) {
        Ok(_) => panic!("{} was accepted", p.display()),
        Err(e) => e.one_line(),
    }
}

#[test]
fn malformed_and_unsupported_dng_give_one_error_naming_file_and_tag() {
    let d = tempfile::tempdir().unwrap();
    let s = bayer_spec(6, 8, 16);
    let check = |name: &str, msg: &str, wants: &[&str]| {
        assert!(msg.contains(name), "error does not name the file: {msg}");
        assert!(!msg.contains('\n'));
        for w in wants {
            assert!(msg.contains(w), "{name}: expected \"{w}\" in: {msg}");
        }
    };
    // compressed (lossless JPEG) → Compression tag named
    let p = d.path().join("ljpeg.dng");
    write_dng_tiff(&p, &s, &[(259, 7)]);
    check(
        "ljpeg.dng",
        &err_of(&p),
        &["Compression (259)", "lossless JPEG"],
    );
    // LinearRaw (demosaicked) DNG
    let p = d.path().join("linear.dng");
    write_dng_tiff(&p, &s, &[(262, 34892)]);
    check("linear.dng", &err_of(&p), &["34892", "LinearRaw"]);
    // a plain TIFF is not a DNG
    let p = d.path().join("plain.dng");
    let mut b = Cursor::new(Vec::new());
    TiffEncoder::new(&mut b)
        .unwrap()
        .write_image::<colortype::Gray16>(8, 6, &s.dn)
        .unwrap();
    std::fs::write(&p, b.into_inner()).unwrap();
    check("plain.dng", &err_of(&p), &["DNGVersion", "50706"]);
    // not a TIFF at all
    let p = d.path().join("garbage.dng");
    std::fs::write(&p, b"this is not a tiff file at all").unwrap();
    check("garbage.dng", &err_of(&p), &["not a readable DNG/TIFF"]);
    // truncated: the tiff encoder puts IFD 0 at the end, so half the file has no directory
    let p = d.path().join("cut_ifd.dng");
    write_dng_tiff(&p, &s, &[]);
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    check("cut_ifd.dng", &err_of(&p), &["not a readable DNG/TIFF"]);
    // truncated image data (directory intact): the strip offsets are named
    let p = d.path().join("cut_data.dng");
    let img = sample_bytes(&s, false);
    write_tiff_by_hand(&p, false, &dng_entries(&s), &img[..img.len() - 10]);
    check(
        "cut_data.dng",
        &err_of(&p),
        &["StripOffsets (273)", "beyond"],
    );
    // hand-made variants with one tag wrong
    let variants: Vec<(&str, Box<dyn Fn(&mut Vec<Entry>)>, Vec<&str>)> = vec![
        (
            "bits12",
            Box::new(|e: &mut Vec<Entry>| e.iter_mut().find(|x| x.0 == 258).unwrap().2 = vec![12]),
            vec!["BitsPerSample (258)", "12"],
        ),
        (
            "nocfa",
            Box::new(|e: &mut Vec<Entry>| e.retain(|x| x.0 != 33422)),
            vec!["CFAPattern (33422) is missing"],
        ),
        (
            "cfacount",
            Box::new(|e: &mut Vec<Entry>| {
                e.iter_mut().find(|x| x.0 == 33422).unwrap().2 = vec![0, 1, 2]
            }),
            vec!["CFAPattern (33422)", "3 entries"],
        ),
        (
            "cfacode",
            Box::new(|e: &mut Vec<Entry>| {
                e.iter_mut().find(|x| x.0 == 33422).unwrap().2 = vec![0, 1, 9, 2]
            }),
            vec!["CFAPattern (33422)", "colour code 9"],
        ),
        (
            "area",
            Box::new(|e: &mut Vec<Entry>| e.push((50829, 4, vec![0, 0, 7, 8]))),
            vec!["ActiveArea (50829)", "6×8"],
        ),
        (
            "blackcount",
            Box::new(|e: &mut Vec<Entry>| {
                e.push((50713, 3, vec![2, 2]));
                e.push((50714, 4, vec![1, 2, 3]));
            }),
            vec!["BlackLevel (50714)", "3 values", "2×2"],
        ),
        (
            "white",
            Box::new(|e: &mut Vec<Entry>| {
                e.iter_mut().find(|x| x.0 == 258).unwrap().2 = vec![8];
                e.iter_mut().find(|x| x.0 == 279).unwrap().2 = vec![48];
                e.push((50717, 4, vec![1000]));
            }),
            vec!["WhiteLevel (50717)", "1000"],
        ),
        (
            "spp",
            Box::new(|e: &mut Vec<Entry>| e.iter_mut().find(|x| x.0 == 277).unwrap().2 = vec![3]),
            vec!["SamplesPerPixel", "277"],
        ),
        (
            "layout",
            Box::new(|e: &mut Vec<Entry>| e.push((50711, 3, vec![2]))),
            vec!["CFALayout (50711)"],
        ),
        (
            "stripcount",
            Box::new(|e: &mut Vec<Entry>| e.iter_mut().find(|x| x.0 == 279).unwrap().2 = vec![20]),
            vec!["StripByteCounts (279)"],
        ),
    ];
    for (name, modify, wants) in variants {
        let mut e = dng_entries(&s);
        modify(&mut e);
        let file = format!("{name}.dng");
        let p = d.path().join(&file);
        write_tiff_by_hand(&p, true, &e, &sample_bytes(&s, true));
        check(&file, &err_of(&p), &wants);
    }
    // an unknown extension is refused by the frame reader, naming what is supported
    let p = d.path().join("frame.cr2");
    std::fs::write(&p, b"x").unwrap();
    let e = read_frame(&p).unwrap_err().one_line();
    check("frame.cr2", &e, &[".cr2", ".dng"]);
}

#[test]
fn headerless_raw_round_trips_in_every_layout_and_bad_size_is_named() {
    let d = tempfile::tempdir().unwrap();
    let (rows, cols) = (5usize, 7usize);
    for (bytes_per_sample, little_endian, header_bytes) in
        [(1, true, 0u64), (2, true, 0), (2, false, 0), (2, true, 16)]
    {
        let bits = (bytes_per_sample * 8) as u16;
        let dn = pattern(rows as u32, cols as u32, bits);
        let mut b = vec![0xABu8; header_bytes as usize];
        for &v in &dn {
            match (bytes_per_sample, little_endian) {
                (1, _) => b.push(v as u8),
                (_, true) => b.extend(v.to_le_bytes()),
                _ => b.extend(v.to_be_bytes()),
            }
        }
        let p = d
            .path()
            .join(format!("f{bits}{little_endian}{header_bytes}.raw"));
        std::fs::write(&p, &b).unwrap();
        let fmt = RawFormat {
            rows,
            cols,
            bytes_per_sample,
            little_endian,
            header_bytes,
        };
        let f = read_raw(&p, &fmt).unwrap();
        assert_eq!((f.rows, f.cols, f.adc_bits), (rows, cols, bits as u32));
        assert_eq!(f.dn, dn, "{bits} bit, little {little_endian}");
        // the opposite byte order reads different numbers (so the test can tell them apart)
        if bytes_per_sample == 2 {
            let swapped = RawFormat {
                little_endian: !little_endian,
                ..fmt
            };
            assert_ne!(read_raw(&p, &swapped).unwrap().dn, dn);
        }
        // one byte short → error naming the file and both sizes
        std::fs::write(&p, &b[..b.len() - 1]).unwrap();
        let e = read_raw(&p, &fmt).unwrap_err().one_line();
        assert!(
            e.contains(&p.file_name().unwrap().to_string_lossy().to_string())
                && e.contains(&format!("{} bytes", b.len() - 1))
                && e.contains(&format!("needs {}", b.len())),
            "{e}"
        );
    }
}

/// Calibrate a simulated set twice — frames as written (PNG) and the same DN re-stored as
/// 16-bit DNGs with black/white levels and a masked border cropped by ActiveArea — and get the
/// same calibration.
#[test]
fn calibrate_reads_dng_frames_end_to_end() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let mut cam = camera(24, 32);
    cam["optics"]["relative_illumination"] = json!("none");
    let radiance = json!({"wavelength_nm": [400, 700], "values": [0.002, 0.002]});
    let mut shots = Vec::new();
    for t in [0.01, 0.3] {
        shots.push(
            json!({"id": format!("dark-{t}"), "target": {"kind": "dark"}, "exposure_s": t,
            "frames": [format!("raw/dark-{t}-0.png"), format!("raw/dark-{t}-1.png")]}),
        );
    }
    for t in [0.004, 0.008, 0.016] {
        shots.push(json!({"id": format!("flat-{t}"), "exposure_s": t,
            "target": {"kind": "uniform", "radiance": radiance},
            "frames": [format!("raw/flat-{t}-0.png"), format!("raw/flat-{t}-1.png")]}));
    }
    let caps = json!({"camera": "camera.json", "shots": shots});
    write_set(dir, &cam, &caps);
    camsim_ok(
        camsim()
            .args(["simulate", "captures.json", "--out", ".", "--seed", "5"])
            .current_dir(dir),
    );
    // re-store every frame as a DNG with a 2-pixel masked border around the active area
    let mut dng_caps = caps.clone();
    for shot in dng_caps["shots"].as_array_mut().unwrap() {
        for f in shot["frames"].as_array_mut().unwrap() {
            let png = f.as_str().unwrap().to_string();
            let frame = read_frame(&dir.join(&png)).unwrap();
            let (rows, cols) = (frame.rows as u32 + 4, frame.cols as u32 + 4);
            let mut dn = vec![7u16; (rows * cols) as usize];
            for r in 0..frame.rows {
                for c in 0..frame.cols {
                    dn[(r + 2) * cols as usize + c + 2] = frame.dn[r * frame.cols + c];
                }
            }
            let s = Spec {
                rows,
                cols,
                bits: 16,
                dn,
                cfa_dim: [2, 2],
                cfa: vec![1, 2, 0, 1],
                black_dim: None,
                black: Some(vec![64]),
                white: Some(4095),
                active_area: Some([2, 2, rows - 2, cols - 2]),
            };
            let name = png.replace(".png", ".dng");
            write_dng_tiff(&dir.join(&name), &s, &[]);
            *f = Value::String(name);
        }
    }
    std::fs::write(dir.join("captures_dng.json"), dng_caps.to_string()).unwrap();
    let run = |caps: &str, out: &str| -> Value {
        camsim_ok(
            camsim()
                .args(["calibrate", caps, "--out", out])
                .current_dir(dir),
        );
        serde_json::from_str(
            &std::fs::read_to_string(dir.join(out).join("calibration.json")).unwrap(),
        )
        .unwrap()
    };
    let a = run("captures.json", "cal_png");
    let b = run("captures_dng.json", "cal_dng");
    for k in [
        "black_level_dn",
        "dark_voltage_v_per_s",
        "read_noise_v",
        "dsnu_sigma_v",
        "prnu_sigma_percent",
        "conversion_gain_v_per_e",
    ] {
        assert_eq!(a[k]["status"], "estimated", "{k}: {}", a[k]);
        assert_eq!(a[k], b[k], "{k} differs between PNG and DNG frames");
    }
    // and the estimates are of this camera (black level 64 DN, gain 5e-5 V/e⁻)
    let bl = b["black_level_dn"]["value"].as_f64().unwrap();
    assert!((bl - 64.0).abs() < 2.0, "black level {bl}");
    // a DNG frame of the wrong size is one error naming the frame and both sizes (issue 16:
    // calibrate used to exit 0 and mention it only in its report), and nothing is written
    let mut bad = dng_caps.clone();
    let mut s = bayer_spec(10, 10, 16);
    s.dn = pattern(10, 10, 12);
    write_dng_tiff(&dir.join("raw/small.dng"), &s, &[]);
    bad["shots"][2]["frames"][0] = json!("raw/small.dng");
    std::fs::write(dir.join("captures_bad.json"), bad.to_string()).unwrap();
    let set = camsim_pipeline::config::load_captures(&dir.join("captures_bad.json"), None).unwrap();
    let e = camsim_pipeline::calibrate_cmd::run_calibrate(&set, &dir.join("cal_bad"), false)
        .unwrap_err()
        .one_line();
    assert!(e.contains("small.dng") && e.contains("10×10"), "{e}");
    assert!(!dir.join("cal_bad").exists());
}
