//! The top view of a map (thesis Figures 5.9, 5.11, 6.9, 6.10).

use nalgebra::Point3;
use plotters::prelude::*;
use rustc_hash::FxHashMap;

use super::colour::{height_colour, PALETTE};
use super::{check_size, draw_error};
use crate::error::{Error, Result};
use crate::occupancy::OccupancyList;
use image::{Rgb, RgbImage};

/// The colour of pixels with no voxel: white.
pub const BACKGROUND: Rgb<u8> = Rgb([255, 255, 255]);
/// The colour of the metre grid: light grey.
pub const GRID_COLOUR: Rgb<u8> = Rgb([215, 215, 215]);

/// Pixel positions are rounded up by this many pixels, so that a world position on a pixel
/// edge (a grid line at a whole metre) lands in the same pixel whatever the rounding.
const EPS: f64 = 1e-6;

/// What a top view shows.
#[derive(Debug, Clone, PartialEq)]
pub struct TopViewOptions {
    /// Metres per pixel; `None`: the map's resolution (one pixel per voxel column).
    pub pixel_size: Option<f64>,
    /// Only voxels whose centres have `z_min <= z <= z_max` (e.g. `(2.3, 2.9)`, the
    /// thesis' structure band, Figure 5.9); `None`: all.
    pub band: Option<(f64, f64)>,
    /// Spacing of grid lines in metres (e.g. 1.0), drawn under the voxels; `None`: no grid.
    pub grid_step: Option<f64>,
    /// Robot paths, one polyline each (only x and y are used), drawn in [`PALETTE`] colours.
    pub paths: Vec<Vec<Point3<f64>>>,
    /// Scan positions, drawn as small black squares.
    pub positions: Vec<Point3<f64>>,
    /// Only voxels with at least this count (at least 1).
    pub min_count: u16,
    /// Empty border around the content, metres.
    pub margin: f64,
}

impl Default for TopViewOptions {
    fn default() -> Self {
        TopViewOptions {
            pixel_size: None,
            band: None,
            grid_step: Some(1.0),
            paths: Vec::new(),
            positions: Vec::new(),
            min_count: 1,
            margin: 0.5,
        }
    }
}

/// A rendered top view and where it lies in the world.
#[derive(Debug, Clone)]
pub struct TopView {
    /// The picture: x to the right, y up; pixels with no voxel are [`BACKGROUND`] (or
    /// [`GRID_COLOUR`] on grid lines).
    pub image: RgbImage,
    /// World x of the left edge of the image.
    pub x_min: f64,
    /// World y of the top edge of the image.
    pub y_max: f64,
    /// Metres per pixel.
    pub pixel_size: f64,
    /// The heights coloured from the bottom to the top of [`height_colour`]'s ramp.
    pub z_range: (f64, f64),
    /// Voxel columns drawn.
    pub columns: usize,
}

impl TopView {
    /// The pixel `(column, row)` holding the world point `(x, y)`, `None` outside the image.
    pub fn pixel_of(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        let i = ((x - self.x_min) / self.pixel_size + EPS).floor();
        let j = ((self.y_max - y) / self.pixel_size + EPS).floor();
        (i >= 0.0 && j >= 0.0 && i < self.image.width() as f64 && j < self.image.height() as f64)
            .then_some((i as u32, j as u32))
    }

    /// Whether the pixel holding `(x, y)` shows a voxel (neither background nor grid).
    pub fn shows_voxel_at(&self, x: f64, y: f64) -> bool {
        self.pixel_of(x, y).is_some_and(|(i, j)| {
            let p = *self.image.get_pixel(i, j);
            p != BACKGROUND && p != GRID_COLOUR
        })
    }
}

/// Renders a map seen from above: each voxel column (within the band) takes the colour of
/// its highest voxel's height. The image covers the map's voxels, positions and paths plus
/// the margin. Errors on an invalid option, or an image over
/// [`super::MAX_SIDE`] pixels a side.
///
/// ```
/// use olmap::occupancy::OccupancyList;
/// use olmap::geometry::VoxelKey;
/// use olmap::render::{render_top_view, TopViewOptions};
/// let mut map = OccupancyList::new(0.1).unwrap();
/// map.set(VoxelKey::new(10, 5, 3), 1).unwrap();
/// let view = render_top_view(&map, &TopViewOptions::default()).unwrap();
/// assert!(view.shows_voxel_at(1.05, 0.55));
/// assert!(!view.shows_voxel_at(1.25, 0.55));
/// ```
pub fn render_top_view(map: &OccupancyList, options: &TopViewOptions) -> Result<TopView> {
    let r = map.resolution();
    let ps = options.pixel_size.unwrap_or(r);
    check_options(ps, options)?;
    let min_count = options.min_count.max(1);
    let (top, z_lo, z_hi) = highest_per_column(map, options.band, min_count);
    let z_range = options.band.unwrap_or((z_lo, z_hi));
    let frame = Frame::covering(&top, r, ps, options)?;
    let mut image = RgbImage::from_pixel(frame.w, frame.h, BACKGROUND);
    if let Some(g) = options.grid_step {
        draw_grid(&mut image, &frame, g);
    }
    let columns = paint_columns(&mut image, &frame, top, r, z_range);
    draw_paths_and_positions(&mut image, &frame, options)?;
    Ok(TopView {
        image,
        x_min: frame.x_min,
        y_max: frame.y_max,
        pixel_size: ps,
        z_range,
        columns,
    })
}

/// Errors on an invalid pixel size `ps`, band, grid step or margin.
fn check_options(ps: f64, options: &TopViewOptions) -> Result<()> {
    if !(ps.is_finite() && ps > 0.0) {
        return Err(Error::InvalidArgument(format!(
            "pixel size must be > 0 m, got {ps}"
        )));
    }
    if let Some((lo, hi)) = options.band {
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(Error::InvalidArgument(format!(
                "height band must be finite with min <= max, got {lo}..{hi}"
            )));
        }
    }
    if let Some(g) = options.grid_step {
        if !(g.is_finite() && g > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "grid step must be > 0 m, got {g}"
            )));
        }
    }
    if !(options.margin.is_finite() && options.margin >= 0.0) {
        return Err(Error::InvalidArgument(format!(
            "margin must be >= 0 m, got {}",
            options.margin
        )));
    }
    Ok(())
}

/// The highest voxel centre per `(x, y)` column among the voxels with at least `min_count`
/// within the band, and the lowest and highest such centres (infinite when none).
fn highest_per_column(
    map: &OccupancyList,
    band: Option<(f64, f64)>,
    min_count: u16,
) -> (FxHashMap<(i32, i32), f64>, f64, f64) {
    let r = map.resolution();
    let mut top: FxHashMap<(i32, i32), f64> = FxHashMap::default();
    let (mut z_lo, mut z_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (k, c) in map.iter() {
        if c < min_count {
            continue;
        }
        let z = (k.z as f64 + 0.5) * r;
        if let Some((lo, hi)) = band {
            if z < lo || z > hi {
                continue;
            }
        }
        z_lo = z_lo.min(z);
        z_hi = z_hi.max(z);
        let e = top.entry((k.x, k.y)).or_insert(f64::NEG_INFINITY);
        *e = e.max(z);
    }
    (top, z_lo, z_hi)
}

/// The bounding box of what a top view shows, grown point by point.
struct Extent {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Extent {
    fn cover(&mut self, x: f64, y: f64) {
        self.x0 = self.x0.min(x);
        self.y0 = self.y0.min(y);
        self.x1 = self.x1.max(x);
        self.y1 = self.y1.max(y);
    }
}

/// Where the picture lies in the world and its size in pixels.
#[derive(Clone, Copy)]
struct Frame {
    /// World x of the left edge.
    x_min: f64,
    /// World y of the top edge.
    y_max: f64,
    /// Metres per pixel.
    ps: f64,
    /// Width, pixels.
    w: u32,
    /// Height, pixels.
    h: u32,
}

impl Frame {
    /// The frame covering the columns, positions and paths plus the margin. Errors on a
    /// position or path point that is not finite, or a picture too large.
    fn covering(
        top: &FxHashMap<(i32, i32), f64>,
        r: f64,
        ps: f64,
        options: &TopViewOptions,
    ) -> Result<Frame> {
        let mut e = Extent {
            x0: f64::INFINITY,
            y0: f64::INFINITY,
            x1: f64::NEG_INFINITY,
            y1: f64::NEG_INFINITY,
        };
        for &(i, j) in top.keys() {
            e.cover(i as f64 * r, j as f64 * r);
            e.cover((i + 1) as f64 * r, (j + 1) as f64 * r);
        }
        for p in options
            .positions
            .iter()
            .chain(options.paths.iter().flatten())
        {
            if !(p.x.is_finite() && p.y.is_finite()) {
                return Err(Error::InvalidArgument(format!(
                    "positions and paths must be finite, got {p}"
                )));
            }
            e.cover(p.x, p.y);
        }
        let Extent {
            mut x0,
            mut y0,
            mut x1,
            mut y1,
        } = e;
        if !x0.is_finite() {
            (x0, y0, x1, y1) = (0.0, 0.0, ps, ps);
        }
        let m = options.margin;
        let (x_min, y_max) = (x0 - m, y1 + m);
        let w = ((x1 + m - x_min) / ps).ceil().max(1.0);
        let h = ((y_max - (y0 - m)) / ps).ceil().max(1.0);
        if w > super::MAX_SIDE as f64 || h > super::MAX_SIDE as f64 {
            return Err(Error::InvalidArgument(format!(
                "a top view of {w} x {h} pixels is over the limit of {} a side; use a larger pixel size",
                super::MAX_SIDE
            )));
        }
        let (w, h) = (w as u32, h as u32);
        check_size(w, h)?;
        Ok(Frame {
            x_min,
            y_max,
            ps,
            w,
            h,
        })
    }

    /// The pixel `(column, row)` of the world point `(x, y)`, possibly outside the image.
    fn pixel(&self, x: f64, y: f64) -> (i32, i32) {
        (
            ((x - self.x_min) / self.ps + EPS).floor() as i32,
            ((self.y_max - y) / self.ps + EPS).floor() as i32,
        )
    }
}

/// Draws the grid lines every `g` metres across the whole image.
fn draw_grid(image: &mut RgbImage, frame: &Frame, g: f64) {
    let Frame {
        x_min,
        y_max,
        ps,
        w,
        h,
    } = *frame;
    let (gx0, gx1) = (
        (x_min / g).ceil() as i64,
        ((x_min + w as f64 * ps) / g).floor() as i64,
    );
    let (gy0, gy1) = (
        ((y_max - h as f64 * ps) / g).ceil() as i64,
        (y_max / g).floor() as i64,
    );
    // More lines than pixels (a grid step below the pixel size, 1 m at 1e20 m per pixel):
    // every column and row holds a line; walking the lines would take forever.
    let columns: Vec<i32> = if gx1.saturating_sub(gx0) >= w as i64 {
        (0..w as i32).collect()
    } else {
        (gx0..=gx1)
            .map(|k| frame.pixel(k as f64 * g, y_max).0)
            .collect()
    };
    for i in columns {
        if (0..w as i32).contains(&i) {
            for j in 0..h {
                image.put_pixel(i as u32, j, GRID_COLOUR);
            }
        }
    }
    let rows: Vec<i32> = if gy1.saturating_sub(gy0) >= h as i64 {
        (0..h as i32).collect()
    } else {
        (gy0..=gy1)
            .map(|k| frame.pixel(x_min, k as f64 * g).1)
            .collect()
    };
    for j in rows {
        if (0..h as i32).contains(&j) {
            for i in 0..w {
                image.put_pixel(i, j as u32, GRID_COLOUR);
            }
        }
    }
}

/// Paints each column in the colour of its height within `z_range`, lowest first so that,
/// when pixels are larger than voxels, a pixel shows its highest column. Returns the
/// number of columns.
fn paint_columns(
    image: &mut RgbImage,
    frame: &Frame,
    top: FxHashMap<(i32, i32), f64>,
    r: f64,
    z_range: (f64, f64),
) -> usize {
    let (w, h) = (frame.w, frame.h);
    let span = (z_range.1 - z_range.0).max(1e-9);
    let mut columns: Vec<((i32, i32), f64)> = top.into_iter().collect();
    columns.sort_unstable_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    for &((i, j), z) in &columns {
        let colour = height_colour((z - z_range.0) / span);
        let (pa, pb) = (
            frame.pixel(i as f64 * r, (j + 1) as f64 * r),
            frame.pixel((i + 1) as f64 * r, j as f64 * r),
        );
        // The pixels whose area the column covers (at least the one of its centre).
        let (cx, cy) = frame.pixel((i as f64 + 0.5) * r, (j as f64 + 0.5) * r);
        let (ia, ib) = (pa.0.min(cx), (pb.0 - 1).max(cx));
        let (ja, jb) = (pa.1.min(cy), (pb.1 - 1).max(cy));
        for py in ja.max(0)..=jb.min(h as i32 - 1) {
            for px in ia.max(0)..=ib.min(w as i32 - 1) {
                image.put_pixel(px as u32, py as u32, colour);
            }
        }
    }
    columns.len()
}

/// Draws the paths (in [`PALETTE`] colours) and the scan positions (small black squares).
fn draw_paths_and_positions(
    image: &mut RgbImage,
    frame: &Frame,
    options: &TopViewOptions,
) -> Result<()> {
    let root = BitMapBackend::with_buffer(image, (frame.w, frame.h)).into_drawing_area();
    for (n, path) in options.paths.iter().enumerate() {
        let [r, g, b] = PALETTE[n % PALETTE.len()];
        let pts: Vec<(i32, i32)> = path.iter().map(|p| frame.pixel(p.x, p.y)).collect();
        root.draw(&PathElement::new(pts, RGBColor(r, g, b).stroke_width(2)))
            .map_err(draw_error)?;
    }
    for p in &options.positions {
        let (i, j) = frame.pixel(p.x, p.y);
        root.draw(&Rectangle::new(
            [(i - 2, j - 2), (i + 2, j + 2)],
            BLACK.filled(),
        ))
        .map_err(draw_error)?;
    }
    root.present().map_err(draw_error)?;
    Ok(())
}
