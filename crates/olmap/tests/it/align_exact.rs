//! The exact (branch-and-bound) search against the exhaustive search (Algorithm 7) on
//! small problems: every degree-of-freedom set, windows and the whole target, with and
//! without free space. The exact search must return the exhaustive search's result: the
//! same best score and pose, the same candidates (up to [`align::EXACT_MAX_AMBIGUITY`])
//! and ambiguity (up to one more: "more than the cap").

use olmap::align::{self, Alignment, Dof, Region, SearchMode, SearchParams, SearchTarget};
use olmap::geometry::Pose;
use olmap::occupancy::OccupancyList;

fn same(exact: &Alignment, sure: &Alignment, what: &str) {
    assert!(exact.exact && sure.exact, "{what}: both are guaranteed");
    assert_eq!(exact.score, sure.score, "{what}: best score");
    assert_eq!(exact.overlap, sure.overlap, "{what}: best overlap");
    assert_eq!(
        exact.pose.to_row_major_3x4(),
        sure.pose.to_row_major_3x4(),
        "{what}: best pose"
    );
    assert_eq!(
        exact.ambiguity,
        sure.ambiguity.min(align::EXACT_MAX_AMBIGUITY + 1),
        "{what}: ambiguity (counted up to one past the cap)"
    );
    // The exhaustive search lists up to 32 heads; the exact one counts (and lists) up to
    // its cap.
    let listed = sure.candidates.len().min(align::EXACT_MAX_AMBIGUITY);
    assert_eq!(
        exact.candidates,
        sure.candidates[..listed],
        "{what}: candidates (up to the exact search's cap)"
    );
}

/// A small deterministic generator (the cases are fixed, and differ from each other).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

#[test]
fn exact_equals_exhaustive_on_random_small_problems() {
    let pts = olmap::fixtures::furnished_room(0.05);
    let mut rng = Lcg(12);
    let dofs = [
        Dof::XyYaw,
        Dof::XyzYaw,
        Dof::SixDof {
            max_tilt: 3f64.to_radians(),
        },
    ];
    for case in 0..9 {
        let dof = dofs[case % 3];
        let t_room_target = Pose::from_xyz_ypr(
            rng.range(4.0, 8.0),
            rng.range(3.0, 6.0),
            1.2,
            rng.range(-3.0, 3.0),
            0.0,
            0.0,
        );
        let motion = Pose::from_xyz_ypr(
            rng.range(-0.8, 0.8),
            rng.range(-0.8, 0.8),
            0.0,
            rng.range(-0.2, 0.2),
            0.0,
            0.0,
        );
        let range = 6.0;
        let target_cloud = olmap::fixtures::scan_of(&pts, &t_room_target, range);
        let source = olmap::fixtures::scan_of(&pts, &(t_room_target * motion), range);
        let resolution = 0.25;
        let (xy, z, yaw) = match dof {
            Dof::SixDof { .. } => (0.6, 0.25, 4f64.to_radians()),
            _ => (1.0, 0.5, 15f64.to_radians()),
        };
        let params = SearchParams {
            resolution,
            levels: 3,
            dof,
            region: Region::Window { xy, z, yaw },
            max_scan_voxels: 400,
            max_range: range,
            search: SearchMode::Exact,
            ..Default::default()
        };
        // With free space (a target from a scan) on even cases, occupancy only on odd ones.
        let target = if case % 2 == 0 {
            SearchTarget::from_cloud(&target_cloud, resolution, 3).unwrap()
        } else {
            let map = OccupancyList::from_cloud(&target_cloud, resolution).unwrap();
            SearchTarget::from_map(map, 3).unwrap()
        };
        let exact = align::global_search(&source, &target, &params).unwrap();
        let sure = align::exhaustive_search(&source, &target, &params).unwrap();
        same(&exact, &sure, &format!("case {case} ({dof:?})"));
    }
}

#[test]
fn exact_equals_exhaustive_over_the_whole_target() {
    let pts = olmap::fixtures::furnished_room(0.05);
    let t_room_target = Pose::from_xyz_ypr(6.0, 4.5, 1.2, 0.4, 0.0, 0.0);
    let motion = Pose::from_xyz_ypr(0.9, -0.4, 0.0, 2.0, 0.0, 0.0);
    let range = 4.0;
    let target = olmap::fixtures::scan_of(&pts, &t_room_target, range);
    let source = olmap::fixtures::scan_of(&pts, &(t_room_target * motion), range);
    let params = SearchParams {
        resolution: 0.3,
        levels: 3,
        dof: Dof::XyYaw,
        region: Region::Global,
        max_scan_voxels: 300,
        max_range: range,
        search: SearchMode::Exact,
        ..Default::default()
    };
    let target = SearchTarget::from_cloud(&target, params.resolution, params.levels).unwrap();
    let exact = align::global_search(&source, &target, &params).unwrap();
    let sure = align::exhaustive_search(&source, &target, &params).unwrap();
    same(&exact, &sure, "whole target, every heading");
    // More clusters than the exact search lists: it lists the cap and counts one more, so
    // a verification sees a head it was not given (and a global match is doubted).
    assert!(
        sure.ambiguity > align::EXACT_MAX_AMBIGUITY,
        "{}",
        sure.ambiguity
    );
    assert_eq!(exact.ambiguity, align::EXACT_MAX_AMBIGUITY + 1);
    assert_eq!(exact.candidates.len(), align::EXACT_MAX_AMBIGUITY);
    // This room is very ambiguous (30 clusters); each cluster is a further pass. With one
    // neighbourhood holding every pose, one pass finds the optimum and the second starts
    // with nothing left: the pruning alone must bound fewer nodes than there are poses.
    let one = SearchParams {
        ambiguity_distance: 100.0,
        ambiguity_angle: std::f64::consts::PI,
        ..params.clone()
    };
    let exact_one = align::global_search(&source, &target, &one).unwrap();
    let sure_one = align::exhaustive_search(&source, &target, &one).unwrap();
    same(&exact_one, &sure_one, "whole target, one cluster");
    assert_eq!(exact_one.ambiguity, 1);
    assert!(
        exact_one.evaluated < sure_one.evaluated / 2,
        "branch and bound bounds fewer nodes ({}) than half the poses ({})",
        exact_one.evaluated,
        sure_one.evaluated
    );
    // The multi-resolution search is not guaranteed, and never beats the optimum.
    let fast = align::global_search(
        &source,
        &target,
        &SearchParams {
            search: SearchMode::MultiResolution,
            ..params.clone()
        },
    )
    .unwrap();
    assert!(!fast.exact);
    assert!(fast.score <= exact.score);
}

/// The whole target in x, y, z and heading at a resolution fine enough for the bound grids
/// to sample their windows every 2 or 4 cells at the coarse levels.
#[test]
fn exact_equals_exhaustive_in_3d_over_the_whole_target() {
    let pts = olmap::fixtures::furnished_room(0.05);
    let t_room_target = Pose::from_xyz_ypr(5.0, 4.0, 1.2, -0.7, 0.0, 0.0);
    let motion = Pose::from_xyz_ypr(-0.6, 0.7, 0.1, 1.1, 0.0, 0.0);
    let range = 5.0;
    let target = olmap::fixtures::scan_of(&pts, &t_room_target, range);
    let source = olmap::fixtures::scan_of(&pts, &(t_room_target * motion), range);
    let params = SearchParams {
        resolution: 0.2,
        levels: 5,
        dof: Dof::XyzYaw,
        region: Region::Global,
        max_scan_voxels: 250,
        max_range: range,
        search: SearchMode::Exact,
        ..Default::default()
    };
    let target = SearchTarget::from_cloud(&target, params.resolution, params.levels).unwrap();
    let exact = align::global_search(&source, &target, &params).unwrap();
    let sure = align::exhaustive_search(&source, &target, &params).unwrap();
    eprintln!(
        "3d whole: exact {} ({} nodes), exhaustive {} ({} poses)",
        exact.score, exact.evaluated, sure.score, sure.evaluated
    );
    same(&exact, &sure, "whole target in 3D");
}
