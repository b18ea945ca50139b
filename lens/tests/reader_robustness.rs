//! Deterministic mutation fuzzing of the lens readers: whatever the input, every reader
//! returns `Ok` or `Err` (never panics), and error messages are one line. Lenses that readers
//! accept are also validated, given first-order properties and traced a little, again without
//! panics. Inputs: the `.zmx` and `.dat` files of /work/shared/data/real/lens/prescriptions,
//! the ISET `.dat` and `.json` lenses of /work/shared/data/iset/lenses and `lenses/*.json`.
//! Without the shared data the test fails (naming the folders) unless
//! `CAMSIM_LENS_FUZZ_WITHOUT_SHARED=1` asks for the reduced, JSON-only run.
//! Mutations (xorshift64*, fixed seed): delete / duplicate / swap / replace lines, flip,
//! delete or insert characters, truncate, replace a number by garbage (NaN, inf, 1e308, -0,
//! 0, empty, huge integers, …), and raw byte flips for `.zmx` (exercising `decode_text`).
use camsim_lens::readers::{
    decode_text, iset_json_focal_length_mm, read_iset_dat, read_iset_json, read_zmx, ZmxOptions,
};
use camsim_lens::trace::Ray;
use camsim_lens::{Clipping, GlassCatalog, LensError, LensPrescription, PrescriptionFile};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

struct XorShift(u64);
impl XorShift {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

const GARBAGE: [&str; 16] = [
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-320",
    "-0",
    "0",
    "",
    "-",
    "1e999",
    "99999999999999999999",
    "0x10",
    "1,5",
    "\u{00e9}",
];

fn files(dir: &str, ext: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == ext))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Byte ranges of numbers (maximal runs of [0-9.eE+-]) containing a digit.
fn number_spans(s: &str) -> Vec<(usize, usize)> {
    let b = s.as_bytes();
    let mut out = vec![];
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() || b[i] == b'-' || b[i] == b'.' {
            let st = i;
            while i < b.len() && (b[i].is_ascii_digit() || b"eE+-.".contains(&b[i])) {
                i += 1;
            }
            if b[st..i].iter().any(|c| c.is_ascii_digit()) {
                out.push((st, i));
            }
        } else {
            i += 1;
        }
    }
    out
}

fn char_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i.min(s.len())
}

/// Apply 1–4 random text mutations.
fn mutate(src: &str, rng: &mut XorShift) -> String {
    let mut s = src.to_string();
    for _ in 0..1 + rng.below(4) {
        let mut lines: Vec<String> = s.lines().map(String::from).collect();
        match rng.below(9) {
            0 if !lines.is_empty() => {
                let i = rng.below(lines.len());
                lines.remove(i);
                s = lines.join("\n");
            }
            1 if !lines.is_empty() => {
                let i = rng.below(lines.len());
                let l = lines[i].clone();
                lines.insert(i, l);
                s = lines.join("\n");
            }
            2 if lines.len() > 1 => {
                let (i, j) = (rng.below(lines.len()), rng.below(lines.len()));
                lines.swap(i, j);
                s = lines.join("\n");
            }
            3 if !lines.is_empty() => {
                let i = rng.below(lines.len());
                let j = rng.below(lines.len());
                lines[i] = match rng.below(3) {
                    0 => String::new(),
                    1 => GARBAGE[rng.below(GARBAGE.len())].to_string(),
                    _ => lines[j].clone(),
                };
                s = lines.join("\n");
            }
            4 if !s.is_empty() => {
                // flip a character
                let i = char_boundary(&s, rng.below(s.len()));
                let c = s[i..].chars().next().unwrap_or(' ');
                let r = match rng.below(4) {
                    0 => char::from_u32((c as u32) ^ (1 << rng.below(7))).unwrap_or('?'),
                    1 => ['{', '}', '[', ']', '"', ',', ':', ' ', '\t', '#'][rng.below(10)],
                    2 => char::from(b'0' + rng.below(10) as u8),
                    _ => '\u{0}',
                };
                s.replace_range(i..i + c.len_utf8(), &r.to_string());
            }
            5 if !s.is_empty() => {
                // delete a short run
                let i = char_boundary(&s, rng.below(s.len()));
                let j = char_boundary(&s, (i + 1 + rng.below(8)).min(s.len()));
                if j > i {
                    s.replace_range(i..j, "");
                }
            }
            6 => {
                // truncate
                let i = char_boundary(&s, rng.below(s.len() + 1));
                s.truncate(i);
            }
            7 => {
                // insert garbage at a random position
                let i = char_boundary(&s, rng.below(s.len() + 1));
                let g = GARBAGE[rng.below(GARBAGE.len())];
                s.insert_str(i, &format!(" {g} "));
            }
            _ => {
                // replace a number by garbage
                let sp = number_spans(&s);
                if !sp.is_empty() {
                    let (a, b) = sp[rng.below(sp.len())];
                    s.replace_range(a..b, GARBAGE[rng.below(GARBAGE.len())]);
                }
            }
        }
    }
    s
}

#[derive(Default)]
struct Stats {
    calls: usize,
    ok: usize,
    built: usize,
    traced: usize,
}

fn check_msg(what: &str, e: &LensError) {
    let m = e.to_string();
    assert!(!m.contains('\n'), "{what}: multi-line error message: {m:?}");
    assert!(!m.is_empty(), "{what}: empty error message");
}

/// Run `f` under catch_unwind; a panic fails the test with the input that caused it.
fn guarded<T>(what: &str, input: &str, f: impl FnOnce() -> T) -> T {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(v) => v,
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            let _ = std::fs::write(
                std::env::temp_dir().join("camsim_reader_robustness_panic.txt"),
                input,
            );
            panic!(
                "{what} panicked ({msg}); input saved to {}",
                std::env::temp_dir()
                    .join("camsim_reader_robustness_panic.txt")
                    .display()
            );
        }
    }
}

/// Validate an accepted file form, compute first order and trace a few rays: no panics.
fn exercise(what: &str, input: &str, pf: &PrescriptionFile, cat: &GlassCatalog, st: &mut Stats) {
    let Ok(l) = guarded(what, input, || LensPrescription::from_file_form(pf, cat))
        .map_err(|e| check_msg(what, &e))
    else {
        return;
    };
    st.built += 1;
    exercise_lens(what, input, &l, st);
}

fn exercise_lens(what: &str, input: &str, l: &LensPrescription, st: &mut Stats) {
    guarded(what, input, || {
        let w = l.primary_nm;
        let fo = match l.first_order(w) {
            Ok(fo) => fo,
            Err(e) => return check_msg(what, &e),
        };
        for field in [0.0, 10.0] {
            match l.aim_field(field, w, &fo) {
                Ok(aim) => {
                    for (px, py) in [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0)] {
                        let _ = l.trace(&aim.ray(px, py), w, Clipping::SemiDiameters);
                        let _ = l.trace(&aim.ray(px, py), w, Clipping::None);
                    }
                }
                Err(e) => check_msg(what, &e),
            }
        }
        st.traced += 1;
    });
}

fn lens_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses")
}

#[test]
fn mutated_lens_files_never_panic() {
    let t0 = std::time::Instant::now();
    let cat = GlassCatalog::bundled();
    let opts = ZmxOptions::default();
    let real = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/real/lens/prescriptions"
    );
    let iset = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/iset/lenses");
    let mut zmx = files(real, "zmx");
    let mut dat = files(real, "dat");
    dat.extend(files(iset, "dat"));
    let iset_json = files(iset, "json");
    let ours = files(lens_dir().to_str().unwrap(), "json");
    zmx.sort();
    dat.sort();
    // Without ../shared the fuzz would shrink to the repository's JSON lenses and still pass:
    // fail loudly instead, unless CAMSIM_LENS_FUZZ_WITHOUT_SHARED=1 asks for the reduced run
    // (then said on stderr).
    if zmx.is_empty() || dat.is_empty() || iset_json.is_empty() {
        let why = format!(
            "lens reader fuzz: no .zmx/.dat/ISET .json seed files ({} .zmx, {} .dat, {} ISET .json) \
             under {real} and {iset}: the shared data (../shared beside the checkout) is missing",
            zmx.len(),
            dat.len(),
            iset_json.len()
        );
        if std::env::var_os("CAMSIM_LENS_FUZZ_WITHOUT_SHARED").is_some_and(|v| v == "1") {
            eprintln!(
                "{why}; CAMSIM_LENS_FUZZ_WITHOUT_SHARED=1: fuzzing only the {} lenses/*.json",
                ours.len()
            );
        } else {
            panic!("{why}; set CAMSIM_LENS_FUZZ_WITHOUT_SHARED=1 to fuzz only lenses/*.json");
        }
    }
    assert!(
        !ours.is_empty(),
        "no lenses/*.json found in {}",
        lens_dir().display()
    );
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let mut st = Stats::default();
    // (kind, raw bytes) of every seed file.
    let mut seeds: Vec<(u8, String, Vec<u8>)> = vec![];
    for (k, v) in [(0u8, &zmx), (1, &dat), (2, &iset_json), (3, &ours)] {
        for p in v.iter() {
            seeds.push((k, p.display().to_string(), std::fs::read(p).unwrap()));
        }
    }
    const PER_SEED_MAX: usize = 200;
    const TOTAL: usize = 12000;
    let per_seed = (TOTAL / seeds.len().max(1)).clamp(20, PER_SEED_MAX);
    for (kind, name, bytes) in &seeds {
        let text = decode_text(bytes);
        for it in 0..per_seed {
            let what = format!("{name} mutation {it}");
            // .zmx: sometimes mutate raw bytes (UTF-16/BOM handling), else decoded text.
            let (input_bytes, input_text) = if *kind == 0 && it % 5 == 0 {
                let mut b = bytes.clone();
                for _ in 0..1 + rng.below(4) {
                    match rng.below(3) {
                        0 if !b.is_empty() => {
                            let i = rng.below(b.len());
                            b[i] ^= 1 << rng.below(8);
                        }
                        1 => {
                            let i = rng.below(b.len() + 1);
                            b.truncate(i);
                        }
                        _ if !b.is_empty() => {
                            let i = rng.below(b.len());
                            b.remove(i); // misaligns UTF-16
                        }
                        _ => {}
                    }
                }
                let t = String::from_utf8_lossy(&b).to_string();
                (b, t)
            } else {
                let t = mutate(&text, &mut rng);
                (t.clone().into_bytes(), t)
            };
            st.calls += 1;
            let res: Result<Option<PrescriptionFile>, LensError> = match kind {
                0 => guarded(&what, &input_text, || {
                    read_zmx(&input_bytes, "fuzz", &opts).map(Some)
                }),
                1 => guarded(&what, &input_text, || {
                    read_iset_dat(&input_text, "fuzz").map(Some)
                }),
                2 => {
                    if let Err(e) = guarded(&what, &input_text, || {
                        iset_json_focal_length_mm(&input_text)
                    }) {
                        check_msg(&what, &e);
                    }
                    guarded(&what, &input_text, || {
                        read_iset_json(&input_text, "fuzz").map(Some)
                    })
                }
                _ => {
                    match guarded(&what, &input_text, || {
                        LensPrescription::from_json_str(&input_text, &cat)
                    }) {
                        Ok(l) => {
                            st.ok += 1;
                            st.built += 1;
                            exercise_lens(&what, &input_text, &l, &mut st);
                        }
                        Err(e) => check_msg(&what, &e),
                    }
                    Ok(None)
                }
            };
            match res {
                Ok(Some(pf)) => {
                    st.ok += 1;
                    exercise(&what, &input_text, &pf, &cat, &mut st);
                }
                Ok(None) => {}
                Err(e) => check_msg(&what, &e),
            }
        }
    }
    eprintln!(
        "{} seeds, {} mutated inputs, {} accepted by the reader, {} validated, {} traced, {:.2} s",
        seeds.len(),
        st.calls,
        st.ok,
        st.built,
        st.traced,
        t0.elapsed().as_secs_f64()
    );
    assert!(st.calls >= 1000);
}

#[test]
fn rays_that_miss_a_surface_are_lost_not_panics() {
    // A strongly curved second surface (R = 5 mm) behind a 40 mm EPD: rays above ~5 mm
    // height miss the sphere entirely (negative discriminant), or hit outside the conic's
    // domain; the trace must return None and the analyses Ok or Err.
    let text = r#"{
      "name": "miss", "units": "mm",
      "surfaces": [
        {"radius_mm": null, "thickness_mm": 2.0, "material": {"nd": 1.5, "vd": 0}, "stop": true},
        {"radius_mm": 5.0, "thickness_mm": 2.0, "material": {"nd": 1.7, "vd": 0}},
        {"radius_mm": -3.0, "thickness_mm": 20.0, "material": "air", "conic": -4.0,
         "aspheric_coeffs": [1e-3, -1e-4]}
      ],
      "object_distance_mm": null, "fields_deg": [0, 30], "wavelengths_nm": [587.6],
      "aperture": {"epd_mm": 40.0}
    }"#;
    let l = LensPrescription::from_json_str(text, &GlassCatalog::bundled()).unwrap();
    let w = l.primary_nm;
    let ray = Ray {
        origin_mm: [0.0, 15.0, -10.0],
        direction: [0.0, 0.0, 1.0],
        opl_mm: 0.0,
    };
    let r = guarded("trace", text, || l.trace(&ray, w, Clipping::None));
    assert!(
        r.is_none(),
        "a ray at 15 mm cannot meet an R = 5 mm sphere: {r:?}"
    );
    let r = guarded("trace", text, || l.trace(&ray, w, Clipping::SemiDiameters));
    assert!(r.is_none());
    // Grazing / backward / degenerate rays.
    for d in [
        [0.0, 1.0, 0.0],
        [0.0, 0.0, -1.0],
        [0.0, 0.6, 0.8],
        [f64::NAN, 0.0, 1.0],
    ] {
        for y in [0.0, 4.999, 5.0, 1e300, f64::NAN] {
            let ray = Ray {
                origin_mm: [0.0, y, -10.0],
                direction: d,
                opl_mm: 0.0,
            };
            let _ = guarded("trace", text, || l.trace(&ray, w, Clipping::None));
            let _ = guarded("trace", text, || l.trace(&ray, w, Clipping::SemiDiameters));
            let _ = guarded("trace_to_stop", text, || l.trace_to_stop(&ray, w));
        }
    }
    // Analyses over a pupil most of whose rays are lost.
    guarded("analyses", text, || {
        let grid = camsim_lens::analysis::pupil_grid(9);
        for f in [0.0, 30.0] {
            if let Err(e) = l.ray_fan(f, w, w, &grid, Clipping::None) {
                check_msg("ray_fan", &e);
            }
            if let Err(e) = l.spot_diagram(f, w, 9, 0.0, Clipping::None) {
                check_msg("spot_diagram", &e);
            }
            if let Err(e) = l.relative_illumination(f, w, 9) {
                check_msg("relative_illumination", &e);
            }
            if let Err(e) = l.distortion(f) {
                check_msg("distortion", &e);
            }
        }
    });
}
