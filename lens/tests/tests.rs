//! Integration tests of camsim-lens: one test binary for the crate, one module per topic
//! (`cargo test --release -p camsim-lens --test tests <module>::`).

mod batch;
mod closed_form;
mod cos4;
mod field_curvature;
mod field_model;
mod focus_model;
mod fold;
mod full_field;
mod glass;
mod glass_catalogs;
mod glass_formulas;
mod huygens;
mod iset_json;
mod lenses_dir;
mod mtf_sampling;
mod odd_asphere;
mod optics_ref;
mod optics_ref_finite;
mod optics_ref_literature;
mod optics_ref_zmx;
mod pupil;
mod reader_robustness;
mod readers;
mod round_trip;
mod zmx;
mod zmx_real;
