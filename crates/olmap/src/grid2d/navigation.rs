//! The navigation grid of thesis §7.3: a 2D free / occupied / unknown grid for path
//! planning, recovered from a 3D occupancy list and the poses its scans were taken from.

use rustc_hash::FxHashSet;

use super::raytrace::bresenham;
use super::trinary::{Trinary, TrinaryGrid};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::OccupancyList;

/// Most cells a navigation grid may hold.
const MAX_NAV_CELLS: usize = 1 << 26;
/// The most ray steps a navigation grid may take (about a minute on one core): each
/// distinct scan position casts `8 reach` rays of up to `reach` cells, or to the grid's
/// edge. A range of 1e9 m at 0.1 m would otherwise cast 8e10 rays from every position.
pub const MAX_NAV_RAY_STEPS: f64 = 1e10;

/// How [`navigation_grid`] builds the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavGridParams {
    /// Metres per cell; `None`: the map's resolution.
    pub resolution: Option<f64>,
    /// The robot-height band `(z_min, z_max)`, metres: voxels whose centres lie in it are
    /// obstacles (e.g. `(0.1, 1.2)`: above the floor, up to the robot's height).
    pub band: (f64, f64),
    /// Rays from a scan position reach at most this far, metres (the scanner's range).
    pub max_range: f64,
    /// Voxels need at least this count to be obstacles (at least 1).
    pub min_count: u16,
    /// Cells of unknown border around the content.
    pub margin_cells: usize,
}

impl Default for NavGridParams {
    fn default() -> Self {
        NavGridParams {
            resolution: None,
            band: (0.1, 1.2),
            max_range: 30.0,
            min_count: 1,
            margin_cells: 2,
        }
    }
}

/// Builds the navigation grid of a map (thesis §7.3).
///
/// * **Occupied**: a cell holding the centre of a voxel within the height band;
/// * **free**: a cell on a straight line (traced with [`bresenham`], in the x, y plane)
///   from the position of one of `scan_poses` that stays within `max_range` and meets no
///   occupied cell before it: the scanner saw through the band there, as the thesis'
///   "trace a ray from the pose to the nearest occupied voxel in each direction";
/// * **unknown**: everything else, including the space behind obstacles and beyond range.
///
/// Every direction is traced: each pose sends a ray to every cell on the border of the
/// square of half-side `max_range`, so all cells within range are reached. The scanner's
/// field of view is taken as all-round (as the thesis' rotating-mirror scanner and the
/// simulator's lidars); a blind sector would be reported free. The grid covers the band's
/// voxels and the poses plus the margin, with the default ROS thresholds.
///
/// ```
/// use olmap::occupancy::OccupancyList;
/// use olmap::geometry::{Pose, VoxelKey};
/// use olmap::grid2d::{navigation_grid, NavGridParams, Trinary};
/// let mut map = OccupancyList::new(0.1).unwrap();
/// for y in -10..10 { map.set(VoxelKey::new(20, y, 5), 1).unwrap(); } // a wall at x = 2 m
/// let pose = Pose::from_xyz_ypr(0.05, 0.05, 0.5, 0.0, 0.0, 0.0);
/// let grid = navigation_grid(&map, &[pose], &NavGridParams::default()).unwrap();
/// assert_eq!(grid.at_world(1.0, 0.05), Some(Trinary::Free));
/// assert_eq!(grid.at_world(2.05, 0.05), Some(Trinary::Occupied));
/// ```
pub fn navigation_grid(
    map: &OccupancyList,
    scan_poses: &[Pose],
    params: &NavGridParams,
) -> Result<TrinaryGrid> {
    let res = params.resolution.unwrap_or(map.resolution());
    let (z_lo, z_hi) = params.band;
    let valid = res.is_finite()
        && res > 0.0
        && z_lo.is_finite()
        && z_hi.is_finite()
        && z_lo <= z_hi
        && params.max_range.is_finite()
        && params.max_range >= 0.0;
    if !valid {
        return Err(Error::InvalidArgument(format!(
            "navigation grid needs resolution > 0, a finite band with min <= max and a finite range >= 0, got {params:?}"
        )));
    }
    let cell = |x: f64| (x / res).floor() as i64;
    let min_count = params.min_count.max(1);
    let r = map.resolution();
    let mut occupied: FxHashSet<(i64, i64)> = FxHashSet::default();
    for (k, c) in map.iter() {
        let z = (k.z as f64 + 0.5) * r;
        if c >= min_count && z >= z_lo && z <= z_hi {
            occupied.insert((cell((k.x as f64 + 0.5) * r), cell((k.y as f64 + 0.5) * r)));
        }
    }
    let mut sources = Vec::with_capacity(scan_poses.len());
    for p in scan_poses {
        let t = p.translation();
        if !(t.x.is_finite() && t.y.is_finite()) || t.x.abs() > 1e9 || t.y.abs() > 1e9 {
            return Err(Error::InvalidArgument(format!(
                "scan positions must be finite, got {p}"
            )));
        }
        sources.push((cell(t.x), cell(t.y)));
    }
    let all = occupied.iter().chain(sources.iter());
    let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
    for &(i, j) in all {
        lo = (lo.0.min(i), lo.1.min(j));
        hi = (hi.0.max(i), hi.1.max(j));
    }
    if lo.0 > hi.0 {
        return Ok(TrinaryGrid::unknown(res, [0.0, 0.0, 0.0], 0, 0));
    }
    let m = params.margin_cells as i64;
    // Saturating: at a resolution of 1e-20 m the cells are near i64's ends, and the size
    // check refuses the grid.
    let (lo, hi) = (
        (lo.0.saturating_sub(m), lo.1.saturating_sub(m)),
        (hi.0.saturating_add(m), hi.1.saturating_add(m)),
    );
    let span = |a: i64, b: i64| b.saturating_sub(a).saturating_add(1) as usize;
    let (w, h) = (span(lo.0, hi.0), span(lo.1, hi.1));
    if w.checked_mul(h).is_none_or(|n| n > MAX_NAV_CELLS) {
        return Err(Error::TooLarge {
            what: format!("a {w} x {h} navigation grid"),
            limit: format!("{MAX_NAV_CELLS} cells; use a coarser resolution"),
        });
    }
    let mut grid = TrinaryGrid::unknown(res, [lo.0 as f64 * res, lo.1 as f64 * res, 0.0], w, h);
    let index = |(i, j): (i64, i64)| -> Option<usize> {
        let (a, b) = (i - lo.0, j - lo.1);
        (a >= 0 && b >= 0 && (a as usize) < w && (b as usize) < h)
            .then(|| b as usize * w + a as usize)
    };
    for &c in &occupied {
        if let Some(k) = index(c) {
            grid.cells[k] = Trinary::Occupied;
        }
    }
    let reach_cells = (params.max_range / res).floor();
    let positions = scan_poses.len().max(1) as f64;
    let steps = positions * 8.0 * reach_cells.max(1.0) * reach_cells.min((w + h) as f64);
    if steps > MAX_NAV_RAY_STEPS {
        return Err(Error::TooLarge {
            what: format!(
                "a navigation grid from {} positions with rays of {reach_cells:.3e} cells \
                 ({} m at {res} m): {steps:.3e} ray steps; use a smaller max_range",
                scan_poses.len(),
                params.max_range
            ),
            limit: format!("{MAX_NAV_RAY_STEPS:.0e} ray steps"),
        });
    }
    // The targets of one position are listed before they are cast.
    crate::limits::check_memory(
        || format!("the ray targets of a navigation grid with rays of {reach_cells:.3e} cells"),
        8.0 * reach_cells * 16.0,
    )?;
    let reach = reach_cells as i64;
    let reach2 = reach * reach;
    let mut seen: FxHashSet<(i64, i64)> = FxHashSet::default();
    for &s in &sources {
        if !seen.insert(s) || occupied.contains(&s) {
            continue;
        }
        // Targets: the border of the square of half-side `reach` around the source.
        let mut targets = Vec::with_capacity(8 * reach.max(1) as usize);
        for d in -reach..=reach {
            targets.push((s.0 + d, s.1 - reach));
            targets.push((s.0 + d, s.1 + reach));
            targets.push((s.0 - reach, s.1 + d));
            targets.push((s.0 + reach, s.1 + d));
        }
        for t in targets {
            for c in bresenham(s, t) {
                let (dx, dy) = (c.0 - s.0, c.1 - s.1);
                if dx * dx + dy * dy > reach2 {
                    break;
                }
                let Some(k) = index(c) else { break };
                if grid.cells[k] == Trinary::Occupied {
                    break;
                }
                grid.cells[k] = Trinary::Free;
            }
        }
    }
    Ok(grid)
}
