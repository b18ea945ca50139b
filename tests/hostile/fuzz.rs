//! Deterministic mutation fuzzing of every reader (issue 16, acceptance 2): camera, captures,
//! run and study JSON; .zmx; .dat; lens JSON; glTF and .glb; PNG, TIFF, DNG and raw frames;
//! EXR. Each reader gets [`mutations`] inputs derived from valid seeds by a fixed-seed
//! generator (structure-aware for JSON: a node replaced by an extreme number, a wrong type, a
//! deleted or unknown key; byte-level otherwise: bit flips, interesting integers, insertions,
//! deletions, truncation, duplicated ranges). A reader may accept or refuse an input; it must
//! not panic (caught with `catch_unwind`), abort or hang. A failure names the reader, the
//! mutation and the file it saved the input to.
//!
//! Readers run with a 256 MB memory limit on their thread
//! (`camsim_pipeline::budget::with_thread_max_memory`), so a mutated size is refused by the
//! budget rather than allocated.
use crate::cli::{camera, captures};
use camsim_core::exr_io;
use camsim_core::RawFrame;
use camsim_pipeline::{budget, config, frames, lens_cmd, raw_input, run, study};
use serde_json::{json, Value};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Mutations per reader and run: `CAMSIM_FUZZ_MUTATIONS`, or 10,000 (issue 16, acceptance 2;
/// docs/limits.md).
pub fn mutations() -> usize {
    std::env::var("CAMSIM_FUZZ_MUTATIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000)
}

/// xorshift64* (Vigna 2016): a fixed-seed generator, so every run tries the same inputs.
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed (any value; 0 is mapped to a fixed odd constant).
    pub fn new(seed: u64) -> Self {
        Rng(seed.max(1).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in 0..n (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

const INTERESTING_NUMBERS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "0.5",
    "2",
    "3",
    "7",
    "255",
    "65535",
    "65536",
    "4294967295",
    "4294967296",
    "9007199254740993",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775808",
    "1e-300",
    "1e-9",
    "1e6",
    "1e9",
    "1e12",
    "1e18",
    "1e30",
    "3e38",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
];

fn interesting_value(rng: &mut Rng) -> Value {
    match rng.below(10) {
        0..=5 => serde_json::from_str(INTERESTING_NUMBERS[rng.below(INTERESTING_NUMBERS.len())])
            .unwrap_or(Value::Null),
        6 => Value::String(
            [
                "", "x", "lens", "gaussian", "uniform", "..", "/", "a.png", "a.exr", "$file",
            ][rng.below(10)]
            .into(),
        ),
        7 => Value::Null,
        8 => json!([]),
        _ => json!({}),
    }
}

/// Every path (object keys and array indices) of `v`, the root included.
fn paths(v: &Value, prefix: &mut Vec<PathSeg>, out: &mut Vec<Vec<PathSeg>>) {
    out.push(prefix.clone());
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                prefix.push(PathSeg::Key(k.clone()));
                paths(x, prefix, out);
                prefix.pop();
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                prefix.push(PathSeg::Index(i));
                paths(x, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

#[derive(Clone)]
enum PathSeg {
    Key(String),
    Index(usize),
}

fn at_mut<'a>(v: &'a mut Value, path: &[PathSeg]) -> Option<&'a mut Value> {
    let mut cur = v;
    for s in path {
        cur = match s {
            PathSeg::Key(k) => cur.get_mut(k.as_str())?,
            PathSeg::Index(i) => cur.get_mut(*i)?,
        };
    }
    Some(cur)
}

/// One structure-aware mutation of a JSON document.
pub fn mutate_json(seed: &Value, rng: &mut Rng) -> Value {
    let mut v = seed.clone();
    for _ in 0..1 + rng.below(3) {
        let mut all = Vec::new();
        paths(&v, &mut Vec::new(), &mut all);
        let p = all[rng.below(all.len())].clone();
        let donor = {
            let q = &all[rng.below(all.len())];
            let mut tmp = v.clone();
            at_mut(&mut tmp, q).cloned()
        };
        let Some(node) = at_mut(&mut v, &p) else {
            continue;
        };
        match rng.below(8) {
            0..=2 => *node = interesting_value(rng),
            3 => {
                // numbers scaled by an extreme factor
                if let Some(x) = node.as_f64() {
                    let k = [1e-300, -1.0, 0.0, 1e3, 1e9, 1e300][rng.below(6)];
                    *node = json!(x * k);
                } else {
                    *node = interesting_value(rng);
                }
            }
            4 => match node {
                Value::Object(m) if !m.is_empty() => {
                    let k = m.keys().nth(rng.below(m.len())).cloned().unwrap();
                    m.remove(&k);
                }
                Value::Array(a) if !a.is_empty() => {
                    a.remove(rng.below(a.len()));
                }
                _ => *node = Value::Null,
            },
            5 => match node {
                Value::Object(m) => {
                    m.insert("unknown_key".into(), interesting_value(rng));
                }
                Value::Array(a) => {
                    if let Some(x) = a.first().cloned() {
                        for _ in 0..rng.below(4) {
                            a.push(x.clone());
                        }
                    } else {
                        a.push(interesting_value(rng));
                    }
                }
                _ => *node = interesting_value(rng),
            },
            6 => {
                // a subtree moved elsewhere (a wrong but plausible type)
                if let Some(d) = donor {
                    *node = d;
                }
            }
            _ => {
                if let Value::String(s) = node {
                    s.push_str(["x", "/../a", "\u{0}", "é", ".json"][rng.below(5)]);
                } else {
                    *node = interesting_value(rng);
                }
            }
        }
    }
    v
}

/// One byte-level mutation.
pub fn mutate_bytes(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        if b.is_empty() {
            b.push(rng.next() as u8);
            continue;
        }
        let i = rng.below(b.len());
        match rng.below(9) {
            0 => b[i] ^= 1 << rng.below(8),
            1 => b[i] = [0u8, 0xff, 0x7f, 0x80, 1][rng.below(5)],
            2 => {
                // an interesting 32-bit integer, either byte order
                let v: u32 =
                    [0, 1, 0x7fff_ffff, 0xffff_ffff, 0x8000_0000, 65535, 100_000][rng.below(7)];
                let bytes = if rng.below(2) == 0 {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                for (k, x) in bytes.iter().enumerate() {
                    if i + k < b.len() {
                        b[i + k] = *x;
                    }
                }
            }
            3 => {
                let n = 1 + rng.below(16);
                for _ in 0..n {
                    b.insert(i, rng.next() as u8);
                }
            }
            4 => {
                let n = (1 + rng.below(64)).min(b.len() - i);
                b.drain(i..i + n);
            }
            5 => b.truncate(i),
            6 => {
                let n = (1 + rng.below(64)).min(b.len() - i);
                let chunk = b[i..i + n].to_vec();
                let j = rng.below(b.len());
                for (k, x) in chunk.into_iter().enumerate() {
                    b.insert(j + k, x);
                }
            }
            7 => {
                let v = rng.next().to_le_bytes();
                for (k, x) in v.iter().enumerate() {
                    if i + k < b.len() {
                        b[i + k] = *x;
                    }
                }
            }
            _ => {
                // ASCII digits: stretch a number in a text format
                if b[i].is_ascii_digit() {
                    for _ in 0..1 + rng.below(12) {
                        b.insert(i, b'9');
                    }
                } else {
                    b[i] = b'9';
                }
            }
        }
    }
    b
}

/// Where a failing input is kept.
fn keep(name: &str, i: usize, bytes: &[u8]) -> PathBuf {
    let p = std::env::temp_dir().join(format!("camsim-fuzz-{name}-{i}"));
    let _ = std::fs::write(&p, bytes);
    p
}

/// Replace the contents of `file` by `bytes`: written over the old contents, then cut to
/// length. Not `std::fs::write`: on ext4 a truncate-to-zero followed by a write makes the
/// close start writeback (`auto_da_alloc`, ext4(5)), about 4 ms per input on this machine —
/// more than most readers take to parse the input.
fn overwrite(file: &Path, bytes: &[u8]) {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .open(file)
        .unwrap();
    f.write_all(bytes).unwrap();
    f.set_len(bytes.len() as u64).unwrap();
}

/// An input a reader works on for longer than this is a hang (issue 16 counts a run of over
/// 30 s as one): the watchdog of [`fuzz`] keeps it, names it and ends the test process, since
/// a stuck reader cannot be interrupted from outside its thread.
pub const HANG_S: u64 = 30;

/// The input being read, for the watchdog: (mutation index, bytes, start).
type Current = std::sync::Mutex<Option<(usize, Vec<u8>, Instant)>>;

/// Start the watchdog of one reader's run: every 0.1 s it looks at `current`; an input read for
/// over [`HANG_S`] seconds is kept and the process exits with a message naming it. It stops
/// when `current` is dropped by [`fuzz`] (the `Arc` count falls to one).
fn watchdog(name: &str, current: &std::sync::Arc<Current>) {
    let (name, current) = (name.to_string(), std::sync::Arc::clone(current));
    std::thread::spawn(move || {
        while std::sync::Arc::strong_count(&current) > 1 {
            std::thread::sleep(Duration::from_millis(100));
            let c = current.lock().unwrap_or_else(|p| p.into_inner());
            if let Some((i, bytes, t0)) = &*c {
                if t0.elapsed() > Duration::from_secs(HANG_S) {
                    eprintln!(
                        "fuzz {name}: mutation {i} has run for over {HANG_S} s, a hang (input \
                         kept at {})",
                        keep(&name, *i, bytes).display()
                    );
                    std::process::exit(1);
                }
            }
        }
    });
}

/// Run `reader` on [`mutations`] inputs made by `make` (mutation index → bytes, written to
/// `file` before the call). Panics name the reader, the mutation and the kept input; a hang
/// (over [`HANG_S`]) ends the process naming them.
pub fn fuzz(
    name: &str,
    file: &Path,
    mut make: impl FnMut(&mut Rng) -> Vec<u8>,
    reader: impl Fn(&Path) -> Result<(), String>,
) -> FuzzStats {
    let mut rng = Rng::new(0xC0FF_EE00 ^ name.len() as u64 ^ (name.as_bytes()[0] as u64) << 8);
    let start = Instant::now();
    let (mut ok, mut refused) = (0usize, 0usize);
    let mut slowest = (0usize, Duration::ZERO);
    let mut failure = None;
    let current: std::sync::Arc<Current> = Default::default();
    watchdog(name, &current);
    for i in 0..mutations() {
        let bytes = make(&mut rng);
        overwrite(file, &bytes);
        let t0 = Instant::now();
        *current.lock().unwrap() = Some((i, bytes, t0));
        let r = catch_unwind(AssertUnwindSafe(|| {
            budget::with_thread_max_memory(256 << 20, || reader(file))
        }));
        let bytes = match current.lock().unwrap().take() {
            Some((_, b, _)) => b,
            None => Vec::new(),
        };
        if t0.elapsed() > slowest.1 {
            slowest = (i, t0.elapsed());
        }
        match r {
            Ok(Ok(())) => ok += 1,
            Ok(Err(e)) => {
                refused += 1;
                if e.contains('\n') {
                    failure = Some(format!(
                        "{name}: mutation {i}: a multi-line error {e:?} (input kept at {})",
                        keep(name, i, &bytes).display()
                    ));
                    break;
                }
            }
            Err(p) => {
                let why = p
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                failure = Some(format!(
                    "{name}: mutation {i} panicked: {why} (input kept at {})",
                    keep(name, i, &bytes).display()
                ));
                break;
            }
        }
    }
    drop(current);
    if let Some(f) = failure {
        panic!("{f}");
    }
    let s = FuzzStats {
        accepted: ok,
        refused,
        elapsed: start.elapsed(),
        slowest,
    };
    eprintln!(
        "fuzz {name}: {} mutations, {} accepted, {} refused, {:.2} s (slowest: mutation {}, \
         {:.3} s)",
        mutations(),
        s.accepted,
        s.refused,
        s.elapsed.as_secs_f64(),
        s.slowest.0,
        s.slowest.1.as_secs_f64()
    );
    s
}

/// What one reader's run did.
#[derive(Debug)]
pub struct FuzzStats {
    /// Inputs the reader accepted.
    pub accepted: usize,
    /// Inputs it refused with an error.
    pub refused: usize,
    /// Wall time.
    pub elapsed: Duration,
    /// The slowest input: its mutation index and the reader's time on it.
    pub slowest: (usize, Duration),
}

fn json_fuzz(
    name: &str,
    file: &Path,
    seed: &Value,
    reader: impl Fn(&Path) -> Result<(), String>,
) -> FuzzStats {
    let text = serde_json::to_vec_pretty(seed).unwrap();
    fuzz(
        name,
        file,
        |rng| {
            if rng.below(5) == 0 {
                mutate_bytes(&text, rng)
            } else {
                serde_json::to_vec_pretty(&mutate_json(seed, rng)).unwrap()
            }
        },
        reader,
    )
}

fn bytes_fuzz(
    name: &str,
    file: &Path,
    seed: &[u8],
    reader: impl Fn(&Path) -> Result<(), String>,
) -> FuzzStats {
    fuzz(name, file, |rng| mutate_bytes(seed, rng), reader)
}

fn shared() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// Both kinds of outcome must occur: a fuzzer whose inputs are all refused (or all accepted)
/// tests nothing of the other path.
fn assert_mixed(s: &FuzzStats, name: &str) {
    assert!(s.accepted > 0 && s.refused > 0, "{name}: {s:?}");
}

#[test]
fn camera_json() {
    let d = tempfile::tempdir().unwrap();
    let mut seed = camera(8, 8);
    seed["optics"]["blur"] = json!({"kind": "gaussian", "sigma_um": 1.5});
    seed["optics"]["diffuser"] = json!({"fwhm_um": 2.0});
    let s = json_fuzz("camera", &d.path().join("camera.json"), &seed, |p| {
        config::load_camera(p).map(|_| ()).map_err(|e| e.one_line())
    });
    assert_mixed(&s, "camera");
}

#[test]
fn captures_json() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("camera.json"), camera(8, 8).to_string()).unwrap();
    let mut seed = captures(1.0, 0.01);
    seed["simulation"] =
        json!({"wavelength_nm": {"start_nm": 400, "stop_nm": 700, "step_nm": 10}, "seed": 3});
    seed["raw_format"] = json!({"bits_per_sample": 16, "endianness": "big", "header_bytes": 4});
    seed["shots"].as_array_mut().unwrap().push(json!(
        {"id": "pts", "exposure_s": 0.01, "target": {"kind": "point_array", "radiance": 1.0, "spacing_px": 4, "mean_luminance_cd_m2": 10}, "frames": ["a.raw"]}));
    let s = json_fuzz("captures", &d.path().join("captures.json"), &seed, |p| {
        config::load_captures(p, None)
            .map(|_| ())
            .map_err(|e| e.one_line())
    });
    assert_mixed(&s, "captures");
}

#[test]
fn run_json() {
    let d = tempfile::tempdir().unwrap();
    let mut cam: Value = serde_json::from_str(camsim_pipeline::run::TABLE1_CAMERA).unwrap();
    cam["sensor"]["rows"] = json!(16);
    cam["sensor"]["cols"] = json!(16);
    let seed = json!({
        "camera": cam,
        "target": {"kind": "macbeth", "illuminant": "D65", "mean_luminance_cd_m2": 61},
        "exposure_s": 0.01,
        "seed": 1,
        "processor": {"demosaic": "malvar", "white_balance": "grey_world", "output_bits": 8},
        "display": {"name": "lcdExample", "samples_per_pixel": 2}
    });
    let s = json_fuzz("run", &d.path().join("run.json"), &seed, |p| {
        run::check_config(Some(p)).map_err(|e| e.one_line())
    });
    assert_mixed(&s, "run");
}

#[test]
fn study_json() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("inc.json"),
        json!({"kind": "none"}).to_string(),
    )
    .unwrap();
    let mut cam: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/study_codesign/camera.json")).unwrap(),
    )
    .unwrap();
    cam["optics"]["blur"] = json!({"$file": "inc.json"});
    let seed = json!({
        "name": "fuzz",
        "point": {"camera": cam,
                  "conditions": {"luminance_cd_m2": 100, "exposure_s": 0.01},
                  "metrics": {"snr": {}, "dynamic_range": {}}},
        "parameters": [
            {"name": "lum", "path": "conditions.luminance_cd_m2", "values": [30, 300]},
            {"name": "pitch", "path": "camera.sensor.pixel_pitch_um", "values": [1.0, 2.0], "labels": ["a", "b"]}
        ]
    });
    let s = json_fuzz("study", &d.path().join("study.json"), &seed, |p| {
        study::spec::load_study(p)
            .map(|_| ())
            .map_err(|e| e.one_line())
    });
    assert_mixed(&s, "study");
}

#[test]
fn zmx() {
    let d = tempfile::tempdir().unwrap();
    let seed = std::fs::read(
        shared().join("data/real/lens/prescriptions/rayoptics_US00583336-2-scaled.zmx"),
    )
    .expect("../shared/data/real/lens/prescriptions (see BRIEF: ln -s /work/shared)");
    let s = bytes_fuzz("zmx", &d.path().join("lens.zmx"), &seed, |p| {
        lens_cmd::load_lens(p).map(|_| ()).map_err(|e| e.one_line())
    });
    assert_mixed(&s, "zmx");
}

#[test]
fn iset_dat() {
    let d = tempfile::tempdir().unwrap();
    let seed = std::fs::read(shared().join("data/real/lens/prescriptions/pbrt_dgauss.50mm.dat"))
        .expect("../shared/data/real/lens/prescriptions");
    let s = bytes_fuzz("dat", &d.path().join("lens.dat"), &seed, |p| {
        lens_cmd::load_lens(p).map(|_| ()).map_err(|e| e.one_line())
    });
    assert_mixed(&s, "dat");
}

#[test]
fn lens_json() {
    let d = tempfile::tempdir().unwrap();
    let seed: Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("lenses/cooke_triplet_sasian_50mm_f4.json")).unwrap(),
    )
    .unwrap();
    let s = json_fuzz("lens-json", &d.path().join("lens.json"), &seed, |p| {
        lens_cmd::load_lens(p).map(|_| ()).map_err(|e| e.one_line())
    });
    assert_mixed(&s, "lens-json");
}

fn load_scene(p: &Path) -> Result<(), String> {
    camsim_render::gltf_load::load_gltf(p)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

#[test]
fn gltf() {
    let d = tempfile::tempdir().unwrap();
    let scenes = repo().join("scenes");
    std::fs::copy(
        scenes.join("uniform_emitter.bin"),
        d.path().join("uniform_emitter.bin"),
    )
    .unwrap();
    let seed: Value = serde_json::from_str(
        &std::fs::read_to_string(scenes.join("uniform_emitter.gltf")).unwrap(),
    )
    .unwrap();
    let s = json_fuzz("gltf", &d.path().join("scene.gltf"), &seed, load_scene);
    assert_mixed(&s, "gltf");
}

/// A GLB container (glTF 2.0 §4.4) of a .gltf whose single buffer is its .bin.
fn glb_of(gltf: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = gltf.clone();
    j["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut js = serde_json::to_vec(&j).unwrap();
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let total = 12 + 8 + js.len() + 8 + b.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

#[test]
fn glb() {
    let d = tempfile::tempdir().unwrap();
    let scenes = repo().join("scenes");
    let gltf: Value = serde_json::from_str(
        &std::fs::read_to_string(scenes.join("uniform_emitter.gltf")).unwrap(),
    )
    .unwrap();
    let bin = std::fs::read(scenes.join("uniform_emitter.bin")).unwrap();
    let seed = glb_of(&gltf, &bin);
    let p = d.path().join("scene.glb");
    std::fs::write(&p, &seed).unwrap();
    load_scene(&p).expect("the seed GLB loads");
    let s = bytes_fuzz("glb", &p, &seed, load_scene);
    assert_mixed(&s, "glb");
}

fn frame(rows: usize, cols: usize) -> RawFrame {
    RawFrame {
        rows,
        cols,
        adc_bits: 12,
        dn: (0..rows * cols).map(|i| (i * 37 % 4096) as u16).collect(),
        layout: None,
    }
}

fn read_frame(p: &Path) -> Result<(), String> {
    raw_input::read_frame(p)
        .map(|_| ())
        .map_err(|e| e.one_line())
}

#[test]
fn png_frames() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("f.png");
    frames::write_png16(&p, &frame(8, 8)).unwrap();
    let seed = std::fs::read(&p).unwrap();
    let s = bytes_fuzz("png", &p, &seed, read_frame);
    assert_mixed(&s, "png");
}

#[test]
fn tiff_frames() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("f.tif");
    frames::write_frame(&p, &frame(8, 8)).unwrap();
    let seed = std::fs::read(&p).unwrap();
    let s = bytes_fuzz("tiff", &p, &seed, read_frame);
    assert_mixed(&s, "tiff");
}

#[test]
fn dng_frames() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("f.dng");
    let sensor = camsim_pipeline::config::camera_from_file(
        &d.path().join("camera.json"),
        serde_json::from_value(camera(8, 8)).unwrap(),
    )
    .unwrap()
    .sensor;
    frames::write_dng(&p, &frame(8, 8), &frames::DngLayout::for_sensor(&sensor)).unwrap();
    let seed = std::fs::read(&p).unwrap();
    read_frame(&p).expect("the seed DNG reads");
    let s = bytes_fuzz("dng", &p, &seed, read_frame);
    assert_mixed(&s, "dng");
}

#[test]
fn raw_frames() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("f.raw");
    let seed: Vec<u8> = std::iter::repeat_n(0xAB, 4)
        .chain(frame(8, 8).dn.iter().flat_map(|v| v.to_be_bytes()))
        .collect();
    let fmt = raw_input::RawFormat {
        rows: 8,
        cols: 8,
        bytes_per_sample: 2,
        little_endian: false,
        header_bytes: 4,
    };
    // The layout is mutated too (header and sizes), with the file.
    let layouts = std::cell::RefCell::new(Rng::new(77));
    let s = bytes_fuzz("raw", &p, &seed, |p| {
        let mut r = layouts.borrow_mut();
        let mut f = fmt;
        match r.below(6) {
            0 => f.header_bytes = [0, 3, u64::MAX, 1 << 40, u32::MAX as u64][r.below(5)],
            1 => f.rows = [0, 1, usize::MAX, 1 << 33][r.below(4)],
            2 => f.cols = [0, 7, usize::MAX / 2][r.below(3)],
            3 => f.bytes_per_sample = 1,
            _ => {}
        }
        raw_input::read_raw(p, &f)
            .map(|_| ())
            .map_err(|e| e.one_line())
    });
    assert_mixed(&s, "raw");
}

#[test]
fn exr() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("s.exr");
    let grid = camsim_core::spectrum::WavelengthGrid::regular(400.0, 700.0, 100.0).unwrap();
    let planes = (0..grid.len())
        .map(|b| (0..6 * 5).map(|i| (i + b) as f32 * 0.1).collect())
        .collect();
    let img = camsim_core::image::SpectralImage::new(
        6,
        5,
        camsim_core::image::SpectralBasis::Bands(grid),
        planes,
    )
    .unwrap();
    exr_io::write_spectral_exr(&p, &img, exr_io::RADIANCE_UNITS, None).unwrap();
    let seed = std::fs::read(&p).unwrap();
    let s = bytes_fuzz("exr", &p, &seed, |p| {
        camsim_pipeline::targets::read_exr_target(p, 256e6)
            .map(|_| ())
            .map_err(|e| e.one_line())
    });
    assert_mixed(&s, "exr");
}
