//! Mirrors and coordinate breaks (camsim_lens::fold) against closed forms: a mirror's focal
//! length is |R|/2, a paraboloid images an axial point stigmatically, a spherical mirror's
//! marginal rays cross the axis at R/(2 cos θ) from the centre of curvature, a plane mirror
//! (at normal incidence or folded at any angle by coordinate breaks) leaves the image of the
//! unfolded system unchanged, and a decentred image plane shifts the image by the decentre.
use camsim_lens::analysis::pupil_grid;
use camsim_lens::fold::CoordinateBreak;
use camsim_lens::{Clipping, GlassCatalog, LensPrescription, PrescriptionFile, TraceSystem};

fn lens_from(json: &str) -> LensPrescription {
    let f: PrescriptionFile = serde_json::from_str(json).unwrap();
    LensPrescription::from_file_form(&f, &GlassCatalog::bundled()).unwrap()
}

fn mirror_lens(radius_mm: f64, conic: f64, image_mm: f64) -> LensPrescription {
    lens_from(&format!(
        r#"{{"surfaces": [{{"radius_mm": {radius_mm}, "thickness_mm": {image_mm},
            "material": "mirror", "conic": {conic}, "stop": true}}],
            "fields_deg": [0, 1], "wavelengths_nm": [550], "aperture": {{"epd_mm": 40}}}}"#
    ))
}

#[test]
fn concave_mirror_focal_length_is_half_the_radius() {
    for r in [-200.0, -80.0, -1000.0] {
        let l = mirror_lens(r, 0.0, r / 2.0);
        let fo = l.first_order(550.0).unwrap();
        assert!(
            (fo.efl_mm - r.abs() / 2.0).abs() < 1e-9 * r.abs(),
            "{r}: {fo:?}"
        );
        // the paraxial image of infinity is at the focus: unfolded image distance |R|/2
        assert!((fo.paraxial_image_distance_mm - r.abs() / 2.0).abs() < 1e-9 * r.abs());
        assert!((l.image_distance_mm() - r.abs() / 2.0).abs() < 1e-12);
    }
    // a convex mirror diverges: EFL = −|R|/2
    let fo = mirror_lens(300.0, 0.0, -100.0).first_order(550.0).unwrap();
    assert!((fo.efl_mm + 150.0).abs() < 1e-9, "{fo:?}");
}

#[test]
fn paraboloid_images_an_axial_point_stigmatically() {
    let l = mirror_lens(-200.0, -1.0, -100.0);
    let fo = l.first_order(550.0).unwrap();
    let aim = l.aim_field(0.0, 550.0, &fo).unwrap();
    let mut n = 0;
    for p in pupil_grid(9) {
        let t = l
            .trace(&aim.ray(p[0], p[1]), 550.0, Clipping::None)
            .unwrap();
        assert!(
            t.image_mm[0].hypot(t.image_mm[1]) < 1e-9,
            "{p:?}: {:?}",
            t.image_mm
        );
        // unfolded image space: light travels towards +z, image plane at z = +100
        assert!(t.direction[2] > 0.0 && (t.image_mm[2] - 100.0).abs() < 1e-9);
        n += 1;
    }
    assert!(n > 50);
}

#[test]
fn spherical_mirror_rays_cross_the_axis_at_the_closed_form_point() {
    // A ray parallel to the axis at height h meets a sphere of radius |R| at angle θ,
    // sin θ = h/|R|, and crosses the axis |R|/(2 cos θ) from the centre of curvature, i.e.
    // |R| − |R|/(2 cos θ) from the vertex.
    let r = 100.0;
    let l = mirror_lens(-r, 0.0, -r / 2.0);
    let fo = l.first_order(550.0).unwrap();
    let aim = l.aim_field(0.0, 550.0, &fo).unwrap();
    for py in [0.2, 0.5, 0.9, 1.0] {
        let h = py * aim.entrance_pupil_radius_mm;
        let t = l.trace(&aim.ray(0.0, py), 550.0, Clipping::None).unwrap();
        // axis crossing (unfolded z from the vertex) from the image point and direction
        let z_cross = t.image_mm[2] - t.image_mm[1] * t.direction[2] / t.direction[1];
        let theta = (h / r).asin();
        let want = r - r / (2.0 * theta.cos());
        assert!((z_cross - want).abs() < 1e-9, "h {h}: {z_cross} vs {want}");
    }
}

/// A biconvex N-BK7 singlet followed by a mirror section `tail` (JSON surfaces) or by the
/// straight continuation.
fn singlet_with(tail: &str, breaks: &str) -> LensPrescription {
    lens_from(&format!(
        r#"{{"surfaces": [
            {{"radius_mm": 60, "thickness_mm": 6, "material": {{"glass": "N-BK7"}}, "stop": true}},
            {{"radius_mm": -80, "thickness_mm": 30, "material": "air"}},
            {tail}],
            "coordinate_breaks": [{breaks}],
            "fields_deg": [0, 4, 8], "wavelengths_nm": [486.1, 587.6, 656.3],
            "aperture": {{"epd_mm": 12}}}}"#
    ))
}

/// Every image-space quantity of `a` equals that of `b`: first order, and real rays of a
/// pupil grid at several fields (image point, direction, optical path).
fn assert_same_image(a: &LensPrescription, b: &LensPrescription, what: &str) {
    for wl in [486.1, 587.6, 656.3] {
        let (fa, fb) = (a.first_order(wl).unwrap(), b.first_order(wl).unwrap());
        for (x, y, k) in [
            (fa.efl_mm, fb.efl_mm, "efl"),
            (fa.bfl_mm, fb.bfl_mm, "bfl"),
            (fa.exit_pupil_z_mm, fb.exit_pupil_z_mm, "exit pupil"),
            (
                fa.paraxial_image_distance_mm,
                fb.paraxial_image_distance_mm,
                "image distance",
            ),
        ] {
            assert!((x - y).abs() < 1e-9, "{what} {wl} nm {k}: {x} vs {y}");
        }
        for th in [0.0, 4.0, -8.0] {
            let (aa, ab) = (
                a.aim_field(th, wl, &fa).unwrap(),
                b.aim_field(th, wl, &fb).unwrap(),
            );
            assert!((aa.aim_y_mm - ab.aim_y_mm).abs() < 1e-9, "{what}: aim");
            for p in pupil_grid(5) {
                let ta = a.trace(&aa.ray(p[0], p[1]), wl, Clipping::None).unwrap();
                let tb = b.trace(&ab.ray(p[0], p[1]), wl, Clipping::None).unwrap();
                for k in 0..3 {
                    assert!(
                        (ta.image_mm[k] - tb.image_mm[k]).abs() < 1e-9
                            && (ta.direction[k] - tb.direction[k]).abs() < 1e-12,
                        "{what} {wl} nm {th}° {p:?}: {ta:?} vs {tb:?}"
                    );
                }
                assert!((ta.opl_mm - tb.opl_mm).abs() < 1e-9, "{what}: OPL");
            }
        }
    }
}

const UNFOLDED: &str = r#"{"radius_mm": null, "thickness_mm": 20, "material": "air"},
    {"radius_mm": null, "thickness_mm": 40, "material": "air"}"#;

#[test]
fn flat_mirror_image_equals_the_unfolded_systems() {
    let straight = singlet_with(UNFOLDED, "");
    let folded = singlet_with(
        r#"{"radius_mm": null, "thickness_mm": -20, "material": "mirror"},
           {"radius_mm": null, "thickness_mm": -40, "material": "air"}"#,
        "",
    );
    assert_same_image(&folded, &straight, "flat mirror");
    // the mirror reverses the layout: the image plane lies 30 mm before the singlet's rear
    let lay = folded.layout();
    assert!((lay.image.origin_mm[2] - (6.0 + 30.0 - 60.0)).abs() < 1e-12);
}

#[test]
fn plane_fold_mirrors_keep_efl_and_image_at_any_angle() {
    let straight = singlet_with(UNFOLDED, "");
    for (axis, angle) in [("x", 45.0), ("y", 45.0), ("x", 30.0), ("y", -20.0)] {
        // break (tilt α), flat mirror, break (tilt α), negative thickness: the Zemax fold
        let folded = singlet_with(
            r#"{"radius_mm": null, "thickness_mm": 20, "material": "air"},
               {"radius_mm": null, "thickness_mm": 0, "material": "air"},
               {"radius_mm": null, "thickness_mm": 0, "material": "mirror"},
               {"radius_mm": null, "thickness_mm": -40, "material": "air"}"#,
            &format!(
                r#"{{"surface": 3, "tilt_{axis}_deg": {angle}}},
                   {{"surface": 5, "tilt_{axis}_deg": {angle}}}"#
            ),
        );
        assert_same_image(&folded, &straight, &format!("fold {axis} {angle}°"));
        // closed-form layout: the axis turns by 2α in the plane normal to the tilt axis and
        // the image lies 40 mm from the mirror along the reflected axis
        let lay = folded.layout();
        let a = (2.0 * angle as f64).to_radians();
        let (zc, zs) = (a.cos(), a.sin());
        let want_dir = if axis == "x" {
            [0.0, zs, -zc] // reflected axis for a tilt about x
        } else {
            [-zs, 0.0, -zc]
        };
        let m = [0.0, 0.0, 56.0];
        for k in 0..3 {
            let want = m[k] + 40.0 * want_dir[k];
            assert!(
                (lay.image.origin_mm[k] - want).abs() < 1e-9,
                "{axis} {angle}: image origin {:?}",
                lay.image.origin_mm
            );
        }
        // the batched trace falls back to the folded trace
        let wl = 587.6;
        let fo = folded.first_order(wl).unwrap();
        let aim = folded.aim_field(4.0, wl, &fo).unwrap();
        let grid = pupil_grid(6);
        let b = TraceSystem::new(&folded, wl).trace_pupil(&aim, &grid, Clipping::None);
        for (i, p) in grid.iter().enumerate() {
            let t = folded
                .trace(&aim.ray(p[0], p[1]), wl, Clipping::None)
                .unwrap();
            assert_eq!(b.get(i).unwrap().image_mm, t.image_mm);
        }
    }
}

#[test]
fn decentred_image_plane_shifts_the_image() {
    let straight = singlet_with(UNFOLDED, "");
    let shifted = singlet_with(UNFOLDED, r#"{"surface": 3, "decenter_y_mm": 2.5}"#);
    let wl = 587.6;
    for th in [0.0, 8.0] {
        let a = straight.aimed_chief_ray(th, wl).unwrap().chief.image_mm;
        let b = shifted.aimed_chief_ray(th, wl).unwrap().chief.image_mm;
        assert!((b[1] - (a[1] - 2.5)).abs() < 1e-9 && (b[0] - a[0]).abs() < 1e-12);
    }
}

#[test]
fn coordinate_break_files_round_trip_and_bad_ones_are_refused() {
    let l = singlet_with(
        UNFOLDED,
        r#"{"surface": 2, "tilt_x_deg": 3, "tilt_first": true}"#,
    );
    let back = serde_json::to_string(&l.to_file_form()).unwrap();
    let l2 = lens_from(&back);
    assert_eq!(l2.coordinate_breaks, l.coordinate_breaks);
    assert_eq!(
        l.coordinate_breaks[0],
        CoordinateBreak {
            surface: 2,
            decenter_x_mm: 0.0,
            decenter_y_mm: 0.0,
            tilt_x_deg: 3.0,
            tilt_y_deg: 0.0,
            tilt_z_deg: 0.0,
            tilt_first: true,
        }
    );
    let try_load = |tail: &str, breaks: &str| {
        let json = format!(
            r#"{{"surfaces": [
            {{"radius_mm": 60, "thickness_mm": 6, "material": {{"glass": "N-BK7"}}, "stop": true}},
            {{"radius_mm": -80, "thickness_mm": 30}}, {tail}],
            "coordinate_breaks": [{breaks}], "aperture": {{"epd_mm": 12}}}}"#
        );
        let f: PrescriptionFile = serde_json::from_str(&json).unwrap();
        LensPrescription::from_file_form(&f, &GlassCatalog::bundled())
            .unwrap_err()
            .to_string()
    };
    let flat = r#"{"radius_mm": null, "thickness_mm": 50}"#;
    let e = try_load(flat, r#"{"surface": 7, "tilt_x_deg": 1}"#);
    assert!(
        e.contains("coordinate_breaks[0]") && e.contains("surface 7"),
        "{e}"
    );
    let e = try_load(
        r#"{"radius_mm": 40, "thickness_mm": 50}"#,
        r#"{"surface": 2}"#,
    );
    assert!(e.contains("surface 2") && e.contains("flat"), "{e}");
    let e = try_load(flat, r#"{"surface": 2}, {"surface": 2, "tilt_y_deg": 2}"#);
    assert!(e.contains("two coordinate breaks"), "{e}");
    let e = try_load(flat, r#"{"surface": 0}"#);
    assert!(e.contains("surface 0") && e.contains("stop"), "{e}");
}
