//! The trust suite: simulated scan pairs with ground truth, built to tempt a registration
//! into a confident wrong answer (unrelated places, identical rooms, rows of identical
//! desks, featureless corridors, symmetric halls, bare floors, two walls, the two long sides
//! of a furnished corridor ring, stretches of one of them) beside pairs
//! that do have one right answer (the same place, partial views, half the points random
//! outliers, low overlap, a small piece of a scan). [`trust_cases`] draws them; the
//! benchmark `olmap bench --trust` registers every pair and tabulates, per kind, how often
//! the verdict was trusted and right, trusted and wrong, or not trusted.
//!
//! Every pair is two scans of the enhanced rotating-mirror scanner (8 m, 2 cm noise; the
//! demo's sensor) in the robot frame (sensor 0.6 m above the floor), from robot poses on the
//! floor. The truth is `T_target_source`; "right" means within [`RIGHT_TRANSLATION`] and
//! [`RIGHT_ROTATION`] of it (the issue's 0.3 m / 3°).

use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use serde::Serialize;

use super::rng::SimRng;
use super::robot::RobotModel;
use super::scanners::MirrorScanner;
use super::world::World;
use super::worlds::{
    corridor, corridor_ring, desk_hall, floor_only, free_spot, lab, office, symmetric_hall,
    twin_rooms, two_walls,
};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::occupancy::OccupancyList;

/// A translation error up to this is right (metres).
pub const RIGHT_TRANSLATION: f64 = 0.3;
/// A rotation error up to this is right (radians; 3°).
pub const RIGHT_ROTATION: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// The kinds of pairs, each with what a sound verdict may answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrustScene {
    /// Two scans 0.5-3 m apart in the lab or the office: one right answer.
    SamePlace,
    /// As [`TrustScene::SamePlace`], the source cut to a 120° sector of its view.
    Partial,
    /// As [`TrustScene::SamePlace`], as many random points as real ones added to the source
    /// (uniform in its bounding box): half its points are outliers.
    Outliers,
    /// Two scans of one world whose true overlap is 5-15 % of the source's voxels.
    LowOverlap,
    /// A piece of a scan (the points within 1.5 m of one of its points, moved by a random
    /// transform) against the whole scan.
    Subset,
    /// Scans of two different places (different worlds, or different seeds of one): no
    /// right answer exists.
    Unrelated,
    /// Scans in a row of identical rooms ([`super::twin_rooms`]).
    TwinRooms,
    /// Scans along rows of identical desks ([`super::desk_hall`]).
    DeskRows,
    /// Scans in a hall symmetric under a half turn ([`super::symmetric_hall`]).
    SymmetricHall,
    /// Scans 1-6 m apart in a featureless 40 m corridor.
    Corridor,
    /// Scans of a bare floor ([`super::floor_only`]).
    Planar,
    /// Scans of two perpendicular walls and nothing else ([`super::two_walls`]).
    TwoWalls,
    /// One scan from the middle of each long side of a corridor ring
    /// ([`super::corridor_ring`]): two stretches of one corridor 13 m apart, a solid core
    /// between them, so nothing is shared, but both are 3 m wide, 2.8 m high and lined
    /// with the same kinds of things. The batch mapper once trusted one for the other
    /// (issue 23's ring, thesis-degraded odometry). No right answer exists.
    OppositeCorridors,
    /// Two scans 1-6 m apart along one long side of the corridor ring: a furnished
    /// corridor, where a slide along it can fit nearly as well (the mappers once trusted
    /// 0.4 m slides there).
    RingCorridor,
}

/// What a pair's answer can be, which decides how its verdict is judged.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Answer {
    /// One right pose, with enough shared structure: a sound verdict trusts it (and is
    /// right).
    Unique,
    /// One right pose but little evidence (low overlap, a small piece): trusting is
    /// optional, being wrong is not.
    Scarce,
    /// Several poses fit about equally, or the scene leaves a degree of freedom free:
    /// trusting is allowed only when right.
    Ambiguous,
    /// No right pose exists: any trusted answer is wrong.
    None,
}

impl TrustScene {
    /// Every kind, in table order.
    pub const ALL: [TrustScene; 14] = [
        TrustScene::SamePlace,
        TrustScene::Partial,
        TrustScene::Outliers,
        TrustScene::LowOverlap,
        TrustScene::Subset,
        TrustScene::Unrelated,
        TrustScene::TwinRooms,
        TrustScene::DeskRows,
        TrustScene::SymmetricHall,
        TrustScene::Corridor,
        TrustScene::Planar,
        TrustScene::TwoWalls,
        TrustScene::OppositeCorridors,
        TrustScene::RingCorridor,
    ];

    /// The kebab-case name.
    pub fn name(self) -> &'static str {
        match self {
            TrustScene::SamePlace => "same-place",
            TrustScene::Partial => "partial",
            TrustScene::Outliers => "outliers",
            TrustScene::LowOverlap => "low-overlap",
            TrustScene::Subset => "subset",
            TrustScene::Unrelated => "unrelated",
            TrustScene::TwinRooms => "twin-rooms",
            TrustScene::DeskRows => "desk-rows",
            TrustScene::SymmetricHall => "symmetric-hall",
            TrustScene::Corridor => "corridor",
            TrustScene::Planar => "planar",
            TrustScene::TwoWalls => "two-walls",
            TrustScene::OppositeCorridors => "opposite-corridors",
            TrustScene::RingCorridor => "ring-corridor",
        }
    }

    /// What the pairs of this kind can answer.
    pub fn answer(self) -> Answer {
        match self {
            TrustScene::SamePlace | TrustScene::Partial | TrustScene::Outliers => Answer::Unique,
            TrustScene::LowOverlap | TrustScene::Subset => Answer::Scarce,
            TrustScene::Unrelated | TrustScene::OppositeCorridors => Answer::None,
            _ => Answer::Ambiguous,
        }
    }
}

/// One pair of the suite.
#[derive(Debug, Clone)]
pub struct TrustCase {
    /// The kind.
    pub scene: TrustScene,
    /// A name unique in the suite (`kind-NN`).
    pub name: String,
    /// The scan to register (robot frame, sensor origin set).
    pub source: PointCloud,
    /// The scan it is registered onto.
    pub target: PointCloud,
    /// The true `T_target_source`; `None` for unrelated places.
    pub truth: Option<Pose>,
    /// Fraction of the source's 0.1 m voxels that meet the target's at the truth (0 without
    /// one).
    pub true_overlap: f64,
    /// The world the target scan was taken in.
    pub world: Arc<World>,
    /// The target robot's pose in it, `T_world_robot`.
    pub t_world_target: Pose,
}

impl TrustCase {
    /// Whether `pose` (`T_target_source`) is right: within [`RIGHT_TRANSLATION`] and
    /// [`RIGHT_ROTATION`] of the truth. `None` when there is no truth.
    pub fn is_right(&self, pose: &Pose) -> Option<bool> {
        self.truth.map(|t| {
            let (dt, dr) = pose_error(pose, &t);
            dt <= RIGHT_TRANSLATION && dr <= RIGHT_ROTATION
        })
    }

    /// Whether a wrong `pose` (`T_target_source`) is an **alias**: the source scan is what
    /// the robot would have seen there, so no verdict on these two scans could tell it
    /// from the truth. The target's world is scanned again from the robot pose `pose`
    /// puts the source at; the pose is an alias when at least [`ALIAS_AGREEMENT`] of the
    /// source's 0.1 m voxels lie within one cell of that scan's and (for whole scans) the
    /// other way round. Partial views, outlier-laden scans and pieces are checked one way
    /// only (the scan they come from is larger).
    pub fn is_alias(&self, pose: &Pose) -> Result<bool> {
        let rig = Rig::new();
        let seen = rig.scan(&self.world, &(self.t_world_target * *pose), 0x0a11a5, 2);
        let (s, r) = (voxels(&self.source)?, voxels(&seen)?);
        let one_way = near_fraction(&s, &r) >= ALIAS_AGREEMENT;
        Ok(match self.scene {
            TrustScene::Partial | TrustScene::Outliers | TrustScene::Subset => one_way,
            _ => one_way && near_fraction(&r, &s) >= ALIAS_AGREEMENT,
        })
    }
}

/// Share of voxels that must agree for a wrong pose to count as an alias
/// ([`TrustCase::is_alias`]).
pub const ALIAS_AGREEMENT: f64 = 0.9;

fn voxels(c: &PointCloud) -> Result<OccupancyList> {
    OccupancyList::from_cloud(c, 0.1)
}

/// The fraction of `a`'s voxels with a voxel of `b` within one cell.
fn near_fraction(a: &OccupancyList, b: &OccupancyList) -> f64 {
    if a.is_empty() {
        return 0.0;
    }
    let near = a
        .iter()
        .filter(|(k, _)| {
            (-1..=1).any(|dx| {
                (-1..=1).any(|dy| {
                    (-1..=1).any(|dz| {
                        b.count(crate::geometry::VoxelKey::new(k.x + dx, k.y + dy, k.z + dz)) > 0
                    })
                })
            })
        })
        .count();
    near as f64 / a.len() as f64
}

/// Translation (metres) and rotation (radians) between two poses.
pub fn pose_error(a: &Pose, b: &Pose) -> (f64, f64) {
    (
        (a.translation() - b.translation()).norm(),
        a.rotation().angle_to(&b.rotation()),
    )
}

/// The suite: `per_scene` pairs of every [`TrustScene`], all drawn from `seed`. The same
/// seed gives the same pairs. `progress(done, total)` counts pairs.
pub fn trust_cases(
    seed: u64,
    per_scene: usize,
    mut progress: impl FnMut(usize, usize),
) -> Result<Vec<TrustCase>> {
    let total = per_scene * TrustScene::ALL.len();
    let mut out = Vec::with_capacity(total);
    for scene in TrustScene::ALL {
        for k in 0..per_scene {
            out.push(trust_case(seed, scene, k)?);
            progress(out.len(), total);
        }
    }
    Ok(out)
}

/// Pair `index` of `scene` in the suite of `seed`: the same pair [`trust_cases`] draws
/// there (its draws depend on the seed, the kind and the index alone), without drawing
/// the others.
///
/// ```no_run
/// use olmap::sim::{trust_case, TrustScene};
/// let case = trust_case(4, TrustScene::RingCorridor, 7).unwrap();
/// assert_eq!(case.name, "ring-corridor-07");
/// ```
pub fn trust_case(seed: u64, scene: TrustScene, index: usize) -> Result<TrustCase> {
    let s = TrustScene::ALL
        .iter()
        .position(|&k| k == scene)
        .unwrap_or_default();
    let mut rng = SimRng::for_item(seed, 0x7275_7374 + s as u64, index as u64);
    let case_seed = rng.next_u64();
    let mut case = draw(scene, case_seed, &mut rng)?;
    case.name = format!("{}-{index:02}", scene.name());
    Ok(case)
}

/// The scanner and robot every pair uses.
struct Rig {
    scanner: MirrorScanner,
    robot: RobotModel,
}

impl Rig {
    fn new() -> Self {
        Rig {
            scanner: MirrorScanner::enhanced(),
            robot: RobotModel::default(),
        }
    }

    /// A scan from the robot pose `t_world_robot`, in the robot frame.
    fn scan(&self, world: &World, t_world_robot: &Pose, seed: u64, stream: u64) -> PointCloud {
        let sensor = self.robot.sensor_pose();
        self.scanner
            .scan(world, &[], &(*t_world_robot * sensor), seed, stream)
            .transformed(&sensor)
    }
}

fn robot_at(x: f64, y: f64, yaw: f64) -> Pose {
    Pose::from_xyz_ypr(x, y, 0.0, yaw, 0.0, 0.0)
}

/// A heading along the x axis, either way (0 or π, one draw).
fn along_x(rng: &mut SimRng) -> f64 {
    if rng.chance(0.5) {
        0.0
    } else {
        std::f64::consts::PI
    }
}

fn random_yaw(rng: &mut SimRng) -> f64 {
    rng.range(-std::f64::consts::PI, std::f64::consts::PI)
}

fn spot(world: &World, rng: &mut SimRng) -> Result<(f64, f64)> {
    free_spot(world, rng, 0.4)
        .ok_or_else(|| Error::InvalidArgument(format!("no free spot in {}", world.name())))
}

/// A free spot `lo..hi` metres from `(x, y)` (the first of 200 tries, else any free spot).
fn spot_near(
    world: &World,
    rng: &mut SimRng,
    at: (f64, f64),
    lo: f64,
    hi: f64,
) -> Result<(f64, f64)> {
    for _ in 0..200 {
        let (r, a) = (rng.range(lo, hi), random_yaw(rng));
        let (x, y) = (at.0 + r * a.cos(), at.1 + r * a.sin());
        if world.is_clear(x, y, 0.4, 0.05, 1.0) && inside(world, x, y) {
            return Ok((x, y));
        }
    }
    spot(world, rng)
}

/// Whether `(x, y)` lies inside the world's bounding box (spots near a spot stay indoors).
fn inside(world: &World, x: f64, y: f64) -> bool {
    world.bounds().is_some_and(|b| {
        x > b.min.x + 0.4 && x < b.max.x - 0.4 && y > b.min.y + 0.4 && y < b.max.y - 0.4
    })
}

/// A drawn pair: the scans, the truth, and where the target was taken (for the alias test).
struct Drawn {
    source: PointCloud,
    target: PointCloud,
    truth: Option<Pose>,
    world: Arc<World>,
    t_world_target: Pose,
}

/// A two-scan pair of `world` from robot poses `a` (target) and `b` (source).
fn pair(rig: &Rig, world: &Arc<World>, a: Pose, b: Pose, seed: u64) -> Drawn {
    Drawn {
        target: rig.scan(world, &a, seed, 0),
        source: rig.scan(world, &b, seed, 1),
        truth: Some(a.inverse() * b),
        world: Arc::clone(world),
        t_world_target: a,
    }
}

/// [`pair`] of robots standing at `a` (target) and `b` (source), each turned at random.
fn pair_with_random_headings(
    rig: &Rig,
    world: &Arc<World>,
    a: (f64, f64),
    b: (f64, f64),
    seed: u64,
    rng: &mut SimRng,
) -> Drawn {
    let pa = robot_at(a.0, a.1, random_yaw(rng));
    let pb = robot_at(b.0, b.1, random_yaw(rng));
    pair(rig, world, pa, pb, seed)
}

/// The share of a drawn pair's source voxels that meet the target's at the truth (0
/// without one).
fn true_overlap(d: &Drawn) -> Result<f64> {
    match d.truth {
        Some(t) => overlap_at(&d.source, &d.target, &t),
        None => Ok(0.0),
    }
}

/// Lab or office, by the seed's parity.
fn furnished(seed: u64) -> Arc<World> {
    Arc::new(if seed.is_multiple_of(2) {
        lab(seed)
    } else {
        office(seed)
    })
}

fn draw(scene: TrustScene, seed: u64, rng: &mut SimRng) -> Result<TrustCase> {
    let rig = Rig::new();
    let d = match scene {
        TrustScene::SamePlace | TrustScene::Partial | TrustScene::Outliers => {
            let mut d = same_place(&rig, seed, rng)?;
            if scene == TrustScene::Partial {
                d.source = sector(&d.source, random_yaw(rng), 120f64.to_radians());
            } else if scene == TrustScene::Outliers {
                d.source = with_outliers(&d.source, rng);
            }
            d
        }
        TrustScene::LowOverlap => low_overlap(&rig, seed, rng)?,
        TrustScene::Subset => {
            let world = furnished(seed);
            let a = spot(&world, rng)?;
            let at = robot_at(a.0, a.1, random_yaw(rng));
            let target = rig.scan(&world, &at, seed, 0);
            let piece = piece_of(&target, 1.5, rng);
            let moved = Pose::from_xyz_ypr(
                rng.range(-2.0, 2.0),
                rng.range(-2.0, 2.0),
                0.0,
                random_yaw(rng),
                0.0,
                0.0,
            );
            Drawn {
                source: piece.transformed(&moved),
                target,
                truth: Some(moved.inverse()),
                world,
                t_world_target: at,
            }
        }
        TrustScene::Unrelated => {
            let worlds = [
                lab(seed),
                office(seed),
                twin_rooms(seed),
                desk_hall(seed),
                symmetric_hall(seed),
                corridor(seed),
            ];
            let i = rng.index(worlds.len());
            let j = (i + 1 + rng.index(worlds.len() - 1)) % worlds.len();
            let (wa, wb) = (&worlds[i], &worlds[j]);
            let a = spot(wa, rng)?;
            let b = spot(wb, rng)?;
            let at = robot_at(a.0, a.1, random_yaw(rng));
            let target = rig.scan(wa, &at, seed, 0);
            let source = rig.scan(wb, &robot_at(b.0, b.1, random_yaw(rng)), seed, 1);
            Drawn {
                source,
                target,
                truth: None,
                world: Arc::new(wa.clone()),
                t_world_target: at,
            }
        }
        TrustScene::TwinRooms | TrustScene::DeskRows | TrustScene::SymmetricHall => {
            let (world, lo, hi) = match scene {
                TrustScene::TwinRooms => (twin_rooms(seed), 0.5, 12.0),
                TrustScene::DeskRows => (desk_hall(seed), 1.0, 5.0),
                _ => (symmetric_hall(seed), 0.5, 10.0),
            };
            let world = Arc::new(world);
            let a = spot(&world, rng)?;
            let b = spot_near(&world, rng, a, lo, hi)?;
            pair(
                &rig,
                &world,
                robot_at(a.0, a.1, random_yaw(rng)),
                robot_at(b.0, b.1, random_yaw(rng)),
                seed,
            )
        }
        TrustScene::Corridor => {
            let world = Arc::new(corridor(seed));
            let x = rng.range(8.0, 32.0);
            let dx = rng.range(1.0, 6.0) * if rng.chance(0.5) { 1.0 } else { -1.0 };
            let yaw_a = along_x(rng);
            let yaw_b = yaw_a + rng.range(-0.5, 0.5);
            pair(
                &rig,
                &world,
                robot_at(x, 1.0 + rng.range(-0.3, 0.3), yaw_a),
                robot_at(x + dx, 1.0 + rng.range(-0.3, 0.3), yaw_b),
                seed,
            )
        }
        TrustScene::OppositeCorridors => {
            // The ring's long corridors run along x (outer walls 0-26 m): the south one's
            // centre line at y = 1.5 m, the north one's at 14.5 m. Their middles (x 9-17 m)
            // see neither end within the scanner's 8 m.
            let world = corridor_ring(seed);
            let along = |y: f64, rng: &mut SimRng| {
                let yaw = along_x(rng);
                robot_at(
                    rng.range(9.0, 17.0),
                    y + rng.range(-0.3, 0.3),
                    yaw + rng.range(-0.3, 0.3),
                )
            };
            let (south, north) = (along(1.5, rng), along(14.5, rng));
            let (at, from) = if rng.chance(0.5) {
                (south, north)
            } else {
                (north, south)
            };
            Drawn {
                target: rig.scan(&world, &at, seed, 0),
                source: rig.scan(&world, &from, seed, 1),
                truth: None,
                world: Arc::new(world),
                t_world_target: at,
            }
        }
        TrustScene::RingCorridor => {
            // One long side of the ring (outer walls 0-26 m along x; centre lines at y = 1.5
            // and 14.5 m), away from the corners.
            let world = Arc::new(corridor_ring(seed));
            let y = if rng.chance(0.5) { 1.5 } else { 14.5 };
            let x = rng.range(5.0, 21.0);
            let dx = rng.range(1.0, 6.0) * if rng.chance(0.5) { 1.0 } else { -1.0 };
            let yaw = along_x(rng);
            pair(
                &rig,
                &world,
                robot_at(x, y + rng.range(-0.3, 0.3), yaw + rng.range(-0.3, 0.3)),
                robot_at(
                    (x + dx).clamp(3.5, 22.5),
                    y + rng.range(-0.3, 0.3),
                    yaw + rng.range(-0.3, 0.3),
                ),
                seed,
            )
        }
        TrustScene::Planar | TrustScene::TwoWalls => {
            let world = Arc::new(if scene == TrustScene::Planar {
                floor_only()
            } else {
                two_walls()
            });
            let a = (rng.range(1.0, 5.0), rng.range(1.0, 5.0));
            let b = (a.0 + rng.range(-2.0, 2.0), a.1 + rng.range(-2.0, 2.0));
            let b = (b.0.max(0.8), b.1.max(0.8));
            pair_with_random_headings(&rig, &world, a, b, seed, rng)
        }
    };
    let true_overlap = true_overlap(&d)?;
    Ok(TrustCase {
        scene,
        name: String::new(),
        source: d.source,
        target: d.target,
        truth: d.truth,
        true_overlap,
        world: d.world,
        t_world_target: d.t_world_target,
    })
}

/// One pair of scans in `world`, `near` metres apart (minimum, maximum) with random
/// headings, and the source's true overlap with the target.
fn draw_in_world(
    rig: &Rig,
    world: &Arc<World>,
    seed: u64,
    rng: &mut SimRng,
    near: (f64, f64),
) -> Result<(f64, Drawn)> {
    let a = spot(world, rng)?;
    let b = spot_near(world, rng, a, near.0, near.1)?;
    let p = pair_with_random_headings(rig, world, a, b, seed, rng);
    Ok((true_overlap(&p)?, p))
}

/// Two scans 0.5-3 m apart in one furnished world that share at least 30 % of the source's
/// voxels (up to 60 draws; the best otherwise).
fn same_place(rig: &Rig, seed: u64, rng: &mut SimRng) -> Result<Drawn> {
    let world = furnished(seed);
    let mut best: Option<(f64, Drawn)> = None;
    for _ in 0..60 {
        let (f, p) = draw_in_world(rig, &world, seed, rng, (0.5, 3.0))?;
        if f >= 0.3 {
            return Ok(p);
        }
        if best.as_ref().is_none_or(|(g, _)| f > *g) {
            best = Some((f, p));
        }
    }
    best.map(|(_, p)| p)
        .ok_or_else(|| Error::InvalidArgument("no same-place pair".into()))
}

/// Pairs of one world drawn until the true overlap is 5-15 % (up to 60 tries; the last
/// draw otherwise).
fn low_overlap(rig: &Rig, seed: u64, rng: &mut SimRng) -> Result<Drawn> {
    let world = furnished(seed);
    let mut last = None;
    for _ in 0..60 {
        let (f, d) = draw_in_world(rig, &world, seed, rng, (2.0, 9.0))?;
        if (0.05..=0.15).contains(&f) {
            return Ok(d);
        }
        last = Some(d);
    }
    last.ok_or_else(|| Error::InvalidArgument("no low-overlap pair".into()))
}

/// The fraction of the source's 0.1 m voxels (moved by `pose`) that the target occupies.
fn overlap_at(source: &PointCloud, target: &PointCloud, pose: &Pose) -> Result<f64> {
    let res = 0.1;
    let t = OccupancyList::from_cloud(target, res)?;
    let s = OccupancyList::from_cloud(&source.transformed(pose), res)?;
    if s.is_empty() {
        return Ok(0.0);
    }
    let hits = s.iter().filter(|(k, _)| t.count(*k) > 0).count();
    Ok(hits as f64 / s.len() as f64)
}

/// The points of `cloud` whose bearing from the sensor (about z) lies within `width / 2` of
/// `centre`.
fn sector(cloud: &PointCloud, centre: f64, width: f64) -> PointCloud {
    let o = cloud.origin();
    let keep: Vec<Point3<f32>> = cloud
        .points()
        .iter()
        .copied()
        .filter(|p| {
            let a = (p.y as f64 - o.y).atan2(p.x as f64 - o.x);
            crate::geometry::wrap_angle(a - centre).abs() <= 0.5 * width
        })
        .collect();
    with_origin(keep, o)
}

/// `cloud` with as many uniformly random points (in its bounding box) as it has.
fn with_outliers(cloud: &PointCloud, rng: &mut SimRng) -> PointCloud {
    let mut pts = cloud.points().to_vec();
    if let Some(b) = cloud.bounding_box() {
        for _ in 0..cloud.len() {
            let p = Vector3::new(
                rng.range(b.min.x, b.max.x),
                rng.range(b.min.y, b.max.y),
                rng.range(b.min.z, b.max.z),
            );
            pts.push(Point3::from(p.cast::<f32>()));
        }
    }
    with_origin(pts, cloud.origin())
}

/// The points within `radius` of one of the cloud's points (picked at random among those
/// 1.5-5 m from the sensor).
fn piece_of(cloud: &PointCloud, radius: f32, rng: &mut SimRng) -> PointCloud {
    let o = cloud.origin().cast::<f32>();
    let far: Vec<&Point3<f32>> = cloud
        .points()
        .iter()
        .filter(|p| (1.5..=5.0).contains(&(**p - o).norm()))
        .collect();
    let pool: Vec<&Point3<f32>> = if far.is_empty() {
        cloud.points().iter().collect()
    } else {
        far
    };
    if pool.is_empty() {
        return cloud.clone();
    }
    let centre = *pool[rng.index(pool.len())];
    let keep = cloud
        .points()
        .iter()
        .copied()
        .filter(|p| (p - centre).norm() <= radius)
        .collect();
    with_origin(keep, cloud.origin())
}

fn with_origin(points: Vec<Point3<f32>>, origin: Point3<f64>) -> PointCloud {
    let mut c = PointCloud::from_points(points);
    c.set_origin(origin);
    c
}
