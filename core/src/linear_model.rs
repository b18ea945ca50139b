//! linear_model
