//! Scan alignment.
pub mod icp;
