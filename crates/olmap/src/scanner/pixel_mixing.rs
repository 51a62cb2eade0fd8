//! The pixel-mixing filter (thesis §4.4.1): a beam falling partly on a foreground and
//! partly on a background surface returns a range in between, a point floating in free
//! space. Such returns show as range discontinuities along `theta` and `phi` whose voxel
//! is isolated.
//!
//! The filter works on an organised scan, a [`RangeImage`] (rows = sweeps, i.e. `phi`;
//! columns = beams, i.e. `theta`). A return `r` is flagged as mixed when, along either
//! axis, it lies strictly between its two neighbours with jumps above
//! [`MixedPixelParams::jump`] on both sides, or when it is isolated (at least two valid
//! neighbours among its eight and none within `jump`); in both cases only when no
//! surface explains it: a return that the linear extrapolation `2 a - a2` of a neighbour
//! `a` and the next one out `a2` (in any of the four directions) predicts within
//! [`MixedPixelParams::support`] lies on a smooth surface seen at a grazing angle and is
//! kept, provided that run of neighbours is itself smooth (`a` lies within `support` of
//! `2 a2 - a3`): the other mixed pixels along a depth edge are random and explain
//! nothing.

use crate::error::{Error, Result};

/// Thresholds of the mixed-pixel filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MixedPixelParams {
    /// Range jump to a neighbour that counts as a discontinuity, metres.
    pub jump: f64,
    /// Largest difference from a neighbouring surface's linear extrapolation at which a
    /// return is taken to lie on that surface, metres.
    pub support: f64,
}

impl MixedPixelParams {
    /// Thresholds for a range noise of standard deviation `sigma`: `jump = 5 sigma`,
    /// `support = 7.5 sigma` (the extrapolation `2 a - a2 - r` has standard deviation
    /// `sqrt(6) sigma`, so `support` is about three of those).
    pub fn for_sigma(sigma: f64) -> Self {
        MixedPixelParams {
            jump: 5.0 * sigma,
            support: 7.5 * sigma,
        }
    }
}

impl Default for MixedPixelParams {
    /// [`MixedPixelParams::for_sigma`] of the LMS 200's 0.02 m: jump 0.1 m, support 0.15 m.
    fn default() -> Self {
        Self::for_sigma(0.02)
    }
}

/// An organised scan: `rows x cols` ranges, row-major; non-finite or non-positive entries
/// are missing returns.
#[derive(Debug, Clone, PartialEq)]
pub struct RangeImage {
    rows: usize,
    cols: usize,
    ranges: Vec<f32>,
}

impl RangeImage {
    /// An image from row-major ranges; an error when `ranges.len() != rows * cols`.
    pub fn new(rows: usize, cols: usize, ranges: Vec<f32>) -> Result<Self> {
        if rows.checked_mul(cols) != Some(ranges.len()) {
            return Err(Error::InvalidArgument(format!(
                "range image: {} ranges for {rows} x {cols}",
                ranges.len()
            )));
        }
        Ok(RangeImage { rows, cols, ranges })
    }

    /// The raw ranges of a mirror log, one row per sweep (shorter sweeps padded with
    /// missing returns). The ranges are whole optical paths, which differ from the
    /// distance beyond the mirror by `d / cos theta`, nearly constant between neighbouring
    /// beams; [`super::convert_log`] uses the distance beyond the mirror.
    pub fn from_log(log: &super::MirrorLog) -> Self {
        let cols = log.sweeps.iter().map(|s| s.ranges.len()).max().unwrap_or(0);
        let mut ranges = vec![f32::INFINITY; log.sweeps.len() * cols];
        for (k, s) in log.sweeps.iter().enumerate() {
            ranges[k * cols..k * cols + s.ranges.len()].copy_from_slice(&s.ranges);
        }
        RangeImage {
            rows: log.sweeps.len(),
            cols,
            ranges,
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// The range at `(row, col)`, `None` when missing or outside the image.
    pub fn get(&self, row: isize, col: isize) -> Option<f64> {
        if row < 0 || col < 0 || row as usize >= self.rows || col as usize >= self.cols {
            return None;
        }
        let r = self.ranges[row as usize * self.cols + col as usize] as f64;
        (r.is_finite() && r > 0.0).then_some(r)
    }
}

/// Flags the mixed pixels of an organised scan (see the [module documentation](self)):
/// one flag per pixel, row-major; missing returns are never flagged.
pub fn mixed_pixels(image: &RangeImage, params: &MixedPixelParams) -> Result<Vec<bool>> {
    if !(params.jump > 0.0 && params.support >= 0.0) {
        return Err(Error::InvalidArgument(
            "mixed-pixel filter: jump must be > 0 and support >= 0".into(),
        ));
    }
    let (rows, cols) = (image.rows as isize, image.cols as isize);
    let mut flags = vec![false; image.ranges.len()];
    const DIRS: [(isize, isize); 4] = [(0, 1), (0, -1), (1, 0), (-1, 0)];
    for row in 0..rows {
        for col in 0..cols {
            let Some(r) = image.get(row, col) else {
                continue;
            };
            let supported = DIRS.iter().any(|&(dr, dc)| {
                let at = |k: isize| image.get(row + k * dr, col + k * dc);
                match (at(1), at(2), at(3)) {
                    (Some(a), Some(a2), Some(a3)) => {
                        (a - (2.0 * a2 - a3)).abs() <= params.support
                            && (r - (2.0 * a - a2)).abs() <= params.support
                    }
                    _ => false,
                }
            });
            if supported {
                continue;
            }
            let between = [(0, 1), (1, 0)].iter().any(|&(dr, dc)| {
                match (image.get(row - dr, col - dc), image.get(row + dr, col + dc)) {
                    (Some(a), Some(b)) => {
                        (r - a).abs() > params.jump
                            && (r - b).abs() > params.jump
                            && (r - a) * (r - b) < 0.0
                    }
                    _ => false,
                }
            });
            let mut valid = 0;
            let mut near = false;
            for dr in -1..=1 {
                for dc in -1..=1 {
                    if (dr, dc) == (0, 0) {
                        continue;
                    }
                    if let Some(a) = image.get(row + dr, col + dc) {
                        valid += 1;
                        near |= (r - a).abs() <= params.jump;
                    }
                }
            }
            let isolated = valid >= 2 && !near;
            flags[(row * cols + col) as usize] = between || isolated;
        }
    }
    Ok(flags)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_a_return_between_foreground_and_background_only() {
        // A slanted floor-like surface (range growing steadily along the rows and the
        // columns: a grazing view) with a foreground block in one corner.
        let (rows, cols) = (12, 14);
        let mut v = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                let fg = r < 6 && c < 6;
                v.push(if fg {
                    1.0
                } else {
                    2.0 + 0.3 * c as f32 + 0.02 * r as f32
                });
            }
        }
        // Mixed pixels: one on the block's right edge (along theta), one below it
        // (along phi).
        v[3 * cols + 6] = 1.8;
        v[6 * cols + 2] = 1.5;
        let img = RangeImage::new(rows, cols, v).unwrap();
        let f = mixed_pixels(&img, &MixedPixelParams::default()).unwrap();
        let flagged: Vec<usize> = (0..f.len()).filter(|&i| f[i]).collect();
        assert_eq!(flagged, vec![3 * cols + 6, 6 * cols + 2]);
        assert!(RangeImage::new(2, 2, vec![1.0; 3]).is_err());
    }
}
