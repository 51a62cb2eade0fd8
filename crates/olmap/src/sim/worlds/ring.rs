//! A corridor ring: a loop long enough that odometry and scan-to-map registration drift
//! measurably before the robot sees its start again (issue 23's ≥ 60 m loop). The world
//! carries its route — the corridor's centre line — so the simulator drives robots round
//! it instead of on a random walk.

use nalgebra::{Point3, Vector3};

use super::{aabb, bin, block, Objects};
use crate::sim::rng::SimRng;
use crate::sim::world::{room_shell, World};

/// Outer size of the ring (inside the outer walls), metres.
const OUTER: (f64, f64) = (26.0, 16.0);
/// Width of the corridor, metres.
const WIDTH: f64 = 3.0;
/// Ceiling height, metres.
const HEIGHT: f64 = 2.8;
/// Spacing of the things along a wall, metres (drawn uniformly in this range).
const SPACING: (f64, f64) = (1.5, 3.5);

/// A closed corridor 3 m wide and 2.8 m high round a solid 20 x 10 m core (outer walls
/// 26 x 16 m inside; inner corner at the origin): the centre line is a 23 x 13 m
/// rectangle, a 72 m loop. Both walls carry things at irregular places drawn from the
/// seed — door frames, wall columns, shelves, cabinets, boxes and bins 1.5-3.5 m apart, and
/// lamps under the ceiling — so every
/// stretch within a scanner's 8 m fixes the position along the corridor, and no two
/// stretches look alike. The route runs anticlockwise along the centre line from the
/// middle of the south corridor.
pub fn corridor_ring(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (len, depth) = OUTER;
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(len, depth, HEIGHT),
        0.2,
        true,
    ));
    // The core: a solid block leaving a WIDTH-wide corridor all round.
    o.structure([aabb(WIDTH, WIDTH, 0.0, len - WIDTH, depth - WIDTH, HEIGHT)]);

    // Walk each wall (outer walls facing in, core walls facing out) and stand things
    // against it. `along` runs over the wall's length, `normal` points into the corridor.
    struct Wall {
        start: (f64, f64),
        dir: (f64, f64),
        normal: (f64, f64),
        length: f64,
    }
    let walls = [
        // Outer walls.
        Wall {
            start: (0.0, 0.0),
            dir: (1.0, 0.0),
            normal: (0.0, 1.0),
            length: len,
        },
        Wall {
            start: (len, 0.0),
            dir: (0.0, 1.0),
            normal: (-1.0, 0.0),
            length: depth,
        },
        Wall {
            start: (len, depth),
            dir: (-1.0, 0.0),
            normal: (0.0, -1.0),
            length: len,
        },
        Wall {
            start: (0.0, depth),
            dir: (0.0, -1.0),
            normal: (1.0, 0.0),
            length: depth,
        },
        // Core walls.
        Wall {
            start: (WIDTH, WIDTH),
            dir: (1.0, 0.0),
            normal: (0.0, -1.0),
            length: len - 2.0 * WIDTH,
        },
        Wall {
            start: (len - WIDTH, WIDTH),
            dir: (0.0, 1.0),
            normal: (1.0, 0.0),
            length: depth - 2.0 * WIDTH,
        },
        Wall {
            start: (len - WIDTH, depth - WIDTH),
            dir: (-1.0, 0.0),
            normal: (0.0, 1.0),
            length: len - 2.0 * WIDTH,
        },
        Wall {
            start: (WIDTH, depth - WIDTH),
            dir: (0.0, -1.0),
            normal: (-1.0, 0.0),
            length: depth - 2.0 * WIDTH,
        },
    ];
    for wall in &walls {
        let yaw = wall.dir.1.atan2(wall.dir.0);
        // The world point `along` metres along the wall and `out` metres into the corridor.
        let at = |along: f64, out: f64| {
            (
                wall.start.0 + wall.dir.0 * along + wall.normal.0 * out,
                wall.start.1 + wall.dir.1 * along + wall.normal.1 * out,
            )
        };
        let mut s = rng.range(0.3, SPACING.1);
        while s < wall.length - 0.6 {
            // Depth into the corridor stays ≤ 0.6 m: a 1.8 m lane stays clear.
            let (w, d) = (rng.range(0.3, 1.4), rng.range(0.2, 0.6));
            if s + w > wall.length - 0.3 {
                break;
            }
            let (cx, cy) = at(s + 0.5 * w, 0.5 * d);
            match rng.index(6) {
                // A door: two jambs and a lintel standing 0.12 m out of the wall.
                0 => {
                    let door = rng.range(0.8, 1.0);
                    let (jamb, out, top) = (0.08, 0.12, 2.1);
                    let (ax, ay) = at(s + 0.5 * jamb, 0.5 * out);
                    let (bx, by) = at(s + 1.5 * jamb + door, 0.5 * out);
                    let (lx, ly) = at(s + jamb + 0.5 * door, 0.5 * out);
                    o.structure([
                        block(ax, ay, 0.0, jamb, out, top, yaw),
                        block(bx, by, 0.0, jamb, out, top, yaw),
                        block(lx, ly, top - 0.1, door + 2.0 * jamb, out, 0.1, yaw),
                    ]);
                    s += door + 2.0 * jamb;
                }
                // A wall column, floor to ceiling.
                1 => {
                    o.structure([block(cx, cy, 0.0, w.min(0.5), d.min(0.4), HEIGHT, yaw)]);
                    s += w.min(0.5);
                }
                // A tall shelf.
                2 => {
                    o.furniture([block(cx, cy, 0.0, w, d.min(0.45), rng.range(1.6, 2.2), yaw)]);
                    s += w;
                }
                // A cabinet.
                3 => {
                    o.furniture([block(cx, cy, 0.0, w, d, rng.range(0.8, 1.3), yaw)]);
                    s += w;
                }
                // A box, a little turned.
                4 => {
                    let turn = rng.range(-0.3, 0.3);
                    o.furniture([block(
                        cx,
                        cy,
                        0.0,
                        w.min(0.8),
                        d,
                        rng.range(0.3, 0.9),
                        yaw + turn,
                    )]);
                    s += w;
                }
                // A bin.
                _ => {
                    o.furniture([bin(cx, cy, 0.5 * d.max(0.3), rng.range(0.4, 0.9))]);
                    s += w;
                }
            }
            s += rng.range(SPACING.0, SPACING.1);
        }
    }
    // Lamps hanging from the ceiling along the centre line, at irregular places and sizes.
    let half = 0.5 * WIDTH;
    let centre = [
        ((half, half), (len - half, half)),
        ((len - half, half), (len - half, depth - half)),
        ((len - half, depth - half), (half, depth - half)),
        ((half, depth - half), (half, half)),
    ];
    for (a, b) in centre {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let length = (dx * dx + dy * dy).sqrt();
        let (ux, uy) = (dx / length, dy / length);
        let mut s = rng.range(0.5, 3.0);
        while s < length {
            let side = rng.range(-0.6, 0.6);
            let (x, y) = (a.0 + ux * s - uy * side, a.1 + uy * s + ux * side);
            let (l, w, t) = (
                rng.range(0.3, 1.2),
                rng.range(0.2, 0.4),
                rng.range(0.05, 0.15),
            );
            let drop = rng.range(0.0, 0.3);
            o.structure([block(x, y, HEIGHT - drop - t, l, w, t + drop, uy.atan2(ux))]);
            s += l + rng.range(1.5, 4.5);
        }
    }
    // The closed route: from the middle of the south corridor, anticlockwise.
    let route = vec![
        (0.5 * len, half),
        (len - half, half),
        (len - half, depth - half),
        (half, depth - half),
        (half, half),
    ];
    World::new("corridor-ring", o.0).with_route(route)
}
