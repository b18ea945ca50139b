//! Field model: save/load, interpolation, rotation, on-axis distortion and illumination.
use camsim_lens::analysis::pupil_grid;
use camsim_lens::field_model::rotate_psf;
use camsim_lens::trace::Ray;
use camsim_lens::{
    Clipping, FieldModel, FieldModelOptions, GlassCatalog, LensPrescription, PsfKind,
};

fn lens() -> LensPrescription {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../lenses/double_gauss_50mm_f2.json");
    LensPrescription::from_json_file(p, &GlassCatalog::bundled()).unwrap()
}

fn geometric() -> (LensPrescription, FieldModel) {
    let l = lens();
    let o = FieldModelOptions {
        n_fields: 3,
        kind: PsfKind::Geometric,
        psf_n: 41,
        psf_pitch_um: 2.0,
        pupil_n: 48,
        ri_grid_n: 32,
        ..Default::default()
    };
    let m = FieldModel::compute(&l, &o).unwrap();
    (l, m)
}

#[test]
fn on_axis_distortion_is_zero_and_relative_illumination_is_one() {
    let (_, m) = geometric();
    assert_eq!(m.paraxial_height_mm[0], 0.0);
    for j in 0..m.wavelengths_nm.len() {
        // Rotational symmetry: the on-axis chief ray stays on the axis.
        assert!(m.real_height_mm[0][j].abs() < 1e-12);
        assert_eq!(m.distortion_pct(0, j), 0.0);
    }
    assert!((m.relative_illumination[0] - 1.0).abs() < 1e-12);
    assert!((m.relative_illumination_at(0.0) - 1.0).abs() < 1e-12);
}

#[test]
fn interpolated_psf_at_a_tabulated_point_equals_the_table() {
    let (_, m) = geometric();
    for (k, &h) in m.paraxial_height_mm.iter().enumerate() {
        for (j, &w) in m.wavelengths_nm.iter().enumerate() {
            for (a, b) in m.psf_on_y(h, w).iter().zip(&m.psf[k][j]) {
                assert_eq!(a, b, "field {k} wavelength {j}");
            }
            // Azimuth 90° (+y) = no rotation.
            for (a, b) in m.psf_at(0.0, h, w).iter().zip(&m.psf[k][j]) {
                assert!((a - b).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn psf_rotated_by_90_degrees_equals_the_psf_traced_on_plus_x() {
    let (l, m) = geometric();
    let l = l.focused(l.primary_nm).unwrap();
    let (k, j) = (2, 1);
    let th = m.field_angles_deg[k].to_radians();
    let w = m.wavelengths_nm[j];
    let fo = l.first_order(w).unwrap();
    let aim = l.aim_field(m.field_angles_deg[k], w, &fo).unwrap();
    // Rays of a field point on +x: direction (sin θ, 0, cos θ); pupil points around the aimed
    // chief ray, now offset along x.
    let d = [th.sin(), 0.0, th.cos()];
    let r = aim.entrance_pupil_radius_mm;
    let ray = |u: f64, v: f64| {
        let pe = [aim.aim_y_mm + u * r, v * r, aim.entrance_pupil_z_mm];
        let s = 200.0;
        Ray {
            origin_mm: [pe[0] - s * d[0], pe[1] - s * d[1], pe[2] - s * d[2]],
            direction: d,
            opl_mm: 0.0,
        }
    };
    let chief = l.trace(&ray(0.0, 0.0), w, Clipping::None).unwrap();
    assert!(chief.image_mm[1].abs() < 1e-12 && chief.image_mm[0] > 0.0);
    let n = m.psf_n;
    let c0 = (n / 2) as f64;
    let p = m.psf_pitch_um * 1e-3;
    let mut direct = vec![0.0; n * n];
    let mut total = 0.0;
    for q in pupil_grid(48) {
        if let Some(t) = l.trace(&ray(q[0], q[1]), w, Clipping::SemiDiameters) {
            let ix = ((t.image_mm[0] - chief.image_mm[0]) / p + c0 + 0.5).floor();
            let iy = ((t.image_mm[1] - chief.image_mm[1]) / p + c0 + 0.5).floor();
            if ix >= 0.0 && iy >= 0.0 && (ix as usize) < n && (iy as usize) < n {
                direct[iy as usize * n + ix as usize] += 1.0;
                total += 1.0;
            }
        }
    }
    direct.iter_mut().for_each(|v| *v /= total);
    // The +y PSF rotated to azimuth 0 (+x): by −90°, both directly and through psf_at.
    let h = m.paraxial_height_mm[k];
    let rot = rotate_psf(&m.psf[k][j], n, -90.0);
    let via = m.psf_at(h, 0.0, w);
    let l1: f64 = rot.iter().zip(&direct).map(|(a, b)| (a - b).abs()).sum();
    let l1v: f64 = via.iter().zip(&direct).map(|(a, b)| (a - b).abs()).sum();
    // A ray landing within rounding of a bin edge may switch bins (L1 change 2/N per ray,
    // N ≈ 1800 rays): allow 3 such rays.
    let tol = 6.0 / total;
    assert!(l1 <= tol && l1v <= tol, "L1 {l1} {l1v} (tol {tol})");
    // The rotated PSF is not the unrotated one (the off-axis spot is not 90°-symmetric).
    let l1u: f64 = m.psf[k][j]
        .iter()
        .zip(&direct)
        .map(|(a, b)| (a - b).abs())
        .sum();
    assert!(l1u > 10.0 * tol, "{l1u}");
}

#[test]
fn save_load_round_trip_wave_model() {
    let l = lens();
    let o = FieldModelOptions {
        n_fields: 2,
        kind: PsfKind::Wave,
        psf_n: 15,
        psf_pitch_um: 1.0,
        pupil_n: 32,
        pad: 4,
        ri_grid_n: 16,
        ..Default::default()
    };
    let m = FieldModel::compute(&l, &o).unwrap();
    let path = std::env::temp_dir().join(format!("camsim_field_model_{}.json", std::process::id()));
    m.save(&path).unwrap();
    let back = FieldModel::load(&path).unwrap();
    std::fs::remove_file(&path).ok();
    let text_keys = [
        "\"psf_pitch_um\"",
        "\"wavelengths_nm\"",
        "\"paraxial_height_mm\"",
    ];
    let j = serde_json::to_string(&m).unwrap();
    assert!(text_keys.iter().all(|k| j.contains(k)));
    // serde_json's default float parser may differ from the shortest-round-trip printer by
    // 1 ulp, so compare to 1e-15 relative rather than bit-for-bit.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * a.abs().max(b.abs()).max(1e-300);
    assert_eq!(back.psf_n, m.psf_n);
    assert_eq!(back.lens_name, m.lens_name);
    assert_eq!(back.psf_kind, m.psf_kind);
    for (a, b) in back
        .psf
        .iter()
        .flatten()
        .flatten()
        .zip(m.psf.iter().flatten().flatten())
    {
        assert!(close(*a, *b));
    }
    for (a, b) in back
        .real_height_mm
        .iter()
        .flatten()
        .zip(m.real_height_mm.iter().flatten())
    {
        assert!(close(*a, *b));
    }
    for (a, b) in back
        .relative_illumination
        .iter()
        .zip(&m.relative_illumination)
    {
        assert!(close(*a, *b));
    }
    assert!(close(back.psf_pitch_um, m.psf_pitch_um) && close(back.efl_mm, m.efl_mm));
    // The on-axis wave PSF sums to 1 and is mirror-symmetric in x and y (rotational symmetry
    // of the lens; the FFT pupil grid is symmetric), to FFT round-off.
    let n = m.psf_n;
    for p0 in &m.psf[0] {
        assert!((p0.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let peak = p0.iter().cloned().fold(0.0, f64::max);
        for iy in 0..n {
            for ix in 0..n {
                let v = p0[iy * n + ix];
                assert!((v - p0[iy * n + n - 1 - ix]).abs() < 1e-9 * peak);
                assert!((v - p0[(n - 1 - iy) * n + ix]).abs() < 1e-9 * peak);
            }
        }
    }
}
