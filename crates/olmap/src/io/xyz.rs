//! TODO
use super::LoadedCloud;
use crate::cloud::PointCloud;
use crate::error::ParseError;
use std::io::{BufRead, Write};

/// Reads.
pub fn read<R: BufRead>(_reader: R) -> Result<LoadedCloud, ParseError> {
    Err(ParseError::Unsupported("not yet".into()))
}

/// Writes.
pub fn write<W: Write>(_w: W, _cloud: &PointCloud) -> std::io::Result<()> {
    Err(std::io::Error::other("not yet"))
}
