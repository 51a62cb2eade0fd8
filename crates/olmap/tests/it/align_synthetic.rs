//! Global alignment on synthetic scenes: the multi-resolution search against the
//! exhaustive reference, and random rigid motions recovered.

use nalgebra::Point3;
use olmap::align::{self, Dof, Region, SearchParams, SearchTarget};
use olmap::cloud::PointCloud;
use olmap::geometry::{Pose, PoseError};
use proptest::prelude::*;

/// Points on the surfaces of an asymmetric furnished room (walls, floor, boxes, a pillar),
/// every `step` metres, in the room frame.
pub fn room(step: f64) -> Vec<Point3<f64>> {
    let mut pts = Vec::new();
    let mut face = |o: [f64; 3], u: [f64; 3], v: [f64; 3], lu: f64, lv: f64| {
        let (nu, nv) = ((lu / step) as i32, (lv / step) as i32);
        for i in 0..=nu {
            for j in 0..=nv {
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
    // Room 12 x 9 x 3 m, origin at a corner.
    face([0.0, 0.0, 0.0], x, y, 12.0, 9.0);
    face([0.0, 0.0, 0.0], x, z, 12.0, 3.0);
    face([0.0, 9.0, 0.0], x, z, 12.0, 3.0);
    face([0.0, 0.0, 0.0], y, z, 9.0, 3.0);
    face([12.0, 0.0, 0.0], y, z, 9.0, 3.0);
    // Boxes (two visible faces each) and a pillar: break every symmetry.
    for &(bx, by, w, d, h) in &[
        (2.0, 1.5, 1.2, 0.8, 0.9),
        (8.5, 6.0, 2.0, 1.0, 1.6),
        (5.0, 7.2, 0.6, 0.6, 2.2),
    ] {
        face([bx, by, 0.0], x, z, w, h);
        face([bx, by, 0.0], y, z, d, h);
        face([bx + w, by, 0.0], y, z, d, h);
        face([bx, by + d, 0.0], x, z, w, h);
        face([bx, by, h], x, y, w, d);
    }
    for k in 0..40 {
        let a = k as f64 / 40.0 * std::f64::consts::TAU;
        for j in 0..30 {
            pts.push(Point3::new(
                9.0 + 0.3 * a.cos(),
                2.5 + 0.3 * a.sin(),
                j as f64 * 0.1,
            ));
        }
    }
    pts
}

/// The room seen from a sensor at `sensor` (room frame): points within `range`, in the
/// sensor frame of a sensor with pose `T_room_sensor`.
fn scan(pts: &[Point3<f64>], t_room_sensor: &Pose, range: f64) -> PointCloud {
    let inv = t_room_sensor.inverse();
    let origin = Point3::from(t_room_sensor.translation());
    PointCloud::from_points(
        pts.iter()
            .filter(|p| (*p - origin).norm() < range)
            .map(|p| inv.transform_point(p).cast::<f32>())
            .collect(),
    )
}

#[test]
fn multi_resolution_equals_exhaustive_on_small_problems() {
    let pts = room(0.05);
    let t_room_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.0, 0.0, 0.0);
    let target = scan(&pts, &t_room_target, 8.0);
    for (i, motion) in [
        Pose::from_xyz_ypr(0.43, -0.27, 0.0, 4f64.to_radians(), 0.0, 0.0),
        Pose::from_xyz_ypr(-0.61, 0.35, 0.0, -7f64.to_radians(), 0.0, 0.0),
        Pose::from_xyz_ypr(0.12, 0.71, 0.0, 2f64.to_radians(), 0.0, 0.0),
    ]
    .iter()
    .enumerate()
    {
        let t_room_source = t_room_target * *motion;
        let source = scan(&pts, &t_room_source, 8.0);
        let params = SearchParams {
            resolution: 0.2,
            levels: 3,
            dof: Dof::XyYaw,
            region: Region::Window {
                xy: 1.0,
                z: 0.0,
                yaw: 10f64.to_radians(),
            },
            max_survivors: 10_000,
            ..Default::default()
        };
        let target = SearchTarget::from_cloud(&target, params.resolution, params.levels).unwrap();
        let fast = align::global_search(&source, &target, &params).unwrap();
        let sure = align::exhaustive_search(&source, &target, &params).unwrap();
        let same_cell = (fast.pose.translation() - sure.pose.translation()).norm() < 1e-9
            && PoseError::between(&fast.pose, &sure.pose).rotation_deg < 1e-9;
        assert!(
            same_cell || fast.overlap + 1 >= sure.overlap,
            "case {i}: multi-resolution {} at {} vs exhaustive {} at {}",
            fast.overlap,
            fast.pose,
            sure.overlap,
            sure.pose
        );
        assert!(
            sure.evaluated > fast.evaluated,
            "the multi-resolution search evaluates fewer poses"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    #[test]
    fn random_rigid_motions_are_recovered(
        x in -2.0f64..2.0, y in -1.5f64..1.5, yaw in -3.1f64..3.1, sx in 3.0f64..9.0, sy in 2.5f64..6.5,
    ) {
        let pts = room(0.05);
        let t_room_target = Pose::from_xyz_ypr(sx, sy, 1.2, 0.3, 0.0, 0.0);
        let motion = Pose::from_xyz_ypr(x, y, 0.0, yaw, 0.0, 0.0);
        let t_room_source = t_room_target * motion;
        let source = scan(&pts, &t_room_source, 15.0);
        let target = scan(&pts, &t_room_target, 15.0);
        let a = align::align_clouds(&source, &target, &SearchParams::default()).unwrap();
        let e = PoseError::between(&a.pose, &motion);
        // The search lattice is 0.1 m and 0.2 degrees at the finest level.
        prop_assert!(e.translation_m < 0.15 && e.rotation_deg < 1.0, "{e:?} for {motion}");
    }
}
