//! The sensor-side trace and the exit-pupil sampler of `camsim_lens::pupil`.
//!
//! * The sensor-side trace is checked against the crate's forward trace: the ray that leaves
//!   the front of the lens, reversed and traced from object space, lands on the sensor point it
//!   started from and crosses the stop at the same point (at wavelengths on the 1-nm index
//!   grid, where the interpolated index is exact, so the two traces differ only by rounding).
//! * The sampler is uniform on its box (chi-square on 8×8 cells, after undoing the rotation to
//!   the film point's azimuth), its pdf is 1 / box area, and every transmitted ray starts inside
//!   its box (rays from a square 4× the largest box).
//! * The chief-ray aim crosses the stop at its centre.
//! * The film irradiance per unit radiance on the axis (the real lens's camera equation)
//!   against closed forms: a bare circular stop (the disc's projected solid angle), the
//!   paraxial camera equation at a small aperture, and the film moved along the axis (the exit
//!   pupil's solid angle from the film); off the axis, the bare stop's disc seen from an
//!   off-axis film point (the configuration factor of a disc to a parallel element).
use camsim_core::rng::stream;
use camsim_lens::pupil::{ExitPupilOptions, ExitPupilTable, SensorSideLens};
use camsim_lens::{Clipping, GlassCatalog, LensPrescription, Ray};
use rand::RngExt;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// The bundled f/2 double Gauss at its paraxial focus, with the stop's clear radius set to
/// the paraxial value (as the path tracer's camera does).
fn lens() -> LensPrescription {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses/double_gauss_50mm_f2.json");
    let l = LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap();
    l.focused(l.primary_nm)
        .unwrap()
        .with_aperture_stop_clear()
        .unwrap()
}

/// Film radius of the table (mm): 15° of field of the 50-mm lens.
const R_MAX_MM: f64 = 13.4;

fn table(l: &LensPrescription, side: &SensorSideLens) -> ExitPupilTable {
    let fo = l.first_order(l.primary_nm).unwrap();
    ExitPupilTable::new(
        side,
        R_MAX_MM,
        &ExitPupilOptions {
            bins: 16,
            grid: 48,
            wavelengths_nm: [400.0, l.primary_nm, 700.0],
            search_half_width_mm: 30.0,
            exit_pupil_to_image_mm: side.image_z_mm() - fo.exit_pupil_z_mm,
        },
    )
    .unwrap()
}

#[test]
fn sensor_side_trace_reverses_the_forward_trace() {
    let l = lens();
    let side = SensorSideLens::new(&l).unwrap();
    let tab = table(&l, &side);
    let mut rng = stream(41, &[]);
    let mut checked = 0;
    for _ in 0..400 {
        let r = rng.random::<f64>() * R_MAX_MM * 0.95;
        let phi = rng.random::<f64>() * std::f64::consts::TAU;
        let p = [r * phi.cos(), r * phi.sin()];
        let wl = [450.0, 550.0, 650.0][checked % 3];
        let s = tab.sample(p, [rng.random(), rng.random()]).unwrap();
        let Some(e) = side.trace_through(p, s.rear_point_mm, wl, Clipping::SemiDiameters) else {
            continue;
        };
        // Lens frame: z = z_img − z'; the light travels opposite to the sensor-side ray.
        let d = [-e.direction[0], -e.direction[1], e.direction[2]];
        let q = [
            e.origin_mm[0],
            e.origin_mm[1],
            side.image_z_mm() - e.origin_mm[2],
        ];
        let back = 50.0;
        let ray = Ray {
            origin_mm: [q[0] - back * d[0], q[1] - back * d[1], q[2] - back * d[2]],
            direction: d,
            opl_mm: 0.0,
        };
        let t = l
            .trace(&ray, wl, Clipping::SemiDiameters)
            .expect("forward trace lost the ray");
        let err = (t.image_mm[0] - p[0]).hypot(t.image_mm[1] - p[1]);
        assert!(
            err < 1e-8,
            "film point {p:?} at {wl} nm: forward trace lands {err:.2e} mm away"
        );
        let stop_err = (t.stop_mm[0] - e.stop_mm[0]).hypot(t.stop_mm[1] - e.stop_mm[1]);
        assert!(
            stop_err < 1e-8,
            "stop crossings differ by {stop_err:.2e} mm"
        );
        checked += 1;
    }
    // The box holds the vignetted pupil, a disc and lens-shaped cut-outs: more than half of
    // its area transmits.
    assert!(
        checked > 200,
        "only {checked} of 400 sampled rays got through"
    );
}

#[test]
fn exit_pupil_sampler_is_uniform_on_its_box_chi_square() {
    let l = lens();
    let side = SensorSideLens::new(&l).unwrap();
    let tab = table(&l, &side);
    let (dr, bins) = tab.bounds();
    let mut rng = stream(42, &[]);
    let cells = 8usize;
    let n = 64_000;
    let trials = 6;
    for trial in 0..trials {
        let r = rng.random::<f64>() * R_MAX_MM * 0.95;
        let phi = rng.random::<f64>() * std::f64::consts::TAU;
        let p = [r * phi.cos(), r * phi.sin()];
        let b = bins[(r / dr) as usize].unwrap();
        let mut hist = vec![0usize; cells * cells];
        for _ in 0..n {
            let s = tab.sample(p, [rng.random(), rng.random()]).unwrap();
            assert!((s.pdf_per_mm2 * b.area_mm2() - 1.0).abs() < 1e-12);
            assert_eq!(s.box_area_mm2, b.area_mm2());
            let (c, sn) = (phi.cos(), phi.sin());
            let q = s.rear_point_mm;
            let (x, y) = (c * q[0] + sn * q[1], -sn * q[0] + c * q[1]);
            let fx = (x - b.x0_mm) / (b.x1_mm - b.x0_mm);
            let fy = (y - b.y0_mm) / (b.y1_mm - b.y0_mm);
            assert!((-1e-9..=1.0 + 1e-9).contains(&fx) && (-1e-9..=1.0 + 1e-9).contains(&fy));
            let i = ((fx * cells as f64) as usize).min(cells - 1);
            let j = ((fy * cells as f64) as usize).min(cells - 1);
            hist[j * cells + i] += 1;
        }
        let e = n as f64 / (cells * cells) as f64;
        let chi2: f64 = hist.iter().map(|&o| (o as f64 - e).powi(2) / e).sum();
        let p_value = 1.0
            - ChiSquared::new((cells * cells - 1) as f64)
                .unwrap()
                .cdf(chi2);
        // 6 trials at α = 1e-3 each: joint false-failure rate 0.6 %.
        assert!(
            p_value > 1e-3,
            "trial {trial}: chi² {chi2:.1}, p = {p_value:.2e}"
        );
    }
}

#[test]
fn exit_pupil_bounds_hold_every_transmitted_ray_and_the_chief_ray_hits_the_stop_centre() {
    let l = lens();
    let side = SensorSideLens::new(&l).unwrap();
    let tab = table(&l, &side);
    let (dr, bins) = tab.bounds();
    assert!(
        bins.iter().all(Option::is_some),
        "an empty pupil box inside the image circle"
    );
    let e = bins
        .iter()
        .flatten()
        .map(|b| b.x0_mm.abs().max(b.x1_mm.abs()).max(b.y1_mm.abs()))
        .fold(0.0, f64::max)
        * 2.0;
    let mut rng = stream(43, &[]);
    let (mut through, mut outside) = (0, 0);
    for _ in 0..60_000 {
        let r = rng.random::<f64>() * R_MAX_MM * 0.999;
        let q = [
            (2.0 * rng.random::<f64>() - 1.0) * e,
            (2.0 * rng.random::<f64>() - 1.0) * e,
        ];
        let wl = 400.0 + 300.0 * rng.random::<f64>();
        if side
            .trace_through([r, 0.0], q, wl, Clipping::SemiDiameters)
            .is_some()
        {
            through += 1;
            match bins[(r / dr) as usize] {
                Some(b)
                    if (b.x0_mm..=b.x1_mm).contains(&q[0])
                        && (b.y0_mm..=b.y1_mm).contains(&q[1]) => {}
                _ => outside += 1,
            }
        }
    }
    assert!(through > 1000, "only {through} rays got through");
    assert_eq!(
        outside, 0,
        "{outside} of {through} transmitted rays started outside their box"
    );
    // The chief ray at the interval ends (where it is solved) crosses the stop centre.
    for k in 0..bins.len() {
        let r = k as f64 * dr;
        let a = tab.chief_aim([0.0, r]).unwrap();
        let ex = side
            .trace_through([0.0, r], a, l.primary_nm, Clipping::None)
            .unwrap();
        let off = ex.stop_mm[0].hypot(ex.stop_mm[1]);
        assert!(
            off < 1e-6,
            "film radius {r} mm: chief ray misses the stop centre by {off:.2e} mm"
        );
    }
}

/// A bare circular stop of radius R (no power, air on both sides) with the film d behind it:
/// E/L = ∫ cos⁴θ/d² dA over the disc = π sin²θ_max = π R²/(R² + d²) (the disc's projected
/// solid angle). The midpoint rule on the bundle's bounds is within 2·10⁻³ of it.
#[test]
fn axial_irradiance_of_a_bare_stop_is_the_projected_solid_angle_of_its_disc() {
    for (r_mm, d_mm) in [(5.0, 20.0), (10.0, 10.0), (1.0, 40.0)] {
        let text = format!(
            r#"{{"name": "stop", "units": "mm",
              "surfaces": [{{"radius_mm": null, "thickness_mm": {d_mm}, "material": "air",
                            "stop": true, "semi_diameter_mm": {r_mm}}}],
              "object_distance_mm": null, "fields_deg": [0], "wavelengths_nm": [550],
              "aperture": {{"epd_mm": {}}}}}"#,
            2.0 * r_mm
        );
        let l = LensPrescription::from_json_str(&text, &GlassCatalog::bundled()).unwrap();
        let side = SensorSideLens::new(&l).unwrap();
        let got = side.axial_irradiance_per_radiance_sr(550.0, 384);
        let want = std::f64::consts::PI * r_mm * r_mm / (r_mm * r_mm + d_mm * d_mm);
        eprintln!("R {r_mm} mm, d {d_mm} mm: E/L {got:.6} sr, closed form {want:.6} sr");
        assert!((got / want - 1.0).abs() < 2e-3, "{got} vs {want}");
    }
}

/// The double Gauss stopped down to f/16 (pupil aberrations negligible) with the film at the
/// paraxial image: E/L is the paraxial camera equation π/(4N_w²) (paper Eq. 1) within 0.3 %.
/// Moving the film towards the lens by δ raises it by the exit pupil's solid angle from the
/// film, (z_xp/(z_xp − δ))², z_xp the paraxial exit pupil's distance from the image (within
/// 0.2 % of that ratio); at f/2 the real pupil's spherical aberration adds more than 0.5 %.
#[test]
fn axial_irradiance_is_the_paraxial_camera_equation_at_a_small_aperture() {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses/double_gauss_50mm_f2.json");
    let base = LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap();
    let w = base.primary_nm;
    let mut l16 = base.clone();
    l16.aperture = camsim_lens::prescription::Aperture::FNumber(16.0);
    let l16 = l16.focused(w).unwrap();
    let fo = l16.first_order(w).unwrap();
    let parax = std::f64::consts::PI / (4.0 * fo.working_f_number * fo.working_f_number);
    let e = camsim_lens::pupil::axial_irradiance_per_radiance_sr(&l16, &[w]).unwrap()[0];
    eprintln!("f/16 at the paraxial image: E/L {e:.6e} sr, π/(4N_w²) {parax:.6e} sr");
    assert!((e / parax - 1.0).abs() < 3e-3, "{e} vs {parax}");
    // the film 0.3 mm closer to the lens
    let delta = 0.3;
    let moved = l16.with_image_distance(l16.image_distance_mm() - delta);
    let em = camsim_lens::pupil::axial_irradiance_per_radiance_sr(&moved, &[w]).unwrap()[0];
    let z_xp = fo.exit_pupil_from_image_mm.abs();
    let want = (z_xp / (z_xp - delta)).powi(2);
    eprintln!(
        "film moved {delta} mm: ratio {:.5}, exit-pupil solid angle {want:.5}",
        em / e
    );
    assert!((em / e / want - 1.0).abs() < 2e-3, "{} vs {want}", em / e);
    // f/2: the real pupil is larger than the paraxial one
    let l2 = base.focused(w).unwrap();
    let fo2 = l2.first_order(w).unwrap();
    let parax2 = std::f64::consts::PI / (4.0 * fo2.working_f_number * fo2.working_f_number);
    let e2 = camsim_lens::pupil::axial_irradiance_per_radiance_sr(&l2, &[w]).unwrap()[0];
    eprintln!(
        "f/2 at the paraxial image: E/L / π/(4N_w²) = {:.5}",
        e2 / parax2
    );
    assert!(e2 / parax2 > 1.005, "{e2} vs {parax2}");
}

/// Off the axis, a bare circular stop of radius R with the film d behind it, film point r off
/// the axis: E/L = ∫ cos⁴θ/d² dA over the disc is the projected solid angle of a disc seen from
/// a parallel element off its axis, (π/2)·(1 − (d² + r² − R²)/√((d² + r² + R²)² − 4r²R²))
/// (the disc-to-parallel-element configuration factor; r = 0 gives π R²/(R² + d²)). The
/// midpoint rule on the bundle's bounds is within 2·10⁻³ of it, and so is the ratio to the axis
/// (`SensorSideLens::relative_illumination`, which must differ from cos⁴ of the chief ray, the disc's
/// centre, by more than that at these points).
#[test]
fn off_axis_irradiance_of_a_bare_stop_is_the_projected_solid_angle_of_its_disc() {
    let e = |rr: f64, d: f64, r: f64| {
        let (d2, r2, rr2) = (d * d, r * r, rr * rr);
        0.5 * std::f64::consts::PI
            * (1.0 - (d2 + r2 - rr2) / ((d2 + r2 + rr2).powi(2) - 4.0 * r2 * rr2).sqrt())
    };
    for (r_mm, d_mm) in [(5.0, 20.0), (10.0, 10.0)] {
        let text = format!(
            r#"{{"name": "stop", "units": "mm",
              "surfaces": [{{"radius_mm": null, "thickness_mm": {d_mm}, "material": "air",
                            "stop": true, "semi_diameter_mm": {r_mm}}}],
              "object_distance_mm": null, "fields_deg": [0], "wavelengths_nm": [550],
              "aperture": {{"epd_mm": {}}}}}"#,
            2.0 * r_mm
        );
        let l = LensPrescription::from_json_str(&text, &GlassCatalog::bundled()).unwrap();
        let side = SensorSideLens::new(&l).unwrap();
        let film: Vec<f64> = [0.3, 0.8, 1.5].iter().map(|f| f * d_mm).collect();
        let pts: Vec<(f64, f64)> = film.iter().map(|r| (*r, 550.0)).collect();
        let ri = side.relative_illumination(&pts, 384).unwrap();
        for (p, ri) in film.iter().zip(ri) {
            let got = side.irradiance_per_radiance_sr(*p, 550.0, 384);
            let want = e(r_mm, d_mm, *p);
            let ri_want = want / e(r_mm, d_mm, 0.0);
            let cos4 = (d_mm / d_mm.hypot(*p)).powi(4);
            eprintln!(
                "R {r_mm} mm, d {d_mm} mm, film {p} mm: E/L {got:.6} sr, closed form {want:.6} sr; RI {ri:.5} vs {ri_want:.5} (cos⁴ {cos4:.5})"
            );
            assert!((got / want - 1.0).abs() < 2e-3, "{got} vs {want}");
            assert!((ri / ri_want - 1.0).abs() < 2e-3, "{ri} vs {ri_want}");
            assert!((cos4 / ri_want - 1.0).abs() > 4e-3, "no power at {p} mm");
        }
    }
}
