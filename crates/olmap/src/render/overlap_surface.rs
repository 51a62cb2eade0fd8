//! The overlap surface of an alignment (thesis Figure 6.6): for every x, y near a pose, the
//! overlap of the scan at its best heading.

use rayon::prelude::*;

use super::colour::heat_colour;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::OccupancyList;
use image::RgbImage;

/// Where and how finely [`overlap_surface`] evaluates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OverlapSurfaceParams {
    /// The surface covers `centre ± half_width` metres in x and y.
    pub half_width: f64,
    /// Spacing of the x, y samples in whole voxels (at least 1).
    pub stride: u32,
    /// Headings tried per cell, evenly over the full turn starting at the centre's yaw
    /// (1 to [`MAX_HEADINGS`]).
    pub headings: u32,
}

/// The most headings [`overlap_surface`] tries per cell: 3600, every 0.1°.
pub const MAX_HEADINGS: u32 = 3600;

impl Default for OverlapSurfaceParams {
    fn default() -> Self {
        OverlapSurfaceParams {
            half_width: 2.0,
            stride: 1,
            headings: 36,
        }
    }
}

/// Best-heading overlap over a square grid of x, y positions.
#[derive(Debug, Clone, PartialEq)]
pub struct OverlapSurface {
    /// World x of column 0.
    pub x0: f64,
    /// World y of row 0 (the lowest y).
    pub y0: f64,
    /// Metres between samples.
    pub step: f64,
    /// Samples per side.
    pub n: usize,
    /// Overlap (thesis (5.7)) at the best heading, `values[row * n + column]`.
    pub values: Vec<u64>,
    /// The best heading (yaw, radians) per sample.
    pub best_yaw: Vec<f64>,
}

impl OverlapSurface {
    /// The sample with the largest overlap: `(x, y, yaw, overlap)` (the first on ties).
    pub fn peak(&self) -> (f64, f64, f64, u64) {
        let (i, &v) = self
            .values
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))
            .unwrap_or((0, &0));
        let (c, r) = (i % self.n.max(1), i / self.n.max(1));
        (
            self.x0 + c as f64 * self.step,
            self.y0 + r as f64 * self.step,
            self.best_yaw.get(i).copied().unwrap_or(0.0),
            v,
        )
    }

    /// A heat map, `pixels` per sample, highest y at the top, overlap from black (the
    /// lowest on the surface) through red and yellow to white (the peak): floors and
    /// ceilings overlap everywhere, so the scale starts at the surface's minimum.
    pub fn to_image(&self, pixels: u32) -> RgbImage {
        let p = pixels.max(1);
        let top = self.values.iter().copied().max().unwrap_or(0) as f64;
        let low = self.values.iter().copied().min().unwrap_or(0) as f64;
        let span = (top - low).max(1.0);
        let n = self.n as u32;
        RgbImage::from_fn(n * p, n * p, |u, v| {
            let (c, r) = (u / p, n - 1 - v / p);
            heat_colour((self.values[(r * n + c) as usize] as f64 - low) / span)
        })
    }
}

/// Evaluates the overlap of `scan` (in its own frame) with `map` for `scan` placed at every
/// x, y within `params.half_width` of `centre`'s position, on a grid of `params.stride`
/// voxels, keeping at each the best of `params.headings` yaws (pitch, roll and height from
/// `centre`). Each heading rotates the scan once; translations are then whole voxel offsets
/// ([`OccupancyList::overlap_keys`], thesis §5.3.3), so the grid is aligned to the map's
/// voxels nearest the centre.
pub fn overlap_surface(
    map: &OccupancyList,
    scan: &OccupancyList,
    centre: &Pose,
    params: &OverlapSurfaceParams,
) -> Result<OverlapSurface> {
    let r = map.resolution();
    if scan.resolution() != r {
        return Err(Error::InvalidArgument(format!(
            "overlap needs equal resolutions, got map {r} m and scan {} m",
            scan.resolution()
        )));
    }
    let stride = params.stride.max(1) as i64;
    let half = (params.half_width / r / stride as f64 + 1e-9).floor();
    if !(0.0..=500.0).contains(&half) || !(1..=MAX_HEADINGS).contains(&params.headings) {
        return Err(Error::InvalidArgument(format!(
            "overlap surface needs 0 <= half_width / (stride * resolution) <= 500 and 1 to \
             {MAX_HEADINGS} headings, got {params:?}"
        )));
    }
    let half = half as i64;
    let n = (2 * half + 1) as usize;
    // One overlap per heading and cell is held until the best heading is picked.
    crate::limits::check_memory(
        || {
            format!(
                "an overlap surface of {n} x {n} cells and {} headings",
                params.headings
            )
        },
        (n * n) as f64 * params.headings as f64 * 8.0,
    )?;
    let t = centre.translation();
    if !t.iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidArgument(format!(
            "overlap surface centre must be finite, got {centre}"
        )));
    }
    let (yaw0, pitch, roll) = centre.yaw_pitch_roll();
    // Snap the centre to the voxel lattice so that offsets are whole voxels.
    let (cx, cy) = ((t.x / r).round() * r, (t.y / r).round() * r);
    let per_heading: Vec<Vec<u64>> = (0..params.headings)
        .into_par_iter()
        .map(|k| {
            let yaw = yaw0 + std::f64::consts::TAU * k as f64 / params.headings as f64;
            let keys = scan.transformed_keys(&Pose::from_xyz_ypr(cx, cy, t.z, yaw, pitch, roll));
            let mut out = Vec::with_capacity(n * n);
            for row in -half..=half {
                for col in -half..=half {
                    let off = [(col * stride) as i32, (row * stride) as i32, 0];
                    out.push(map.overlap_keys(&keys, off));
                }
            }
            out
        })
        .collect();
    let mut values = vec![0u64; n * n];
    let mut best_yaw = vec![yaw0; n * n];
    for (k, vals) in per_heading.iter().enumerate() {
        let yaw = yaw0 + std::f64::consts::TAU * k as f64 / params.headings as f64;
        for (i, &v) in vals.iter().enumerate() {
            if v > values[i] {
                values[i] = v;
                best_yaw[i] = yaw;
            }
        }
    }
    let step = stride as f64 * r;
    Ok(OverlapSurface {
        x0: cx - half as f64 * step,
        y0: cy - half as f64 * step,
        step,
        n,
        values,
        best_yaw,
    })
}
