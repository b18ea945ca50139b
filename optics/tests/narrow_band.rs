//! Issue 17 §1: narrow-band light through wavelength-dependent blurs. A uniform scene's mean
//! signal `∫ R(λ) E(λ) dλ` must not depend on the blur: every per-band blur (diffraction,
//! wavefront, sampled PSF sets), the wavelength-independent ones (Gaussian, pillbox) and the
//! defocus effect block give the unblurred value within 1e-6 relative, for lines,
//! boxes of 1–20 nm on and off the grid and measured LED / fluorescent lamps, on band grids of
//! 1, 2, 5 and 10 nm. The responses are a measured camera's (Nikon D5100, NPL).
//!
//! Data are read from ../shared (colour-science 0.4.7 exports, BSD-3; not copied).
use camsim_core::{SceneRadiance, SpectralImage, Spectrum, WavelengthGrid};
use camsim_optics::{form_image, Blur, Defocus, OpticsModel, PsfSet, RelativeIllumination};
use std::path::PathBuf;

fn shared(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/real/spectral/colour_science")
        .join(rel)
}

/// The D5100's three channel responses.
fn camera_responses() -> Vec<Spectrum> {
    let text = std::fs::read_to_string(shared("camera_ssf_Nikon_5100_NPL.csv")).unwrap();
    let mut wl = Vec::new();
    let mut ch = vec![Vec::new(); 3];
    for line in text.lines().skip(1) {
        let f: Vec<f64> = line.split(',').map(|t| t.trim().parse().unwrap()).collect();
        wl.push(f[0]);
        for c in 0..3 {
            ch[c].push(f[1 + c]);
        }
    }
    ch.into_iter()
        .map(|v| Spectrum::sampled(wl.clone(), v).unwrap())
        .collect()
}

/// A measured lamp of `light_sources_measured.csv` (name, wavelength_nm, value rows).
fn lamp(name: &str) -> Spectrum {
    let text = std::fs::read_to_string(shared("light_sources_measured.csv")).unwrap();
    let (mut wl, mut v) = (Vec::new(), Vec::new());
    for line in text.lines().skip(1) {
        let mut it = line.rsplitn(3, ',');
        let (val, w, n) = (it.next().unwrap(), it.next().unwrap(), it.next().unwrap());
        if n.trim_matches('"') == name {
            wl.push(w.parse::<f64>().unwrap());
            v.push(val.parse::<f64>().unwrap());
        }
    }
    assert!(wl.len() > 10, "lamp {name} not found");
    Spectrum::sampled(wl, v).unwrap()
}

fn boxed(lo: f64, hi: f64) -> Spectrum {
    Spectrum::sampled(vec![lo, hi], vec![1.0, 1.0]).unwrap()
}

/// A spectral line: a triangle of 0.1 nm full width at `at_nm`.
fn line(at_nm: f64) -> Spectrum {
    Spectrum::sampled(vec![at_nm - 0.1, at_nm, at_nm + 0.1], vec![0.0, 1.0, 0.0]).unwrap()
}

fn uniform(s: Spectrum) -> SceneRadiance {
    let (rows, cols) = (12, 14);
    SceneRadiance {
        radiance: SpectralImage::from_single_spectrum(rows, cols, s, vec![1.0; rows * cols]),
        sample_pitch_m: 1.5e-6,
        object_distance_m: None,
        illuminant: None,
        depth_m: None,
        sample_aperture: Default::default(),
    }
}

/// A two-wavelength PSF set: a narrow and a wide separable triangle.
fn psf_set() -> PsfSet {
    let tri = |w: f64| -> Vec<Vec<f64>> {
        (0..9)
            .map(|i| {
                (0..9)
                    .map(|j| {
                        let a = (1.0 - (i as f64 - 4.0).abs() / w).max(0.0);
                        let b = (1.0 - (j as f64 - 4.0).abs() / w).max(0.0);
                        a * b
                    })
                    .collect()
            })
            .collect()
    };
    PsfSet::new(vec![450.0, 650.0], 0.5, vec![tri(1.5), tri(4.5)]).unwrap()
}

fn mean_signals(
    o: &OpticsModel,
    sc: &SceneRadiance,
    g: &WavelengthGrid,
    r: &[Spectrum],
) -> Vec<f64> {
    let e = form_image(o, sc, g).unwrap().irradiance;
    r.iter()
        .map(|q| {
            let m = e.integrate_against(q);
            m.iter().map(|v| *v as f64).sum::<f64>() / m.len() as f64
        })
        .collect()
}

#[test]
fn uniform_scene_mean_does_not_depend_on_the_blur() {
    let responses = camera_responses();
    let mut spectra: Vec<(String, Spectrum)> = vec![
        ("line 546.07".into(), line(546.07)),
        ("line 550".into(), line(550.0)),
        ("line 404.66".into(), line(404.66)),
    ];
    for w in [1.0, 2.0, 5.0, 10.0, 20.0] {
        spectra.push((format!("{w}-nm box on grid"), boxed(540.0, 540.0 + w)));
        spectra.push((format!("{w}-nm box off grid"), boxed(543.3, 543.3 + w)));
    }
    for name in [
        "3-LED-1 (457/540/605)",
        "Phosphor LED YAG",
        "F32T8/TL841 (Triphosphor)",
        "Cool White FL",
        "LPS",
    ] {
        spectra.push((name.into(), lamp(name)));
    }
    let mut base = OpticsModel::diffraction_limited(4.0, 4e-3);
    base.relative_illumination = RelativeIllumination::None;
    let with_blur = |blur: Blur| OpticsModel {
        blur,
        ..base.clone()
    };
    // A lens-free defocus: the effect block's disk on top of diffraction.
    let mut defocused = with_blur(Blur::Diffraction);
    defocused.effects.defocus = Some(Defocus::Pillbox { radius_um: 2.5 });
    let blurs = [
        ("diffraction", with_blur(Blur::Diffraction)),
        (
            "wavefront",
            with_blur(Blur::Wavefront {
                defocus_um: 0.3,
                pupil_samples: 32,
            }),
        ),
        ("PSF set", with_blur(Blur::Psf(psf_set()))),
        ("Gaussian", with_blur(Blur::Gaussian { sigma_um: 1.7 })),
        ("pillbox", with_blur(Blur::Pillbox { width_um: 4.0 })),
        ("diffraction + defocus block", defocused),
    ];
    let mut worst = 0.0f64;
    for step in [1.0, 2.0, 5.0, 10.0] {
        let g = WavelengthGrid::regular(400.0, 700.0, step).unwrap();
        for (name, s) in &spectra {
            let sc = uniform(s.clone());
            let none = OpticsModel {
                blur: Blur::None,
                ..base.clone()
            };
            let want = mean_signals(&none, &sc, &g, &responses);
            for (bname, o) in &blurs {
                let got = mean_signals(o, &sc, &g, &responses);
                for (c, (a, b)) in got.iter().zip(&want).enumerate() {
                    // channels with no light in the band are compared to the brightest one
                    let scale = want.iter().cloned().fold(0.0, f64::max);
                    let rel = (a - b).abs() / scale;
                    worst = worst.max(rel);
                    assert!(
                        rel < 1e-6,
                        "{name}, {step}-nm grid, {bname} channel {c}: {a} vs {b} (rel {rel:.2e})"
                    );
                }
            }
        }
    }
    eprintln!("worst relative difference {worst:.2e}");
}
