//! What a search aligns against: a map pyramid, and the free space seen by its scans.

use std::ops::Deref;
use std::sync::{Arc, Mutex, OnceLock};

use super::score::{CellGrid, DenseGrid, RowGrid};
use crate::cloud::PointCloud;
use crate::error::Result;
use crate::geometry::Pose;
use crate::occupancy::{OccupancyList, Pyramid, VoxelRay};

/// Rays keep this much clear of their endpoint before they count as free space (metres),
/// so that range noise and mixed pixels in front of a surface are not "free".
pub const FREE_SPACE_MARGIN: f64 = 0.3;

/// The target of a search: occupied voxels per level and, when the target was built from
/// scans with known sensor origins, the free space their rays crossed.
///
/// Free space makes the score `2 * hits - conflicts`, where a conflict is a scan voxel that
/// lands where the target saw through. Without it, voxel overlap favours poses that put the
/// scan's dense near field onto the target's dense near field: in a corridor, "the robot
/// did not move" (3DTK scan002 against scan000 scores 2,737 at the identity against 1,735
/// at the true pose 3.4 m ahead at 0.1 m); with conflicts counted the true pose wins at
/// every level.
pub struct SearchTarget {
    pub(crate) pyramid: Pyramid,
    pub(crate) free: Vec<Option<DenseGrid>>,
    /// Per level, the occupied voxels as a dense grid, made when the agreement
    /// ([`super::consistency`]) first asks for it; a scan added sets its voxels in the
    /// grids made (growing their boxes).
    occupied: Vec<OnceLock<Option<DenseGrid>>>,
    /// Per level, what the search scores poses against (occupied and free cells, and the
    /// same as rows), made when a search first needs it and dropped when a scan is added:
    /// every search of an unchanged target (the upright look after the first search, a
    /// mapper's attempts between placements) reuses it.
    grids: Vec<LevelGrids>,
}

/// One level's search grids ([`SearchTarget::cells`], [`SearchTarget::cells_reaching`],
/// [`SearchTarget::rows`]).
#[derive(Default)]
struct LevelGrids {
    /// [`CellGrid::whole_box`].
    whole_box: OnceLock<Option<KeyBox>>,
    cells: OnceLock<Option<CellGrid>>,
    part: Mutex<PartCells>,
    rows: OnceLock<Option<RowGrid>>,
}

/// A key box `[lo, hi]`.
type KeyBox = ([i64; 3], [i64; 3]);

/// The last [`CellGrid`] a level made over part of its box, and how many it made.
#[derive(Default)]
struct PartCells {
    grid: Option<Arc<CellGrid>>,
    made: u32,
}

/// A level's cells as [`SearchTarget::cells_reaching`] gives them: the whole level's, or a
/// grid over the part of it the candidates reach.
pub(crate) enum SearchCells<'a> {
    /// [`SearchTarget::cells`].
    Whole(&'a CellGrid),
    /// A grid over a box holding every key the candidates look up.
    Part(Arc<CellGrid>),
}

impl Deref for SearchCells<'_> {
    type Target = CellGrid;

    fn deref(&self) -> &CellGrid {
        match self {
            SearchCells::Whole(g) => g,
            SearchCells::Part(g) => g,
        }
    }
}

/// Levels whose whole box is at most this many cells (2 MiB at one bit) are always made
/// whole: small enough that a part would save nothing worth a second grid.
const MIN_PART_WORTHY_CELLS: u64 = 1 << 24;

/// A part is made only when it holds at most one cell in this many of the whole box.
const PART_SHARE: u64 = 2;

/// After this many parts of a level, the next miss makes the whole grid: a target searched
/// again and again in different places (a mapper's attempts) pays for the whole once.
const MAX_PARTS: u32 = 2;

/// Cells in the key box `[lo, hi]` (saturating).
fn box_cells((lo, hi): KeyBox) -> u64 {
    (0..3).fold(1u64, |n, i| {
        n.saturating_mul((hi[i] - lo[i] + 1).max(0) as u64)
    })
}

/// Empty search-grid caches for a pyramid of `levels`.
fn empty_grids(levels: usize) -> Vec<LevelGrids> {
    (0..levels).map(|_| LevelGrids::default()).collect()
}

/// The largest box, in cells, of a level's [`SearchTarget::occupied_grid`] (2^28 bits =
/// 32 MiB; larger maps answer from the hash).
const MAX_OCCUPIED_GRID_CELLS: u64 = 1 << 28;

impl SearchTarget {
    /// A target from a map alone (no free space known).
    pub fn from_map(map: OccupancyList, levels: usize) -> Result<Self> {
        let pyramid = Pyramid::new(map, levels)?;
        let free = (0..levels).map(|_| None).collect();
        Ok(SearchTarget {
            pyramid,
            free,
            occupied: (0..levels).map(|_| OnceLock::new()).collect(),
            grids: empty_grids(levels),
        })
    }

    /// A target from a map and the free space known about it (at the map's voxel edge):
    /// a level's cell is free when it holds a free voxel (a ray crossed it) and no cell
    /// within [`MAP_FREE_CLEARANCE_CELLS`] of it is occupied at that level (the constant
    /// says why not the scans' [`FREE_SPACE_MARGIN`]). A level whose box is too large for
    /// a dense grid keeps no free space, as [`SearchTarget::from_scans`] leaves it.
    ///
    /// # Errors
    /// [`crate::Error::InvalidArgument`] when the free space's voxel edge is not the
    /// map's, and as [`SearchTarget::from_map`].
    pub fn from_map_and_free(
        map: OccupancyList,
        free: &crate::occupancy::FreeSpace,
        levels: usize,
    ) -> Result<Self> {
        free.check_resolution(map.resolution())?;
        let mut t = Self::from_map(map, levels)?;
        let pyramid = &t.pyramid;
        t.free = {
            use rayon::prelude::*;
            (0..levels)
                .into_par_iter()
                .map(|level| free_at_level(free, pyramid.level(level), level as u32))
                .collect()
        };
        Ok(t)
    }

    /// The same occupied cells without free space: what a map without it is searched
    /// against.
    pub(crate) fn without_free_space(&self) -> SearchTarget {
        let levels = self.pyramid.levels();
        SearchTarget {
            pyramid: self.pyramid.clone(),
            free: (0..levels).map(|_| None).collect(),
            occupied: (0..levels).map(|_| OnceLock::new()).collect(),
            grids: empty_grids(levels),
        }
    }

    /// The same target from its level `k` up, at `2^k` times the resolution (its
    /// occupied cells and free space as they are at those levels); `None` when `k` is not
    /// a level.
    pub(crate) fn coarsened(&self, k: usize) -> Option<SearchTarget> {
        let pyramid = self.pyramid.above(k)?;
        let levels = pyramid.levels();
        Some(SearchTarget {
            pyramid,
            free: self.free[k..].to_vec(),
            occupied: (0..levels).map(|_| OnceLock::new()).collect(),
            grids: empty_grids(levels),
        })
    }

    /// A target from one scan in its own frame: endpoints voxelised at `resolution`, and
    /// free space ray traced from the scan's origin at every level.
    pub fn from_cloud(cloud: &PointCloud, resolution: f64, levels: usize) -> Result<Self> {
        Self::from_scans(&[(cloud, Pose::identity())], resolution, levels)
    }

    /// A target from several scans with their poses in the target frame.
    pub fn from_scans(
        scans: &[(&PointCloud, Pose)],
        resolution: f64,
        levels: usize,
    ) -> Result<Self> {
        let mut t = SearchTarget {
            pyramid: Pyramid::new(OccupancyList::new(resolution)?, levels)?,
            free: (0..levels).map(|_| None).collect(),
            occupied: (0..levels).map(|_| OnceLock::new()).collect(),
            grids: empty_grids(levels),
        };
        for (c, pose) in scans {
            t.add_scan(c, pose)?;
        }
        Ok(t)
    }

    /// Adds a scan placed at `pose` (`T_target_scan`): its endpoints join every level, its
    /// rays extend the free space. Only the new scan is traced: building a map scan by scan
    /// costs each scan once.
    ///
    /// A point whose voxel key is outside the representable range is an error naming it
    /// ([`OccupancyList::check_keys`]): a target never silently loses points.
    pub fn add_scan(&mut self, cloud: &PointCloud, pose: &Pose) -> Result<()> {
        self.add_scan_within(cloud, pose, &|_| None)
    }

    /// A target from one scan in its own frame whose free space at a level is read only
    /// within `read_within(level)` metres of the scan's origin (`None`: everywhere): rays
    /// are traced at that level only as far as that, plus what [`add_free_space`] adds.
    /// Every cell read there is as [`SearchTarget::from_cloud`] makes it; the grids are
    /// made or not as there too.
    pub(crate) fn from_cloud_read_within(
        cloud: &PointCloud,
        resolution: f64,
        levels: usize,
        read_within: &dyn Fn(usize) -> Option<f64>,
    ) -> Result<Self> {
        let mut t = Self::from_scans(&[], resolution, levels)?;
        t.add_scan_within(cloud, &Pose::identity(), read_within)?;
        Ok(t)
    }

    /// [`SearchTarget::add_scan`] tracing each level's rays only as far as `read_within`
    /// says ([`SearchTarget::from_cloud_read_within`]).
    fn add_scan_within(
        &mut self,
        cloud: &PointCloud,
        pose: &Pose,
        read_within: &dyn Fn(usize) -> Option<f64>,
    ) -> Result<()> {
        let mut endpoints = OccupancyList::new(self.pyramid.base().resolution())?;
        endpoints.check_keys(cloud, pose, "the target")?;
        endpoints.add_points(cloud, pose, 1);
        self.pyramid.merge(&endpoints)?;
        // Occupancy only grows: a level's occupied grid made before takes the new voxels
        // in place (its box grown to take them) rather than being made again over the
        // whole level.
        let levels = self.pyramid.levels();
        let made = std::mem::replace(
            &mut self.occupied,
            (0..levels).map(|_| OnceLock::new()).collect(),
        );
        for (level, (cell, grid)) in self.occupied.iter().zip(made).enumerate() {
            if let Some(grid) = grid.into_inner().flatten() {
                if let Some(grid) = with_voxels(grid, &endpoints, level) {
                    let _ = cell.set(Some(grid));
                }
            }
        }
        self.grids = empty_grids(levels);
        for level in 0..levels {
            let grid = self.free[level].take();
            let level_list = self.pyramid.level(level);
            self.free[level] = add_free_space(grid, cloud, pose, level_list, read_within(level));
        }
        Ok(())
    }

    /// The finest voxel edge, metres: the resolution every search of this target runs at
    /// (whatever [`super::SearchParams::resolution`] says).
    pub fn resolution(&self) -> f64 {
        self.pyramid.base().resolution()
    }

    /// The occupied voxels of a level as a dense grid (one bit read per lookup), made on
    /// first use; `None` when the level's box is too large for one.
    pub(crate) fn occupied_grid(&self, level: usize) -> Option<&DenseGrid> {
        self.occupied[level]
            .get_or_init(|| DenseGrid::occupied(self.pyramid.level(level), MAX_OCCUPIED_GRID_CELLS))
            .as_ref()
    }

    /// A level's occupied and free cells as the search scores them, made on first use;
    /// `None` when the level's box is too large (the hash table and the free grid answer).
    pub(crate) fn cells(&self, level: usize) -> Option<&CellGrid> {
        self.grids[level]
            .cells
            .get_or_init(|| CellGrid::new(self.pyramid.level(level), self.free[level].as_ref()))
            .as_ref()
    }

    /// [`CellGrid::whole_box`] of a level, found on first use.
    fn whole_box(&self, level: usize) -> Option<KeyBox> {
        *self.grids[level].whole_box.get_or_init(|| {
            CellGrid::whole_box(self.pyramid.level(level), self.free[level].as_ref())
        })
    }

    /// The cells a search scores against when every key it looks up lies in `reach`: the
    /// whole level's ([`SearchTarget::cells`]) when they were made before, when the level
    /// is small, or when `reach` covers more than a quarter of it; otherwise a grid over
    /// `reach` within the level's box (the last one is kept and reused while later reaches
    /// fit in it). Both score the same; the part costs a fraction of the whole to make.
    /// `None` when the level is empty or its box too large, as for the whole.
    ///
    /// Measured (libpointmatcher car 401 onto 400, six degrees of freedom, one thread): the
    /// target spans 127 x 131 x 40 m, so its finest level's whole grid is 662 M cells (83
    /// MB), made for candidates reaching a fraction of it.
    pub(crate) fn cells_reaching(&self, level: usize, reach: KeyBox) -> Option<SearchCells<'_>> {
        let slot = &self.grids[level];
        if let Some(whole) = slot.cells.get() {
            return whole.as_ref().map(SearchCells::Whole);
        }
        let (lo, hi) = self.whole_box(level)?;
        let whole_cells = box_cells((lo, hi));
        // Keys outside the whole box score nothing in either grid, so the part needs only
        // the reach inside it; an axis it misses altogether gets any one cell of the box.
        let mut plo = [0; 3];
        let mut phi = [0; 3];
        for i in 0..3 {
            (plo[i], phi[i]) = (lo[i].max(reach.0[i]), hi[i].min(reach.1[i]));
            if phi[i] < plo[i] {
                (plo[i], phi[i]) = (lo[i], lo[i]);
            }
        }
        let part_cells = box_cells((plo, phi));
        let whole = || self.cells(level).map(SearchCells::Whole);
        if whole_cells <= MIN_PART_WORTHY_CELLS
            || part_cells.saturating_mul(PART_SHARE) > whole_cells
        {
            return whole();
        }
        let mut part = slot.part.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(g) = part.grid.as_ref().filter(|g| g.covers(plo, phi)) {
            return Some(SearchCells::Part(Arc::clone(g)));
        }
        if part.made >= MAX_PARTS {
            drop(part);
            return whole();
        }
        let made = CellGrid::over(
            self.pyramid.level(level),
            self.free[level].as_ref(),
            plo,
            phi,
        );
        let Some(made) = made else {
            drop(part);
            return whole();
        };
        let made = Arc::new(made);
        part.grid = Some(Arc::clone(&made));
        part.made += 1;
        Some(SearchCells::Part(made))
    }

    /// [`SearchTarget::cells`] as rows, for scoring boxes of translations that would
    /// otherwise take `lookups` cell lookups: the rows made before, or made now when the
    /// lookups are at least as many as the level's cells (making them reads every cell
    /// once; for fewer lookups the cells answer sooner, with the same counts). `None`
    /// without cells or below that.
    ///
    /// Measured (3DTK scan001 onto scan000, 0.1 m, one thread): the finest level's rows
    /// (16.7 M cells) took 59 ms to make, to score 2,532 poses of 2,516 voxels (6.4 M
    /// lookups) that the cells score in a few milliseconds.
    pub(crate) fn rows(&self, level: usize, lookups: u64) -> Option<&RowGrid> {
        let slot = &self.grids[level].rows;
        if let Some(made) = slot.get() {
            return made.as_ref();
        }
        if lookups < box_cells(self.whole_box(level)?) {
            return None;
        }
        let cells = self.cells(level)?;
        slot.get_or_init(|| RowGrid::new(cells)).as_ref()
    }

    /// The map pyramid.
    pub fn pyramid(&self) -> &Pyramid {
        &self.pyramid
    }

    /// Whether free space is known.
    pub fn has_free_space(&self) -> bool {
        self.free.iter().any(Option::is_some)
    }
}

/// `grid` (a level's [`SearchTarget::occupied_grid`]) with the voxels of `endpoints` (at
/// the base resolution) set at pyramid level `level` (key `floor(k / 2^level)`), its box
/// grown to hold them; `None` when the grown box would hold more than
/// [`MAX_OCCUPIED_GRID_CELLS`] (the level is then answered as [`DenseGrid::occupied`]
/// answers it: by the hash). The result equals [`DenseGrid::occupied`] of the merged level:
/// the same box (the union of the old one and the new voxels') and the same cells.
fn with_voxels(grid: DenseGrid, endpoints: &OccupancyList, level: usize) -> Option<DenseGrid> {
    let f = 1i64 << level;
    let keys: Vec<[i64; 3]> = endpoints
        .iter()
        .filter(|(_, c)| *c > 0)
        .map(|(k, _)| [k.x as i64, k.y as i64, k.z as i64].map(|v| v.div_euclid(f)))
        .collect();
    let (mut lo, mut hi) = grid.bounds();
    for k in &keys {
        for i in 0..3 {
            lo[i] = lo[i].min(k[i]);
            hi[i] = hi[i].max(k[i]);
        }
    }
    if box_cells((lo, hi)) > MAX_OCCUPIED_GRID_CELLS {
        return None;
    }
    let mut grid = if (lo, hi) == grid.bounds() {
        grid
    } else {
        grid.grown(lo, hi)?
    };
    for [x, y, z] in keys {
        grid.set(x, y, z);
    }
    Some(grid)
}

/// How near an occupied cell, in cells on every axis, a map's free cell is not counted free
/// ([`SearchTarget::from_map_and_free`]): 1, the cells round a surface, where range noise
/// and mixed pixels fall.
///
/// Not [`FREE_SPACE_MARGIN`]: scans' rays keep that margin before their own endpoint
/// only, while a map does not say where its rays came from, so a margin would have to be
/// kept round every surface, also beside it where rays grazing it saw through. Measured on
/// the 3DTK scans (each localised in an OctoMap tree of another, made by `olmap voxelize
/// --free-space`, at the poses of the reference and of wrong answers): with 1 cell the
/// scan's side of the agreement is within 0.01-0.03 of what the scan-to-scan registration
/// gives with its rays (right poses 0.905-1.000 against 0.894-1.000 at 0.1 m, wrong ones
/// 0.511-0.748 against 0.500-0.679 at 0.1 and 0.05 m); keeping the 0.3 m margin round every
/// surface raised a wrong pose's to 0.861, past the verdict's 0.85, where its rays give
/// 0.571.
pub const MAP_FREE_CLEARANCE_CELLS: i64 = 1;

/// Level `shift`'s free space from a map's free voxels ([`SearchTarget::from_map_and_free`]):
/// every cell holding a free voxel, then every cell within [`MAP_FREE_CLEARANCE_CELLS`]
/// (on every axis) of an occupied cell of the level cleared.
fn free_at_level(
    free: &crate::occupancy::FreeSpace,
    level: &OccupancyList,
    shift: u32,
) -> Option<DenseGrid> {
    let (mut lo, mut hi) = free.key_box_at(shift)?;
    if let Some((l, h)) = DenseGrid::key_box(level) {
        for i in 0..3 {
            lo[i] = lo[i].min(l[i]);
            hi[i] = hi[i].max(h[i]);
        }
    }
    let mut grid = DenseGrid::empty(lo, hi)?;
    free.for_each_column_at(shift, |x, y, z0, z1| grid.set_column(x, y, z0, z1));
    let r = MAP_FREE_CLEARANCE_CELLS;
    for (k, _) in level.iter() {
        let k = [k.x as i64, k.y as i64, k.z as i64];
        for x in k[0] - r..=k[0] + r {
            for y in k[1] - r..=k[1] + r {
                grid.clear_column(x, y, k[2] - r, k[2] + r);
            }
        }
    }
    Some(grid)
}

/// Cells a ray is traced past `read_within` in [`add_free_space`]: a cell's half diagonal
/// twice (where a ray enters it against its centre, and the centre against the point read)
/// and a face neighbour (√3 + 1 < 3).
const TRACE_PAST_READ_CELLS: f64 = 3.0;

/// Adds the cells crossed by a scan's rays at the level's resolution (minus the last
/// [`FREE_SPACE_MARGIN`] of each ray) to a free-space grid, then clears every occupied cell
/// of the level. `None` when the grid would be too large (the box is the whole scan's
/// whatever `read_within` says).
///
/// With `read_within`, a ray stops at the first cell it enters farther than that plus
/// three cells from the origin: every cell whose centre lies within `read_within` plus a
/// cell's half diagonal and one face neighbour is entered before that (a cell's centre is
/// at most half its diagonal from where a ray enters it), so those cells are as the whole
/// ray leaves them.
fn add_free_space(
    grid: Option<DenseGrid>,
    cloud: &PointCloud,
    pose: &Pose,
    level: &OccupancyList,
    read_within: Option<f64>,
) -> Option<DenseGrid> {
    let cell = level.resolution();
    let skip = (FREE_SPACE_MARGIN / cell).ceil() as usize + 1;
    let origin = pose.transform_point(&cloud.origin());
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    let mut grow = |p: &nalgebra::Point3<f64>| {
        for i in 0..3 {
            let k = (p[i] / cell).floor() as i64;
            lo[i] = lo[i].min(k);
            hi[i] = hi[i].max(k);
        }
    };
    grow(&origin);
    let moved = cloud.transformed(pose);
    if let Some(b) = moved.bounding_box() {
        grow(&b.min);
        grow(&b.max);
    }
    let mut grid = match grid {
        Some(g) => g.grown(lo, hi)?,
        None => DenseGrid::empty(lo, hi)?,
    };
    grid.par_set(moved.points(), |pts, cells| {
        for p in pts {
            let end = p.cast();
            let mut ray = VoxelRay::new(&origin, &end, cell);
            let n = (ray.remaining() as usize).saturating_sub(skip);
            // The segment parameter (0 at the origin, 1 at the point) to stop past.
            let stop = read_within.map_or(f64::INFINITY, |r| {
                (r + TRACE_PAST_READ_CELLS * cell) / (end - origin).norm()
            });
            for _ in 0..n {
                let Some(k) = ray.next() else { break };
                if ray.entry() > stop {
                    break;
                }
                cells.set(k.x as i64, k.y as i64, k.z as i64);
            }
        }
    });
    // Occupied cells (of every scan so far) are never free.
    for (k, _) in level.iter() {
        grid.clear(k.x as i64, k.y as i64, k.z as i64);
    }
    Some(grid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::align::score::cells::tests::lcg;
    use crate::geometry::VoxelKey;

    /// A target whose one level spans 401 x 401 x 201 cells (past
    /// [`MIN_PART_WORTHY_CELLS`]), with voxels scattered through it.
    fn large_target() -> SearchTarget {
        let mut map = OccupancyList::new(0.1).unwrap();
        let mut s = 9u64;
        map.set(VoxelKey::new(0, 0, 0), 1).unwrap();
        map.set(VoxelKey::new(400, 400, 200), 1).unwrap();
        for _ in 0..20000 {
            let k = [lcg(&mut s) % 401, lcg(&mut s) % 401, lcg(&mut s) % 201];
            map.set(VoxelKey::new(k[0] as i32, k[1] as i32, k[2] as i32), 1)
                .unwrap();
        }
        SearchTarget::from_map(map, 1).unwrap()
    }

    /// A small reach gets a part that scores as the whole grid; a reach inside the kept
    /// part reuses it; a reach over half the box, or a miss after [`MAX_PARTS`] parts,
    /// gets the whole grid.
    #[test]
    fn searches_reaching_a_small_part_of_a_large_level_get_a_part() {
        let target = large_target();
        let small = ([100, 120, 40], [180, 200, 90]);
        let part = target.cells_reaching(0, small).unwrap();
        assert!(matches!(part, SearchCells::Part(_)));
        assert!(part.covers(small.0, small.1) && !part.covers([0; 3], [400, 400, 200]));
        // Inside the part, it scores as the whole.
        let mut s = 4u64;
        let base: Vec<[i64; 3]> = (0..300)
            .map(|_| {
                [
                    110 + lcg(&mut s) % 60,
                    130 + lcg(&mut s) % 60,
                    50 + lcg(&mut s) % 30,
                ]
            })
            .collect();
        let ts: Vec<[i32; 3]> = (0..30)
            .map(|_| {
                [
                    (lcg(&mut s) % 11 - 5) as i32,
                    (lcg(&mut s) % 11 - 5) as i32,
                    (lcg(&mut s) % 9 - 4) as i32,
                ]
            })
            .collect();
        let whole = CellGrid::new(target.pyramid().level(0), None).unwrap();
        let want = whole.score(&base, &ts);
        assert!(want.iter().any(|c| c.0 > 0), "the test must hit something");
        assert_eq!(part.score(&base, &ts), want);
        // A reach inside the kept part reuses it.
        let inner = target
            .cells_reaching(0, ([120, 130, 50], [150, 160, 60]))
            .unwrap();
        match (&part, &inner) {
            (SearchCells::Part(a), SearchCells::Part(b)) => assert!(Arc::ptr_eq(a, b)),
            _ => panic!("a reach inside the part gets the part"),
        }
        // Over half the box: the whole grid (not made yet, so a second part is possible).
        let wide = target.cells_reaching(0, ([-50, -50, -50], [300, 450, 250]));
        assert!(matches!(wide, Some(SearchCells::Whole(_))));
        let target = large_target();
        for k in 0..MAX_PARTS as i64 {
            let reach = ([10 * k, 0, 0], [10 * k + 50, 50, 50]);
            assert!(matches!(
                target.cells_reaching(0, reach),
                Some(SearchCells::Part(_))
            ));
        }
        let after = target.cells_reaching(0, ([300, 300, 100], [350, 350, 150]));
        assert!(matches!(after, Some(SearchCells::Whole(_))));
        // Once the whole grid is made, every reach gets it.
        let again = target.cells_reaching(0, ([0, 0, 0], [50, 50, 50]));
        assert!(matches!(again, Some(SearchCells::Whole(_))));
    }

    /// Occupied grids made before a scan is added take its voxels in place (growing their
    /// boxes, negative keys included) and end as a grid made afresh over the merged levels.
    #[test]
    fn occupied_grids_kept_across_added_scans_equal_grids_made_afresh() {
        let mut s = 21u64;
        let mut cloud = |cx: f64, cy: f64| {
            let pts = (0..400)
                .map(|_| {
                    nalgebra::Point3::new(
                        (cx + (lcg(&mut s) % 300) as f64 * 0.01) as f32,
                        (cy + (lcg(&mut s) % 300) as f64 * 0.01) as f32,
                        ((lcg(&mut s) % 150) as f64 * 0.01) as f32,
                    )
                })
                .collect();
            PointCloud::from_points(pts)
        };
        let mut target = SearchTarget::from_scans(&[], 0.1, 3).unwrap();
        // Inside the first box, then growing it towards negative keys and away.
        for (i, (cx, cy)) in [(0.0, 0.0), (0.5, 0.5), (-4.3, 1.0), (6.1, -7.7)]
            .into_iter()
            .enumerate()
        {
            let c = cloud(cx, cy);
            let pose = Pose::from_xyz_ypr(0.2 * i as f64, -0.1, 0.0, 0.3 * i as f64, 0.0, 0.0);
            target.add_scan(&c, &pose).unwrap();
            for level in 0..3 {
                let kept = target.occupied_grid(level).unwrap();
                let fresh =
                    DenseGrid::occupied(target.pyramid().level(level), MAX_OCCUPIED_GRID_CELLS)
                        .unwrap();
                assert_eq!(kept.bounds(), fresh.bounds(), "scan {i}, level {level}");
                assert_eq!(kept.words(), fresh.words(), "scan {i}, level {level}");
            }
        }
    }

    /// A map's free voxels are free at every level where no occupied cell of that level
    /// is within one cell; a free space of another voxel edge is refused.
    #[test]
    fn a_map_s_free_voxels_are_free_at_each_level_away_from_its_surfaces() {
        let mut map = OccupancyList::new(0.1).unwrap();
        map.set(VoxelKey::new(0, 0, 0), 1).unwrap();
        let mut free = crate::occupancy::FreeSpace::new(0.1).unwrap();
        // A slab of free voxels from x = -20 to -1 (the surface at x = 0), 3 voxels thick.
        free.push(VoxelKey::new(-20, -1, -1), VoxelKey::new(-1, 1, 1))
            .unwrap();
        let t = SearchTarget::from_map_and_free(map.clone(), &free, 3).unwrap();
        assert!(t.has_free_space());
        let at = |level: usize, x: i64, y: i64, z: i64| {
            t.free[level].as_ref().unwrap().contains(x, y, z)
        };
        // Level 0: the voxel next to the surface is not free, the one after it is; the
        // surface itself never is.
        assert!(!at(0, -1, 0, 0) && at(0, -2, 0, 0) && at(0, -20, 0, 0) && !at(0, 0, 0, 0));
        assert!(!at(0, -2, 2, 0), "outside the free voxels");
        // Level 1 (0.2 m): cell -1 holds free voxels -2 and -1 but touches the surface's
        // cell 0; cell -2 is free.
        assert!(!at(1, -1, 0, 0) && at(1, -2, 0, 0) && at(1, -10, 0, 0));
        // Level 2 (0.4 m): cells -1 (voxels -4..-1) not free, -2 and beyond free.
        assert!(!at(2, -1, 0, 0) && at(2, -2, 0, 0) && at(2, -5, 0, 0));
        assert!(!at(2, -6, 0, 0), "no free voxel below -20");
        let other = crate::occupancy::FreeSpace::new(0.05).unwrap();
        assert!(SearchTarget::from_map_and_free(map, &other, 3).is_err());
    }
}
