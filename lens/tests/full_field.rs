//! Every shipped lens (lenses/*.json) traces at its full field: the real chief ray of the
//! largest `fields_deg` passes the stop centre, and rays of the pupil reach the image
//! (issue 17 §3: the 87° fisheye used to fail at its own 60° field with "paraxial chief ray is
//! lost"; wide angles now use real-ray aiming from the stop outward, camsim_lens::trace).
use camsim_lens::analysis::pupil_grid;
use camsim_lens::{Clipping, GlassCatalog, LensPrescription};
use std::path::Path;

#[test]
fn every_shipped_lens_traces_at_its_full_field() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses");
    let mut n = 0;
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    for p in files {
        if p.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let lens = LensPrescription::from_json_file(&p, &GlassCatalog::bundled())
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let lens = lens.focused(lens.primary_nm).unwrap();
        let wl = lens.primary_nm;
        let fo = lens.first_order(wl).unwrap();
        let full = lens.fields_deg.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        for th in [full, 0.5 * full, -full] {
            let aim = lens
                .aim_field(th, wl, &fo)
                .unwrap_or_else(|e| panic!("{} at {th}°: {e}", p.display()));
            // the chief ray meets the stop centre
            let s = lens.trace_to_stop(&aim.ray(0.0, 0.0), wl).unwrap();
            assert!(
                s[0].abs() < 1e-9 && s[1].abs() < 1e-8,
                "{} {th}°: stop {s:?}",
                p.display()
            );
            let chief = lens.trace(&aim.ray(0.0, 0.0), wl, Clipping::None).unwrap();
            // image on the side of the field's sign (no fold-over through the axis)
            if th != 0.0 && fo.efl_mm > 0.0 {
                assert!(
                    chief.image_mm[1] * th > 0.0,
                    "{} {th}°: image y {}",
                    p.display(),
                    chief.image_mm[1]
                );
            }
            let fan = lens
                .ray_fan(th, wl, wl, &pupil_grid(9), Clipping::None)
                .unwrap();
            let ok = fan.rays.iter().filter(|r| r.is_some()).count();
            assert!(
                ok * 2 > fan.rays.len(),
                "{} {th}°: {ok}/{} rays",
                p.display(),
                fan.rays.len()
            );
        }
        n += 1;
    }
    assert!(n >= 15, "{n} lenses");
}

/// The fisheye maps field angle to image height monotonically up to its 60° field.
#[test]
fn fisheye_image_height_rises_with_field_to_60_deg() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses/iset_fisheye_87deg_12.5mm.json");
    let lens = LensPrescription::from_json_file(&p, &GlassCatalog::bundled()).unwrap();
    let wl = lens.primary_nm;
    let fo = lens.first_order(wl).unwrap();
    let aim = lens.aim_field(60.0, wl, &fo).unwrap();
    // the image height rises monotonically with field up to 60° (a fisheye maps angle to height)
    let mut last = 0.0;
    for k in 1..=12 {
        let th = 5.0 * k as f64;
        let a = lens.aim_field(th, wl, &fo).unwrap();
        let y = lens
            .trace(&a.ray(0.0, 0.0), wl, Clipping::None)
            .unwrap()
            .image_mm[1]
            .abs();
        assert!(y > last, "{th}°: {y} after {last}");
        last = y;
    }
    assert!(aim.aim_y_mm.abs() > 0.0);
}
