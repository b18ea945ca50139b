//! `camsim develop`: DNG and headerless raw development. A neutral field renders as the
//! neutral of the closed form; the real Bayer mosaic of ../shared developed by camsim and by
//! LibRaw (rawpy) agrees to mean ΔE2000 ≤ 1; bad raw files give one clear error line and
//! write nothing.
use crate::util::camsim;
use camsim_metrics::delta_e_2000;
use camsim_pipeline::color_eval::linear_srgb_to_lab;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The real mosaic (MIT, mushfiqulalam/isp; README of ../shared/data/real): 768×512 crop of
/// a 14-bit Nikon NEF, RGGB, black 600, white 15520 (values of the upstream code).
fn real_mosaic() -> PathBuf {
    repo()
        .join("../shared/data/real/captures/mushfiqulalam_bayer/DSC_1339_768x512_rggb_uint16le.raw")
}
const REAL_ROWS: usize = 512;
const REAL_COLS: usize = 768;

/// An XYZ → camera matrix of a typical DSLR (row-major), used as ColorMatrix1 (D65).
const CM: [f64; 9] = [
    0.8139, -0.2171, -0.0663, -0.8747, 1.6541, 0.2295, -0.1925, 0.2008, 0.8093,
];

/// One IFD entry: tag, TIFF type, values (as u32 for SHORT/LONG, or (num, den) for rationals).
enum V {
    Short(Vec<u16>),
    Long(Vec<u32>),
    Byte(Vec<u8>),
    Rational(Vec<(u32, u32)>),
    SRational(Vec<(i32, i32)>),
}

/// A little-endian, one-strip DNG with the given tags (the strip offset tag 273 is filled in).
fn write_dng(path: &Path, rows: usize, cols: usize, data: &[u16], mut tags: Vec<(u16, V)>) {
    let image: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    tags.push((273, V::Long(vec![0])));
    tags.push((279, V::Long(vec![image.len() as u32])));
    tags.push((256, V::Long(vec![cols as u32])));
    tags.push((257, V::Long(vec![rows as u32])));
    tags.push((278, V::Long(vec![rows as u32])));
    tags.sort_by_key(|t| t.0);
    let n = tags.len();
    let ifd_len = 2 + 12 * n + 4;
    let mut extra: Vec<u8> = vec![];
    let extra_at = 8 + ifd_len;
    let mut entries: Vec<u8> = vec![];
    let mut strip_entry = None;
    for (tag, v) in &tags {
        let (ty, count, bytes): (u16, usize, Vec<u8>) = match v {
            V::Short(x) => (3, x.len(), x.iter().flat_map(|a| a.to_le_bytes()).collect()),
            V::Long(x) => (4, x.len(), x.iter().flat_map(|a| a.to_le_bytes()).collect()),
            V::Byte(x) => (1, x.len(), x.clone()),
            V::Rational(x) => (
                5,
                x.len(),
                x.iter()
                    .flat_map(|(a, b)| [a.to_le_bytes(), b.to_le_bytes()].concat())
                    .collect(),
            ),
            V::SRational(x) => (
                10,
                x.len(),
                x.iter()
                    .flat_map(|(a, b)| [a.to_le_bytes(), b.to_le_bytes()].concat())
                    .collect(),
            ),
        };
        entries.extend_from_slice(&tag.to_le_bytes());
        entries.extend_from_slice(&ty.to_le_bytes());
        entries.extend_from_slice(&(count as u32).to_le_bytes());
        if *tag == 273 {
            strip_entry = Some(entries.len());
        }
        if bytes.len() <= 4 {
            let mut b = bytes.clone();
            b.resize(4, 0);
            entries.extend_from_slice(&b);
        } else {
            entries.extend_from_slice(&((extra_at + extra.len()) as u32).to_le_bytes());
            extra.extend_from_slice(&bytes);
            if extra.len() % 2 == 1 {
                extra.push(0);
            }
        }
    }
    let image_at = (extra_at + extra.len()) as u32;
    let s = strip_entry.unwrap();
    entries[s..s + 4].copy_from_slice(&image_at.to_le_bytes());
    let mut out = b"II*\0".to_vec();
    out.extend_from_slice(&8u32.to_le_bytes());
    out.extend_from_slice(&(n as u16).to_le_bytes());
    out.extend_from_slice(&entries);
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&extra);
    out.extend_from_slice(&image);
    std::fs::write(path, out).unwrap();
}

fn rat(x: f64) -> (i32, i32) {
    ((x * 10000.0).round() as i32, 10000)
}

/// The standard tags of a 16-bit RGGB DNG with ColorMatrix1 = CM (D65) and a neutral.
fn colour_tags(black: u16, white: u16, neutral: [f64; 3]) -> Vec<(u16, V)> {
    vec![
        (254, V::Long(vec![0])),
        (258, V::Short(vec![16])),
        (259, V::Short(vec![1])),
        (262, V::Short(vec![32803])),
        (277, V::Short(vec![1])),
        (33421, V::Short(vec![2, 2])),
        (33422, V::Byte(vec![0, 1, 1, 2])),
        (50706, V::Byte(vec![1, 4, 0, 0])),
        (50714, V::Short(vec![black])),
        (50717, V::Short(vec![white])),
        (50721, V::SRational(CM.iter().map(|&x| rat(x)).collect())),
        (
            50728,
            V::Rational(
                neutral
                    .iter()
                    .map(|&x| ((x * 10000.0).round() as u32, 10000))
                    .collect(),
            ),
        ),
        (50778, V::Short(vec![21])),
    ]
}

/// Camera response to the D65 white (CM · XYZ_D65), the neutral of a D65 scene.
fn d65_neutral() -> [f64; 3] {
    let w = [0.3127 / 0.3290, 1.0, (1.0 - 0.3127 - 0.3290) / 0.3290];
    let v: Vec<f64> = (0..3)
        .map(|i| (0..3).map(|j| CM[3 * i + j] * w[j]).sum())
        .collect();
    let mx = v.iter().cloned().fold(0.0, f64::max);
    [v[0] / mx, v[1] / mx, v[2] / mx]
}

fn read_png16(p: &Path) -> (usize, usize, Vec<[f64; 3]>) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
    let px = buf[..info.buffer_size()]
        .chunks_exact(6)
        .map(|c| {
            [0, 1, 2].map(|k| {
                camsim_isp::srgb_decode(
                    u16::from_be_bytes([c[2 * k], c[2 * k + 1]]) as f64 / 65535.0,
                )
            })
        })
        .collect();
    (info.height as usize, info.width as usize, px)
}

fn develop_ok(args: &[&str]) -> String {
    let o = camsim().arg("develop").args(args).output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(o.status.success(), "camsim develop {args:?}: {e}");
    e
}

/// A neutral field (the camera's D65 neutral at 40 % of the white level) renders as the sRGB
/// neutral of luminance 0.4 (closed form of the DNG chain: white balance makes the three
/// channels 0.4, the normalised matrix maps WB'd (1, 1, 1) to sRGB white).
#[test]
fn develop_renders_a_neutral_dng_field_as_the_closed_form_grey() {
    let d = tempfile::tempdir().unwrap();
    let (rows, cols, black, white) = (16usize, 20usize, 64u16, 4095u16);
    let n = d65_neutral();
    let level = 0.4;
    let data: Vec<u16> = (0..rows * cols)
        .map(|i| {
            let k = match ((i / cols) % 2, (i % cols) % 2) {
                (0, 0) => 0,
                (1, 1) => 2,
                _ => 1,
            };
            (black as f64 + level * n[k] * (white - black) as f64).round() as u16
        })
        .collect();
    let p = d.path().join("grey.dng");
    write_dng(&p, rows, cols, &data, colour_tags(black, white, n));
    let out = d.path().join("grey.png");
    develop_ok(&[
        p.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--bits",
        "16",
    ]);
    let (r, c, px) = read_png16(&out);
    assert_eq!((r, c), (rows, cols));
    for (i, v) in px.iter().enumerate() {
        for k in 0..3 {
            // DN rounding (±0.5 DN of 4031) and 16-bit coding
            assert!(
                (v[k] - level).abs() < 5e-3,
                "pixel {i} channel {k}: {} vs {level}",
                v[k]
            );
        }
    }
}

/// camsim develop against LibRaw (rawpy, bilinear "LINEAR" demosaic, same DNG white balance
/// and ColorMatrix, highlight clip, no auto-brightening) on DNGs built by pidng from the real
/// Bayer mosaic: mean ΔE2000 ≤ 1 over the image (a 4-pixel border excluded, where the two
/// demosaics treat borders differently). White balances: the D65 neutral of the matrix, and a
/// tungsten-like neutral with camsim in LibRaw's convention (`--adaptation camera`: von Kries
/// in camera space); with the DNG specification's Bradford adaptation the tungsten case is
/// reported, and must differ.
#[test]
fn develop_agrees_with_libraw_on_the_real_bayer_mosaic() {
    let setup = std::process::Command::new("bash")
        .arg(repo().join("tools/libraw_setup.sh"))
        .output()
        .unwrap();
    assert!(
        setup.status.success(),
        "tools/libraw_setup.sh failed: {}",
        String::from_utf8_lossy(&setup.stderr)
    );
    let python = std::env::var_os("CAMSIM_LIBRAW_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".venv-libraw"))
        .join("bin/python");
    let d = tempfile::tempdir().unwrap();
    let cm: Vec<String> = CM.iter().map(|x| format!("{x}")).collect();
    let n65 = d65_neutral();
    let tungsten = [0.75, 1.0, 0.42];
    let mut report = vec![];
    for (name, n, adaptation) in [
        ("d65", n65, "bradford"),
        ("tungsten", tungsten, "camera"),
        ("tungsten_bradford", tungsten, "bradford"),
    ] {
        let dng = d.path().join(format!("{name}.dng"));
        let lr = d.path().join(format!("{name}.u16"));
        let o = std::process::Command::new(&python)
            .arg(repo().join("tools/libraw_develop.py"))
            .arg(real_mosaic())
            .args([
                &REAL_ROWS.to_string(),
                &REAL_COLS.to_string(),
                "600",
                "15520",
                "RGGB",
            ])
            .arg(cm.join(","))
            .arg(n.map(|x| format!("{x:.4}")).join(","))
            .arg(&dng)
            .arg(&lr)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "libraw_develop.py: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let png = d.path().join(format!("{name}.png"));
        develop_ok(&[
            dng.to_str().unwrap(),
            "--out",
            png.to_str().unwrap(),
            "--bits",
            "16",
            "--demosaic",
            "bilinear",
            "--adaptation",
            adaptation,
        ]);
        let (r, c, ours) = read_png16(&png);
        assert_eq!((r, c), (REAL_ROWS, REAL_COLS));
        let bytes = std::fs::read(&lr).unwrap();
        let theirs: Vec<[f64; 3]> = bytes
            .chunks_exact(6)
            .map(|b| {
                [0, 1, 2].map(|k| u16::from_le_bytes([b[2 * k], b[2 * k + 1]]) as f64 / 65535.0)
            })
            .collect();
        let (mut s, mut m, mut worst) = (0.0, 0usize, 0.0f64);
        let b = 4;
        for y in b..r - b {
            for x in b..c - b {
                let i = y * c + x;
                let de = delta_e_2000(linear_srgb_to_lab(ours[i]), linear_srgb_to_lab(theirs[i]));
                s += de;
                m += 1;
                worst = worst.max(de);
            }
        }
        let mean = s / m as f64;
        report.push(format!(
            "{name} ({adaptation}): mean ΔE2000 {mean:.3}, max {worst:.2}"
        ));
        if name == "tungsten_bradford" {
            // the DNG specification's Bradford adaptation is not LibRaw's camera-space von
            // Kries: for a non-D65 neutral they differ measurably (reported, docs/isp.md)
            assert!(
                mean > 0.3,
                "{name}: the two adaptations should differ, ΔE2000 {mean:.3}"
            );
        } else {
            assert!(
                mean <= 1.0,
                "{name}: camsim vs LibRaw mean ΔE2000 = {mean:.3} (max {worst:.2})"
            );
        }
    }
    eprintln!("camsim develop vs LibRaw: {}", report.join("; "));
}

/// The headerless real mosaic develops with a stated layout (grey-world balance, camera RGB).
#[test]
fn develop_headerless_raw_with_a_stated_layout() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("real.png");
    let e = develop_ok(&[
        real_mosaic().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--layout",
        "rows=512,cols=768,cfa=RGGB,black=600,white=15520,bits=16,endian=little",
    ]);
    assert!(e.contains("not colorimetric"), "{e}");
    assert!(out.exists());
}

fn develop_err(input: &Path, out: &Path, extra: &[&str]) -> String {
    let o = camsim()
        .arg("develop")
        .arg(input)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let e = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(e.trim_end().lines().count(), 1, "one line: {e}");
    assert!(!out.exists(), "{} was written", out.display());
    e
}

/// Truncated files, wrong tags, unsupported compression, bad layouts: one line naming the file
/// and what was expected; nothing (not even a temporary file) is left behind.
#[test]
fn bad_raw_files_give_one_clear_error_and_write_nothing() {
    let d = tempfile::tempdir().unwrap();
    let (rows, cols) = (8usize, 8usize);
    let data = vec![1000u16; rows * cols];
    let good = |tags: Vec<(u16, V)>, name: &str| -> PathBuf {
        let p = d.path().join(name);
        write_dng(&p, rows, cols, &data, tags);
        p
    };
    let base = || colour_tags(64, 4095, [0.5, 1.0, 0.7]);
    let out = d.path().join("never.png");
    let mut cases: Vec<(PathBuf, Vec<&str>)> = vec![];
    // truncated: the image data is cut
    let p = good(base(), "truncated.dng");
    let b = std::fs::read(&p).unwrap();
    std::fs::write(&p, &b[..b.len() - 40]).unwrap();
    cases.push((p, vec!["truncated.dng", "beyond the file"]));
    // truncated inside the header
    let p = d.path().join("stub.dng");
    std::fs::write(&p, &b[..10]).unwrap();
    cases.push((p, vec!["stub.dng", "not a readable DNG/TIFF"]));
    // unsupported compression (lossless JPEG)
    let mut t = base();
    t.retain(|x| x.0 != 259);
    t.push((259, V::Short(vec![7])));
    cases.push((
        good(t, "ljpeg.dng"),
        vec!["ljpeg.dng", "Compression", "lossless JPEG"],
    ));
    // wrong tags: AsShotNeutral with two values, ColorMatrix1 with six, a CFA colour code 9,
    // no AsShotNeutral, CalibrationIlluminant without a temperature
    let mut t = base();
    t.retain(|x| x.0 != 50728);
    t.push((50728, V::Rational(vec![(1, 2), (1, 1)])));
    cases.push((
        good(t, "neutral2.dng"),
        vec!["neutral2.dng", "AsShotNeutral", "expected 3"],
    ));
    let mut t = base();
    t.retain(|x| x.0 != 50721);
    t.push((50721, V::SRational(vec![(1, 1); 6])));
    cases.push((
        good(t, "cm6.dng"),
        vec!["cm6.dng", "ColorMatrix1", "needs 9"],
    ));
    let mut t = base();
    t.retain(|x| x.0 != 33422);
    t.push((33422, V::Byte(vec![0, 1, 9, 2])));
    cases.push((
        good(t, "code9.dng"),
        vec!["code9.dng", "CFAPattern", "colour code 9"],
    ));
    let mut t = base();
    t.retain(|x| x.0 != 50728);
    cases.push((
        good(t, "noneutral.dng"),
        vec!["noneutral.dng", "AsShotNeutral", "missing"],
    ));
    let mut t = base();
    t.retain(|x| x.0 != 50778);
    t.push((50778, V::Short(vec![255])));
    cases.push((
        good(t, "ill255.dng"),
        vec!["ill255.dng", "CalibrationIlluminant1", "255"],
    ));
    for (p, needles) in &cases {
        let e = develop_err(p, &out, &[]);
        for n in needles {
            assert!(e.contains(n), "{}: '{n}' missing in: {e}", p.display());
        }
    }
    // headerless raw: wrong size for the layout, missing layout, bad layout key
    let raw = d.path().join("short.raw");
    std::fs::write(&raw, vec![0u8; 100]).unwrap();
    let e = develop_err(
        &raw,
        &out,
        &["--layout", "rows=8,cols=8,cfa=RGGB,black=0,white=1023"],
    );
    assert!(e.contains("short.raw") && e.contains("100 bytes"), "{e}");
    let e = develop_err(&raw, &out, &[]);
    assert!(e.contains("--layout"), "{e}");
    let e = develop_err(
        &raw,
        &out,
        &[
            "--layout",
            "rows=8,cols=8,cfa=RGGB,black=0,white=1023,gain=2",
        ],
    );
    assert!(e.contains("unknown key 'gain'"), "{e}");
    // nothing else was left in the folder (no temporary files)
    let left: Vec<String> = std::fs::read_dir(d.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with('.') || n.ends_with(".png"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}
