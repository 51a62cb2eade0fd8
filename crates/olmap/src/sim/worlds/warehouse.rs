//! A warehouse of 200 x 200 m: the large world of issue 27 (map building at scale, and
//! global localisation in a map of more than 10^7 voxels). Its repetition is the hard part:
//! every aisle is two walls of identical racks, and only what stands on the shelves tells
//! one bay from another.

use nalgebra::{Point3, Vector3};

use super::{aabb, block, Objects};
use crate::sim::rng::SimRng;
use crate::sim::world::{room_shell, World};

/// Inside size of the hall (x, y, height), metres.
const WAREHOUSE_SIZE: (f64, f64, f64) = (200.0, 200.0, 10.0);
/// Depth of a double (back-to-back) rack row, metres.
const ROW_DEPTH: f64 = 2.2;
/// Width of an aisle between two rows, metres.
const AISLE: f64 = 3.6;
/// Where the first row starts (y), metres; the rows end before `WAREHOUSE_SIZE.1 - 10`.
const FIRST_ROW: f64 = 12.0;
/// The rows' runs along x, with 4 m cross-aisles between them, metres.
const RUNS: [(f64, f64); 4] = [(10.0, 52.0), (56.0, 98.0), (102.0, 144.0), (148.0, 190.0)];
/// Length of a bay (between two uprights), metres.
const BAY: f64 = 2.8;
/// Rack height, metres, and the heights of its beam levels.
const RACK_HEIGHT: f64 = 6.0;
const LEVELS: [f64; 3] = [0.15, 2.1, 4.1];

/// The warehouse for `seed`: a 200 x 200 x 10 m hall with columns on a 20 m grid along its
/// walls, 31 double rack rows (2.2 m deep, 6 m high, 3.6 m aisles) in four runs separated
/// by cross-aisles, uprights every 2.8 m, beams at three levels, and on every shelf of
/// every bay face a random load (none, or one to three boxes of random size, place and
/// turn) drawn from the seed. The route is a serpentine through the aisles, east along the
/// first, west along the next, …, and back south along the open west side: a closed
/// route of about 6.3 km, so a robot's stops cover as many aisles as its steps reach.
pub fn warehouse(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (sx, sy, sz) = WAREHOUSE_SIZE;
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(sx, sy, sz),
        0.3,
        true,
    ));
    // Columns along the outer walls, every 20 m.
    for k in 1..10 {
        let s = 20.0 * k as f64;
        o.structure([
            block(s, 0.3, 0.0, 0.6, 0.6, sz, 0.0),
            block(s, sy - 0.3, 0.0, 0.6, 0.6, sz, 0.0),
            block(0.3, s, 0.0, 0.6, 0.6, sz, 0.0),
            block(sx - 0.3, s, 0.0, 0.6, 0.6, sz, 0.0),
        ]);
    }
    let rows = row_count();
    for r in 0..rows {
        let y0 = FIRST_ROW + r as f64 * (ROW_DEPTH + AISLE);
        let y1 = y0 + ROW_DEPTH;
        for &(x0, x1) in &RUNS {
            rack_run(&mut rng, &mut o, x0, x1, y0, y1);
        }
    }
    World::new("warehouse", o.0).with_route(route(rows))
}

/// How many rows fit between `FIRST_ROW` and 10 m before the north wall.
fn row_count() -> usize {
    let span = WAREHOUSE_SIZE.1 - 10.0 - FIRST_ROW;
    ((span + AISLE) / (ROW_DEPTH + AISLE)).floor() as usize
}

/// One run of a double rack row over `[x0, x1] x [y0, y1]`: uprights, beams and loads.
fn rack_run(rng: &mut SimRng, o: &mut Objects, x0: f64, x1: f64, y0: f64, y1: f64) {
    let bays = ((x1 - x0) / BAY).floor() as usize;
    let post = 0.1;
    // Uprights at both faces and the spine between the two halves.
    for b in 0..=bays {
        let x = x0 + b as f64 * BAY;
        o.structure([
            aabb(x, y0, 0.0, x + post, y0 + post, RACK_HEIGHT),
            aabb(x, y1 - post, 0.0, x + post, y1, RACK_HEIGHT),
        ]);
    }
    let x_end = x0 + bays as f64 * BAY + post;
    o.structure([aabb(
        x0,
        0.5 * (y0 + y1) - 0.05,
        0.0,
        x_end,
        0.5 * (y0 + y1) + 0.05,
        RACK_HEIGHT,
    )]);
    for &z in &LEVELS {
        o.structure([
            aabb(x0, y0, z, x_end, y0 + post, z + 0.12),
            aabb(x0, y1 - post, z, x_end, y1, z + 0.12),
        ]);
    }
    // Loads: per bay, face and level, none or 1-3 boxes.
    let half = 0.5 * ROW_DEPTH - 0.15;
    for b in 0..bays {
        let bx = x0 + b as f64 * BAY + post;
        for (face_y, inward) in [(y0 + 0.1, 1.0), (y1 - 0.1, -1.0)] {
            for (l, &z) in LEVELS.iter().enumerate() {
                let room = if l + 1 < LEVELS.len() {
                    LEVELS[l + 1] - z - 0.25
                } else {
                    RACK_HEIGHT - z - 0.3
                };
                let count = match rng.index(10) {
                    0..=2 => 0,
                    3..=6 => 1,
                    7..=8 => 2,
                    _ => 3,
                };
                let mut s = rng.range(0.05, 0.4);
                for _ in 0..count {
                    let w = rng.range(0.5, 1.3);
                    if s + w > BAY - post - 0.05 {
                        break;
                    }
                    let d = rng.range(0.5, half);
                    let h = rng.range(0.3, room.min(1.7));
                    let set_back = rng.range(0.0, half - d);
                    let cy = face_y + inward * (set_back + 0.5 * d);
                    let turn = rng.range(-0.15, 0.15);
                    o.furniture([block(bx + s + 0.5 * w, cy, z + 0.12, w, d, h, turn)]);
                    s += w + rng.range(0.05, 0.5);
                }
            }
        }
    }
}

/// The serpentine route through the aisles (see [`warehouse`]).
fn route(rows: usize) -> Vec<(f64, f64)> {
    let (east, west) = (WAREHOUSE_SIZE.0 - 5.0, 5.0);
    // The aisle before the first row, then one after each row.
    let aisle_y = |k: usize| FIRST_ROW - 0.5 * AISLE + k as f64 * (ROW_DEPTH + AISLE);
    let mut corners = Vec::with_capacity(2 * rows + 3);
    for k in 0..=rows {
        let y = aisle_y(k);
        if k.is_multiple_of(2) {
            corners.push((west, y));
            corners.push((east, y));
        } else {
            corners.push((east, y));
            corners.push((west, y));
        }
    }
    // Back south along the west side (from the east end if the last pass went east).
    if rows.is_multiple_of(2) {
        corners.push((east, WAREHOUSE_SIZE.1 - 4.0));
        corners.push((2.5, WAREHOUSE_SIZE.1 - 4.0));
    }
    corners.push((2.5, aisle_y(0)));
    corners
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_warehouse_is_large_and_its_route_runs_in_free_aisles() {
        let world = warehouse(3);
        let b = world.bounds().expect("objects");
        assert!(b.max.x - b.min.x >= 200.0 && b.max.y - b.min.y >= 200.0);
        assert!(row_count() >= 30, "{} rows", row_count());
        // Every route corner and the middle of every leg is clear for a robot.
        let route = world.route().to_vec();
        let n = route.len();
        let mut length = 0.0;
        for i in 0..n {
            let (a, b) = (route[i], route[(i + 1) % n]);
            length += (b.0 - a.0).hypot(b.1 - a.1);
            for t in [0.0, 0.25, 0.5, 0.75] {
                let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
                assert!(
                    world.is_clear(x, y, 0.5, 0.05, 1.0),
                    "({x:.1}, {y:.1}) blocked"
                );
            }
        }
        assert!(length > 5_000.0, "route {length:.0} m");
        // A rack upright stands where the geometry says.
        assert!(!world.is_clear(10.05, FIRST_ROW + 0.05, 0.01, 0.05, 1.0));
    }
}
