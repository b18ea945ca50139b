//! Scenes from the world (issue 18, acceptance 3): an sRGB picture through lcdExample gives
//! the radiance of ISETCam's `sceneFromFile` (closed form, convention in
//! camsim_core::scene_import), illuminant swap round-trips to 1e-6, ENVI / npy cubes
//! round-trip and lying headers are refused, and a target of known field of view covers the
//! predicted number of pixels.
use crate::cli::{camera, write_set};
use camsim_core::colorimetry::luminance_weight_for_photons;
use camsim_core::constants::{PhysicalConstants, ISETCAM, SI};
use camsim_core::illuminant::{
    estimate_illuminant, swap_illuminant, EstimateMethod, IlluminantFamily,
};
use camsim_core::image::{SceneRadiance, SpectralBasis, SpectralImage};
use camsim_core::scene_import::{scene_from_rgb, DisplayPrimaries, RgbCodes};
use camsim_core::spectrum::{Spectrum, WavelengthGrid};
use camsim_pipeline::scene_files::{read_envi, read_npy_cube};
use serde_json::{json, Value};
use std::path::Path;

/// lcdExample as stored in data/iset: wavelengths, spd[primary][λ], gamma[level][primary],
/// pixel pitch (m), viewing distance (m) — read straight from the JSON, not through camsim.
struct Lcd {
    wl: Vec<f64>,
    spd: Vec<Vec<f64>>,
    gamma: Vec<Vec<f64>>,
    pitch_m: f64,
    distance_m: f64,
}

fn lcd_example() -> Lcd {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/iset/displays/lcdExample.json");
    let v: Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let nums = |x: &Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|y| y.as_f64().unwrap())
            .collect()
    };
    Lcd {
        wl: nums(&v["wavelength_nm"]),
        spd: v["spd"].as_array().unwrap().iter().map(nums).collect(),
        gamma: v["gamma"].as_array().unwrap().iter().map(nums).collect(),
        pitch_m: 0.0254 / v["dpi"].as_f64().unwrap(),
        distance_m: v["viewing_distance_m"].as_f64().unwrap(),
    }
}

/// A deterministic 8-bit RGB picture with 0 and 255 in every channel.
fn picture(rows: usize, cols: usize) -> Vec<u8> {
    let mut v: Vec<u8> = (0..rows * cols * 3)
        .map(|i| ((i * 97 + (i / 3) * 13 + 7) % 256) as u8)
        .collect();
    v[0..3].copy_from_slice(&[0, 0, 0]);
    v[3..6].copy_from_slice(&[255, 255, 255]);
    v
}

/// ISETCam's procedure in closed form (vcReadImage with an 8-bit picture and a 1024-level
/// table): L_q(λ) = Σ_p gTable[round(d_p · 1023 / 255)][p] · spd_p(λ) · λ / (h c).
fn isetcam_radiance(lcd: &Lcd, rgb: [u8; 3], wl_index: usize, c: &PhysicalConstants) -> f64 {
    let top = (lcd.gamma.len() - 1) as f64;
    let e: f64 = (0..3)
        .map(|p| {
            let row = (rgb[p] as f64 * top / 255.0).round() as usize;
            lcd.gamma[row][p] * lcd.spd[p][wl_index]
        })
        .sum();
    let w = lcd.wl[wl_index];
    e * w * 1e-9 / (c.planck_j_s * c.light_speed_m_per_s)
}

fn compare_to_closed_form(img: &SpectralImage, pic: &[u8], lcd: &Lcd, c: &PhysicalConstants) {
    let grid = WavelengthGrid::new(lcd.wl.clone()).unwrap();
    let (mut worst, mut peak) = (0.0f64, 0.0f64);
    for r in 0..img.rows {
        for col in 0..img.cols {
            let i = (r * img.cols + col) * 3;
            let got = img.pixel_spectrum(r, col, &grid);
            for (b, g) in got.iter().enumerate() {
                let want = isetcam_radiance(lcd, [pic[i], pic[i + 1], pic[i + 2]], b, c);
                worst = worst.max((g - want).abs());
                peak = peak.max(want.abs());
            }
        }
    }
    assert!(peak > 0.0);
    assert!(
        worst / peak < 1e-6,
        "radiance differs from ISETCam's closed form by {:.3e} of its peak",
        worst / peak
    );
}

#[test]
fn srgb_picture_through_lcd_example_gives_isetcam_radiance() {
    let lcd = lcd_example();
    let (rows, cols) = (6, 7);
    let pic = picture(rows, cols);
    // core, with ISETCam's Planck constant: the procedure to the last digit
    let prim = DisplayPrimaries {
        spd_energy: lcd
            .spd
            .iter()
            .map(|s| Spectrum::sampled(lcd.wl.clone(), s.clone()).unwrap())
            .collect(),
        gamma: (0..3)
            .map(|p| lcd.gamma.iter().map(|g| g[p]).collect())
            .collect(),
        pixel_pitch_m: lcd.pitch_m,
        viewing_distance_m: lcd.distance_m,
    };
    let codes = RgbCodes {
        rows,
        cols,
        channels: 3,
        bits: 8,
        codes: pic.iter().map(|&v| v as u16).collect(),
    };
    let s = scene_from_rgb(&codes, &prim, &ISETCAM).unwrap();
    compare_to_closed_form(&s.radiance, &pic, &lcd, &ISETCAM);
    // geometry: cols · atan(pitch / distance), at the viewing distance
    let fov = cols as f64 * (lcd.pitch_m / lcd.distance_m).atan().to_degrees();
    assert!((s.fov_deg - fov).abs() < 1e-12 && s.distance_m == lcd.distance_m);
    // illuminant: the white point Σ_p spd_p (ISETCam: sum(spd, 2)), in photons
    for (b, &w) in lcd.wl.iter().enumerate() {
        let want = (0..3).map(|p| lcd.spd[p][b]).sum::<f64>() * w * 1e-9
            / (ISETCAM.planck_j_s * ISETCAM.light_speed_m_per_s);
        let got = s.illuminant_photons.eval(w);
        assert!((got - want).abs() <= 1e-9 * want.abs().max(1e-30), "{w} nm");
    }

    // the pipeline: a PNG file and a target object, SI constants
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_raw(cols as u32, rows as u32, pic.clone())
        .unwrap()
        .save(dir.path().join("p.png"))
        .unwrap();
    let t = json!({"kind": "image", "file": "p.png", "display": "lcdExample"});
    let w =
        camsim_pipeline::world_targets::rgb_image_target(t.as_object().unwrap(), dir.path(), false)
            .unwrap();
    let camsim_core::scene::Target::Image { radiance } = &w.target else {
        panic!("an image target")
    };
    compare_to_closed_form(radiance, &pic, &lcd, &SI);
    assert_eq!(
        w.illuminant.as_ref().unwrap().1,
        "display white point",
        "the default illuminant"
    );
    // independent check of units: the full-white pixel (row 0, col 1) has the luminance of
    // the display's white as the display crate computes it (energy, exact CIE integral)
    let lum = radiance.integrate_against(&luminance_weight_for_photons(&SI));
    let white = camsim_display::DisplayModel::load("lcdExample")
        .unwrap()
        .peak_luminance_cd_per_m2();
    assert!(
        ((lum[1] as f64) - white).abs() < 1e-5 * white,
        "{} vs {white}",
        lum[1]
    );
}

/// A band cube of pseudo-random radiance under D65, photons.
fn random_cube_scene() -> SceneRadiance {
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let d65 = camsim_core::data::illuminant("D65")
        .unwrap()
        .energy_to_photons(&SI);
    let mut x = 12345u64;
    let planes: Vec<Vec<f32>> = grid
        .wavelength_nm
        .iter()
        .map(|&w| {
            (0..20)
                .map(|_| {
                    x = x
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    let refl = 0.05 + 0.9 * ((x >> 33) as f64 / (1u64 << 31) as f64);
                    (refl * d65.eval(w)) as f32
                })
                .collect()
        })
        .collect();
    SceneRadiance {
        radiance: SpectralImage::new(4, 5, SpectralBasis::Bands(grid), planes).unwrap(),
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: Some(d65),
        depth_m: None,
        sample_aperture: Default::default(),
    }
}

fn max_rel_diff(a: &SpectralImage, b: &SpectralImage, grid: &WavelengthGrid) -> f64 {
    let (a, b) = (a.to_bands(grid), b.to_bands(grid));
    let mut worst = 0.0f64;
    for (pa, pb) in a.planes.iter().zip(&b.planes) {
        for (x, y) in pa.iter().zip(pb) {
            if *y != 0.0 {
                worst = worst.max(((x - y) / y).abs() as f64);
            }
        }
    }
    worst
}

#[test]
fn illuminant_swap_round_trips_and_is_the_reflectance_formula() {
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let tungsten = camsim_core::data::illuminant("tungsten")
        .unwrap()
        .energy_to_photons(&SI);
    let d65 = camsim_core::data::illuminant("D65")
        .unwrap()
        .energy_to_photons(&SI);
    // the formula: radiance / old × new, per band (no luminance preservation)
    let orig = random_cube_scene();
    let mut s = orig.clone();
    swap_illuminant(&mut s, &tungsten, false, &SI).unwrap();
    for (b, &w) in grid.wavelength_nm.iter().enumerate() {
        let k = tungsten.eval(w) / d65.eval(w);
        let (got, want) = (
            s.radiance.planes[b][7] as f64,
            orig.radiance.planes[b][7] as f64 * k,
        );
        assert!((got - want).abs() <= 1e-6 * want, "{w} nm: {got} vs {want}");
    }
    // round trip D65 → tungsten → D65, with the mean luminance kept (ISETCam's default)
    let mut s = orig.clone();
    swap_illuminant(&mut s, &tungsten, true, &SI).unwrap();
    swap_illuminant(&mut s, &d65, true, &SI).unwrap();
    let e = max_rel_diff(&s.radiance, &orig.radiance, &grid);
    assert!(e < 1e-6, "band cube round trip: {e:.3e}");
    // the same for a picture on a display (a linear model on the primaries)
    let lcd = camsim_display::DisplayModel::load("lcdExample").unwrap();
    let prim = DisplayPrimaries {
        spd_energy: lcd.primary_spd.clone(),
        gamma: (0..3)
            .map(|p| lcd.gamma.table(p).unwrap().to_vec())
            .collect(),
        pixel_pitch_m: lcd.pixel_pitch_m(),
        viewing_distance_m: lcd.viewing_distance_m,
    };
    let pic = picture(3, 4);
    let rgb = scene_from_rgb(
        &RgbCodes {
            rows: 3,
            cols: 4,
            channels: 3,
            bits: 8,
            codes: pic.iter().map(|&v| v as u16).collect(),
        },
        &prim,
        &SI,
    )
    .unwrap();
    let orig = SceneRadiance {
        radiance: rgb.radiance,
        sample_pitch_m: 1e-6,
        object_distance_m: None,
        illuminant: Some(rgb.illuminant_photons.clone()),
        depth_m: None,
        sample_aperture: Default::default(),
    };
    let mut s = orig.clone();
    swap_illuminant(&mut s, &tungsten, true, &SI).unwrap();
    swap_illuminant(&mut s, &rgb.illuminant_photons, true, &SI).unwrap();
    let e = max_rel_diff(&s.radiance, &orig.radiance, &grid);
    assert!(e < 1e-6, "display scene round trip: {e:.3e}");
}

/// A Macbeth chart under D65 swapped to illuminant A is the chart under A (reflectance
/// kept), both at 50 cd/m²: through the pipeline's target keys.
#[test]
fn swap_illuminant_key_relights_a_reflectance_scene() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = camera(24, 36);
    cam["optics"]["blur"] = json!({"kind": "none"});
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "swapped", "exposure_s": 0.01, "frames": ["a.png"],
         "target": {"kind": "macbeth", "illuminant": "D65", "swap_illuminant": "A",
                    "mean_luminance_cd_m2": 50}},
        {"id": "direct", "exposure_s": 0.01, "frames": ["b.png"],
         "target": {"kind": "macbeth", "illuminant": "A", "mean_luminance_cd_m2": 50}}]});
    write_set(dir.path(), &cam, &caps);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let a = camsim_pipeline::chain::shot_scene(&set, 0, &grid).unwrap();
    let b = camsim_pipeline::chain::shot_scene(&set, 1, &grid).unwrap();
    let e = max_rel_diff(&a.radiance, &b.radiance, &grid);
    assert!(e < 1e-3, "swapped vs direct: {e:.3e}");
    // the swapped shot carries the new illuminant downstream (white balance, reports)
    assert_eq!(
        set.shots[0].target.illuminant, set.shots[1].target.illuminant,
        "the swapped scene carries the new illuminant"
    );
}

#[test]
fn illuminant_estimates_pick_the_right_family_and_temperature() {
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let refl = camsim_core::data::macbeth_reflectances_row_major().unwrap();
    let chart = |ill: &Spectrum| {
        let planes: Vec<Vec<f32>> = grid
            .wavelength_nm
            .iter()
            .map(|&w| {
                refl.iter()
                    .map(|r| (r.eval(w) * ill.eval(w)) as f32)
                    .collect()
            })
            .collect();
        SpectralImage::new(4, 6, SpectralBasis::Bands(grid.clone()), planes).unwrap()
    };
    let bb3000 = camsim_core::scene::blackbody_energy(
        3000.0,
        380.0,
        780.0,
        camsim_core::scene::PLANCK_C1,
        camsim_core::scene::PLANCK_C2,
    )
    .energy_to_photons(&SI);
    let d65 = camsim_core::data::illuminant("D65")
        .unwrap()
        .energy_to_photons(&SI);
    // Grey world is exact when its hypothesis holds: spectrally flat greys under 3000 K give
    // the candidate nearest 3000 K (5-mired grid: 2985 or 3030 K).
    let greys: Vec<Vec<f32>> = grid
        .wavelength_nm
        .iter()
        .map(|&w| {
            (1..=6)
                .map(|k| (0.15 * k as f64 * bb3000.eval(w)) as f32)
                .collect()
        })
        .collect();
    let greys = SpectralImage::new(2, 3, SpectralBasis::Bands(grid.clone()), greys).unwrap();
    let e = estimate_illuminant(&greys, &grid, EstimateMethod::GreyWorld, &SI).unwrap();
    assert_eq!(e.family, IlluminantFamily::Blackbody);
    assert!((e.cct_k - 3000.0).abs() < 35.0, "greys: {} K", e.cct_k);
    assert!(e.relative_residual < 1e-4, "{}", e.relative_residual);
    // On a Macbeth chart the white patch carries the brightest-pixel estimate close; grey world
    // is pulled warm by the chart's reddish mean reflectance (a known bias of the hypothesis).
    let est = |ill: &Spectrum, m| {
        let e = estimate_illuminant(&chart(ill), &grid, m, &SI).unwrap();
        (e.family, e.cct_k)
    };
    let (fam, t) = est(&bb3000, EstimateMethod::Brightest);
    assert!(
        fam == IlluminantFamily::Blackbody && (t - 3000.0).abs() < 300.0,
        "{fam:?} {t}"
    );
    let (fam, t) = est(&d65, EstimateMethod::Brightest);
    assert!(
        fam == IlluminantFamily::Daylight && (t - 6504.0).abs() < 650.0,
        "{fam:?} {t}"
    );
    // grey world on the chart: warm by 15–30 % (measured: 2469 K for 3000 K, 4878 K for D65),
    // and farther off than the brightest pixels
    let (_, t) = est(&bb3000, EstimateMethod::GreyWorld);
    assert!(t < 3000.0 && t > 0.7 * 3000.0, "grey world, 3000 K: {t}");
    let (_, t) = est(&d65, EstimateMethod::GreyWorld);
    assert!(t < 6504.0 && t > 0.7 * 6504.0, "grey world, D65: {t}");
    // the scale: the white patch (row 3, col 0) has reflectance ≈ its own (0.9 or so) → the
    // brightest pixel's radiance / illuminant is ≈ 1 at 550 nm
    let e = estimate_illuminant(&chart(&d65), &grid, EstimateMethod::Brightest, &SI).unwrap();
    let white = chart(&d65).pixel_spectrum(3, 0, &grid);
    let r = white[15] / e.spectrum_photons.eval(550.0);
    assert!((r - 1.0).abs() < 0.05, "brightest reflectance {r}");
}

/// The 3 × 4 × 5 test cube: v(b, r, c) = 1 + 100 b + 10 r + c.
fn cube_value(b: usize, r: usize, c: usize) -> f64 {
    1.0 + 100.0 * b as f64 + 10.0 * r as f64 + c as f64
}

fn encode(v: f64, ty: u32, big: bool) -> Vec<u8> {
    macro_rules! e {
        ($x:expr) => {
            if big {
                $x.to_be_bytes().to_vec()
            } else {
                $x.to_le_bytes().to_vec()
            }
        };
    }
    match ty {
        2 => e!(v as i16),
        12 => e!(v as u16),
        4 => e!(v as f32),
        5 => e!(v),
        _ => unreachable!(),
    }
}

/// Write NAME.hdr + NAME.raw for the test cube; returns the header path.
fn write_envi(dir: &Path, name: &str, interleave: &str, ty: u32, big: bool) -> std::path::PathBuf {
    let (rows, cols, bands) = (3, 4, 5);
    let mut data = Vec::new();
    let idx: Vec<(usize, usize, usize)> = match interleave {
        "bsq" => (0..bands)
            .flat_map(|b| (0..rows).flat_map(move |r| (0..cols).map(move |c| (b, r, c))))
            .collect(),
        "bil" => (0..rows)
            .flat_map(|r| (0..bands).flat_map(move |b| (0..cols).map(move |c| (b, r, c))))
            .collect(),
        _ => (0..rows)
            .flat_map(|r| (0..cols).flat_map(move |c| (0..bands).map(move |b| (b, r, c))))
            .collect(),
    };
    for (b, r, c) in idx {
        data.extend(encode(cube_value(b, r, c), ty, big));
    }
    let hdr = dir.join(format!("{name}.hdr"));
    std::fs::write(
        &hdr,
        format!(
            "ENVI\ndescription = {{test cube}}\nsamples = {cols}\nlines   = {rows}\nbands = {bands}\n\
             header offset = 0\nfile type = ENVI Standard\ndata type = {ty}\ninterleave = {interleave}\n\
             byte order = {}\nwavelength units = Micrometers\nwavelength = {{\n 0.45, 0.50,\n 0.55, 0.60, 0.65}}\n",
            u8::from(big)
        ),
    )
    .unwrap();
    std::fs::write(dir.join(format!("{name}.raw")), data).unwrap();
    hdr
}

fn check_cube(c: &camsim_pipeline::scene_files::SpectralCube) {
    assert_eq!((c.rows, c.cols, c.planes.len()), (3, 4, 5));
    assert_eq!(c.wavelength_nm, vec![450.0, 500.0, 550.0, 600.0, 650.0]);
    for b in 0..5 {
        for r in 0..3 {
            for col in 0..4 {
                assert_eq!(c.planes[b][r * 4 + col] as f64, cube_value(b, r, col));
            }
        }
    }
}

#[test]
fn envi_cubes_round_trip_in_every_interleave_and_type() {
    let dir = tempfile::tempdir().unwrap();
    for il in ["bsq", "bil", "bip"] {
        for (ty, big) in [(4, false), (4, true), (5, false), (12, true), (2, false)] {
            let name = format!("c_{il}_{ty}_{big}");
            let hdr = write_envi(dir.path(), &name, il, ty, big);
            let c = read_envi(&hdr, None).unwrap_or_else(|e| panic!("{name}: {e}"));
            check_cube(&c);
        }
    }
}

#[test]
fn envi_refuses_truncated_data_and_lying_headers() {
    let dir = tempfile::tempdir().unwrap();
    let hdr = write_envi(dir.path(), "c", "bsq", 4, false);
    let raw = dir.path().join("c.raw");
    let good = std::fs::read(&raw).unwrap();
    // truncated by one byte
    std::fs::write(&raw, &good[..good.len() - 1]).unwrap();
    let e = read_envi(&hdr, None).unwrap_err();
    assert!(
        e.contains("c.raw") && e.contains("239 bytes") && e.contains("240"),
        "{e}"
    );
    std::fs::write(&raw, &good).unwrap();
    let text = std::fs::read_to_string(&hdr).unwrap();
    let lie = |from: &str, to: &str| {
        std::fs::write(&hdr, text.replace(from, to)).unwrap();
        let e = read_envi(&hdr, None).unwrap_err();
        assert!(!e.contains('\n'), "one line: {e}");
        assert!(e.contains("c."), "names the file: {e}");
        e
    };
    // more lines than the data hold
    let e = lie("lines   = 3", "lines   = 4");
    assert!(e.contains("320"), "{e}");
    // a wavelength missing
    let e = lie(" 0.55, 0.60, 0.65}", " 0.55, 0.60}");
    assert!(
        e.contains("`wavelength` lists 4 wavelengths for 5 bands"),
        "{e}"
    );
    // decreasing wavelengths
    let e = lie("0.55, 0.60", "0.60, 0.55");
    assert!(e.contains("must increase"), "{e}");
    // unknown data type and interleave, zero bands, no units on µm values
    assert!(lie("data type = 4", "data type = 6").contains("`data type` = 6"));
    assert!(lie("interleave = bsq", "interleave = bxx").contains("`interleave` = bxx"));
    assert!(lie("bands = 5", "bands = 0").contains("`bands` = 0"));
    assert!(lie("wavelength units = Micrometers\n", "").contains("`wavelength units`"));
    // a header claiming a cube far over the memory budget is refused before reading
    let e = lie("samples = 4\n", "samples = 4000000000\n");
    assert!(e.contains("samples × lines × bands"), "{e}");
    // not an ENVI header at all
    std::fs::write(&hdr, "hello\n").unwrap();
    assert!(read_envi(&hdr, None)
        .unwrap_err()
        .contains("not an ENVI header"));
}

/// An npy file of the test cube (rows × cols × bands).
fn write_npy(path: &Path, descr: &str, fortran: bool, shape: &str, skip_last: usize) {
    let header = format!(
        "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}",
        if fortran { "True" } else { "False" }
    );
    let mut h = header.into_bytes();
    while (10 + h.len() + 1) % 64 != 0 {
        h.push(b' ');
    }
    h.push(b'\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((h.len() as u16).to_le_bytes());
    out.extend(h);
    let (big, ty) = (
        descr.starts_with('>'),
        if descr.ends_with('4') { 4 } else { 5 },
    );
    let order: Vec<(usize, usize, usize)> = if fortran {
        (0..5)
            .flat_map(|b| (0..4).flat_map(move |c| (0..3).map(move |r| (b, r, c))))
            .collect()
    } else {
        (0..3)
            .flat_map(|r| (0..4).flat_map(move |c| (0..5).map(move |b| (b, r, c))))
            .collect()
    };
    for (b, r, c) in order {
        out.extend(encode(cube_value(b, r, c), ty, big));
    }
    out.truncate(out.len() - skip_last);
    std::fs::write(path, out).unwrap();
}

#[test]
fn npy_cubes_round_trip_and_lying_headers_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let wl = [450.0, 500.0, 550.0, 600.0, 650.0];
    let p = dir.path().join("c.npy");
    for descr in ["<f4", ">f4", "<f8", ">f8"] {
        for fortran in [false, true] {
            write_npy(&p, descr, fortran, "(3, 4, 5)", 0);
            check_cube(&read_npy_cube(&p, &wl).unwrap_or_else(|e| panic!("{descr}: {e}")));
        }
    }
    let refuse = |descr: &str, shape: &str, skip: usize, wl: &[f64], needle: &str| {
        write_npy(&p, descr, false, shape, skip);
        let e = read_npy_cube(&p, wl).unwrap_err();
        assert!(
            e.contains(needle) && e.contains("c.npy") && !e.contains('\n'),
            "{needle}: {e}"
        );
    };
    refuse("<f4", "(3, 4, 5)", 1, &wl, "bytes");
    refuse("<f4", "(3, 5, 5)", 0, &wl, "bytes");
    refuse("<f4", "(12, 5)", 0, &wl, "expected 3 axes");
    refuse("<i4", "(3, 4, 5)", 0, &wl, "float32 or float64");
    refuse("<f4", "(3, 4, 5)", 0, &wl[..4], "4 wavelengths for 5 bands");
    refuse("<f4", "(300000, 400000, 5)", 0, &wl, "shape");
    // a header length beyond the file
    let mut b = std::fs::read(&p).unwrap();
    b[8] = 0xff;
    b[9] = 0xff;
    b.truncate(200);
    std::fs::write(&p, b).unwrap();
    assert!(read_npy_cube(&p, &wl)
        .unwrap_err()
        .contains("header claims"));
    // negative radiance
    let mut v = b"\x93NUMPY\x01\x00".to_vec();
    let h = b"{'descr': '<f4', 'fortran_order': False, 'shape': (1, 1, 1), }\n";
    v.extend((h.len() as u16).to_le_bytes());
    v.extend(h);
    v.extend((-1.0f32).to_le_bytes());
    std::fs::write(&p, v).unwrap();
    assert!(read_npy_cube(&p, &[550.0])
        .unwrap_err()
        .contains("value -1"));
}

/// A cube target through the capture-set parser, and a broken one is one line naming the
/// captures file, the key and the cube file.
#[test]
fn cube_targets_parse_and_errors_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    write_npy(&dir.path().join("c.npy"), "<f4", false, "(3, 4, 5)", 0);
    write_envi(dir.path(), "e", "bil", 4, false);
    let cam = camera(12, 16);
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "npy", "exposure_s": 0.01, "frames": ["a.png"],
         "target": {"kind": "cube", "file": "c.npy", "wavelength_nm": [450, 500, 550, 600, 650],
                    "fov_deg": 0.1, "distance_m": 2.0}},
        {"id": "envi", "exposure_s": 0.01, "frames": ["b.png"],
         "target": {"kind": "cube", "file": "e.hdr", "illuminant": "D65"}}]});
    write_set(dir.path(), &cam, &caps);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let w = &set.shots[0].target.world;
    assert_eq!((w.fov_deg, w.distance_m), (Some(0.1), Some(2.0)));
    assert!(
        w.illuminant_source
            .as_deref()
            .unwrap()
            .starts_with("estimated (grey world)"),
        "{w:?}"
    );
    assert!(set.shots[0].target.illuminant.is_some());
    assert_eq!(
        set.shots[1].target.world.illuminant_source.as_deref(),
        Some("given: D65")
    );
    // a truncated cube
    let b = std::fs::read(dir.path().join("c.npy")).unwrap();
    std::fs::write(dir.path().join("c.npy"), &b[..b.len() - 4]).unwrap();
    let e = camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None)
        .unwrap_err()
        .one_line();
    assert!(
        e.contains("captures.json") && e.contains(".file") && e.contains("c.npy"),
        "{e}"
    );
}

/// Coverage (in pixels) of a white picture of field of view `fov_deg` at `distance_m`:
/// Σ luminance / white luminance over the sensor.
fn coverage_px(fov_deg: f64, distance_m: Option<f64>) -> (f64, usize) {
    let dir = tempfile::tempdir().unwrap();
    image::RgbImage::from_raw(16, 10, vec![255u8; 16 * 10 * 3])
        .unwrap()
        .save(dir.path().join("w.png"))
        .unwrap();
    let mut cam = camera(60, 80);
    cam["optics"]["blur"] = json!({"kind": "none"});
    let mut t = json!({"kind": "image", "file": "w.png", "display": "lcdExample",
                       "fov_deg": fov_deg});
    if let Some(d) = distance_m {
        t["distance_m"] = json!(d);
    }
    let caps = json!({"camera": "camera.json", "shots": [
        {"id": "w", "exposure_s": 0.01, "frames": ["a.png"], "target": t}]});
    write_set(dir.path(), &cam, &caps);
    let set =
        camsim_pipeline::config::load_captures(&dir.path().join("captures.json"), None).unwrap();
    let grid = WavelengthGrid::regular(400.0, 700.0, 10.0).unwrap();
    let scene = camsim_pipeline::chain::shot_scene(&set, 0, &grid).unwrap();
    assert_eq!(
        (scene.radiance.rows, scene.radiance.cols),
        (60, 80),
        "one sample per pixel"
    );
    assert_eq!(scene.object_distance_m, distance_m);
    let lum = scene
        .radiance
        .integrate_against(&luminance_weight_for_photons(&SI));
    let white = camsim_display::DisplayModel::load("lcdExample")
        .unwrap()
        .peak_luminance_cd_per_m2();
    let covered: f64 = lum.iter().map(|v| *v as f64 / white).sum();
    let over_half = lum.iter().filter(|v| **v as f64 > 0.5 * white).count();
    (covered, over_half)
}

#[test]
fn a_target_of_known_fov_covers_the_predicted_pixels() {
    // f = 3 mm, 2 µm pixels, picture 16 × 10: W = 2 s′ tan(F/2), H = W · 10/16
    let (f, p) = (3e-3, 2e-6);
    for (fov, d) in [(1.5, None), (1.2, Some(0.05)), (0.8, Some(1.0))] {
        let s_img: f64 = match d {
            None => f,
            Some(d) => 1.0 / (1.0 / f - 1.0 / d),
        };
        let w = 2.0 * s_img * (0.5 * f64::to_radians(fov)).tan() / p;
        let h = w * 10.0 / 16.0;
        let (covered, n) = coverage_px(fov, d);
        assert!(
            (covered - w * h).abs() < 1e-4 * w * h,
            "FOV {fov}° at {d:?}: covers {covered} px², predicted {}",
            w * h
        );
        // pixels more than half covered: the area within the boundary pixels
        assert!(
            (n as f64 - w * h).abs() <= w + h + 4.0,
            "{n} pixels over half vs {} predicted",
            w * h
        );
    }
    // the sensor's own field of view: the picture (same aspect) fills it exactly
    let sensor_fov = 2.0 * (0.5 * 80.0 * p / f).atan().to_degrees();
    let (covered, _) = coverage_px(sensor_fov, None);
    assert!((covered - 80.0 * 50.0).abs() < 1e-5 * 4000.0, "{covered}");
}
