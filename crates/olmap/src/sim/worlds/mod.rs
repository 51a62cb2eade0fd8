//! Built-in indoor worlds: an empty box room, a furnished lab (thesis §6.5), an office floor
//! with a stairwell shaft, a featureless corridor, and worlds built to break a verdict
//! ([`traps`]: identical rooms, rows of identical desks, a symmetric hall, a bare floor, two
//! walls), a [`corridor_ring`] robots drive round (a 72 m loop) and a 200 x 200 m
//! [`warehouse`] of rack rows (the large world). Every generator is deterministic in
//! its seed (through [`SimRng`]), so a dataset is reproducible from its world name and seed.
//!
//! Static objects all carry id 0; structure (floors, walls, ceilings, pillars, stairs) uses
//! [`Material::WALL`], movable things [`Material::FURNITURE`].

use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;
use std::str::FromStr;

use nalgebra::{Point3, Vector3};

use super::rng::SimRng;
use super::shape::{Material, Object, Shape};
use super::world::{room_shell, World};

mod ring;
mod traps;
mod warehouse;

pub use ring::corridor_ring;
pub use traps::{desk_hall, floor_only, symmetric_hall, twin_rooms, two_walls};
pub use warehouse::warehouse;

/// Height band a ground robot occupies: what [`free_spot`] keeps clear of.
const ROBOT_BAND: (f64, f64) = (0.05, 1.0);

/// How many random positions [`free_spot`] tries.
const FREE_SPOT_ATTEMPTS: usize = 20_000;

/// The built-in worlds, by name.
///
/// ```
/// use olmap::sim::WorldKind;
/// let kind: WorldKind = "box-room".parse().unwrap();
/// assert_eq!(kind, WorldKind::BoxRoom);
/// assert_eq!(kind.name(), "box-room");
/// assert!("castle".parse::<WorldKind>().is_err());
/// let world = kind.build(1);
/// assert_eq!(world.name(), "box-room");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WorldKind {
    /// [`office`]: corridor, rooms with doors, a stairwell shaft.
    Office,
    /// [`lab`]: one furnished 20 x 20 x 3 m room.
    Lab,
    /// [`corridor`]: a long featureless corridor.
    Corridor,
    /// [`box_room`] of 8 x 6 x 3 m.
    BoxRoom,
    /// [`twin_rooms`]: three identical furnished rooms in a row.
    TwinRooms,
    /// [`desk_hall`]: a hall with rows of identical desks.
    DeskHall,
    /// [`symmetric_hall`]: a hall symmetric under a half turn.
    SymmetricHall,
    /// [`corridor_ring`]: a 72 m corridor loop with its route.
    CorridorRing,
    /// [`warehouse`]: a 200 x 200 m hall of rack rows with a serpentine route.
    Warehouse,
}

impl WorldKind {
    /// Every kind, in a fixed order.
    pub const ALL: [WorldKind; 9] = [
        WorldKind::Office,
        WorldKind::Lab,
        WorldKind::Corridor,
        WorldKind::BoxRoom,
        WorldKind::TwinRooms,
        WorldKind::DeskHall,
        WorldKind::SymmetricHall,
        WorldKind::CorridorRing,
        WorldKind::Warehouse,
    ];

    /// The lower-case name ("office", "lab", "corridor", "box-room", "twin-rooms",
    /// "desk-hall", "symmetric-hall", "corridor-ring", "warehouse").
    pub fn name(self) -> &'static str {
        match self {
            WorldKind::Office => "office",
            WorldKind::Lab => "lab",
            WorldKind::Corridor => "corridor",
            WorldKind::BoxRoom => "box-room",
            WorldKind::TwinRooms => "twin-rooms",
            WorldKind::DeskHall => "desk-hall",
            WorldKind::SymmetricHall => "symmetric-hall",
            WorldKind::CorridorRing => "corridor-ring",
            WorldKind::Warehouse => "warehouse",
        }
    }

    /// Generates the world for `seed` (the box room ignores the seed).
    pub fn build(self, seed: u64) -> World {
        match self {
            WorldKind::Office => office(seed),
            WorldKind::Lab => lab(seed),
            WorldKind::Corridor => corridor(seed),
            WorldKind::BoxRoom => box_room(Vector3::new(8.0, 6.0, 3.0)),
            WorldKind::TwinRooms => twin_rooms(seed),
            WorldKind::DeskHall => desk_hall(seed),
            WorldKind::SymmetricHall => symmetric_hall(seed),
            WorldKind::CorridorRing => corridor_ring(seed),
            WorldKind::Warehouse => warehouse(seed),
        }
    }
}

impl fmt::Display for WorldKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for WorldKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        WorldKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = WorldKind::ALL.iter().map(|k| k.name()).collect();
                format!(
                    "unknown world '{s}' (expected one of: {})",
                    names.join(", ")
                )
            })
    }
}

/// Collects a world's objects (id 0).
#[derive(Default)]
struct Objects(Vec<Object>);

impl Objects {
    fn structure(&mut self, shapes: impl IntoIterator<Item = Shape>) {
        self.add(shapes, Material::WALL);
    }

    fn furniture(&mut self, shapes: impl IntoIterator<Item = Shape>) {
        self.add(shapes, Material::FURNITURE);
    }

    fn add(&mut self, shapes: impl IntoIterator<Item = Shape>, material: Material) {
        self.0.extend(shapes.into_iter().map(|shape| Object {
            shape,
            material,
            id: 0,
        }));
    }
}

/// An axis-aligned box from its corners (short hand).
fn aabb(x0: f64, y0: f64, z0: f64, x1: f64, y1: f64, z1: f64) -> Shape {
    Shape::aabb_box(Point3::new(x0, y0, z0), Point3::new(x1, y1, z1))
}

/// A box standing on `z0`, `w` along its own x, `d` along its own y, `h` tall, turned by
/// `yaw` about its centre.
fn block(cx: f64, cy: f64, z0: f64, w: f64, d: f64, h: f64, yaw: f64) -> Shape {
    Shape::Box {
        center: Point3::new(cx, cy, z0 + 0.5 * h),
        half: Vector3::new(0.5 * w, 0.5 * d, 0.5 * h),
        yaw,
    }
}

/// A point `(lx, ly)` of a frame at `(cx, cy)` turned by `yaw`, in world coordinates.
fn turn(cx: f64, cy: f64, yaw: f64, lx: f64, ly: f64) -> (f64, f64) {
    let (s, c) = yaw.sin_cos();
    (cx + c * lx - s * ly, cy + s * lx + c * ly)
}

/// A table or desk: a 4 cm top on four 5 cm square legs.
fn table(cx: f64, cy: f64, w: f64, d: f64, h: f64, yaw: f64) -> Vec<Shape> {
    let top = 0.04;
    let leg = 0.05;
    let mut s = vec![block(cx, cy, h - top, w, d, top, yaw)];
    let (lx, ly) = (0.5 * w - leg, 0.5 * d - leg);
    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let (x, y) = turn(cx, cy, yaw, sx * lx, sy * ly);
        s.push(block(x, y, 0.0, leg, leg, h - top, yaw));
    }
    s
}

/// A bin: a short vertical cylinder on the floor.
fn bin(cx: f64, cy: f64, radius: f64, height: f64) -> Shape {
    Shape::Cylinder {
        base: Point3::new(cx, cy, 0.0),
        radius,
        height,
    }
}

/// A floor rectangle `[x0, x1] x [y0, y1]`.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    fn new(x0: f64, y0: f64, x1: f64, y1: f64) -> Rect {
        Rect { x0, y0, x1, y1 }
    }

    /// The footprint of shapes (their bounds' union in x, y).
    fn of(shapes: &[Shape]) -> Rect {
        let mut r = Rect::new(
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for b in shapes.iter().filter_map(Shape::bounds) {
            r.x0 = r.x0.min(b.min.x);
            r.y0 = r.y0.min(b.min.y);
            r.x1 = r.x1.max(b.max.x);
            r.y1 = r.y1.max(b.max.y);
        }
        r
    }

    fn inside(&self, outer: &Rect) -> bool {
        self.x0 >= outer.x0 && self.y0 >= outer.y0 && self.x1 <= outer.x1 && self.y1 <= outer.y1
    }

    /// Whether the rectangles come closer than `gap`.
    fn near(&self, other: &Rect, gap: f64) -> bool {
        self.x0 < other.x1 + gap
            && other.x0 < self.x1 + gap
            && self.y0 < other.y1 + gap
            && other.y0 < self.y1 + gap
    }

    /// A uniform point inside.
    fn sample(&self, rng: &mut SimRng) -> (f64, f64) {
        (rng.range(self.x0, self.x1), rng.range(self.y0, self.y1))
    }
}

/// Furniture placement by rejection: each group must lie inside its zone and keep a gap to
/// everything placed before.
struct Layout {
    placed: Vec<Rect>,
}

impl Layout {
    /// Tries `make` up to 40 times; keeps the first group that fits.
    fn place(
        &mut self,
        rng: &mut SimRng,
        zone: &Rect,
        gap: f64,
        mut make: impl FnMut(&mut SimRng) -> Vec<Shape>,
    ) -> Option<Vec<Shape>> {
        for _ in 0..40 {
            let shapes = make(rng);
            let fp = Rect::of(&shapes);
            if fp.inside(zone) && !self.placed.iter().any(|p| p.near(&fp, gap)) {
                self.placed.push(fp);
                return Some(shapes);
            }
        }
        None
    }
}

/// An empty closed room: floor, four walls and ceiling 10 cm thick, inner corner at the
/// origin, inner size `size`.
///
/// ```
/// use nalgebra::{Point3, Vector3};
/// use olmap::sim::box_room;
/// let room = box_room(Vector3::new(8.0, 6.0, 3.0));
/// let hit = room.cast(&Point3::new(2.0, 3.0, 1.0), &Vector3::x(), 20.0).unwrap();
/// assert!((hit.distance - 6.0).abs() < 1e-12);
/// ```
pub fn box_room(size: Vector3<f64>) -> World {
    let mut o = Objects::default();
    o.structure(room_shell(Point3::origin(), size, 0.1, true));
    World::new("box-room", o.0)
}

/// A featureless corridor 40 x 2 x 2.8 m (inside; inner corner at the origin, along x):
/// floor, walls, ceiling and closed ends, 20 cm thick, nothing else. The seed is accepted
/// for uniformity with the other generators and does not change the corridor.
pub fn corridor(seed: u64) -> World {
    let _ = seed;
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(40.0, 2.0, 2.8),
        0.2,
        true,
    ));
    World::new("corridor", o.0)
}

/// A single furnished lab room, 20 x 20 x 3 m inside (inner corner at the origin) after
/// thesis §6.5.
///
/// A 1.2 m margin along the walls stays clear; the rest is cut into a 3 x 3 grid of
/// 4.8 m zones separated by 1.6 m aisles, so robots can drive around every group. Three
/// floor-to-ceiling pillars (radius 0.3 m) stand at fixed, asymmetric places (jittered by
/// the seed). Each zone holds one furniture group picked by the seed (a row of desks
/// with chairs, a yawed table with things on it, tall shelves, cabinets, or clutter boxes),
/// up to two more loose boxes and maybe a bin; one zone is left empty.
pub fn lab(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (size, height) = (20.0, 3.0);
    let mut o = Objects::default();
    o.structure(room_shell(
        Point3::origin(),
        Vector3::new(size, size, height),
        0.2,
        true,
    ));

    let (margin, aisle) = (1.2, 1.6);
    let zone_size = (size - 2.0 * margin - 2.0 * aisle) / 3.0;
    let zone = |i: usize, j: usize| {
        let x0 = margin + i as f64 * (zone_size + aisle);
        let y0 = margin + j as f64 * (zone_size + aisle);
        Rect::new(x0, y0, x0 + zone_size, y0 + zone_size)
    };
    let mut layout = Layout { placed: Vec::new() };

    for (x, y) in [(4.2, 9.3), (15.9, 4.1), (11.2, 16.6)] {
        let (x, y) = (x + rng.range(-0.4, 0.4), y + rng.range(-0.4, 0.4));
        let pillar = Shape::Cylinder {
            base: Point3::new(x, y, 0.0),
            radius: 0.3,
            height,
        };
        layout.placed.push(Rect::of(std::slice::from_ref(&pillar)));
        o.structure([pillar]);
    }

    let empty = rng.index(9);
    for k in 0..9 {
        if k == empty {
            continue;
        }
        let z = zone(k % 3, k / 3);
        match rng.index(5) {
            0 => desk_row(&mut rng, &mut layout, &z, &mut o),
            1 => big_table(&mut rng, &mut layout, &z, &mut o),
            2 => {
                for _ in 0..1 + rng.index(2) {
                    let g = layout.place(&mut rng, &z, 0.3, |r| {
                        let yaw = if r.chance(0.5) { 0.0 } else { FRAC_PI_2 };
                        let yaw = yaw
                            + if r.chance(0.3) {
                                r.range(-0.3, 0.3)
                            } else {
                                0.0
                            };
                        let (x, y) = z.sample(r);
                        let (w, d, h) = (r.range(1.6, 2.2), r.range(0.35, 0.5), r.range(1.8, 2.2));
                        vec![block(x, y, 0.0, w, d, h, yaw)]
                    });
                    o.furniture(g.into_iter().flatten());
                }
            }
            3 => {
                for _ in 0..2 + rng.index(2) {
                    let g = layout.place(&mut rng, &z, 0.3, |r| {
                        let yaw = if r.chance(0.4) {
                            r.range(-PI, PI)
                        } else {
                            FRAC_PI_2 * r.index(2) as f64
                        };
                        let (x, y) = z.sample(r);
                        let (w, d, h) = (r.range(0.8, 1.2), r.range(0.5, 0.7), r.range(0.9, 1.3));
                        vec![block(x, y, 0.0, w, d, h, yaw)]
                    });
                    o.furniture(g.into_iter().flatten());
                }
            }
            _ => {
                let n = 3 + rng.index(4);
                clutter(&mut rng, &mut layout, &z, &mut o, n);
            }
        }
        let extra = rng.index(3);
        clutter(&mut rng, &mut layout, &z, &mut o, extra);
        if rng.chance(0.5) {
            let g = layout.place(&mut rng, &z, 0.3, |r| {
                let (x, y) = z.sample(r);
                vec![bin(x, y, r.range(0.15, 0.3), r.range(0.4, 0.8))]
            });
            o.furniture(g.into_iter().flatten());
        }
    }
    World::new("lab", o.0)
}

/// A row of two or three desks side by side, each with a chair block in front.
fn desk_row(rng: &mut SimRng, layout: &mut Layout, zone: &Rect, o: &mut Objects) {
    let g = layout.place(rng, zone, 0.3, |r| {
        let n = 2 + r.index(2);
        let (w, d, h) = (r.range(1.4, 1.8), r.range(0.7, 0.8), r.range(0.72, 0.76));
        let yaw = FRAC_PI_2 * r.index(4) as f64;
        let (cx, cy) = zone.sample(r);
        let mut s = Vec::new();
        for i in 0..n {
            let along = (i as f64 - 0.5 * (n - 1) as f64) * (w + 0.02);
            let (x, y) = turn(cx, cy, yaw, along, 0.0);
            s.extend(table(x, y, w, d, h, yaw));
            let chair = r.range(-0.3, 0.3);
            let (x, y) = turn(cx, cy, yaw, along + chair, -(0.5 * d + 0.3));
            s.push(block(x, y, 0.0, 0.45, 0.45, 0.45, yaw + r.range(-0.4, 0.4)));
        }
        s
    });
    o.furniture(g.into_iter().flatten());
}

/// A large table at an angle with a few boxes on its top.
fn big_table(rng: &mut SimRng, layout: &mut Layout, zone: &Rect, o: &mut Objects) {
    let g = layout.place(rng, zone, 0.3, |r| {
        let (w, d, h) = (r.range(2.0, 2.6), r.range(1.0, 1.3), 0.74);
        let yaw = r.range(-0.5, 0.5);
        let (cx, cy) = zone.sample(r);
        let mut s = table(cx, cy, w, d, h, yaw);
        for _ in 0..1 + r.index(3) {
            let (bw, bd, bh) = (r.range(0.2, 0.5), r.range(0.2, 0.4), r.range(0.1, 0.4));
            let lx = r.range(-0.5 * (w - bw), 0.5 * (w - bw));
            let ly = r.range(-0.5 * (d - bd), 0.5 * (d - bd));
            let (x, y) = turn(cx, cy, yaw, lx, ly);
            s.push(block(x, y, h, bw, bd, bh, yaw));
        }
        s
    });
    o.furniture(g.into_iter().flatten());
}

/// `n` loose boxes at random angles.
fn clutter(rng: &mut SimRng, layout: &mut Layout, zone: &Rect, o: &mut Objects, n: usize) {
    for _ in 0..n {
        let g = layout.place(rng, zone, 0.3, |r| {
            let (x, y) = zone.sample(r);
            let (w, d, h) = (r.range(0.25, 0.7), r.range(0.25, 0.7), r.range(0.2, 0.8));
            vec![block(x, y, 0.0, w, d, h, r.range(-PI, PI))]
        });
        o.furniture(g.into_iter().flatten());
    }
}

/// An office floor 36 x 15 x 3 m inside (inner corner at the origin): a 2 m corridor along
/// x (y from 6.5 to 8.5) with rooms on both sides, 3.5-7 m wide (seeded), each with a 1 m
/// door (2.1 m high, lintel above) into the corridor and two to four pieces of furniture
/// against its walls, away from the door. One room on the north side (never the first or
/// last) is a stairwell shaft: its walls rise to 6 m, there is no ceiling over it, and a
/// flight of steps with a landing runs along its back wall. Outer walls are 20 cm thick,
/// inner walls 10 cm.
pub fn office(seed: u64) -> World {
    let mut rng = SimRng::new(seed);
    let (len, width, height, shaft_height) = (36.0, 15.0, 3.0, 6.0);
    let (t, ht) = (0.2, 0.05);
    let (corr_lo, corr_hi) = (6.5, 8.5);
    let (south_hi, north_lo) = (corr_lo - 2.0 * ht, corr_hi + 2.0 * ht);
    let mut o = Objects::default();

    // Room boundaries along x, per side.
    let split = |r: &mut SimRng| {
        let mut xs = vec![0.0];
        let mut x = 0.0;
        loop {
            let rest = len - x;
            if rest <= 7.0 {
                xs.push(len);
                return xs;
            }
            let w = if rest < 11.5 {
                0.5 * rest
            } else {
                r.range(4.5, 7.0)
            };
            x += w;
            xs.push(x);
        }
    };
    let south = split(&mut rng);
    let north = split(&mut rng);
    let shaft = 1 + rng.index(north.len() - 3);
    let (sa, sb) = (north[shaft], north[shaft + 1]);
    // The shaft's inside.
    let shaft_rect = Rect::new(sa + ht, north_lo, sb - ht, width);

    // Floor, outer walls (the north one higher along the shaft), ceiling with a hole.
    o.structure([
        aabb(-t, -t, -t, len + t, width + t, 0.0),
        aabb(-t, -t, 0.0, len + t, 0.0, height),
        aabb(-t, 0.0, 0.0, 0.0, width, height),
        aabb(len, 0.0, 0.0, len + t, width, height),
        aabb(-t, width, 0.0, sa, width + t, height),
        aabb(sa, width, 0.0, sb, width + t, shaft_height),
        aabb(sb, width, 0.0, len + t, width + t, height),
        aabb(-t, -t, height, shaft_rect.x0, width + t, height + t),
        aabb(shaft_rect.x1, -t, height, len + t, width + t, height + t),
        aabb(
            shaft_rect.x0,
            -t,
            height,
            shaft_rect.x1,
            shaft_rect.y0,
            height + t,
        ),
    ]);

    for (xs, north_side) in [(&south, false), (&north, true)] {
        let (y0, y1) = if north_side {
            (north_lo, width)
        } else {
            (0.0, south_hi)
        };
        // The corridor wall's band on this side.
        let (wy0, wy1) = if north_side {
            (corr_hi, north_lo)
        } else {
            (south_hi, corr_lo)
        };
        for k in 0..xs.len() - 1 {
            let (a, b) = (xs[k], xs[k + 1]);
            let is_shaft = north_side && k == shaft;
            let top = if is_shaft { shaft_height } else { height };
            // Partition wall at the room's west end (shared with the previous room).
            if k > 0 {
                let tall = north_side && (k == shaft || k == shaft + 1);
                let h = if tall { shaft_height } else { height };
                o.structure([aabb(a - ht, y0, 0.0, a + ht, y1, h)]);
            }
            let room = Rect::new(
                if k > 0 { a + ht } else { a },
                y0,
                if k + 2 < xs.len() { b - ht } else { b },
                y1,
            );
            // Corridor wall with a door.
            let door = rng.range(room.x0 + 0.9, room.x1 - 0.9);
            let (d0, d1) = (door - 0.5, door + 0.5);
            o.structure([
                aabb(a, wy0, 0.0, d0, wy1, top),
                aabb(d1, wy0, 0.0, b, wy1, top),
                aabb(d0, wy0, 2.1, d1, wy1, top),
            ]);
            if is_shaft {
                stairs(&room, &mut o);
            } else {
                office_furniture(&mut rng, &room, north_side, &mut o);
            }
        }
    }
    World::new("office", o.0)
}

/// A straight flight of 18 cm steps along the back (north) wall of a stairwell, with a
/// 1 m landing at its top.
fn stairs(room: &Rect, o: &mut Objects) {
    let (rise, run, width) = (0.18, 0.28, 1.0);
    let steps = (((room.x1 - room.x0 - 1.4) / run).floor() as usize).min(10);
    let x0 = room.x0 + 0.2;
    for i in 0..steps {
        let x = x0 + i as f64 * run;
        o.structure([aabb(
            x,
            room.y1 - width,
            0.0,
            x + run,
            room.y1,
            (i + 1) as f64 * rise,
        )]);
    }
    let x = x0 + steps as f64 * run;
    o.structure([aabb(
        x,
        room.y1 - width,
        0.0,
        x + 1.0,
        room.y1,
        steps as f64 * rise,
    )]);
}

/// Two to four pieces against a room's back and side walls, keeping 1.5 m in front of the
/// corridor wall (the door side) free.
fn office_furniture(rng: &mut SimRng, room: &Rect, north_side: bool, o: &mut Objects) {
    let zone = if north_side {
        Rect::new(room.x0, room.y0 + 1.5, room.x1, room.y1)
    } else {
        Rect::new(room.x0, room.y0, room.x1, room.y1 - 1.5)
    };
    let mut layout = Layout { placed: Vec::new() };
    let gap = 0.03;
    for _ in 0..2 + rng.index(3) {
        let kind = rng.index(4);
        let g = layout.place(rng, &zone, 0.2, |r| {
            let (w, d, h) = match kind {
                0 => (r.range(1.2, 1.6), r.range(0.6, 0.8), 0.74),
                1 => (r.range(0.8, 1.0), r.range(0.45, 0.6), r.range(1.0, 1.3)),
                2 => (r.range(1.6, 2.0), r.range(0.35, 0.45), r.range(1.8, 2.1)),
                _ => (0.4, 0.4, r.range(0.4, 0.6)),
            };
            // Against the back wall, or the west or east one.
            let (x, y, yaw) = match r.index(3) {
                0 => {
                    let y = if north_side {
                        zone.y1 - gap - 0.5 * d
                    } else {
                        zone.y0 + gap + 0.5 * d
                    };
                    (r.range(zone.x0, zone.x1), y, 0.0)
                }
                1 => (
                    zone.x0 + gap + 0.5 * d,
                    r.range(zone.y0, zone.y1),
                    FRAC_PI_2,
                ),
                _ => (
                    zone.x1 - gap - 0.5 * d,
                    r.range(zone.y0, zone.y1),
                    FRAC_PI_2,
                ),
            };
            match kind {
                0 => table(x, y, w, d, h, yaw),
                3 => vec![bin(x, y, 0.5 * w, h)],
                _ => vec![block(x, y, 0.0, w, d, h, yaw)],
            }
        });
        o.furniture(g.into_iter().flatten());
    }
}

/// A random `(x, y)` in the world where a robot of radius `clearance` fits: clear of
/// everything in the robot's height band (5 cm to 1 m) and enclosed (rays from 0.5 m
/// height along +x, -x, +y, -y and down all meet a surface, so the spot is inside the
/// walls). `None` when 20,000 tries find none.
pub fn free_spot(world: &World, rng: &mut SimRng, clearance: f64) -> Option<(f64, f64)> {
    let b = world.bounds()?;
    let reach = 2.0 * (b.max - b.min).norm() + 1.0;
    let (x0, x1) = (b.min.x + clearance, b.max.x - clearance);
    let (y0, y1) = (b.min.y + clearance, b.max.y - clearance);
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    let dirs = [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        -Vector3::z(),
    ];
    for _ in 0..FREE_SPOT_ATTEMPTS {
        let (x, y) = (rng.range(x0, x1), rng.range(y0, y1));
        if !world.is_clear(x, y, clearance, ROBOT_BAND.0, ROBOT_BAND.1) {
            continue;
        }
        let origin = Point3::new(x, y, 0.5);
        if dirs.iter().all(|d| world.cast(&origin, d, reach).is_some()) {
            return Some((x, y));
        }
    }
    None
}
