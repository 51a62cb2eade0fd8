//! Worlds built to break a registration's verdict: places that repeat, mirror or lack
//! structure, where an overlap search finds several equally good answers or none that pins
//! every degree of freedom. The trust suite ([`crate::sim::trust_cases`]) draws its
//! negative and repetitive pairs from them; `olmap simulate --world` builds them too.

use std::f64::consts::PI;

use nalgebra::{Point3, Vector3};

use super::{aabb, bin, block, table, Objects};
use crate::sim::rng::SimRng;
use crate::sim::shape::Shape;
use crate::sim::world::{room_shell, World};

/// Three identical furnished rooms in a row (each 6 x 5 x 3 m inside), joined by 1.2 m
/// wide open doorways at the same place in each partition wall. The furniture is drawn
/// once from the seed and copied into every room, so a scan of one room fits the others
/// as well as its own.
pub fn twin_rooms(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (w, d, h, rooms) = (6.0, 5.0, 3.0, 3);
    let wall = 0.1;
    let pitch = w + wall;
    let mut o = Objects::default();
    let len = rooms as f64 * pitch - wall;
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(len, d, h),
        0.2,
        true,
    ));
    let door_y = rng.range(1.0, d - 2.2);
    for k in 1..rooms {
        let x = k as f64 * pitch - wall;
        o.structure([
            aabb(x, 0.0, 0.0, x + wall, door_y, h),
            aabb(x, door_y + 1.2, 0.0, x + wall, d, h),
            aabb(x, door_y, 2.1, x + wall, door_y + 1.2, h),
        ]);
    }
    // One room's furniture in room coordinates: a desk against the north wall, a shelf on
    // the south wall, a cabinet and a bin.
    let desk_x = rng.range(1.0, 4.0);
    let shelf_x = rng.range(1.5, 4.5);
    let cab = (rng.range(2.0, 4.0), rng.range(1.8, 3.2), rng.range(0.0, PI));
    let bin_at = (rng.range(0.5, 1.0), rng.range(0.5, d - 0.5));
    for k in 0..rooms {
        let x0 = k as f64 * pitch;
        o.furniture(table(x0 + desk_x, d - 0.45, 1.5, 0.75, 0.74, 0.0));
        o.furniture([
            block(x0 + shelf_x, 0.25, 0.0, 1.8, 0.4, 2.0, 0.0),
            block(x0 + cab.0, cab.1, 0.0, 0.9, 0.5, 1.1, cab.2),
            bin(x0 + bin_at.0, bin_at.1, 0.2, 0.6),
        ]);
    }
    World::new("twin-rooms", o.0)
}

/// A hall 24 x 10 x 3 m with three rows of six identical desks (with chairs) on a 2.4 m
/// pitch: shift a scan by one pitch along a row and most of it still fits. The seed only
/// sets the desks' size.
pub fn desk_hall(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (len, width, h) = (24.0, 10.0, 3.0);
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(len, width, h),
        0.2,
        true,
    ));
    let (dw, dd) = (rng.range(1.4, 1.7), rng.range(0.7, 0.8));
    let pitch = 2.4;
    for row in 0..3 {
        let y = 2.0 + 3.0 * row as f64;
        for k in 0..6 {
            let x = 5.0 + pitch * k as f64;
            o.furniture(table(x, y, dw, dd, 0.74, 0.0));
            o.furniture([block(x, y - 0.5 * dd - 0.3, 0.0, 0.45, 0.45, 0.45, 0.0)]);
        }
    }
    World::new("desk-hall", o.0)
}

/// A hall 16 x 10 x 3 m symmetric under a half turn about its centre: two pairs of
/// pillars and two cabinets placed point-symmetrically, so every view has a twin rotated
/// by 180°. The seed moves the pillars (keeping the symmetry).
pub fn symmetric_hall(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (len, width, h) = (16.0, 10.0, 3.0);
    let (cx, cy) = (0.5 * len, 0.5 * width);
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(len, width, h),
        0.2,
        true,
    ));
    let mirror = |x: f64, y: f64| (2.0 * cx - x, 2.0 * cy - y);
    let pillars = [
        (rng.range(3.0, 5.0), rng.range(2.5, 4.0)),
        (rng.range(5.5, 7.0), rng.range(6.5, 8.0)),
    ];
    for (x, y) in pillars {
        for (px, py) in [(x, y), mirror(x, y)] {
            o.structure([Shape::Cylinder {
                base: Point3::new(px, py, 0.0),
                radius: 0.3,
                height: h,
            }]);
        }
    }
    let (x, y) = (rng.range(10.0, 13.0), 0.35);
    for (bx, by, yaw) in [(x, y, 0.0), (mirror(x, y).0, mirror(x, y).1, PI)] {
        o.furniture([block(bx, by, 0.0, 1.6, 0.5, 1.2, yaw)]);
    }
    World::new("symmetric-hall", o.0)
}

/// Nothing but a floor: every scan is one plane, which leaves x, y and heading free.
pub fn floor_only() -> World {
    let mut o = Objects::default();
    o.structure([Shape::horizontal_plane(0.0)]);
    World::new("floor", o.0)
}

/// Two perpendicular walls 30 m long and 20 m tall meeting at the origin (along +x and
/// +y), no floor or ceiling: x, y and heading are fixed, height is not.
pub fn two_walls() -> World {
    let mut o = Objects::default();
    o.structure([
        aabb(-0.2, -0.2, -10.0, 30.0, 0.0, 10.0),
        aabb(-0.2, 0.0, -10.0, 0.0, 30.0, 10.0),
    ]);
    World::new("two-walls", o.0)
}
