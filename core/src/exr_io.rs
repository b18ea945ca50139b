//! exr_io
