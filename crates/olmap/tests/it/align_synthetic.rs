//! Global alignment on synthetic scenes: the multi-resolution search against the
//! exhaustive reference, and random rigid motions recovered.

use olmap::align::{self, Dof, Region, SearchParams, SearchTarget};
use olmap::geometry::{Pose, PoseError};
use proptest::prelude::*;

#[test]
fn multi_resolution_equals_exhaustive_on_small_problems() {
    let pts = olmap::fixtures::furnished_room(0.05);
    let t_room_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.0, 0.0, 0.0);
    let target = olmap::fixtures::scan_of(&pts, &t_room_target, 8.0);
    for (i, motion) in [
        Pose::from_xyz_ypr(0.43, -0.27, 0.0, 4f64.to_radians(), 0.0, 0.0),
        Pose::from_xyz_ypr(-0.61, 0.35, 0.0, -7f64.to_radians(), 0.0, 0.0),
        Pose::from_xyz_ypr(0.12, 0.71, 0.0, 2f64.to_radians(), 0.0, 0.0),
    ]
    .iter()
    .enumerate()
    {
        let t_room_source = t_room_target * *motion;
        let source = olmap::fixtures::scan_of(&pts, &t_room_source, 8.0);
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
        let pts = olmap::fixtures::furnished_room(0.05);
        let t_room_target = Pose::from_xyz_ypr(sx, sy, 1.2, 0.3, 0.0, 0.0);
        let motion = Pose::from_xyz_ypr(x, y, 0.0, yaw, 0.0, 0.0);
        let t_room_source = t_room_target * motion;
        let source = olmap::fixtures::scan_of(&pts, &t_room_source, 15.0);
        let target = olmap::fixtures::scan_of(&pts, &t_room_target, 15.0);
        let a = align::align_clouds(&source, &target, &SearchParams::default()).unwrap();
        let e = PoseError::between(&a.pose, &motion);
        // The search lattice is 0.1 m and 0.2 degrees at the finest level.
        prop_assert!(e.translation_m < 0.15 && e.rotation_deg < 1.0, "{e:?} for {motion}");
    }
}
