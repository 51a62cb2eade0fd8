//! [`OccupancyGrid2d`]: a log-odds occupancy grid updated by ray tracing planar scans
//! (thesis §3.3.3).

use nalgebra::Point3;

use super::raytrace::bresenham;
use super::sensor_model::SensorModel2d;
use super::trinary::{CellCounts, Thresholds, Trinary, TrinaryGrid};
use crate::cloud::LaserScan;
use crate::error::{Error, Result};
use crate::geometry::Pose;

/// Most cells a grid may hold (256 Mi, 1 GiB of log odds).
pub const MAX_CELLS: usize = 1 << 28;

/// Cells added beyond what a scan needs when a growing grid grows, at least (more for
/// large grids: a quarter of the current size), so growth is rare.
const GROW_MARGIN: i64 = 16;

const MARK_FREE: u8 = 1;
const MARK_OCC: u8 = 2;

/// A 2D occupancy grid in log odds (thesis §3.3.3).
///
/// Cell `(i, j)` (column `i` along x, row `j` along y, row 0 at the lowest y) covers
/// `[ox + i r, ox + (i+1) r) x [oy + j r, oy + (j+1) r)` for resolution `r` and origin
/// `(ox, oy)`, the corner of cell (0, 0) (the ROS `map_server` convention). Each cell holds
/// the log odds of being occupied (3.23), 0 (probability 0.5) until observed, kept within
/// the sensor model's `[l_min, l_max]`.
///
/// Two kinds of grid:
/// * [`OccupancyGrid2d::new`] starts empty and **grows** to hold every scan inserted (the
///   sensor and the end of every beam, clipped to the model's `max_range`); its cells stay
///   on the lattice `k r` of the world frame whatever the growth;
/// * [`OccupancyGrid2d::fixed`] covers a given rectangle and never grows; the parts of
///   beams outside it are dropped.
#[derive(Debug, Clone)]
pub struct OccupancyGrid2d {
    resolution: f64,
    /// World position of lattice point (0, 0).
    base: [f64; 2],
    /// Lattice index of cell (0, 0).
    offset: [i64; 2],
    width: usize,
    height: usize,
    grows: bool,
    log_odds: Vec<f32>,
    /// Per-cell scratch marks of the scan being inserted (0 everywhere between scans).
    marks: Vec<u8>,
    touched: Vec<usize>,
}

/// What one [`OccupancyGrid2d::insert_scan`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InsertStats {
    /// Beams traced (beams with a range below `range_min` are skipped).
    pub beams: usize,
    /// Beams ending in a return within `max_range` (the rest only clear free space).
    pub hits: usize,
    /// Cells visited along all beams, counting a cell once per beam through it.
    pub cells_traversed: usize,
    /// Distinct cells updated as free.
    pub free_updates: usize,
    /// Distinct cells updated as occupied.
    pub occupied_updates: usize,
}

fn check_resolution(resolution: f64) -> Result<()> {
    if resolution.is_finite() && resolution > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidArgument(format!(
            "grid resolution must be > 0 m, got {resolution}"
        )))
    }
}

fn too_big(width: i64, height: i64) -> Error {
    Error::TooLarge {
        what: format!("a {width} x {height} cell grid"),
        limit: format!("{MAX_CELLS} cells"),
    }
}

impl OccupancyGrid2d {
    /// An empty grid of `resolution` metres per cell that grows to hold the scans
    /// inserted; its cells lie on the lattice `(k r, l r)` of the world frame.
    pub fn new(resolution: f64) -> Result<Self> {
        check_resolution(resolution)?;
        Ok(OccupancyGrid2d {
            resolution,
            base: [0.0, 0.0],
            offset: [0, 0],
            width: 0,
            height: 0,
            grows: true,
            log_odds: Vec::new(),
            marks: Vec::new(),
            touched: Vec::new(),
        })
    }

    /// A grid of `width x height` cells with cell (0, 0)'s corner at `origin` that never
    /// grows: beams are clipped to it.
    pub fn fixed(resolution: f64, origin: (f64, f64), width: usize, height: usize) -> Result<Self> {
        check_resolution(resolution)?;
        if !(origin.0.is_finite() && origin.1.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "grid origin must be finite, got {origin:?}"
            )));
        }
        if width.checked_mul(height).is_none_or(|n| n > MAX_CELLS) {
            return Err(too_big(width as i64, height as i64));
        }
        let n = width * height;
        Ok(OccupancyGrid2d {
            resolution,
            base: [origin.0, origin.1],
            offset: [0, 0],
            width,
            height,
            grows: false,
            log_odds: vec![0.0; n],
            marks: vec![0; n],
            touched: Vec::new(),
        })
    }

    /// Metres per cell.
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// World position of the corner of cell (0, 0) (its lowest x and y).
    pub fn origin(&self) -> (f64, f64) {
        (
            self.base[0] + self.offset[0] as f64 * self.resolution,
            self.base[1] + self.offset[1] as f64 * self.resolution,
        )
    }

    /// Number of columns (cells along x).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Number of rows (cells along y).
    pub fn height(&self) -> usize {
        self.height
    }

    /// Whether the grid grows to hold new scans ([`OccupancyGrid2d::new`]).
    pub fn grows(&self) -> bool {
        self.grows
    }

    /// The rectangle covered, `((min_x, min_y), (max_x, max_y))`, metres.
    pub fn extent(&self) -> ((f64, f64), (f64, f64)) {
        let (ox, oy) = self.origin();
        (
            (ox, oy),
            (
                ox + self.width as f64 * self.resolution,
                oy + self.height as f64 * self.resolution,
            ),
        )
    }

    /// Lattice index of a world coordinate along axis `a`.
    fn key(&self, v: f64, a: usize) -> i64 {
        ((v - self.base[a]) / self.resolution).floor() as i64
    }

    /// The cell holding the world point `(x, y)`, if inside the grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let i = self.key(x, 0) - self.offset[0];
        let j = self.key(y, 1) - self.offset[1];
        (i >= 0 && j >= 0 && (i as usize) < self.width && (j as usize) < self.height)
            .then_some((i as usize, j as usize))
    }

    /// World position of the centre of cell `(i, j)` (any indices, also outside the grid).
    pub fn cell_center(&self, i: usize, j: usize) -> (f64, f64) {
        let (ox, oy) = self.origin();
        (
            ox + (i as f64 + 0.5) * self.resolution,
            oy + (j as f64 + 0.5) * self.resolution,
        )
    }

    /// Log odds of cell `(i, j)`. Panics if the cell is outside the grid.
    pub fn log_odds(&self, cell: (usize, usize)) -> f32 {
        assert!(
            cell.0 < self.width && cell.1 < self.height,
            "cell {cell:?} outside a {} x {} grid",
            self.width,
            self.height
        );
        self.log_odds[cell.1 * self.width + cell.0]
    }

    /// Occupancy probability of cell `(i, j)` (3.24); 0.5 for a cell never observed.
    /// Panics if the cell is outside the grid.
    pub fn probability(&self, cell: (usize, usize)) -> f64 {
        SensorModel2d::probability(self.log_odds(cell))
    }

    /// Occupancy probability at the world point `(x, y)`; 0.5 (unknown) outside the grid.
    pub fn occupancy(&self, x: f64, y: f64) -> f64 {
        self.cell_of(x, y).map_or(0.5, |c| self.probability(c))
    }

    /// Every cell with its log odds, row by row from row 0 (lowest y), x increasing.
    pub fn cells(&self) -> impl Iterator<Item = ((usize, usize), f32)> + '_ {
        let w = self.width.max(1);
        self.log_odds
            .iter()
            .enumerate()
            .map(move |(k, &l)| ((k % w, k / w), l))
    }

    /// Classifies cell `(i, j)` with `thresholds`. Panics if the cell is outside the grid.
    pub fn classify(&self, cell: (usize, usize), thresholds: Thresholds) -> Trinary {
        thresholds.classify(self.probability(cell))
    }

    /// Numbers of free, occupied and unknown cells for `thresholds`.
    pub fn counts(&self, thresholds: Thresholds) -> CellCounts {
        let mut c = CellCounts::default();
        for &l in &self.log_odds {
            c.add(thresholds.classify(SensorModel2d::probability(l)));
        }
        c
    }

    /// The free / occupied / unknown map for `thresholds` (what ROS `map_saver` writes),
    /// with this grid's resolution, origin (yaw 0) and size.
    pub fn to_trinary(&self, thresholds: Thresholds) -> TrinaryGrid {
        let (ox, oy) = self.origin();
        TrinaryGrid {
            resolution: self.resolution,
            origin: [ox, oy, 0.0],
            width: self.width,
            height: self.height,
            cells: self
                .log_odds
                .iter()
                .map(|&l| thresholds.classify(SensorModel2d::probability(l)))
                .collect(),
            thresholds,
        }
    }

    /// Makes the grid cover lattice keys `[min, max]` (inclusive), keeping its content.
    fn grow_to(&mut self, min: [i64; 2], max: [i64; 2]) -> Result<()> {
        let cur_min = self.offset;
        let cur_max = [
            self.offset[0] + self.width as i64 - 1,
            self.offset[1] + self.height as i64 - 1,
        ];
        let empty = self.width == 0 || self.height == 0;
        if !empty && (0..2).all(|a| min[a] >= cur_min[a] && max[a] <= cur_max[a]) {
            return Ok(());
        }
        let mut new_min = [0i64; 2];
        let mut new_max = [0i64; 2];
        for a in 0..2 {
            // Saturating: at a resolution of 1e-20 m the keys are near i64's ends, and the
            // size check below refuses the grid.
            if empty {
                new_min[a] = min[a].saturating_sub(GROW_MARGIN);
                new_max[a] = max[a].saturating_add(GROW_MARGIN);
                continue;
            }
            let dim = cur_max[a] - cur_min[a] + 1;
            let margin = GROW_MARGIN.max(dim / 4);
            new_min[a] = if min[a] < cur_min[a] {
                min[a].saturating_sub(margin)
            } else {
                cur_min[a]
            };
            new_max[a] = if max[a] > cur_max[a] {
                max[a].saturating_add(margin)
            } else {
                cur_max[a]
            };
        }
        let w = new_max[0].saturating_sub(new_min[0]).saturating_add(1);
        let h = new_max[1].saturating_sub(new_min[1]).saturating_add(1);
        if w.checked_mul(h).is_none_or(|n| n as u64 > MAX_CELLS as u64) {
            return Err(too_big(w, h));
        }
        let (w, h) = (w as usize, h as usize);
        let mut cells = vec![0f32; w * h];
        if !empty {
            let dx = (cur_min[0] - new_min[0]) as usize;
            let dy = (cur_min[1] - new_min[1]) as usize;
            for j in 0..self.height {
                let src = &self.log_odds[j * self.width..(j + 1) * self.width];
                let start = (j + dy) * w + dx;
                cells[start..start + self.width].copy_from_slice(src);
            }
        }
        self.log_odds = cells;
        self.marks = vec![0; w * h];
        self.offset = new_min;
        self.width = w;
        self.height = h;
        Ok(())
    }

    /// Errors unless the model, the scan's angles and the sensor position are usable.
    pub(super) fn check_inputs(
        scan: &LaserScan,
        t_world_sensor: &Pose,
        model: &SensorModel2d,
    ) -> Result<()> {
        model.validate()?;
        if !(scan.angle_min.is_finite() && scan.angle_increment.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "laser scan angles must be finite, got angle_min {} and angle_increment {}",
                scan.angle_min, scan.angle_increment
            )));
        }
        let origin = t_world_sensor.translation();
        if !(origin.x.is_finite() && origin.y.is_finite()) {
            return Err(Error::InvalidArgument(format!(
                "sensor position must be finite, got ({}, {})",
                origin.x, origin.y
            )));
        }
        Ok(())
    }

    /// Integrates one scan taken by a sensor at `t_world_sensor` (thesis §3.3.3, (3.28)).
    ///
    /// Each beam is traced with [`bresenham`] from the sensor's cell to
    /// the cell of its end point:
    /// * a return at range `r` with `range_min <= r <= min(max_range, scan.range_max)`:
    ///   the cells before the end are observed free, the end cell occupied;
    /// * no return (`INFINITY`, or any range beyond that limit): the cells up to the limit
    ///   are observed free, nothing occupied;
    /// * a range below `range_min` (or NaN): the beam is ignored.
    ///
    /// One scan observes each cell at most once: a cell crossed by several beams gets
    /// `l_free` once, and a cell where any beam ends gets `l_occ` (and no `l_free`), so
    /// beams grazing a wall do not erase it. Log odds are then clamped to
    /// `[l_min, l_max]`.
    ///
    /// Beams are placed with the full 3D pose and projected onto the map plane (z dropped):
    /// for a planar robot the pose is `Pose::from_xyz_ypr(x, y, z, yaw, 0, 0)`. A growing
    /// grid first grows to hold the sensor and every beam; a fixed grid drops the cells
    /// outside it. Errors on an invalid model or scan, or when the grid would exceed
    /// [`MAX_CELLS`].
    pub fn insert_scan(
        &mut self,
        scan: &LaserScan,
        t_world_sensor: &Pose,
        model: &SensorModel2d,
    ) -> Result<InsertStats> {
        Self::check_inputs(scan, t_world_sensor, model)?;
        let origin = t_world_sensor.translation();
        let limit = if scan.range_max.is_nan() {
            model.max_range
        } else {
            model.max_range.min(scan.range_max).max(0.0)
        };
        let sensor = [self.key(origin.x, 0), self.key(origin.y, 1)];
        let mut ends: Vec<(i64, i64, bool)> = Vec::with_capacity(scan.ranges.len());
        let (mut lo, mut hi) = (sensor, sensor);
        for (i, &r) in scan.ranges.iter().enumerate() {
            let r = r as f64;
            if r.is_nan() || r < scan.range_min {
                continue;
            }
            let hit = r <= limit;
            let reach = if hit { r } else { limit };
            let (s, c) = scan.angle(i).sin_cos();
            let p = t_world_sensor.transform_point(&Point3::new(reach * c, reach * s, 0.0));
            let k = [self.key(p.x, 0), self.key(p.y, 1)];
            for a in 0..2 {
                lo[a] = lo[a].min(k[a]);
                hi[a] = hi[a].max(k[a]);
            }
            ends.push((k[0], k[1], hit));
        }
        let mut stats = InsertStats {
            beams: ends.len(),
            ..InsertStats::default()
        };
        if ends.is_empty() {
            return Ok(stats);
        }
        if self.grows {
            self.grow_to(lo, hi)?;
        }
        let (w, h) = (self.width as i64, self.height as i64);
        let (ox, oy) = (self.offset[0], self.offset[1]);
        let from = (sensor[0], sensor[1]);
        for &(ex, ey, hit) in &ends {
            stats.hits += hit as usize;
            let line = bresenham(from, (ex, ey));
            let n = line.len();
            stats.cells_traversed += n;
            for (k, (x, y)) in line.enumerate() {
                let (i, j) = (x - ox, y - oy);
                if i < 0 || j < 0 || i >= w || j >= h {
                    continue;
                }
                let idx = (j * w + i) as usize;
                let mark = if hit && k + 1 == n {
                    MARK_OCC
                } else {
                    MARK_FREE
                };
                let old = self.marks[idx];
                if old == 0 {
                    self.touched.push(idx);
                }
                self.marks[idx] = old.max(mark);
            }
        }
        for &idx in &self.touched {
            let (delta, counter) = if self.marks[idx] == MARK_OCC {
                (model.l_occ, &mut stats.occupied_updates)
            } else {
                (model.l_free, &mut stats.free_updates)
            };
            *counter += 1;
            let l = &mut self.log_odds[idx];
            *l = (*l + delta).clamp(model.l_min, model.l_max);
            self.marks[idx] = 0;
        }
        self.touched.clear();
        Ok(stats)
    }
}
