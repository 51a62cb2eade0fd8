//! Synthetic scenes shared by tests, benchmarks and examples (the full simulator is a
//! separate module).

use nalgebra::Point3;

use crate::cloud::PointCloud;
use crate::geometry::Pose;

/// Points on the surfaces of a 40 x 10 x 3 m hall (floor, four walls) with 140
/// pseudo-random boxes (fixed seed), every `step` metres, in the hall frame (origin at a
/// floor corner, x along the hall).
///
/// ```
/// let pts = olmap::fixtures::hall(0.5);
/// assert!(pts.iter().all(|p| p.x >= 0.0 && p.x <= 40.5 && p.z >= 0.0));
/// ```
pub fn hall(step: f64) -> Vec<Point3<f64>> {
    let mut pts = Vec::new();
    let mut face = |o: [f64; 3], u: [f64; 3], v: [f64; 3], lu: f64, lv: f64| {
        for i in 0..=((lu / step) as i32) {
            for j in 0..=((lv / step) as i32) {
                let (a, b) = (i as f64 * step, j as f64 * step);
                pts.push(Point3::new(
                    o[0] + a * u[0] + b * v[0],
                    o[1] + a * u[1] + b * v[1],
                    o[2] + a * u[2] + b * v[2],
                ));
            }
        }
    };
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    face([0.0, 0.0, 0.0], x, y, 40.0, 10.0);
    face([0.0, 0.0, 0.0], x, z, 40.0, 3.0);
    face([0.0, 10.0, 0.0], x, z, 40.0, 3.0);
    face([0.0, 0.0, 0.0], y, z, 10.0, 3.0);
    face([40.0, 0.0, 0.0], y, z, 10.0, 3.0);
    let mut s = 0x1234_5678_9abc_def1u64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..140 {
        let (bx, by) = (1.0 + next() * 37.0, 0.3 + next() * 9.0);
        let (w, d, h) = (0.4 + next() * 1.5, 0.4 + next() * 1.0, 0.5 + next() * 2.0);
        face([bx, by, 0.0], x, z, w, h);
        face([bx, by + d, 0.0], x, z, w, h);
        face([bx, by, 0.0], y, z, d, h);
        face([bx + w, by, 0.0], y, z, d, h);
        face([bx, by, h], x, y, w, d);
    }
    pts
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
