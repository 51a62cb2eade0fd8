//! Arguments and limits (issue 22): no parameter makes the library panic, exhaust the
//! machine or silently lose data. Each test is named after the failure it pins (the audit
//! of issue 22 found them from the command line; the CLI's own tests are in
//! `crates/olmap-cli/tests/limits.rs`).

use nalgebra::{Point3, Vector3};
use olmap::align::{self, Dof, Region, RegisterParams, SearchMode, SearchParams, SearchTarget};
use olmap::cloud::{LaserScan, PointCloud};
use olmap::geometry::{Aabb, Pose, VoxelKey};
use olmap::occupancy::{OccupancyList, SensorModel};
use olmap::Error;

/// Two scans of the furnished room 0.55 m and 6° apart, every 0.2 m (small and quick).
fn room_pair() -> (PointCloud, PointCloud) {
    let scene = olmap::fixtures::furnished_room(0.2);
    let at = |x, y, yaw| Pose::from_xyz_ypr(x, y, 1.5, yaw, 0.0, 0.0);
    let target = olmap::fixtures::scan_of(&scene, &at(6.0, 4.5, 0.0), 8.0);
    let source = olmap::fixtures::scan_of(&scene, &at(6.5, 4.3, 0.1), 8.0);
    (source, target)
}

fn register_with(search: SearchParams) -> olmap::Result<align::Registration> {
    let (source, target) = room_pair();
    let params = RegisterParams {
        search,
        refine: None,
        trust: Default::default(),
    };
    align::register(&source, &target, &params)
}

fn assert_invalid(e: &Error, words: &[&str]) {
    assert!(matches!(e, Error::InvalidArgument(_)), "{e:?}");
    for w in words {
        assert!(e.to_string().contains(w), "'{w}' not in: {e}");
    }
}

fn assert_too_large(e: &Error, words: &[&str]) {
    assert!(matches!(e, Error::TooLarge { .. }), "{e:?}");
    for w in words {
        assert!(e.to_string().contains(w), "'{w}' not in: {e}");
    }
}

#[test]
fn audit_align_resolution_above_max_range_is_an_error() {
    // `olmap align --resolution 40` (any resolution above --max-range) panicked in
    // params.rs ("min > max, or either was NaN").
    let e = register_with(SearchParams {
        resolution: 40.0,
        ..Default::default()
    })
    .unwrap_err();
    assert_invalid(&e, &["resolution (40 m)", "max_range (30 m)"]);
}

#[test]
fn audit_align_zero_max_range_and_nan_resolution_are_errors() {
    // `--max-range 0` and `--resolution nan` panicked there too, in align, map and localize.
    let cases = [
        ("max_range", 0.1, 0.0),
        ("max_range", 0.1, f64::NAN),
        ("max_range", 0.1, 1e-20),
        ("max_range", 0.1, f64::INFINITY),
        ("resolution", f64::NAN, 30.0),
        ("resolution", f64::INFINITY, 30.0),
        ("resolution", -1.0, 30.0),
    ];
    let (source, target) = room_pair();
    let map = OccupancyList::from_cloud(&target, 0.1).unwrap();
    for (name, resolution, max_range) in cases {
        let search = SearchParams {
            resolution,
            max_range,
            ..Default::default()
        };
        let e = register_with(search.clone()).unwrap_err();
        assert_invalid(&e, &[name]);
        if name == "max_range" {
            let params = RegisterParams {
                search: search.clone(),
                ..Default::default()
            };
            let e = align::localize(&source, &map, &params).unwrap_err();
            assert_invalid(&e, &[name]);
        }
        let mut map_params = olmap::mapping::MapParams::default();
        map_params.register.search = search;
        let scans: Vec<olmap::mapping::ScanInput> = [&target, &source]
            .iter()
            .enumerate()
            .map(|(i, c)| olmap::mapping::ScanInput {
                name: format!("scan{i}"),
                cloud: (*c).clone(),
                odometry: None,
            })
            .collect();
        let e = olmap::mapping::build_map(&scans, &map_params, |_, _| {}).unwrap_err();
        assert_invalid(&e, &[name]);
    }
}

#[test]
fn audit_far_guess_in_a_window_does_not_overflow() {
    // `--guess 1e20,0,0,0,0,0 --window 0.5,0.2,15` panicked in align/score/cells.rs (index
    // arithmetic overflowed): the search now finds no overlap there.
    for search in [SearchMode::MultiResolution, SearchMode::Exact] {
        let r = register_with(SearchParams {
            region: Region::Window {
                xy: 0.5,
                z: 0.2,
                yaw: 15f64.to_radians(),
            },
            prior: Pose::from_xyz_ypr(1e20, 0.0, 0.0, 0.0, 0.0, 0.0),
            search,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(r.search.overlap, 0, "{search:?}");
        assert!(!r.trusted);
    }
}

#[test]
fn audit_huge_window_is_refused_before_allocating() {
    // `--window 1e5,1,10` took 5.7 GB and 3e5 aborted on a 13 GB allocation.
    for xy in [1e5, 3e5, 1e9] {
        let e = register_with(SearchParams {
            region: Region::Window {
                xy,
                z: 1.0,
                yaw: 10f64.to_radians(),
            },
            ..Default::default()
        })
        .unwrap_err();
        assert_too_large(&e, &["uniform start", "GiB", "limit 4.0 GiB"]);
    }
}

#[test]
fn audit_tilt_and_window_yaw_beyond_a_half_turn_are_errors() {
    // `--dof 6dof --max-tilt 1e9` aborted on a 47 GB allocation (a tilt of 1e9 degrees).
    let e = register_with(SearchParams {
        dof: Dof::SixDof {
            max_tilt: 1e9f64.to_radians(),
        },
        ..Default::default()
    })
    .unwrap_err();
    assert_invalid(&e, &["max_tilt", "0 to 180 degrees"]);
    let e = register_with(SearchParams {
        region: Region::Window {
            xy: 1.0,
            z: 0.2,
            yaw: 1e9,
        },
        ..Default::default()
    })
    .unwrap_err();
    assert_invalid(&e, &["yaw half-range"]);
}

#[test]
fn audit_align_fine_resolution_names_the_point() {
    // `olmap align --resolution 1e-6` said "the target is empty": the points' keys
    // overflowed the packed range and were dropped.
    let e = register_with(SearchParams {
        resolution: 1e-6,
        ..Default::default()
    })
    .unwrap_err();
    assert_too_large(&e, &["the target: point", "coarser resolution"]);
}

#[test]
fn audit_voxel_key_overflow_names_the_point() {
    // `olmap convert scan000.3d v.xyz --voxel 1e-9` dropped 34 % of the points (keys beyond
    // i32) with exit 0; maps dropped points beyond the packed key range the same way.
    let cloud = PointCloud::from_points(vec![
        Point3::new(1.0, 0.0, 0.0),
        Point3::new(-0.5, 0.2, 0.0),
        Point3::new(3.0, 0.0, 0.0),
    ]);
    let e = cloud.voxel_downsample(1e-9).unwrap_err();
    assert_too_large(&e, &["point 2 at (3, 0, 0) m"]);
    // Inside the key range nothing is lost: three points, three voxels.
    let near = PointCloud::from_points(cloud.points()[..2].to_vec());
    assert_eq!(near.voxel_downsample(1e-9).unwrap().len(), 2);
    // Packed map keys: ±131,071 voxels, ±1.31 m at 10 µm.
    let e = OccupancyList::from_cloud(&cloud, 1e-5).unwrap_err();
    assert_too_large(&e, &["point 2 at (3, 0, 0) m"]);
    let e = SearchTarget::from_cloud(&cloud, 1e-5, 5).err().unwrap();
    assert_too_large(&e, &["the target: point 2"]);
    let moved = Pose::from_xyz_ypr(0.0, 2e4, 0.0, 0.0, 0.0, 0.0);
    let map = OccupancyList::new(0.1).unwrap();
    let e = map.check_keys(&near, &moved, "near.xyz").unwrap_err();
    assert_too_large(&e, &["near.xyz: point 0 at (1, 20000, 0) m"]);
    assert!(map.check_keys(&near, &Pose::identity(), "near.xyz").is_ok());
}

#[test]
fn audit_exact_search_gives_up_on_a_uniform_scene() {
    // The exact search on floor-vs-floor ran unbounded: every pose scores alike and no
    // bound prunes. Past its work budget it stops with a clear error (here a budget small
    // enough for a test; the default is `align::EXACT_MAX_WORK`).
    let floor: Vec<Point3<f32>> = (0..80)
        .flat_map(|i| (0..80).map(move |j| Point3::new(i as f32 * 0.1, j as f32 * 0.1, 0.0)))
        .collect();
    let target = PointCloud::from_points(floor.clone());
    let source = PointCloud::from_points(
        floor
            .iter()
            .filter(|p| p.x < 3.0 && p.y < 3.0)
            .copied()
            .collect(),
    );
    let params = SearchParams {
        search: SearchMode::Exact,
        dof: Dof::XyYaw,
        exact_max_work: 10_000_000,
        ..Default::default()
    };
    let e = align::align_clouds(&source, &target, &params).unwrap_err();
    assert_too_large(&e, &["exact search gave up", "multi-resolution"]);
    // Zero work is not a budget.
    let e = align::align_clouds(
        &source,
        &target,
        &SearchParams {
            exact_max_work: 0,
            ..params
        },
    )
    .unwrap_err();
    assert_invalid(&e, &["exact_max_work"]);
}

#[test]
fn audit_query_segment_with_far_ends_sees_the_occupied_voxel() {
    // `olmap query --segment` over 1e15 m was reported free through an occupied voxel (the
    // walk's keys wrapped), and `query --ray ... --max-range 1e12` walked 1e13 voxels.
    let mut map = OccupancyList::new(0.1).unwrap();
    map.set(VoxelKey::new(0, 0, 0), 3).unwrap();
    map.set(VoxelKey::new(40, 7, -2), 1).unwrap();
    let p = |x: f64| Point3::new(x, 0.05, 0.05);
    for far in [10.0, 1e6, 1e12, 1e15, 1e20, 1e300] {
        assert!(
            !map.segment_is_free(&p(-far), &p(far), 1).unwrap(),
            "segment ±{far} m"
        );
        assert!(
            map.segment_is_free(&p(0.5), &p(far), 1).unwrap(),
            "0.5 m to {far} m"
        );
        assert!(
            map.segment_is_free(
                &Point3::new(-far, 1.0, 0.05),
                &Point3::new(far, 1.0, 0.05),
                1
            )
            .unwrap(),
            "beside the voxel, ±{far} m"
        );
    }
    // A ray from 5 m away enters the voxel 4.9 m on, whatever its range.
    for range in [10.0, 1e6, 1e12, 1e300] {
        let hit = map
            .cast_ray(&p(5.0), &-Vector3::x(), range, 1)
            .unwrap()
            .unwrap_or_else(|| panic!("range {range} m"));
        assert_eq!(hit.key, VoxelKey::new(0, 0, 0));
        assert!((hit.distance - 4.9).abs() < 1e-6, "range {range}: {hit:?}");
        assert!(map
            .cast_ray(&p(5.0), &Vector3::x(), range, 1)
            .unwrap()
            .is_none());
    }
    // A ray from far outside the map's box reaches it too (the walk starts at the box).
    let hit = map
        .cast_ray(&p(-1e9), &Vector3::x(), 2e9, 1)
        .unwrap()
        .unwrap();
    assert_eq!(hit.key, VoxelKey::new(0, 0, 0));
    assert!((hit.distance - 1e9).abs() < 1e-3, "{hit:?}");
    // An empty map answers at once.
    let empty = OccupancyList::new(0.1).unwrap();
    assert!(empty.segment_is_free(&p(-1e15), &p(1e15), 1).unwrap());
    assert!(empty
        .cast_ray(&p(0.0), &Vector3::x(), 1e12, 1)
        .unwrap()
        .is_none());
}

fn laser_scan(n: usize) -> LaserScan {
    let step = 0.5f64.to_radians();
    LaserScan {
        angle_min: -(n as f64) * step / 2.0,
        angle_increment: step,
        range_min: 0.0,
        range_max: 8.0,
        ranges: (0..n).map(|i| 2.0 + (i % 7) as f32 * 0.1).collect(),
        intensities: None,
        time: 0.0,
    }
}

#[test]
fn audit_rwht_huge_radius_does_not_panic() {
    // `olmap beacons --method rwht --radius 1e20` panicked in rwht.rs (index out of bounds).
    let scan = laser_scan(181);
    let params = olmap::beacon::RwhtParams::default();
    for radius in [1e20, 1e9, 1e-20, f64::INFINITY, f64::NAN, 0.0, -1.0] {
        let found = olmap::beacon::detect_circles_rwht(&scan, radius, &params);
        if !(radius.is_finite() && radius > 0.0) {
            assert!(found.is_empty(), "radius {radius}");
        }
    }
}

#[test]
fn audit_repeatability_tiny_bin_does_not_panic() {
    // `olmap scanner repeatability --bin 1e-20` panicked (the bin count overflowed to 0).
    let (a, b) = room_pair();
    let tiny = olmap::scanner::RepeatabilityParams {
        bin_width: 1e-20,
        threshold: 0.02,
    };
    let r = olmap::scanner::repeatability(&a, &b, &tiny).unwrap();
    assert!(r.max > 0.0 && r.mode >= 0.0);
    for (bin_width, threshold) in [(f64::INFINITY, 0.02), (0.002, f64::NAN), (0.0, 0.02)] {
        let p = olmap::scanner::RepeatabilityParams {
            bin_width,
            threshold,
        };
        assert_invalid(
            &olmap::scanner::repeatability(&a, &b, &p).unwrap_err(),
            &["bin width"],
        );
    }
}

#[test]
fn audit_simulation_too_large_is_refused_before_planning() {
    // `olmap simulate --scans-per-robot 1e9` aborted on a 56 GB allocation.
    for (robots, stops) in [(1, 1_000_000_000), (1 << 32, 1), (4, 100_000)] {
        let config = olmap::sim::SimConfig {
            robots,
            stops,
            ..Default::default()
        };
        let e = olmap::sim::simulate(&config, |_, _| {}).unwrap_err();
        assert_too_large(&e, &["simulation", "limit 4.0 GiB"]);
    }
    // The default simulation is far below the limit.
    let default = olmap::sim::SimConfig::default().memory_estimate();
    assert!(default < olmap::limits::MAX_ESTIMATE_BYTES as f64 / 10.0);
}

#[cfg(feature = "render")]
#[test]
fn audit_render_headings_and_fine_grids_are_bounded() {
    use olmap::render::{overlap_surface, render_top_view, OverlapSurfaceParams, TopViewOptions};
    // `olmap render --view overlap --headings 1e8` ran unbounded (a value per heading and
    // cell is kept).
    let (source, target) = room_pair();
    let map = OccupancyList::from_cloud(&target, 0.1).unwrap();
    let scan = OccupancyList::from_cloud(&source, 0.1).unwrap();
    let params = OverlapSurfaceParams {
        headings: 100_000_000,
        ..Default::default()
    };
    let e = overlap_surface(&map, &scan, &Pose::identity(), &params).unwrap_err();
    assert_invalid(&e, &["3600 headings"]);
    // `olmap render --pixel 1e20` (or `--grid 1e-20`) walked 1e20 grid lines: a grid finer
    // than the pixels fills every pixel, as before, in one pass.
    for (pixel, grid) in [(1e20, 1.0), (0.1, 1e-20)] {
        let options = TopViewOptions {
            pixel_size: Some(pixel),
            grid_step: Some(grid),
            ..TopViewOptions::default()
        };
        let view = render_top_view(&map, &options).unwrap();
        let background = view
            .image
            .pixels()
            .filter(|p| **p == olmap::render::BACKGROUND)
            .count();
        assert_eq!(background, 0, "pixel {pixel}, grid {grid}");
    }
}

fn xyz(dir: &std::path::Path, name: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(&p, "1 2 3\n4 5 6\n0.1 0.1 0.1\n").unwrap();
    p
}

/// A change to a conversion job.
type Edit = dyn Fn(&mut olmap::io::ConvertJob);

#[test]
fn audit_convert_inverted_filters_are_refused() {
    // Inverted filters (`--z-min 5 --z-max 1`, `--min-range 10 --max-range 1`, an inverted
    // box) wrote an empty cloud with exit 0.
    let dir = tempfile::tempdir().unwrap();
    let input = xyz(dir.path(), "in.xyz");
    let output = dir.path().join("out.xyz");
    let job = |edit: &Edit| {
        let mut j = olmap::io::ConvertJob {
            input: input.clone(),
            output: output.clone(),
            ..Default::default()
        };
        edit(&mut j);
        olmap::io::convert_cloud_file(&j, std::time::Instant::now())
    };
    let inverted_box = Aabb {
        min: Point3::new(0.0, 5.0, 0.0),
        max: Point3::new(10.0, 1.0, 10.0),
    };
    let cases: [(&Edit, &str); 5] = [
        (
            &|j| {
                j.z_min = Some(5.0);
                j.z_max = Some(1.0);
            },
            "z_min (5 m) is above z_max (1 m)",
        ),
        (
            &|j| {
                j.min_range = Some(10.0);
                j.max_range = Some(1.0);
            },
            "min_range (10 m) is above max_range (1 m)",
        ),
        (
            &move |j| j.crop = Some(inverted_box),
            "y min 5 is above y max 1",
        ),
        (&|j| j.z_min = Some(f64::NAN), "z_min"),
        (&|j| j.voxel = Some(0.0), "voxel edge"),
    ];
    for (edit, words) in cases {
        assert_invalid(&job(edit).unwrap_err(), &[words]);
        assert!(!output.exists(), "{words}: nothing written");
    }
    // A box given corner first keeps its points.
    let r = job(&|j| {
        j.crop = Some(Aabb {
            min: Point3::new(0.0, 0.0, 0.0),
            max: Point3::new(10.0, 10.0, 10.0),
        })
    })
    .unwrap();
    assert_eq!(r.points_written, 3);
}

#[test]
fn audit_map_duplicate_scan_names_are_refused() {
    // `olmap map` on two folders with the same scan names wrote `scan002` twice.
    let dir = tempfile::tempdir().unwrap();
    let a = xyz(dir.path(), "a/scan000.xyz");
    let b = xyz(dir.path(), "b/scan000.xyz");
    let job = olmap::mapping::MapJob {
        scans: vec![a, b],
        odometry: olmap::mapping::OdometrySource::None,
        read: Default::default(),
        first: None,
        params: Default::default(),
        output: dir.path().join("m.olm"),
        poses_out: None,
        free_space_out: None,
        scans_out: None,
        report: None,
        graph_out: None,
    };
    let e = olmap::mapping::run_map_job(&job, &mut |_, _, _| {}).unwrap_err();
    assert_invalid(
        &e,
        &[
            "two scans are named scan000",
            "a/scan000.xyz",
            "b/scan000.xyz",
        ],
    );
    assert!(!dir.path().join("m.olm").exists());
}

#[test]
fn audit_voxelize_endpoints_honour_hit_and_max_count() {
    // `olmap voxelize --max-count/--hit` were ignored in endpoint mode.
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.xyz");
    // Four points in one 0.5 m voxel, one in another.
    std::fs::write(
        &input,
        "0.1 0.1 0.1\n0.2 0.1 0.1\n0.3 0.1 0.1\n0.4 0.1 0.1\n2.1 0.1 0.1\n",
    )
    .unwrap();
    let run = |hit, max_count| {
        let job = olmap::occupancy::VoxelizeJob {
            clouds: vec![input.clone()],
            output: dir.path().join("m.olm"),
            resolution: 0.5,
            ray_trace: false,
            sensor: SensorModel {
                hit,
                max_count,
                ..Default::default()
            },
            poses: Default::default(),
            bucket_radius: 0.0,
            read: Default::default(),
        };
        olmap::occupancy::run_voxelize(&job, &mut |_, _, _| {})
    };
    let map = run(3, 5).unwrap().map;
    assert_eq!(
        map.count(VoxelKey::new(0, 0, 0)),
        5,
        "4 x 3 = 12, capped at 5"
    );
    assert_eq!(map.count(VoxelKey::new(4, 0, 0)), 3);
    // The defaults count points, as before.
    let map = run(1, olmap::occupancy::MAX_COUNT).unwrap().map;
    assert_eq!(map.count(VoxelKey::new(0, 0, 0)), 4);
    assert_invalid(&run(0, 5).unwrap_err(), &["hit"]);
    assert_invalid(&run(1, 0).unwrap_err(), &["max_count"]);
}

#[test]
fn audit_team_dataset_skips_a_bad_scan_and_a_missing_truth() {
    // One bad scan or a missing truth.txt aborted `olmap team`: they are now left out and
    // listed, for the caller to warn about.
    let dir = tempfile::tempdir().unwrap();
    let config = olmap::sim::SimConfig {
        world: olmap::sim::WorldKind::BoxRoom,
        robots: 2,
        stops: 2,
        ..Default::default()
    };
    let data = olmap::sim::simulate(&config, |_, _| {}).unwrap();
    let root = dir.path().join("ds");
    olmap::sim::write_dataset(&root, &data).unwrap();
    std::fs::remove_file(root.join("robot1/truth.txt")).unwrap();
    std::fs::write(root.join("robot0/scans/scan001.pcd"), b"not a pcd").unwrap();
    let on_disk = olmap::sim::read_dataset(&root).unwrap();
    assert_eq!(on_disk.skipped.len(), 1, "{:?}", on_disk.skipped);
    assert!(on_disk.skipped[0].path.ends_with("truth.txt"));
    assert!(!on_disk.has_truth());
    let (store, skipped) = on_disk.to_store_skipping().unwrap();
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert!(skipped[0].path.ends_with("scan001.pcd") && skipped[0].reason.contains("PCD"));
    assert_eq!(store.len(), 3);
    // The strict reading still refuses the bad scan.
    assert!(on_disk.to_store().is_err());
}

#[test]
fn audit_threads_capped() {
    // `--threads 100000` started that many threads.
    let limit = olmap::limits::max_threads();
    let t = olmap::limits::thread_count(100_000);
    assert_eq!((t.threads, t.limit), (limit, limit));
    let note = t.note().unwrap();
    assert!(
        note.contains("100000") && note.contains(&limit.to_string()),
        "{note}"
    );
    assert_eq!(olmap::limits::thread_count(limit).note(), None);
    assert_eq!(
        olmap::limits::thread_count(0).threads,
        0,
        "0 means one per core"
    );
}
