//! Lens prescriptions shared by the test modules.
use camsim_lens::{GlassCatalog, LensPrescription};
use std::path::Path;

/// The double Gauss 50 mm f/2 of `lenses/double_gauss_50mm_f2.json` (bundled glasses).
pub fn double_gauss() -> LensPrescription {
    LensPrescription::from_json_file(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../lenses/double_gauss_50mm_f2.json"),
        &GlassCatalog::bundled(),
    )
    .unwrap()
}
