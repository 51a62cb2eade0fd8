//! Whether two scans agree where both looked: a check of a registration that counts what
//! the overlap does not, the places where one scan saw a surface and the other saw through.
//!
//! Overlap counts coinciding voxels, and in man-made places much coincides anywhere: a
//! floor, a ceiling, a wall at a common height. A wrong pose still puts some of the scan
//! where the target's rays passed freely, and (seen from the other side) some of the
//! target where the scan's rays passed. [`consistency`] measures both at the finest
//! resolution after refinement:
//!
//! * only **surface** voxels count: those with at least [`MIN_SURFACE_NEIGHBOURS`] occupied
//!   voxels of their own scan among their 26 neighbours (a stray return, a speck of dust or
//!   a random outlier has none, and says nothing about a surface);
//! * a source voxel is **supported** when a target voxel is occupied in its 3 x 3 x 3
//!   neighbourhood (one cell of tolerance absorbs the range noise and the grid's phase);
//! * it is **contradicted** when it is not supported and lies deep in the target's free
//!   space: its cell and the six next to it were crossed by the target's rays (minus
//!   [`super::FREE_SPACE_MARGIN`] before each return), so that rays grazing a floor do not
//!   count against the floor;
//! * otherwise the target never observed it, and it does not count.
//!
//! The agreement of one side is `supported / (supported + contradicted)`; the same is
//! computed for the target's voxels against the source's free space, and
//! [`Consistency::agreement`] is the smaller of the two. A right pose scores close to 1
//! (what is left is moving things, glass and rays grazing a surface); a wrong pose leaves
//! surfaces hanging in the other scan's open space.

use super::score::DenseGrid;
use super::target::SearchTarget;
use crate::cloud::PointCloud;
use crate::error::Result;
use nalgebra::Point3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use crate::geometry::{Pose, VoxelKey};
use crate::occupancy::packed::{pack_key, unpack_key, KEY_MAX, KEY_MIN};
use crate::occupancy::OccupancyList;

/// Occupied neighbours (of 26, in its own scan) a voxel needs to count as surface.
pub const MIN_SURFACE_NEIGHBOURS: usize = 4;

/// The 26 neighbour offsets and the voxel itself.
fn neighbourhood(k: VoxelKey) -> impl Iterator<Item = VoxelKey> {
    (-1..=1).flat_map(move |dx| {
        (-1..=1).flat_map(move |dy| {
            (-1..=1).filter_map(move |dz| {
                Some(VoxelKey::new(
                    k.x.checked_add(dx)?,
                    k.y.checked_add(dy)?,
                    k.z.checked_add(dz)?,
                ))
            })
        })
    })
}

/// The largest key box, in cells, of a scan's own dense grid in [`surface`] and
/// [`count_side`] (2^30 bits = 128 MiB, held while a count runs, one for each of its two
/// sides at once, its pages touched only where voxels are; larger lists answer from the
/// hash, several times slower). A 0.05 m map cropped around a warehouse lidar scan spans
/// 1844 x 1883 x 208 cells (92 x 94 x 10.4 m): 7.2 x 10^8.
const MAX_LOCAL_GRID_CELLS: u64 = 1 << 30;

/// Lookups of occupied voxels: one bit of a dense grid when there is one, else the list's
/// hash (the same answers; the grid is several times faster for 27-cell neighbourhoods).
#[derive(Clone, Copy)]
enum Occupied<'a> {
    Dense(&'a DenseGrid),
    Hash(&'a OccupancyList),
}

impl Occupied<'_> {
    /// Whether voxel `k` is occupied (count above zero).
    #[inline]
    fn at(&self, k: VoxelKey) -> bool {
        match self {
            Occupied::Dense(g) => g.contains(k.x as i64, k.y as i64, k.z as i64),
            Occupied::Hash(l) => l.count(k) > 0,
        }
    }

    /// Whether a voxel of the 3 x 3 x 3 block centred on `k` (`k` included) is occupied.
    #[inline]
    fn any_near(&self, k: VoxelKey) -> bool {
        match self {
            Occupied::Dense(g) => g.block_count(k.x as i64, k.y as i64, k.z as i64) > 0,
            Occupied::Hash(_) => neighbourhood(k).any(|n| self.at(n)),
        }
    }

    /// How many of the 26 neighbours of `k` are occupied, counting up to `enough` (a
    /// dense grid counts them all; the hash stops at `enough`).
    #[inline]
    fn neighbours(&self, k: VoxelKey, enough: usize) -> usize {
        match self {
            Occupied::Dense(g) => {
                let (x, y, z) = (k.x as i64, k.y as i64, k.z as i64);
                (g.block_count(x, y, z) - u32::from(g.contains(x, y, z))) as usize
            }
            Occupied::Hash(_) => neighbourhood(k)
                .filter(|n| *n != k && self.at(*n))
                .take(enough)
                .count(),
        }
    }
}

/// The voxels of `list` with at least [`MIN_SURFACE_NEIGHBOURS`] occupied neighbours.
fn surface(list: &OccupancyList) -> OccupancyList {
    let grid = DenseGrid::occupied(list, MAX_LOCAL_GRID_CELLS);
    surface_with(
        list,
        grid.as_ref().map_or(Occupied::Hash(list), Occupied::Dense),
    )
}

/// [`surface`], looking the neighbours up in `occupied` (`list`'s own voxels).
fn surface_with(list: &OccupancyList, occupied: Occupied<'_>) -> OccupancyList {
    list.par_filtered(|k, _| is_surface(occupied, k))
}

/// Whether voxel `k` has at least [`MIN_SURFACE_NEIGHBOURS`] occupied neighbours in
/// `occupied` (whether `k` itself is occupied is not asked).
#[inline]
fn is_surface(occupied: Occupied<'_>, k: VoxelKey) -> bool {
    occupied.neighbours(k, MIN_SURFACE_NEIGHBOURS) >= MIN_SURFACE_NEIGHBOURS
}

/// Upright voxels (of one side) the other scan must observe for [`SideAgreement::agreement`]
/// to be taken over upright structure alone.
pub const MIN_UPRIGHT_SEEN: u64 = 100;

/// One side's count: the surface voxels of one scan against the other's occupancy and
/// free space. Only voxels the other scan observed are counted: a surface voxel it never
/// observed says nothing, and is not looked at (its surface test is skipped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SideAgreement {
    /// Surface voxels with an occupied voxel of the other scan within one cell.
    pub supported: u64,
    /// Surface voxels the other scan saw through (free, and not supported), counted only
    /// in patches: with at least [`MIN_CONTRADICTED_NEIGHBOURS`] such neighbours.
    pub contradicted: u64,
    /// Supported voxels on upright structure (walls, furniture sides: a surface voxel two
    /// layers above or below within one cell sideways), not on a floor or ceiling.
    pub upright_supported: u64,
    /// Contradicted voxels on upright structure.
    pub upright_contradicted: u64,
    /// Contradicted voxels in patches larger than a thing that moves
    /// ([`MOVABLE_WIDTH`] across, [`MOVABLE_HEIGHT`] tall): a wall, a floor-to-ceiling
    /// strip, furniture rows, not a person, a chair or a door.
    pub fixed_contradicted: u64,
    /// Of those, the ones on upright structure.
    pub upright_fixed_contradicted: u64,
}

impl SideAgreement {
    /// The share of this scan's observed surface that the other supports:
    /// `supported / (supported + contradicted)` over its upright voxels when the other
    /// scan observed at least [`MIN_UPRIGHT_SEEN`] of them, else over all its voxels; 1
    /// when the other observed none. Floors and ceilings are left out because any two
    /// indoor places share them: with them, unrelated simulated rooms agreed at 0.89-0.97;
    /// on upright structure alone at 0.75-0.83, while the right real pairs of the data
    /// folder agree at 0.89-1.00.
    pub fn agreement(&self) -> f64 {
        let (s, c) = if self.upright_supported + self.upright_contradicted >= MIN_UPRIGHT_SEEN {
            (self.upright_supported, self.upright_contradicted)
        } else {
            (self.supported, self.contradicted)
        };
        if s + c == 0 {
            1.0
        } else {
            s as f64 / (s + c) as f64
        }
    }

    /// The share of this scan's observed surface (counted as in
    /// [`SideAgreement::agreement`]) that lies where the other saw through in patches
    /// larger than a thing that moves ([`SideAgreement::fixed_contradicted`]); 0 when the
    /// other observed none.
    pub fn fixed_disagreement(&self) -> f64 {
        let (s, c, f) = if self.upright_supported + self.upright_contradicted >= MIN_UPRIGHT_SEEN {
            (
                self.upright_supported,
                self.upright_contradicted,
                self.upright_fixed_contradicted,
            )
        } else {
            (self.supported, self.contradicted, self.fixed_contradicted)
        };
        if s + c == 0 {
            0.0
        } else {
            f as f64 / (s + c) as f64
        }
    }
}

/// How two registered scans agree where both looked (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Consistency {
    /// The source's voxels (moved by the pose) against the target.
    pub source: SideAgreement,
    /// The target's voxels against the source's free space; `None` when the target has no
    /// points to check (a map without them) or the source no sensor origin to trace from.
    pub target: Option<SideAgreement>,
    /// Voxel edge of the check, metres.
    pub resolution: f64,
}

impl Consistency {
    /// The smaller agreement of the two sides (the source's alone when the target side is
    /// unknown).
    pub fn agreement(&self) -> f64 {
        let s = self.source.agreement();
        self.target.map_or(s, |t| s.min(t.agreement()))
    }
}

/// Counts one scan's surface voxels against the other's occupancy and free space:
/// `mine` is all the scan's occupied voxels (already in the other's frame, at the other's
/// resolution); a voxel is tested for being surface only when the other scan observed it
/// (an occupied cell within one cell at its level, or deep free space there), since no
/// other voxel changes a count. In a map cropped around a scan most voxels lie where the
/// scan never looked.
fn count_side(mine: &OccupancyList, origin: &Point3<f64>, other: &SearchTarget) -> SideAgreement {
    let res = other.resolution();
    let levels = other.pyramid().levels();
    let own_grid = DenseGrid::occupied(mine, MAX_LOCAL_GRID_CELLS);
    let own = own_grid
        .as_ref()
        .map_or(Occupied::Hash(mine), Occupied::Dense);
    // Each voxel on its own (counts added in any order are the same): in chunks, side by
    // side.
    let keys: Vec<VoxelKey> = mine.iter().map(|(k, _)| k).collect();
    let count_chunk = |chunk: &[VoxelKey]| {
        let mut side = SideAgreement::default();
        let mut through = Vec::new();
        for &k in chunk {
            let Some(near) = observed(other, k, (mine.center(k) - origin).norm(), res, levels)
            else {
                continue;
            };
            if !is_surface(own, k) {
                continue;
            }
            let up = is_upright(own, k);
            if near {
                side.supported += 1;
                side.upright_supported += u64::from(up);
            } else {
                through.push((k, up));
            }
        }
        (side, through)
    };
    let parts: Vec<Part> = keys.par_chunks(COUNT_CHUNK).map(count_chunk).collect();
    add_parts(parts, res)
}

/// One part of a count: the supported voxels of a chunk, and its voxels seen through
/// (each with whether it is upright).
type Part = (SideAgreement, Vec<(VoxelKey, bool)>);

/// One count from its parallel parts: supported voxels added, seen-through ones counted
/// as contradicted only in patches. A wall or a piece of furniture standing in the other's
/// open space is a patch of voxels; a stray return (noise, a spurious point, a random
/// outlier) is not and says nothing about the pose.
fn add_parts(parts: Vec<Part>, resolution: f64) -> SideAgreement {
    let mut side = SideAgreement::default();
    let mut seen_through = std::collections::HashMap::new();
    for (part, through) in parts {
        side.supported += part.supported;
        side.upright_supported += part.upright_supported;
        seen_through.extend(through);
    }
    let mut contradicted = FxHashMap::default();
    for (k, up) in &seen_through {
        let patch = neighbourhood(*k)
            .filter(|n| n != k && seen_through.contains_key(n))
            .nth(MIN_CONTRADICTED_NEIGHBOURS - 1)
            .is_some();
        if patch {
            side.contradicted += 1;
            side.upright_contradicted += u64::from(*up);
            contradicted.insert(*k, *up);
        }
    }
    for patch in patches(&contradicted) {
        if !movable(&patch, resolution) {
            side.fixed_contradicted += patch.len() as u64;
            side.upright_fixed_contradicted +=
                patch.iter().filter(|k| contradicted[*k]).count() as u64;
        }
    }
    side
}

/// The widest a thing that moves between two scans may be across, in metres (a person, a
/// chair, a door, a trolley): a patch of contradicted voxels that fits in a box this wide
/// in x and y and [`MOVABLE_HEIGHT`] tall may be one, a larger patch is structure.
pub const MOVABLE_WIDTH: f64 = 1.2;

/// The tallest a thing that moves may be, in metres (a door and its frame).
pub const MOVABLE_HEIGHT: f64 = 2.2;

/// The connected patches (26-neighbourhood) of `voxels`, sorted within and between
/// patches so that the result does not depend on the hash's order.
fn patches(voxels: &FxHashMap<VoxelKey, bool>) -> Vec<Vec<VoxelKey>> {
    let mut keys: Vec<VoxelKey> = voxels.keys().copied().collect();
    keys.sort_unstable_by_key(|k| (k.x, k.y, k.z));
    let mut done = FxHashSet::default();
    let mut out = Vec::new();
    for k in keys {
        if !done.insert(k) {
            continue;
        }
        let (mut patch, mut stack) = (Vec::new(), vec![k]);
        while let Some(c) = stack.pop() {
            patch.push(c);
            for n in neighbourhood(c) {
                if voxels.contains_key(&n) && done.insert(n) {
                    stack.push(n);
                }
            }
        }
        out.push(patch);
    }
    out
}

/// Whether a patch of voxels at `resolution` fits in the box of a thing that moves.
fn movable(patch: &[VoxelKey], resolution: f64) -> bool {
    let extent = |f: fn(&VoxelKey) -> i32| {
        let (lo, hi) = patch
            .iter()
            .map(f)
            .fold((i32::MAX, i32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
        f64::from(hi - lo + 1) * resolution
    };
    extent(|k| k.x) <= MOVABLE_WIDTH + 1e-9
        && extent(|k| k.y) <= MOVABLE_WIDTH + 1e-9
        && extent(|k| k.z) <= MOVABLE_HEIGHT + 1e-9
}

/// Whether `other` observed the cell of finest key `k` (in its frame), `d` metres from the
/// sensor of the scan being counted: `Some(true)` when an occupied cell lies within one
/// cell at the level that range is checked at ([`level_at`]), `Some(false)` when the cell
/// lies deep in its free space there ([`deep_free`]), `None` when it never looked.
#[inline]
fn observed(other: &SearchTarget, k: VoxelKey, d: f64, res: f64, levels: usize) -> Option<bool> {
    let level = level_at(d, res, levels);
    let f = 1i32 << level;
    let kl = VoxelKey::new(k.x.div_euclid(f), k.y.div_euclid(f), k.z.div_euclid(f));
    let occ = other.occupied_grid(level).map_or(
        Occupied::Hash(other.pyramid().level(level)),
        Occupied::Dense,
    );
    if occ.any_near(kl) {
        Some(true)
    } else if other.free[level].as_ref().is_some_and(|g| deep_free(g, kl)) {
        Some(false)
    } else {
        None
    }
}

/// A map's surface voxels at one resolution, in the map's own grid, each with whether it
/// lies on upright structure: the map's side of an agreement count prepared once for any
/// number of poses ([`MapSurface::count`]).
///
/// A scan's voxels must be made again at every pose (the scan moves over the other's
/// grid); a map's voxels are already a grid, so the map's side of a count is taken in
/// that grid: each surface voxel's centre is moved into the scan's frame and looked up in
/// what the scan observed. The surface and upright tests are those of the scan's side,
/// made once on the whole map.
pub(crate) struct MapSurface {
    resolution: f64,
    /// Packed keys of the surface voxels, sorted; [`UPRIGHT_BIT`] set on upright ones.
    voxels: Vec<u64>,
}

/// Cells along x of one slab of [`MapSurface::new`].
const SURFACE_SLAB_CELLS: usize = 128;

/// Cells either side of a slab that its tests read: [`is_upright`] looks one cell
/// sideways for a surface voxel, whose own test looks one cell farther.
const SLAB_MARGIN: i64 = 2;

/// A dense grid of `keys` over their key box, or `None` when it holds more than
/// [`MAX_LOCAL_GRID_CELLS`] cells.
fn slab_grid(keys: &[VoxelKey]) -> Option<DenseGrid> {
    if keys.is_empty() {
        return None;
    }
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for k in keys {
        for (i, v) in [k.x, k.y, k.z].into_iter().enumerate() {
            lo[i] = lo[i].min(v as i64);
            hi[i] = hi[i].max(v as i64);
        }
    }
    let cells = (0..3).try_fold(1u64, |n, i| {
        n.checked_mul(u64::try_from(hi[i] - lo[i] + 1).ok()?)
    })?;
    if cells > MAX_LOCAL_GRID_CELLS {
        return None;
    }
    let mut grid = DenseGrid::empty(lo, hi)?;
    for k in keys {
        grid.set(k.x as i64, k.y as i64, k.z as i64);
    }
    Some(grid)
}

/// The bit of a [`MapSurface`] voxel saying it lies on upright structure (above the
/// packed key's 63 bits).
const UPRIGHT_BIT: u64 = 1 << 63;

impl MapSurface {
    /// The surface voxels of `map` ([`MIN_SURFACE_NEIGHBOURS`] occupied neighbours), each
    /// marked when upright ([`is_upright`]).
    ///
    /// The map is taken in slabs of [`SURFACE_SLAB_CELLS`] along x, side by side, each
    /// with a dense grid of its voxels and the [`SLAB_MARGIN`] cells either side that the
    /// tests read (a whole map's box may be too large for one grid: a 200 x 200 x 10 m
    /// hall at 0.05 m spans 3.2 x 10^9 cells; its hash answers the same, many times
    /// slower). A slab's grid is capped as a count's own is ([`MAX_LOCAL_GRID_CELLS`],
    /// 128 MiB; one per thread at once; the hall's slabs hold 20 MiB); past it the slab
    /// answers from the map's hash.
    pub(crate) fn new(map: &OccupancyList) -> Self {
        let mut keys: Vec<VoxelKey> = map.iter().map(|(k, _)| k).collect();
        keys.par_sort_unstable_by_key(|k| (k.x, k.y, k.z));
        let (Some(first), Some(last)) = (keys.first(), keys.last()) else {
            return MapSurface {
                resolution: map.resolution(),
                voxels: Vec::new(),
            };
        };
        let (x0, x1) = (first.x as i64, last.x as i64);
        let slabs: Vec<i64> = (x0..=x1).step_by(SURFACE_SLAB_CELLS).collect();
        // The keys with x in [lo, hi].
        let between = |lo: i64, hi: i64| {
            let a = keys.partition_point(|k| (k.x as i64) < lo);
            let b = keys.partition_point(|k| (k.x as i64) <= hi);
            &keys[a..b]
        };
        let mut voxels: Vec<u64> = slabs
            .par_iter()
            .flat_map_iter(|&start| {
                let end = start + SURFACE_SLAB_CELLS as i64 - 1;
                let own = between(start, end);
                // (A slab in a gap of the map along x has nothing to test.)
                let grid = if own.is_empty() {
                    None
                } else {
                    slab_grid(between(start - SLAB_MARGIN, end + SLAB_MARGIN))
                };
                let occ = grid.as_ref().map_or(Occupied::Hash(map), Occupied::Dense);
                own.iter()
                    .filter(move |&&k| is_surface(occ, k))
                    .filter_map(move |&k| {
                        let up = if is_upright(occ, k) { UPRIGHT_BIT } else { 0 };
                        Some(pack_key(k)? | up)
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        voxels.par_sort_unstable_by_key(|v| v & !UPRIGHT_BIT);
        MapSurface {
            resolution: map.resolution(),
            voxels,
        }
    }

    /// Voxel edge, metres.
    pub(crate) fn resolution(&self) -> f64 {
        self.resolution
    }

    /// The map's side of [`consistency_seen`] with the scan placed by `pose`
    /// (`T_map_scan`): the surface voxels whose centres lie in `within` (map frame; all
    /// when `None`) against `seen`, the scan's view at this surface's resolution in its
    /// own frame, from its sensor at `origin` (scan frame); `None` when no surface voxel
    /// lies in `within`.
    pub(crate) fn count(
        &self,
        seen: &SearchTarget,
        origin: &Point3<f64>,
        pose: &Pose,
        within: Option<&crate::geometry::Aabb>,
    ) -> Option<SideAgreement> {
        let res = self.resolution;
        debug_assert_eq!(res, seen.resolution());
        let levels = seen.pyramid().levels();
        let to_scan = pose.inverse();
        let count_chunk = |chunk: &[u64]| {
            let mut side = SideAgreement::default();
            let mut through = Vec::new();
            let mut inside = false;
            for &v in chunk {
                let k = unpack_key(v & !UPRIGHT_BIT);
                let centre = k.center(res);
                if within.is_some_and(|b| !b.contains(&centre)) {
                    continue;
                }
                inside = true;
                let p = to_scan.transform_point(&centre);
                let Some(ks) = VoxelKey::from_point(&p, res) else {
                    continue;
                };
                let Some(near) = observed(seen, ks, (p - origin).norm(), res, levels) else {
                    continue;
                };
                let up = v & UPRIGHT_BIT != 0;
                if near {
                    side.supported += 1;
                    side.upright_supported += u64::from(up);
                } else {
                    through.push((k, up));
                }
            }
            ((side, through), inside)
        };
        let rows = self.rows_within(within);
        let parts: Vec<(Part, bool)> = rows
            .par_iter()
            .flat_map_iter(|row| row.chunks(COUNT_CHUNK))
            .map(count_chunk)
            .collect();
        // Nothing of the map where the scan could be: no side to count (as for an empty
        // crop of a target's points).
        let any = parts.iter().any(|(_, inside)| *inside);
        any.then(|| add_parts(parts.into_iter().map(|(part, _)| part).collect(), res))
    }

    /// The runs of [`MapSurface::voxels`] whose keys lie in the x-y key columns that
    /// `within` reaches (one run for each x; all voxels when `None`). The voxels are
    /// sorted by packed key, x then y then z, so the voxels of one x and a y range are
    /// consecutive.
    fn rows_within(&self, within: Option<&crate::geometry::Aabb>) -> Vec<&[u64]> {
        let Some(b) = within else {
            return vec![&self.voxels];
        };
        let res = self.resolution;
        let key = |v: f64| (v / res).floor().clamp(KEY_MIN as f64, KEY_MAX as f64) as i32;
        let (x0, x1) = (key(b.min.x), key(b.max.x));
        let (y0, y1) = (key(b.min.y), key(b.max.y));
        let packed = |x: i32, y: i32, z: i32| {
            pack_key(VoxelKey::new(x, y, z)).expect("a key within the packed range")
        };
        let at = |k: u64| self.voxels.partition_point(|v| v & !UPRIGHT_BIT < k);
        (x0..=x1)
            .filter_map(|x| {
                let lo = at(packed(x, y0, KEY_MIN));
                let hi = at(packed(x, y1, KEY_MAX) + 1);
                (lo < hi).then(|| &self.voxels[lo..hi])
            })
            .collect()
    }
}

/// The level [`count_side`] checks a voxel `d` metres from its sensor at: the one whose
/// cell covers [`ANGULAR_TOLERANCE`] at that range (of `levels`, at `res` metres finest).
fn level_at(d: f64, res: f64, levels: usize) -> usize {
    let tol = ANGULAR_TOLERANCE.tan();
    ((d * tol / res).max(1.0).log2().ceil() as usize).min(levels - 1)
}

/// How far from its sensor [`count_side`] checks voxels at `level` ([`level_at`]): up to
/// `2^level * res / tan(ANGULAR_TOLERANCE)` metres, everywhere at the coarsest level
/// (`None`).
fn checked_within(level: usize, res: f64, levels: usize) -> Option<f64> {
    (level + 1 < levels).then(|| (1u64 << level) as f64 * res / ANGULAR_TOLERANCE.tan())
}

/// Voxels per parallel work item of [`count_side`].
const COUNT_CHUNK: usize = 4096;

/// Contradicted voxels (of one side) with fewer contradicted neighbours than this are
/// stray returns and not counted ([`SideAgreement::contradicted`]).
pub const MIN_CONTRADICTED_NEIGHBOURS: usize = 2;

/// Whether `k` lies on upright structure: a surface voxel ([`is_surface`]) two layers
/// above or below it, within one cell sideways (a floor or ceiling one or two layers thick
/// has none). `list` holds all the scan's occupied voxels.
fn is_upright(list: Occupied<'_>, k: VoxelKey) -> bool {
    [-2, 2].iter().any(|&dz| {
        (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                let n = VoxelKey::new(k.x + dx, k.y + dy, k.z + dz);
                list.at(n) && is_surface(list, n)
            })
        })
    })
}

/// Whether a cell and its six face neighbours are all free: the free space eroded by one
/// cell. A ray grazing a floor marks the cells just above the floor free though the floor
/// is there (its returns too sparse to show every cell): a surface voxel in such a cell has
/// an unknown or occupied neighbour below and is not counted as seen through.
fn deep_free(g: &DenseGrid, k: VoxelKey) -> bool {
    let (x, y, z) = (k.x as i64, k.y as i64, k.z as i64);
    [
        (0, 0, 0),
        (1, 0, 0),
        (-1, 0, 0),
        (0, 1, 0),
        (0, -1, 0),
        (0, 0, 1),
        (0, 0, -1),
    ]
    .iter()
    .all(|(dx, dy, dz)| g.contains(x + dx, y + dy, z + dz))
}

/// How far a pose may be off in angle and still count as agreeing: a voxel at distance `d`
/// from its sensor is checked at the coarsest level whose cell is at most `d tan(this)`
/// (radians; 1°, the refinement's accuracy on the real pairs): a degree of pitch moves a
/// wall 20 m away by 0.35 m.
pub const ANGULAR_TOLERANCE: f64 = std::f64::consts::PI / 180.0;

/// The agreement of `source`, placed by `pose` (`T_target_source`), with a prepared
/// `target` (its finest level and free space), and of `target_points` (in the target frame;
/// `None` to skip that side) with the source's free space, at the target's finest
/// resolution.
///
/// ```
/// use nalgebra::Point3;
/// use olmap::align::{consistency, SearchTarget};
/// use olmap::cloud::PointCloud;
/// use olmap::geometry::Pose;
/// // A scan of a corner (floor and two walls) from above the floor, sensor at (1.5, 1.5, 1).
/// let mut points = Vec::new();
/// for i in 0..60 {
///     for j in 0..60 {
///         let (a, b) = (i as f32 * 0.05, j as f32 * 0.05);
///         points.extend([Point3::new(a, b, 0.0), Point3::new(a, 0.0, b), Point3::new(0.0, a, b)]);
///     }
/// }
/// let mut scan = PointCloud::from_points(points);
/// scan.set_origin(Point3::new(1.5, 1.5, 1.0));
/// let target = SearchTarget::from_cloud(&scan, 0.1, 1).unwrap();
/// let right = consistency(&scan, &target, Some(&scan), &Pose::identity()).unwrap();
/// assert!(right.agreement() > 0.99);
/// // Moved 0.8 m into the room, the walls stand in the space the target saw through.
/// let wrong = Pose::from_xyz_ypr(0.8, 0.8, 0.0, 0.0, 0.0, 0.0);
/// assert!(consistency(&scan, &target, Some(&scan), &wrong).unwrap().agreement() < 0.8);
/// ```
///
/// # Errors
/// Only for an invalid resolution (never for a target built by this crate).
pub fn consistency(
    source: &PointCloud,
    target: &SearchTarget,
    target_points: Option<&PointCloud>,
    pose: &Pose,
) -> Result<Consistency> {
    let seen = match target_points {
        Some(t) if !t.is_empty() && !source.is_empty() => Some(source_view(source, target)?),
        _ => None,
    };
    consistency_seen(source, seen.as_ref(), target, target_points, pose)
}

/// What the source saw, for the target side of [`consistency_seen`]: its surfaces and free
/// space at `target`'s finest resolution, in its own frame (the same for every pose, so a
/// caller checking several poses builds it once).
///
/// The counts check a level's free space only up to the range that level stands for (a
/// voxel 20 m out is checked at 0.4 m, one 3 m out at the finest level), so the view's rays
/// are traced at a level only that far (and a few cells more): every cell the counts read
/// is as [`SearchTarget::from_cloud`] makes it. Measured on the libpointmatcher car scan
/// (25,000 points, 8 levels at 0.1 m, one thread): 88 ms traced whole.
pub fn source_view(source: &PointCloud, target: &SearchTarget) -> Result<SearchTarget> {
    let (res, levels) = (target.resolution(), target.pyramid().levels());
    SearchTarget::from_cloud_read_within(source, res, levels, &|level| {
        checked_within(level, res, levels)
    })
}

/// [`consistency`] with the source's view prepared ([`source_view`]; `None` skips the
/// target side).
pub fn consistency_seen(
    source: &PointCloud,
    seen_from_source: Option<&SearchTarget>,
    target: &SearchTarget,
    target_points: Option<&PointCloud>,
    pose: &Pose,
) -> Result<Consistency> {
    let res = target.resolution();
    // The two sides are independent: counted side by side.
    let (source_side, target_side) = rayon::join(
        || source_side(source, target, pose),
        || -> Result<Option<SideAgreement>> {
            match (target_points, seen_from_source) {
                (Some(t), Some(seen)) if !t.is_empty() => {
                    let back = OccupancyList::occupied_by(t, &pose.inverse(), res)?;
                    Ok(Some(count_side(&back, &source.origin(), seen)))
                }
                _ => Ok(None),
            }
        },
    );
    let (source_side, target_side) = (source_side?, target_side?);
    Ok(Consistency {
        source: source_side,
        target: target_side,
        resolution: res,
    })
}

/// The source's side of a count: its voxels placed by `pose` in `target`'s frame, at
/// `target`'s finest resolution, against `target`.
fn source_side(source: &PointCloud, target: &SearchTarget, pose: &Pose) -> Result<SideAgreement> {
    let moved = OccupancyList::occupied_by(source, pose, target.resolution())?;
    Ok(count_side(
        &moved,
        &pose.transform_point(&source.origin()),
        target,
    ))
}

/// [`consistency_seen`] against a map whose surface was prepared once ([`MapSurface`], at
/// `target`'s finest resolution): the source's side as there, the map's side taken in the
/// map's own grid over the surface voxels within `within` (map frame; all when `None`).
/// `seen_from_source` `None` skips the map's side.
pub(crate) fn consistency_with_map(
    source: &PointCloud,
    seen_from_source: Option<&SearchTarget>,
    target: &SearchTarget,
    map: &MapSurface,
    pose: &Pose,
    within: Option<&crate::geometry::Aabb>,
) -> Result<Consistency> {
    let res = target.resolution();
    let (source_side, map_side) = rayon::join(
        || source_side(source, target, pose),
        || seen_from_source.and_then(|seen| map.count(seen, &source.origin(), pose, within)),
    );
    Ok(Consistency {
        source: source_side?,
        target: map_side,
        resolution: res,
    })
}

/// A cheap stand-in for the source side of [`consistency_seen`], for ranking many poses
/// before any is refined: the centres of the source's surface voxels (its own frame), each
/// moved by a pose and counted against the target's finest level alone — supported when an
/// occupied target voxel lies within one cell, contradicted when it lies deep in the
/// target's free space (no patch test, no range-dependent level), without the cost of
/// re-voxelising the scan at each pose.
pub(super) struct QuickFit {
    /// Surface voxel centres of the source, in the source frame.
    centres: Vec<Point3<f64>>,
}

impl QuickFit {
    /// The surface of `source` at `resolution`: at most `max_voxels` of its voxels, a
    /// regular subset in a fixed order (a ranking needs the shape, not every voxel).
    pub(super) fn new(source: &PointCloud, resolution: f64, max_voxels: usize) -> Result<Self> {
        let mut list = OccupancyList::new(resolution)?;
        list.add_points(source, &Pose::identity(), 1);
        let s = surface(&list);
        let mut centres: Vec<Point3<f64>> = s.iter().map(|(k, _)| s.center(k)).collect();
        // A fixed order: the subset, and the caller's centroid and extent, are then the
        // same bit for bit whatever the hash did.
        centres.sort_by(|a, b| {
            (a.x, a.y, a.z)
                .partial_cmp(&(b.x, b.y, b.z))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let stride = centres.len().div_ceil(max_voxels.max(1)).max(1);
        let centres = centres.into_iter().step_by(stride).collect();
        Ok(QuickFit { centres })
    }

    /// The surface voxel centres, in the source frame.
    pub(super) fn centres(&self) -> &[Point3<f64>] {
        &self.centres
    }

    /// The source's surface voxels placed by `pose` in `target` that are supported and
    /// contradicted there.
    pub(super) fn at(&self, target: &SearchTarget, pose: &Pose) -> (u64, u64) {
        let res = target.resolution();
        let occ = target
            .occupied_grid(0)
            .map_or(Occupied::Hash(target.pyramid().level(0)), Occupied::Dense);
        let free = target.free.first().and_then(Option::as_ref);
        let (mut supported, mut contradicted) = (0u64, 0u64);
        for c in &self.centres {
            let Some(k) = VoxelKey::from_point(&pose.transform_point(c), res) else {
                continue;
            };
            if occ.any_near(k) {
                supported += 1;
            } else if free.is_some_and(|g| deep_free(g, k)) {
                contradicted += 1;
            }
        }
        (supported, contradicted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The patches of contradicted voxels a person, a chair or a door make count as
    /// things that may have moved; a wall 3 m wide or a strip from floor to ceiling (2.6
    /// m) is structure. Patches are 26-connected: two people apart are two patches.
    #[test]
    fn a_person_sized_patch_may_have_moved_and_a_wall_has_not() {
        let block = |x0: i32, y0: i32, nx: i32, ny: i32, nz: i32| {
            let mut v = Vec::new();
            for x in x0..x0 + nx {
                for y in y0..y0 + ny {
                    for z in 0..nz {
                        v.push(VoxelKey::new(x, y, z));
                    }
                }
            }
            v
        };
        let res = 0.1;
        // A person's front at 0.1 m: 0.5 m across, 1.7 m tall; a door 0.9 x 2.1 m.
        assert!(movable(&block(0, 0, 5, 1, 17), res));
        assert!(movable(&block(0, 0, 9, 2, 21), res));
        // A wall 3 m wide, a floor-to-ceiling strip 0.4 x 0.7 x 2.6 m.
        assert!(!movable(&block(0, 0, 30, 1, 20), res));
        assert!(!movable(&block(0, 0, 4, 7, 26), res));
        let two_people: FxHashMap<VoxelKey, bool> = block(0, 0, 5, 1, 17)
            .into_iter()
            .chain(block(10, 0, 5, 1, 17))
            .map(|k| (k, true))
            .collect();
        let found = patches(&two_people);
        assert_eq!(found.len(), 2);
        assert!(found.iter().all(|p| p.len() == 85 && movable(p, res)));
        // Side by side they touch: one patch, 1.5 m across, no longer a thing that moves.
        let touching: FxHashMap<VoxelKey, bool> = block(0, 0, 5, 1, 17)
            .into_iter()
            .chain(block(5, 0, 10, 1, 17))
            .map(|k| (k, true))
            .collect();
        let found = patches(&touching);
        assert_eq!(found.len(), 1);
        assert!(!movable(&found[0], res));
    }

    /// A floor, a wall and scattered specks at 0.1 m, some keys negative.
    fn scene() -> OccupancyList {
        let mut points = Vec::new();
        for i in -30..30 {
            for j in -20..20 {
                points.push(Point3::new(i as f32 * 0.05, j as f32 * 0.05, 0.0));
                points.push(Point3::new(i as f32 * 0.05, 1.0, j as f32 * 0.05 + 1.0));
            }
        }
        let mut state = 12345u64;
        for _ in 0..300 {
            let mut next = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 33) as f32 / (1u64 << 31) as f32) * 6.0 - 3.0
            };
            points.push(Point3::new(next(), next(), next()));
        }
        let mut list = OccupancyList::new(0.1).unwrap();
        list.add_points(&PointCloud::from_points(points), &Pose::identity(), 1);
        list
    }

    /// The dense grid answers every lookup as the hash does (inside its box, on its edge and
    /// outside), so the surface and the upright test are the same either way.
    #[test]
    fn dense_lookups_answer_as_the_hash() {
        let list = scene();
        let grid = DenseGrid::occupied(&list, MAX_LOCAL_GRID_CELLS).expect("a small box");
        let (dense, hash) = (Occupied::Dense(&grid), Occupied::Hash(&list));
        let (lo, hi) = grid.bounds();
        let mut checked = 0;
        for x in lo[0] - 2..=hi[0] + 2 {
            for y in lo[1] - 2..=hi[1] + 2 {
                for z in lo[2] - 2..=hi[2] + 2 {
                    let k = VoxelKey::new(x as i32, y as i32, z as i32);
                    assert_eq!(dense.at(k), hash.at(k), "{k:?}");
                    assert_eq!(is_upright(dense, k), is_upright(hash, k), "{k:?}");
                    assert_eq!(dense.any_near(k), hash.any_near(k), "{k:?}");
                    assert_eq!(is_surface(dense, k), is_surface(hash, k), "{k:?}");
                    assert_eq!(
                        dense.neighbours(k, 26),
                        neighbourhood(k).filter(|n| *n != k && hash.at(*n)).count(),
                        "{k:?}"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 10_000);
        let (a, b) = (surface_with(&list, dense), surface_with(&list, hash));
        assert_eq!(a.sorted(), b.sorted());
        // The specks are not surface; the floor and the wall are.
        assert!(a.len() > 1000 && a.len() < list.len());
    }

    /// A list whose box is too large for the cap has no grid; the hash answers.
    #[test]
    fn a_box_past_the_cap_has_no_grid() {
        let list = scene();
        assert!(DenseGrid::occupied(&list, 1000).is_none());
        assert!(DenseGrid::occupied(&OccupancyList::new(0.1).unwrap(), 1 << 20).is_none());
    }

    /// A hall 50 x 36 m with walls 3 m high, its floor and walls every 0.2 m, and square
    /// pillars 0.6 m wide at `pillars`, seen from `origin`.
    fn hall(pillars: &[(f32, f32)], origin: Point3<f64>) -> PointCloud {
        let mut points = Vec::new();
        for i in 0..250 {
            for j in 0..180 {
                points.push(Point3::new(
                    i as f32 * 0.2 - 25.0,
                    j as f32 * 0.2 - 18.0,
                    0.0,
                ));
            }
        }
        for h in 0..15 {
            let z = h as f32 * 0.2;
            for i in 0..250 {
                let x = i as f32 * 0.2 - 25.0;
                points.extend([Point3::new(x, -18.0, z), Point3::new(x, 18.0, z)]);
            }
            for j in 0..180 {
                let y = j as f32 * 0.2 - 18.0;
                points.extend([Point3::new(-25.0, y, z), Point3::new(25.0, y, z)]);
            }
            for &(px, py) in pillars {
                for s in 0..4 {
                    let a = s as f32 * 0.2 - 0.3;
                    points.extend([
                        Point3::new(px + a, py - 0.3, z),
                        Point3::new(px + a, py + 0.3, z),
                        Point3::new(px - 0.3, py + a, z),
                        Point3::new(px + 0.3, py + a, z),
                    ]);
                }
            }
        }
        PointCloud::from_points(points).with_origin(origin)
    }

    /// The source's view traced only as far as each level is read gives the same counts
    /// as the view traced whole, for the right pose and wrong ones (contradictions
    /// included), while tracing less.
    #[test]
    fn a_view_traced_as_far_as_it_is_read_counts_as_one_traced_whole() {
        let pillars = [
            (3.0, 2.0),
            (-8.0, 5.0),
            (12.0, -6.0),
            (-15.0, -10.0),
            (20.0, 9.0),
        ];
        let target_cloud = hall(&pillars, Point3::new(0.0, 0.0, 1.5));
        // The source: some pillars gone, one new, seen from 1.3 m away.
        let source_cloud = hall(
            &[(3.0, 2.0), (12.0, -6.0), (-4.0, -3.0)],
            Point3::new(1.0, 0.8, 1.5),
        );
        // At 0.25 m the points 0.2 m apart make surfaces; level 0 is read up to 14.3 m.
        let levels = 4;
        let target = SearchTarget::from_cloud(&target_cloud, 0.25, levels).unwrap();
        let whole = SearchTarget::from_cloud(&source_cloud, 0.25, levels).unwrap();
        let read = source_view(&source_cloud, &target).unwrap();
        let bits = |t: &SearchTarget, level: usize| -> u32 {
            t.free[level]
                .as_ref()
                .map_or(0, |g| g.words().iter().map(|w| w.count_ones()).sum())
        };
        assert!(
            bits(&read, 0) < bits(&whole, 0) / 2,
            "the finest level is traced much less"
        );
        assert_eq!(
            bits(&read, levels - 1),
            bits(&whole, levels - 1),
            "the coarsest whole"
        );
        let mut contradicted = 0;
        for pose in [
            Pose::identity(),
            Pose::from_xyz_ypr(0.3, -0.2, 0.0, 0.02, 0.0, 0.0),
            Pose::from_xyz_ypr(2.0, 1.0, 0.1, 0.3, 0.01, -0.02),
            Pose::from_xyz_ypr(-6.0, 4.0, 0.0, -1.2, 0.0, 0.0),
            // Walls brought across the source's hall, near it and far.
            Pose::from_xyz_ypr(20.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, 15.0, 0.0, 0.1, 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, 28.0, 0.0, 0.0, 0.0, 0.0),
        ] {
            let a = consistency_seen(
                &source_cloud,
                Some(&whole),
                &target,
                Some(&target_cloud),
                &pose,
            )
            .unwrap();
            let b = consistency_seen(
                &source_cloud,
                Some(&read),
                &target,
                Some(&target_cloud),
                &pose,
            )
            .unwrap();
            let (a, b) = (a.target.unwrap(), b.target.unwrap());
            assert_eq!(a, b, "pose {pose:?}");
            contradicted += a.contradicted;
        }
        assert!(
            contradicted > 0,
            "the wrong poses must contradict somewhere"
        );
    }

    /// The count as first written, for [`count_side`] to answer as: the surface of the
    /// whole list first (its neighbours looked up one by one in the hash, not in blocks of
    /// a dense grid), then every surface voxel counted, observed or not, every lookup in a
    /// hash; also returns how many surface voxels there were and how many of them the
    /// other observed.
    fn count_every_surface_voxel(
        mine: &OccupancyList,
        origin: &Point3<f64>,
        other: &SearchTarget,
    ) -> (SideAgreement, usize, u64) {
        let (res, levels) = (other.resolution(), other.pyramid().levels());
        let surf = surface_with(mine, Occupied::Hash(mine));
        let own = Occupied::Hash(&surf);
        let mut side = SideAgreement::default();
        let mut through = std::collections::HashMap::new();
        let mut observed = 0;
        for (k, _) in surf.iter() {
            let level = level_at((surf.center(k) - origin).norm(), res, levels);
            let f = 1i32 << level;
            let kl = VoxelKey::new(k.x.div_euclid(f), k.y.div_euclid(f), k.z.div_euclid(f));
            let occ = Occupied::Hash(other.pyramid().level(level));
            // Upright: a surface voxel two layers above or below, one cell sideways.
            let up = [-2, 2].iter().any(|&dz| {
                (-1..=1).any(|dx| {
                    (-1..=1).any(|dy| own.at(VoxelKey::new(k.x + dx, k.y + dy, k.z + dz)))
                })
            });
            if neighbourhood(kl).any(|n| occ.at(n)) {
                side.supported += 1;
                side.upright_supported += u64::from(up);
                observed += 1;
            } else if other.free[level].as_ref().is_some_and(|g| deep_free(g, kl)) {
                through.insert(k, up);
                observed += 1;
            }
        }
        let mut contradicted = FxHashMap::default();
        for (k, up) in &through {
            let n = neighbourhood(*k)
                .filter(|n| n != k && through.contains_key(n))
                .count();
            if n >= MIN_CONTRADICTED_NEIGHBOURS {
                side.contradicted += 1;
                side.upright_contradicted += u64::from(*up);
                contradicted.insert(*k, *up);
            }
        }
        // Patches larger than a thing that moves (`patches` and `movable` are tested
        // on their own).
        for patch in patches(&contradicted) {
            if !movable(&patch, other.resolution()) {
                side.fixed_contradicted += patch.len() as u64;
                side.upright_fixed_contradicted +=
                    patch.iter().filter(|k| contradicted[*k]).count() as u64;
            }
        }
        (side, surf.len(), observed)
    }

    /// Testing only the voxels the other scan observed for being surface changes no count:
    /// both sides, the right pose and wrong ones, against every surface voxel counted,
    /// while many surface voxels were never observed.
    #[test]
    fn counting_only_observed_voxels_counts_as_every_surface_voxel() {
        // Specks 0.6 m above the floor, 1.2 m apart: occupied, and (but for the few next
        // to a pillar) not surface, two layers above floor voxels that are not upright.
        let specks = |cloud: PointCloud| {
            let origin = cloud.origin();
            let mut points = cloud.points().to_vec();
            for i in -20..20 {
                for j in -14..14 {
                    points.push(Point3::new(i as f32 * 1.2 + 0.1, j as f32 * 1.2 + 0.1, 0.6));
                }
            }
            PointCloud::from_points(points).with_origin(origin)
        };
        let target_cloud = specks(hall(
            &[(3.0, 2.0), (-8.0, 5.0), (12.0, -6.0)],
            Point3::new(0.0, 0.0, 1.5),
        ));
        let source_cloud = specks(hall(
            &[(3.0, 2.0), (-4.0, -3.0)],
            Point3::new(1.0, 0.8, 1.5),
        ));
        let (res, levels) = (0.25, 4);
        let target = SearchTarget::from_cloud(&target_cloud, res, levels).unwrap();
        let seen = source_view(&source_cloud, &target).unwrap();
        let (mut unobserved, mut contradicted) = (0u64, 0);
        for pose in [
            Pose::identity(),
            Pose::from_xyz_ypr(2.0, 1.0, 0.1, 0.3, 0.01, -0.02),
            Pose::from_xyz_ypr(20.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, 28.0, 0.0, 0.0, 0.0, 0.0),
        ] {
            let c = consistency_seen(
                &source_cloud,
                Some(&seen),
                &target,
                Some(&target_cloud),
                &pose,
            )
            .unwrap();
            let moved = OccupancyList::occupied_by(&source_cloud, &pose, res).unwrap();
            let origin = pose.transform_point(&source_cloud.origin());
            let (source, n, seen_n) = count_every_surface_voxel(&moved, &origin, &target);
            assert_eq!(c.source, source, "source side, pose {pose:?}");
            let back = OccupancyList::occupied_by(&target_cloud, &pose.inverse(), res).unwrap();
            let (other, m, seen_m) =
                count_every_surface_voxel(&back, &source_cloud.origin(), &seen);
            assert_eq!(c.target, Some(other), "target side, pose {pose:?}");
            unobserved += (n + m) as u64 - seen_n - seen_m;
            contradicted += source.contradicted + other.contradicted;
        }
        assert!(
            contradicted > 0,
            "the wrong poses must contradict somewhere"
        );
        assert!(unobserved > 0, "some surface voxels were never observed");
    }

    /// Every voxel's surface and upright flags by hash lookups over the whole map: what
    /// [`MapSurface::new`] must hold, slab by slab.
    fn surface_by_hash(map: &OccupancyList) -> Vec<u64> {
        let occ = Occupied::Hash(map);
        let mut v: Vec<u64> = map
            .iter()
            .filter(|(k, _)| is_surface(occ, *k))
            .map(|(k, _)| pack_key(k).unwrap() | if is_upright(occ, k) { UPRIGHT_BIT } else { 0 })
            .collect();
        v.sort_unstable_by_key(|v| v & !UPRIGHT_BIT);
        v
    }

    /// A map taken slab by slab holds the surface, and the upright marks, that the whole
    /// map's lookups give: at 0.1 m each hall spans 501 cells along x (four slabs, the
    /// pillars and walls across their edges), at 0.25 m 201 (two), and slabs between the
    /// two halls hold nothing.
    #[test]
    fn a_map_surface_made_in_slabs_is_the_surface_made_whole() {
        let sparse = hall(&[(3.0, 2.0), (-8.0, 5.0), (12.8, -6.0)], Point3::origin());
        // Filled in to 0.1 m (the hall's points are 0.2 m apart).
        let mut points = Vec::new();
        for p in sparse.points() {
            for d in 0..8 {
                let step = |bit: u32| if d >> bit & 1 == 1 { 0.1 } else { 0.0 };
                points.push(p + nalgebra::Vector3::new(step(0), step(1), step(2)));
            }
        }
        // Specks in the open, 1.2 m apart: occupied, not surface.
        for i in -20..20 {
            for j in -14..14 {
                points.push(Point3::new(
                    i as f32 * 1.2 + 0.05,
                    j as f32 * 1.2 + 0.05,
                    1.3,
                ));
            }
        }
        // A cloud of voxels in a box across slab edges (at 0.1 m the map's keys start at
        // x = -250, so slabs meet at x = 0.6 m; at 0.25 m at x = 7.0 m), one cell in six
        // filled: many voxels there have about as many neighbours as a surface needs, so
        // a neighbour of a neighbour across the edge decides.
        let mut state = 99u64;
        for x in -20..100 {
            for y in -20..20 {
                for z in 5..15 {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    if state >> 61 == 0 {
                        let c = |v: i32| v as f32 * 0.1 + 0.05;
                        points.push(Point3::new(c(x), c(y), c(z)));
                    }
                }
            }
        }
        // A second hall 80 m along x: a gap of 30 m (300 cells at 0.1 m, slabs with no
        // voxel at all).
        let far: Vec<Point3<f32>> = points
            .iter()
            .map(|p| p + nalgebra::Vector3::new(80.0, 0.0, 0.0))
            .collect();
        points.extend(far);
        let cloud = PointCloud::from_points(points);
        for res in [0.1, 0.25] {
            let mut map = OccupancyList::new(res).unwrap();
            map.add_points(&cloud, &Pose::identity(), 1);
            let made = MapSurface::new(&map);
            let expected = surface_by_hash(&map);
            assert!(expected.iter().any(|v| v & UPRIGHT_BIT != 0));
            assert!(expected.len() < map.len(), "some voxels are not surface");
            assert_eq!(made.voxels, expected, "resolution {res}");
        }
    }

    /// A map's side counted in its own grid is the count of its voxels moved into the
    /// source's frame whenever the move keeps the grid (the identity, and shifts by whole
    /// cells: the same voxels, the same surface), for right and wrong poses; and a count
    /// within a box is the count of the surface voxels whose centres lie in it.
    #[test]
    fn a_map_counted_in_its_own_grid_counts_as_its_voxels_moved_by_whole_cells() {
        let target_cloud = hall(&[(3.0, 2.0), (-8.0, 5.0), (12.0, -6.0)], Point3::origin());
        let source_cloud = hall(&[(3.0, 2.0), (-4.0, -3.0)], Point3::new(1.0, 0.5, 1.5));
        let (res, levels) = (0.25, 4);
        let mut map = OccupancyList::new(res).unwrap();
        map.add_points(&target_cloud, &Pose::identity(), 1);
        let target = SearchTarget::from_map(map.clone(), levels).unwrap();
        let surface = MapSurface::new(&map);
        let seen = source_view(&source_cloud, &target).unwrap();
        let points = map.to_cloud();
        let mut contradicted = 0;
        for pose in [
            Pose::identity(),
            Pose::from_xyz_ypr(2.0, 1.0, 0.0, 0.0, 0.0, 0.0),
            Pose::from_xyz_ypr(-6.5, 4.25, 0.0, 0.0, 0.0, 0.0),
            Pose::from_xyz_ypr(0.0, 28.0, 0.5, 0.0, 0.0, 0.0),
        ] {
            let by_points =
                consistency_seen(&source_cloud, Some(&seen), &target, Some(&points), &pose)
                    .unwrap();
            let in_grid =
                consistency_with_map(&source_cloud, Some(&seen), &target, &surface, &pose, None)
                    .unwrap();
            assert_eq!(in_grid, by_points, "pose {pose:?}");
            contradicted += in_grid.target.unwrap().contradicted;
            // Within a box: the rows it reaches, each voxel's centre tested.
            let b = crate::geometry::Aabb::new(
                Point3::new(-10.3, -4.1, -1.0),
                Point3::new(7.6, 12.2, 1.1),
            );
            let inside = MapSurface {
                resolution: res,
                voxels: surface
                    .voxels
                    .iter()
                    .copied()
                    .filter(|v| b.contains(&map.center(unpack_key(v & !UPRIGHT_BIT))))
                    .collect(),
            };
            assert!(inside.voxels.len() < surface.voxels.len() / 2);
            assert_eq!(
                surface.count(&seen, &source_cloud.origin(), &pose, Some(&b)),
                inside.count(&seen, &source_cloud.origin(), &pose, None),
                "pose {pose:?}"
            );
        }
        assert!(
            contradicted > 0,
            "the wrong poses must contradict somewhere"
        );
        // No surface voxel in the box: no map side (as for an empty crop of points).
        let away = crate::geometry::Aabb::new(
            Point3::new(100.0, 100.0, 0.0),
            Point3::new(110.0, 110.0, 1.0),
        );
        let pose = Pose::identity();
        assert_eq!(
            surface.count(&seen, &source_cloud.origin(), &pose, Some(&away)),
            None
        );
    }
}
