//! Scene targets (filled in below).
