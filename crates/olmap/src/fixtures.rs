//! Synthetic scenes shared by tests, benchmarks and examples (the full simulator is a
//! separate module).

use nalgebra::Point3;

use crate::cloud::PointCloud;
use crate::geometry::Pose;

/// Points sampled on axis-aligned rectangles every `step` metres.
struct Surfaces {
    step: f64,
    pts: Vec<Point3<f64>>,
}

const X: [f64; 3] = [1.0, 0.0, 0.0];
const Y: [f64; 3] = [0.0, 1.0, 0.0];
const Z: [f64; 3] = [0.0, 0.0, 1.0];

impl Surfaces {
    /// The rectangle from corner `o` spanning `lu` along `u` and `lv` along `v`.
    fn rect(&mut self, o: [f64; 3], u: [f64; 3], v: [f64; 3], lu: f64, lv: f64) {
        for i in 0..=((lu / self.step) as i32) {
            for j in 0..=((lv / self.step) as i32) {
                let (a, b) = (i as f64 * self.step, j as f64 * self.step);
                self.pts.push(Point3::new(
                    o[0] + a * u[0] + b * v[0],
                    o[1] + a * u[1] + b * v[1],
                    o[2] + a * u[2] + b * v[2],
                ));
            }
        }
    }

    /// A room's floor and four walls, `lx` x `ly` x `h`, corner at the origin.
    fn room(&mut self, lx: f64, ly: f64, h: f64) {
        self.rect([0.0, 0.0, 0.0], X, Y, lx, ly);
        self.rect([0.0, 0.0, 0.0], X, Z, lx, h);
        self.rect([0.0, ly, 0.0], X, Z, lx, h);
        self.rect([0.0, 0.0, 0.0], Y, Z, ly, h);
        self.rect([lx, 0.0, 0.0], Y, Z, ly, h);
    }

    /// A box standing on the floor at `(bx, by)`, `w` x `d` x `h`: four sides and the top.
    fn block(&mut self, bx: f64, by: f64, w: f64, d: f64, h: f64) {
        self.rect([bx, by, 0.0], X, Z, w, h);
        self.rect([bx, by + d, 0.0], X, Z, w, h);
        self.rect([bx, by, 0.0], Y, Z, d, h);
        self.rect([bx + w, by, 0.0], Y, Z, d, h);
        self.rect([bx, by, h], X, Y, w, d);
    }
}

/// Points on the surfaces of a 40 x 10 x 3 m hall (floor, four walls) with 140
/// pseudo-random boxes (fixed seed), every `step` metres, in the hall frame (origin at a
/// floor corner, x along the hall).
///
/// ```
/// let pts = olmap::fixtures::hall(0.5);
/// assert!(pts.iter().all(|p| p.x >= 0.0 && p.x <= 40.5 && p.z >= 0.0));
/// ```
pub fn hall(step: f64) -> Vec<Point3<f64>> {
    let mut s = Surfaces {
        step,
        pts: Vec::new(),
    };
    s.room(40.0, 10.0, 3.0);
    let mut seed = 0x1234_5678_9abc_def1u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..140 {
        let (bx, by) = (1.0 + next() * 37.0, 0.3 + next() * 9.0);
        let (w, d, h) = (0.4 + next() * 1.5, 0.4 + next() * 1.0, 0.5 + next() * 2.0);
        s.block(bx, by, w, d, h);
    }
    s.pts
}

/// Points on the surfaces of an asymmetric furnished 12 x 9 x 3 m room (floor, walls,
/// three boxes, a pillar of radius 0.3 m at (9, 2.5)), every `step` metres, corner at the
/// origin.
pub fn furnished_room(step: f64) -> Vec<Point3<f64>> {
    let mut s = Surfaces {
        step,
        pts: Vec::new(),
    };
    s.room(12.0, 9.0, 3.0);
    for (bx, by, w, d, h) in [
        (2.0, 1.5, 1.2, 0.8, 0.9),
        (8.5, 6.0, 2.0, 1.0, 1.6),
        (5.0, 7.2, 0.6, 0.6, 2.2),
    ] {
        s.block(bx, by, w, d, h);
    }
    for k in 0..40 {
        let a = k as f64 / 40.0 * std::f64::consts::TAU;
        for j in 0..30 {
            s.pts.push(Point3::new(
                9.0 + 0.3 * a.cos(),
                2.5 + 0.3 * a.sin(),
                j as f64 * 0.1,
            ));
        }
    }
    s.pts
}

/// The scene points within `range` metres of a sensor at pose `T_scene_sensor`, in the
/// sensor frame (no occlusion: every surface in range is seen).
pub fn scan_of(scene: &[Point3<f64>], t_scene_sensor: &Pose, range: f64) -> PointCloud {
    let inv = t_scene_sensor.inverse();
    let origin = Point3::from(t_scene_sensor.translation());
    PointCloud::from_points(
        scene
            .iter()
            .filter(|p| (*p - origin).norm() < range)
            .map(|p| inv.transform_point(p).cast::<f32>())
            .collect(),
    )
}

/// `n` stops along the hall (x from 2 m, `spacing` metres apart, small deterministic
/// sideways and heading offsets), as `T_hall_sensor` with the sensor 2.8 m up.
pub fn hall_trajectory(n: usize, spacing: f64) -> Vec<Pose> {
    (0..n)
        .map(|i| {
            Pose::from_xyz_ypr(
                2.0 + spacing * i as f64,
                5.0 + 0.2 * ((i * 7 % 5) as f64 - 2.0),
                2.8,
                0.2 * ((i * 3 % 7) as f64 - 3.0) / 3.0,
                0.0,
                0.0,
            )
        })
        .collect()
}

/// The three 3DTK example scans of the shared data folder `data_dir` (`3dtk_dat/scan00N.3d`,
/// 3DTK's validity filter applied) as map-building input, with their `.pose` odometry when
/// `odometry`.
pub fn threedtk_scans(
    data_dir: &std::path::Path,
    odometry: bool,
) -> crate::Result<Vec<crate::mapping::ScanInput>> {
    let valid = crate::io::ReadOptions {
        uos_valid_only: true,
        ..Default::default()
    };
    (0..3)
        .map(|i| {
            let base = data_dir.join(format!("3dtk_dat/scan00{i}"));
            Ok(crate::mapping::ScanInput {
                name: format!("scan00{i}"),
                cloud: crate::io::read_cloud_with(base.with_extension("3d"), &valid)?.cloud,
                odometry: if odometry {
                    Some(crate::io::slam6d::read_pose_path(
                        base.with_extension("pose"),
                    )?)
                } else {
                    None
                },
            })
        })
        .collect()
}
