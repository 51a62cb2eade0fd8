//! A map's ICP points indexed in column tiles: one k-d tree per square of the x-y plane
//! ([`TILE_METRES`] a side, all heights), so that a map that grows a scan at a time indexes
//! again only the tiles the scan changed, not the whole map.
//!
//! A query starts in the tile under the query point and walks out ring by ring while a ring
//! could still hold a point nearer than the worst one kept (or within the asked radius):
//! the answer is the same set of nearest points as one tree over every point gives, up to
//! which of two exactly equidistant points is taken. A query near a tile's edge asks the
//! neighbouring tile as well only when its nearest candidates are farther than that edge,
//! which during ICP (correspondence gates of 0.5 m and less, 4 m tiles) is a small fraction
//! of the queries.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use rayon::prelude::*;
use rustc_hash::{FxHashMap, FxHashSet};

use crate::error::{Error, Result};

/// Side of a tile (metres). A warehouse lidar scan added to its map touches 8-33 % of the
/// map's 4 m tiles (twenty-ninth session's measurement over 250 mapped scans), the share of
/// the index built again per placement; larger tiles re-index more, smaller ones send more
/// queries across edges.
pub(super) const TILE_METRES: f64 = 4.0;

/// Slack on distances to a tile's box (metres), against rounding in assigning a point to its
/// tile: a tile is asked whenever it could hold a point up to this much outside its box.
const SLACK: f64 = 1e-6;

/// A point found near a query: its index in the target and its squared distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Near {
    pub(super) item: u32,
    pub(super) distance: f64,
}

/// A tile's position: the floor of x and y over [`TILE_METRES`].
pub(super) type TileKey = (i64, i64);

/// The tile holding `p`.
pub(super) fn tile_of(p: &Point3<f64>) -> TileKey {
    (
        (p.x / TILE_METRES).floor() as i64,
        (p.y / TILE_METRES).floor() as i64,
    )
}

/// The horizontal gap between the columns of tiles `a` and `b` (zero for a tile and its
/// neighbours), less the slack.
pub(super) fn tile_gap(a: TileKey, b: TileKey) -> f64 {
    let gap = |i: i64, j: i64| ((i - j).abs() - 1).max(0) as f64 * TILE_METRES;
    (gap(a.0, b.0).hypot(gap(a.1, b.1)) - SLACK).max(0.0)
}

/// The squared horizontal distance from `q` to the column of tile `key`, less the slack on
/// each axis.
fn box_distance2(q: &Point3<f64>, key: TileKey) -> f64 {
    let axis = |v: f64, k: i64| {
        let lo = k as f64 * TILE_METRES;
        ((lo - v).max(v - (lo + TILE_METRES)) - SLACK).max(0.0)
    };
    let (dx, dy) = (axis(q.x, key.0), axis(q.y, key.1));
    dx * dx + dy * dy
}

/// The `n` points of `tree` nearest `q` (items: the tree's own indices), only those within
/// `max_distance2` (squared metres) when given.
pub(super) fn tree_nearest(
    tree: &ImmutableKdTree<f64, 3>,
    q: &Point3<f64>,
    n: NonZeroUsize,
    max_distance2: Option<f64>,
) -> Vec<Near> {
    let at = [q.x, q.y, q.z];
    let query = tree.query(&at).nearest_n::<SquaredEuclidean<f64>>(n);
    let found = match max_distance2 {
        Some(m) => query.within(m).execute(),
        None => query.execute(),
    };
    found
        .iter()
        .map(|f| Near {
            item: f.item,
            distance: f.distance,
        })
        .collect()
}

/// One tile: the target points in it and their tree (`None` when it has none left).
struct Tile {
    key: TileKey,
    members: Vec<u32>,
    tree: Option<ImmutableKdTree<f64, 3>>,
}

/// The tiles of a target.
pub(super) struct Tiles {
    lookup: FxHashMap<TileKey, u32>,
    tiles: Vec<Tile>,
    /// The least and the greatest tile key on each axis (no tile lies outside).
    lo: TileKey,
    hi: TileKey,
}

impl Tiles {
    /// Every point of `points` indexed in its tile (trees built in parallel, each the same
    /// whatever the thread count).
    pub(super) fn new(points: &[Point3<f64>]) -> Result<Self> {
        let mut tiles = Tiles {
            lookup: FxHashMap::default(),
            tiles: Vec::new(),
            lo: (i64::MAX, i64::MAX),
            hi: (i64::MIN, i64::MIN),
        };
        for (i, p) in points.iter().enumerate() {
            let t = tiles.tile_for(tile_of(p));
            tiles.tiles[t].members.push(i as u32);
        }
        let all: Vec<usize> = (0..tiles.tiles.len()).collect();
        tiles.reindex(&all, points)?;
        Ok(tiles)
    }

    /// The index of tile `key`, made (empty) when there is none.
    fn tile_for(&mut self, key: TileKey) -> usize {
        if let Some(&t) = self.lookup.get(&key) {
            return t as usize;
        }
        self.lo = (self.lo.0.min(key.0), self.lo.1.min(key.1));
        self.hi = (self.hi.0.max(key.0), self.hi.1.max(key.1));
        self.tiles.push(Tile {
            key,
            members: Vec::new(),
            tree: None,
        });
        self.lookup.insert(key, (self.tiles.len() - 1) as u32);
        self.tiles.len() - 1
    }

    /// Follows a change of the target: `points` are its points now, those from `old_len`
    /// on are new, and each of `moved` is a point (index, where it was) that moved. Builds
    /// again the trees of the tiles that gained, lost or moved a point, and returns those
    /// tiles' keys.
    pub(super) fn update(
        &mut self,
        points: &[Point3<f64>],
        old_len: usize,
        moved: &[(u32, Point3<f64>)],
    ) -> Result<Vec<TileKey>> {
        let mut dirty = FxHashSet::default();
        for &(i, was) in moved {
            let (from, to) = (tile_of(&was), tile_of(&points[i as usize]));
            let f = self.tile_for(from);
            dirty.insert(f);
            if from != to {
                let members = &mut self.tiles[f].members;
                if let Some(at) = members.iter().position(|&m| m == i) {
                    members.remove(at);
                }
                let t = self.tile_for(to);
                self.tiles[t].members.push(i);
                dirty.insert(t);
            }
        }
        for (i, p) in points.iter().enumerate().skip(old_len) {
            let t = self.tile_for(tile_of(p));
            self.tiles[t].members.push(i as u32);
            dirty.insert(t);
        }
        let mut dirty: Vec<usize> = dirty.into_iter().collect();
        dirty.sort_unstable();
        self.reindex(&dirty, points)?;
        Ok(dirty.iter().map(|&t| self.tiles[t].key).collect())
    }

    /// Builds the trees of tiles `which` from their members (on the rayon pool).
    fn reindex(&mut self, which: &[usize], points: &[Point3<f64>]) -> Result<()> {
        let built: Vec<Result<Option<ImmutableKdTree<f64, 3>>>> = which
            .par_iter()
            .map(|&t| {
                let members = &self.tiles[t].members;
                if members.is_empty() {
                    return Ok(None);
                }
                let coords: Vec<[f64; 3]> = members
                    .iter()
                    .map(|&i| {
                        let p = points[i as usize];
                        [p.x, p.y, p.z]
                    })
                    .collect();
                ImmutableKdTree::<f64, 3>::new_from_slice(&coords)
                    .map(Some)
                    .map_err(|e| {
                        Error::InvalidArgument(format!("ICP: cannot index the target points: {e}"))
                    })
            })
            .collect();
        for (&t, tree) in which.iter().zip(built) {
            self.tiles[t].tree = tree?;
        }
        Ok(())
    }

    /// Each tile's key and the indices of its points.
    pub(super) fn each(&self) -> impl Iterator<Item = (TileKey, &[u32])> {
        self.tiles.iter().map(|t| (t.key, t.members.as_slice()))
    }

    /// The `n` points nearest `q` (nearest first; ties by index), only those within
    /// `max_distance2` (squared metres) when given.
    pub(super) fn nearest(
        &self,
        q: &Point3<f64>,
        n: NonZeroUsize,
        max_distance2: Option<f64>,
    ) -> Vec<Near> {
        let mut best: Vec<Near> = Vec::with_capacity(2 * n.get());
        let bound = |best: &[Near]| {
            let worst = if best.len() >= n.get() {
                best[n.get() - 1].distance
            } else {
                f64::INFINITY
            };
            max_distance2.map_or(worst, |m| m.min(worst))
        };
        let ask = |key: TileKey, best: &mut Vec<Near>| {
            let b = bound(best);
            if box_distance2(q, key) > b {
                return;
            }
            let Some(&t) = self.lookup.get(&key) else {
                return;
            };
            let tile = &self.tiles[t as usize];
            let Some(tree) = &tile.tree else {
                return;
            };
            let found = tree_nearest(tree, q, n, b.is_finite().then_some(b));
            if found.is_empty() {
                return;
            }
            best.extend(found.into_iter().map(|f| Near {
                item: tile.members[f.item as usize],
                ..f
            }));
            best.sort_unstable_by(|a, b| {
                a.distance.total_cmp(&b.distance).then(a.item.cmp(&b.item))
            });
            best.truncate(n.get());
        };
        let home = tile_of(q);
        ask(home, &mut best);
        // How far `q` is from its own tile's edges: ring r's tiles are at least this plus
        // r - 1 tiles away.
        let (fx, fy) = (
            q.x - home.0 as f64 * TILE_METRES,
            q.y - home.1 as f64 * TILE_METRES,
        );
        let edge = fx
            .min(TILE_METRES - fx)
            .min(fy)
            .min(TILE_METRES - fy)
            .max(0.0);
        let span = (home.0 - self.lo.0)
            .max(self.hi.0 - home.0)
            .max(home.1 - self.lo.1)
            .max(self.hi.1 - home.1);
        for r in 1..=span.max(0) {
            let gap = edge + (r - 1) as f64 * TILE_METRES - SLACK;
            if gap > 0.0 && gap * gap > bound(&best) {
                break;
            }
            if 8 * r as u128 >= self.tiles.len() as u128 {
                // Fewer tiles than the ring has places: ask every tile from this ring out.
                for tile in &self.tiles {
                    let ring = (tile.key.0 - home.0).abs().max((tile.key.1 - home.1).abs());
                    if ring >= r {
                        ask(tile.key, &mut best);
                    }
                }
                break;
            }
            for i in -r..=r {
                ask((home.0 + i, home.1 - r), &mut best);
                ask((home.0 + i, home.1 + r), &mut best);
            }
            for j in (1 - r)..r {
                ask((home.0 - r, home.1 + j), &mut best);
                ask((home.0 + r, home.1 + j), &mut best);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::SimRng;

    /// Every nearest point over one tree of all the points, by brute force: the reference.
    fn brute(points: &[Point3<f64>], q: &Point3<f64>, n: usize, max2: Option<f64>) -> Vec<f64> {
        let mut d: Vec<f64> = points
            .iter()
            .map(|p| (p - q).norm_squared())
            .filter(|&d| max2.is_none_or(|m| d <= m))
            .collect();
        d.sort_by(f64::total_cmp);
        d.truncate(n);
        d
    }

    /// Points spread over 30 x 30 m (tiles of every size of population, a sparse corner).
    fn scattered(rng: &mut SimRng, n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|i| {
                let spread = if i % 50 == 0 { 30.0 } else { 12.0 };
                Point3::new(
                    rng.range(-spread, spread),
                    rng.range(-spread, spread),
                    rng.range(0.0, 3.0),
                )
            })
            .collect()
    }

    /// The tiles answer every query with the distances of the nearest points over all
    /// points: within a gate (ICP's correspondences) and unbounded (normals' `k` nearest),
    /// near tile edges and far from every point; and again after points moved (some across
    /// a tile edge) and were added.
    #[test]
    fn tiles_answer_as_one_tree_over_all_points_before_and_after_a_change() {
        let mut rng = SimRng::new(3);
        let mut points = scattered(&mut rng, 20_000);
        let mut tiles = Tiles::new(&points).unwrap();
        let check = |tiles: &Tiles, points: &[Point3<f64>], rng: &mut SimRng| {
            for _ in 0..1_500 {
                let q = Point3::new(
                    rng.range(-35.0, 35.0),
                    rng.range(-35.0, 35.0),
                    rng.range(-1.0, 4.0),
                );
                for (n, max2) in [(4, Some(0.25)), (4, Some(1.0)), (10, None), (1, None)] {
                    let got = tiles.nearest(&q, NonZeroUsize::new(n).unwrap(), max2);
                    let d: Vec<f64> = got.iter().map(|f| f.distance).collect();
                    assert_eq!(d, brute(points, &q, n, max2), "{q:?} n {n} {max2:?}");
                    for f in &got {
                        assert_eq!(f.distance, (points[f.item as usize] - q).norm_squared());
                    }
                }
            }
        };
        check(&tiles, &points, &mut rng);
        let old_len = points.len();
        let mut moved = Vec::new();
        for i in (0..old_len).step_by(37) {
            let was = points[i];
            // Some by a few centimetres, some across a tile edge.
            let by = if i % 2 == 0 { 0.03 } else { 3.0 };
            points[i] = was + nalgebra::Vector3::new(by, -by, 0.0);
            moved.push((i as u32, was));
        }
        points.extend(scattered(&mut rng, 3_000));
        let dirty = tiles.update(&points, old_len, &moved).unwrap();
        assert!(!dirty.is_empty());
        check(&tiles, &points, &mut rng);
        // Every point sits in its own tile once.
        let mut seen = vec![0; points.len()];
        for (key, members) in tiles.each() {
            for &m in members {
                assert_eq!(tile_of(&points[m as usize]), key);
                seen[m as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }

    /// Gaps between tiles: zero for neighbours, whole tiles between the others.
    #[test]
    fn tile_gaps_count_the_tiles_between() {
        assert_eq!(tile_gap((0, 0), (1, 1)), 0.0);
        assert!((tile_gap((0, 0), (3, 0)) - 2.0 * TILE_METRES).abs() < 1e-5);
        assert!((tile_gap((0, 0), (-2, 2)) - TILE_METRES * 2f64.sqrt()).abs() < 1e-5);
    }
}
