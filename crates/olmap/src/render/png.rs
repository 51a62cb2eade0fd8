//! PNG encoding.

use std::io::{Cursor, Write};
use std::path::Path;

use image::{ImageFormat, RgbImage};

use crate::error::{Error, Result};
use crate::file::write_atomic;

/// The PNG file of an image.
pub fn png_bytes(image: &RgbImage) -> Result<Vec<u8>> {
    let mut out = Cursor::new(Vec::new());
    image
        .write_to(&mut out, ImageFormat::Png)
        .map_err(|e| Error::InvalidArgument(format!("PNG encoding failed: {e}")))?;
    Ok(out.into_inner())
}

/// Writes an image as a PNG file, atomically (a complete file or none).
///
/// ```
/// use olmap::render::{write_png, RgbImage};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("a.png");
/// write_png(&path, &RgbImage::new(3, 2)).unwrap();
/// assert_eq!(&std::fs::read(&path).unwrap()[1..4], b"PNG");
/// ```
pub fn write_png(path: impl AsRef<Path>, image: &RgbImage) -> Result<()> {
    let bytes = png_bytes(image)?;
    write_atomic(path.as_ref(), "PNG image", |w| w.write_all(&bytes))
}
