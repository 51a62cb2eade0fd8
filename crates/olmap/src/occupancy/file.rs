//! Map files: reading and writing occupancy lists by file name.

use std::path::Path;

use super::list::OccupancyList;
use crate::error::{Error, Result};

/// The map file formats olmap knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapFormat {
    /// olmap's `.olm` (exact counts).
    Olm,
}

impl MapFormat {
    /// The format of a path, by extension (case-insensitive).
    pub fn from_path(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "olm" => Some(MapFormat::Olm),
            _ => None,
        }
    }

    /// A short human name.
    pub fn name(self) -> &'static str {
        match self {
            MapFormat::Olm => "olmap .olm",
        }
    }
}

/// A map read from a file.
#[derive(Debug, Clone)]
pub struct LoadedMap {
    /// The occupancy list.
    pub map: OccupancyList,
    /// The file's format.
    pub format: MapFormat,
}

fn unknown(path: &Path) -> Error {
    Error::UnknownFormat {
        path: path.to_path_buf(),
        reason: "not a map file; known map extensions: .olm".into(),
    }
}

/// Reads a map file.
pub fn read_map(path: impl AsRef<Path>) -> Result<LoadedMap> {
    let path = path.as_ref();
    let format = MapFormat::from_path(path).ok_or_else(|| unknown(path))?;
    let map = match format {
        MapFormat::Olm => OccupancyList::read_olm_path(path)?,
    };
    Ok(LoadedMap { map, format })
}

/// Writes a map file (format from the extension), atomically.
pub fn write_map(path: impl AsRef<Path>, map: &OccupancyList) -> Result<MapFormat> {
    let path = path.as_ref();
    let format = MapFormat::from_path(path).ok_or_else(|| unknown(path))?;
    match format {
        MapFormat::Olm => map.write_olm_path(path)?,
    }
    Ok(format)
}
