//! Pictures, map queries and the navigation grid (thesis §5.4, §6.4.2, §7.3), checked on
//! the content of simulated rooms against the simulator's analytic ray casts.

use std::f64::consts::{PI, TAU};

use nalgebra::{Point3, Vector3};
use olmap::geometry::Pose;
use olmap::grid2d::{navigation_grid, NavGridParams, Trinary};
use olmap::occupancy::{OccupancyList, SensorModel};
use olmap::render::{
    bar_chart, heat_colour, overlap_surface, render_depth, render_top_view, Camera,
    OverlapSurfaceParams, Series, TopViewOptions, BACKGROUND, GRID_COLOUR, PALETTE,
};
use olmap::report::HtmlReport;
use olmap::sim::{room_shell, Material, Object, RangeNoise, Shape, SpinningLidar, World};

const RES: f64 = 0.1;

/// The centre of cell (or voxel column) `i` along x or y.
fn c(i: i32) -> f64 {
    (i as f64 + 0.5) * RES
}

/// Offset of the rooms' inner corner from the origin, so that no wall face lies on a voxel
/// boundary (where rounding would pick either neighbour).
const OFF: [f64; 3] = [0.03, 0.04, 0.02];

fn at(x: f64, y: f64, z: f64) -> Point3<f64> {
    Point3::new(x + OFF[0], y + OFF[1], z + OFF[2])
}

/// Two rooms side by side, 10 x 5 x 3 m inside (inner corner at `OFF`, walls 10 cm thick),
/// split at x = 5..5.1 by a wall with a doorway at y = 2..3 up to 2.1 m.
fn two_rooms() -> World {
    let mut shapes = room_shell(at(0.0, 0.0, 0.0), Vector3::new(10.0, 5.0, 3.0), 0.1, true);
    shapes.push(Shape::aabb_box(at(5.0, 0.0, 0.0), at(5.1, 2.0, 3.0)));
    shapes.push(Shape::aabb_box(at(5.0, 3.0, 0.0), at(5.1, 5.0, 3.0)));
    shapes.push(Shape::aabb_box(at(5.0, 2.0, 2.1), at(5.1, 3.0, 3.0)));
    let objects = shapes
        .into_iter()
        .enumerate()
        .map(|(i, shape)| Object {
            shape,
            material: Material::WALL,
            id: i as u32,
        })
        .collect();
    World::new("two rooms", objects)
}

fn scan_poses() -> Vec<Pose> {
    vec![
        Pose::from_xyz_ypr(2.5, 2.3, 1.0, 0.0, 0.0, 0.0),
        Pose::from_xyz_ypr(7.6, 2.6, 1.0, 0.3, 0.0, 0.0),
    ]
}

/// A noise-free spinning lidar covering -60°..+60° in elevation.
fn lidar() -> SpinningLidar {
    SpinningLidar {
        beams: 241,
        elevation_min: (-60f64).to_radians(),
        elevation_max: 60f64.to_radians(),
        azimuth_step: 0.5f64.to_radians(),
        noise: RangeNoise::none(),
    }
}

/// The rooms scanned from every pose, ray traced into a map.
fn room_map(world: &World) -> OccupancyList {
    let mut map = OccupancyList::new(RES).unwrap();
    for (k, pose) in scan_poses().iter().enumerate() {
        let cloud = lidar().scan(world, &[], pose, 7, k as u64);
        map.insert_scan(&cloud, pose, &SensorModel::default())
            .unwrap();
    }
    map
}

/// The scans' end points only, no ray tracing: every surface voxel a beam reached stays
/// (ray tracing frees thin voxels that hold both a surface and free space when a later
/// scan passes through their free part, e.g. the floor's voxels seen through the doorway).
fn endpoint_map(world: &World) -> OccupancyList {
    let mut map = OccupancyList::new(RES).unwrap();
    for (k, pose) in scan_poses().iter().enumerate() {
        let cloud = lidar().scan(world, &[], pose, 7, k as u64);
        map.add_points(&cloud, pose, 1);
    }
    map
}

/// Distance from `p` to the nearest solid of the world (all axis-aligned boxes here).
fn clearance(world: &World, p: &Point3<f64>) -> f64 {
    world
        .objects()
        .iter()
        .map(|o| match o.shape {
            Shape::Box { center, half, .. } => {
                let d = (p - center).abs() - half;
                d.map(|v| v.max(0.0)).norm()
            }
            _ => f64::INFINITY,
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn ray_casts_match_analytic_ranges_within_a_voxel() {
    let world = two_rooms();
    let map = endpoint_map(&world);
    // One voxel, measured along its diagonal: the ray enters the voxel holding the surface.
    let tol = 3f64.sqrt() * RES;
    let mut checked = 0;
    for pose in scan_poses() {
        let o = Point3::from(pose.translation());
        for a in 0..72 {
            for e in [-40.0f64, -20.0, -5.0, 0.0, 10.0, 35.0] {
                let (az, el) = ((a as f64 * 5.0 + 1.7).to_radians(), e.to_radians());
                let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let Some(hit) = world.cast(&o, &d, 30.0) else {
                    continue;
                };
                let range = hit.distance;
                // A voxel layer holding a surface is one voxel thick across it: a ray at
                // incidence theta crosses it over r / cos(theta) <= sqrt(3) r for
                // cos >= 0.6. A ray passing within a voxel diagonal of another surface
                // (a door jamb, the floor near a wall) may enter that surface's voxels
                // first: keep only rays whose path, up to the last 0.35 m, stays clear.
                let cos = hit.normal.dot(&-d);
                let clear = (0..)
                    .map(|k| k as f64 * 0.02)
                    .take_while(|t| *t < range - 0.35)
                    .all(|t| clearance(&world, &(o + d * t)) > tol);
                if cos < 0.6 || !clear {
                    continue;
                }
                let hit = map
                    .cast_ray(&o, &d, 30.0, 1)
                    .unwrap()
                    .unwrap_or_else(|| panic!("no hit from {o} along {d}, expected {range}"));
                assert!(
                    (hit.distance - range).abs() <= tol,
                    "from {o} along {d}: map {} m, world {range} m",
                    hit.distance
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 500, "only {checked} rays checked");
}

#[test]
fn queries_near_points_and_along_segments() {
    let world = two_rooms();
    let map = endpoint_map(&world);
    // Inside a room, away from everything: free; through the dividing wall: blocked;
    // through the doorway: free.
    let a = Point3::new(2.0, 2.5, 1.0);
    assert!(map
        .segment_is_free(&a, &Point3::new(4.0, 1.0, 1.0), 1)
        .unwrap());
    assert!(!map
        .segment_is_free(&a, &Point3::new(7.0, 1.0, 1.0), 1)
        .unwrap());
    assert!(map
        .segment_is_free(&a, &Point3::new(8.0, 2.5, 1.0), 1)
        .unwrap());
    assert!(map.is_occupied(&Point3::new(5.05, 1.0, 1.0)));
    assert!(!map.is_occupied(&Point3::new(5.05, 2.5, 1.0)));
    // Voxels near a point on the wall: all within the radius, and the wall voxel itself.
    let c = Point3::new(5.05, 1.0, 1.0);
    let near = map.occupied_within(&c, 0.25).unwrap();
    assert!(near.iter().any(|(k, _)| *k == map.key_of(&c).unwrap()));
    for (k, _) in &near {
        assert!((map.center(*k) - c).norm() <= 0.25 + 1e-9);
    }
    // The same answer by brute force over the whole list.
    let mut brute: Vec<_> = map
        .iter()
        .filter(|(k, _)| (map.center(*k) - c).norm() <= 0.25)
        .collect();
    brute.sort();
    assert_eq!(near, brute);
    assert!(map
        .occupied_within(&Point3::new(2.5, 2.5, 1.5), 0.5)
        .unwrap()
        .is_empty());
    assert!(map.cast_ray(&a, &Vector3::zeros(), 1.0, 1).is_err());
}

#[test]
fn depth_image_centre_is_the_analytic_range() {
    let world = two_rooms();
    let map = endpoint_map(&world);
    let tol = 3f64.sqrt() * RES;
    let pose = Pose::from_xyz_ypr(2.5, 2.3, 1.0, 0.4, 0.0, 0.0);
    let o = Point3::from(pose.translation());
    let truth = world
        .cast(&o, &pose.transform_vector(&Vector3::x()), 30.0)
        .unwrap()
        .distance;
    let cam = Camera::Pinhole {
        width: 41,
        height: 31,
        fov_x: 1.2,
    };
    let depth = render_depth(&map, &pose, &cam, 20.0, 1).unwrap();
    let centre = depth.range(20, 15).unwrap();
    assert!((centre - truth).abs() <= tol, "{centre} vs {truth}");
    // Panoramic: the centre column looks forward too; the column a quarter turn to the
    // left sees the wall to the left.
    let pano = Camera::Panoramic {
        width: 360,
        height: 61,
        fov_y: PI / 2.0,
    };
    let depth = render_depth(&map, &pose, &pano, 20.0, 1).unwrap();
    for (u, yaw) in [(180u32, 0.0f64), (90, PI / 2.0)] {
        // Column u's ray has azimuth -(u + 0.5 - 180) / 360 * 2 pi.
        let az = -(u as f64 + 0.5 - 180.0) / 360.0 * TAU;
        assert!((az - yaw).abs() < 0.01);
        let d = pose.transform_vector(&Vector3::new(az.cos(), az.sin(), 0.0));
        let truth = world.cast(&o, &d, 30.0).unwrap().distance;
        let got = depth.range(u, 30).unwrap();
        // The row's elevation is half a pixel off the horizon: allow for it.
        let slack = truth * (1.0 / (0.25 / 61.0 * PI).cos() - 1.0);
        assert!(
            (got - truth).abs() <= tol + slack,
            "column {u}: {got} vs {truth}"
        );
    }
    // The picture: near is lighter than far (the wall a quarter turn to the left is
    // nearer than the one straight ahead).
    let img = depth.to_image();
    assert_eq!((img.width(), img.height()), (360, 61));
    let (ahead, left) = (depth.range(180, 30).unwrap(), depth.range(90, 30).unwrap());
    let (ga, gl) = (img.get_pixel(180, 30).0[0], img.get_pixel(90, 30).0[0]);
    assert_eq!(ahead < left, ga > gl, "{ahead} m: {ga}, {left} m: {gl}");
    assert_ne!(ga, gl);
}

#[test]
fn top_view_shows_walls_where_they_are_and_free_space_inside() {
    let world = two_rooms();
    let map = room_map(&world);
    // A band between the floor and the doorway's lintel (2.12 m): walls only.
    let opts = TopViewOptions {
        band: Some((0.3, 2.0)),
        grid_step: Some(1.0),
        ..TopViewOptions::default()
    };
    let view = render_top_view(&map, &opts).unwrap();
    // Cells holding the wall faces (walls of room coordinates x = 0, 5..5.1, 10 and
    // y = 0, 5, offset by OFF: cells 0, 50, 100 in x and 0, 50 in y).
    for j in [5, 15, 35, 45] {
        let y = c(j);
        assert!(view.shows_voxel_at(c(0), y), "west wall at y = {y}");
        assert!(view.shows_voxel_at(c(100), y), "east wall at y = {y}");
        assert!(view.shows_voxel_at(c(50), y), "dividing wall at y = {y}");
    }
    for i in [10, 30, 70, 90] {
        assert!(view.shows_voxel_at(c(i), c(0)) && view.shows_voxel_at(c(i), c(50)));
    }
    for (x, y) in [(2.55, 2.55), (1.55, 3.75), (7.35, 1.35), (c(50), c(25))] {
        assert!(!view.shows_voxel_at(x, y), "free at ({x}, {y})");
        let (i, j) = view.pixel_of(x, y).unwrap();
        let p = *view.image.get_pixel(i, j);
        assert!(p == BACKGROUND || p == GRID_COLOUR);
    }
    // The 1 m grid line at x = 2 m crosses the free interior.
    let (i, j) = view.pixel_of(2.0 + 0.5 * RES, 2.55).unwrap();
    assert_eq!(*view.image.get_pixel(i, j), GRID_COLOUR);
    // No band: the ceiling covers the rooms (where the lidar reached it, up to 60°
    // elevation), coloured as the highest height.
    let full = render_top_view(&map, &TopViewOptions::default()).unwrap();
    assert!(full.shows_voxel_at(c(10), c(10)));
    let top = full.z_range.1;
    assert!(
        (top - 3.05).abs() < 1e-9,
        "ceiling voxels at 3.05 m, got {top}"
    );
    let (i, j) = full.pixel_of(c(10), c(10)).unwrap();
    assert_eq!(
        *full.image.get_pixel(i, j),
        olmap::render::height_colour(1.0)
    );
    // Paths are drawn in their colour.
    let path = vec![Point3::new(1.0, 1.0, 0.0), Point3::new(4.0, 1.0, 0.0)];
    let drawn = render_top_view(
        &map,
        &TopViewOptions {
            band: Some((0.3, 2.5)),
            paths: vec![path],
            grid_step: None,
            ..TopViewOptions::default()
        },
    )
    .unwrap();
    let (i, j) = drawn.pixel_of(2.55, 1.0).unwrap();
    let [r, g, b] = PALETTE[0];
    let near_path =
        (j.saturating_sub(1)..=j + 1).any(|jj| drawn.image.get_pixel(i, jj).0 == [r, g, b]);
    assert!(near_path);
}

#[test]
fn navigation_grid_of_two_rooms_with_a_doorway() {
    let world = two_rooms();
    let map = room_map(&world);
    let params = NavGridParams {
        band: (0.1, 1.2),
        max_range: 15.0,
        ..NavGridParams::default()
    };
    let grid = navigation_grid(&map, &scan_poses(), &params).unwrap();
    // Interior cells (those holding no wall face) are free, in both rooms.
    let mut interior = 0;
    for i in (1..=99).filter(|i| !(50..=51).contains(i)) {
        for j in 1..=49 {
            assert_eq!(
                grid.at_world(c(i), c(j)),
                Some(Trinary::Free),
                "cell ({i}, {j})"
            );
            interior += 1;
        }
    }
    assert_eq!(interior, 97 * 49);
    // Walls are occupied: the outer ones, and the dividing one beside the doorway, whose
    // cells 21..=29 (y 2.1..3.0 m, within the opening at 2.04..3.04 m) are free. Cells 20
    // and 30 hold a door jamb and part of the opening: either, never unknown.
    for j in 0..=50 {
        assert_eq!(
            grid.at_world(c(0), c(j)),
            Some(Trinary::Occupied),
            "west wall {j}"
        );
        assert_eq!(
            grid.at_world(c(100), c(j)),
            Some(Trinary::Occupied),
            "east wall {j}"
        );
        for i in [50, 51] {
            let got = grid.at_world(c(i), c(j)).unwrap();
            match j {
                20 | 30 => assert_ne!(got, Trinary::Unknown, "door jamb ({i}, {j})"),
                21..=29 => assert_eq!(got, Trinary::Free, "doorway ({i}, {j})"),
                _ => assert_eq!(got, Trinary::Occupied, "dividing wall ({i}, {j})"),
            }
        }
    }
    for i in 0..=100 {
        assert_eq!(
            grid.at_world(c(i), c(0)),
            Some(Trinary::Occupied),
            "south wall {i}"
        );
        assert_eq!(
            grid.at_world(c(i), c(50)),
            Some(Trinary::Occupied),
            "north wall {i}"
        );
    }
    // Behind the walls nothing was seen.
    assert_eq!(grid.at_world(c(-1), c(25)), Some(Trinary::Unknown));
    // The ROS files round trip.
    let dir = tempfile::tempdir().unwrap();
    let yaml = olmap::grid2d::write_ros_map(dir.path().join("nav.pgm"), &grid).unwrap();
    assert_eq!(
        olmap::grid2d::read_ros_map(&yaml).unwrap().cells,
        grid.cells
    );
}

#[test]
fn overlap_surface_peaks_at_the_true_position() {
    let world = two_rooms();
    let res = 0.2;
    let mut map = OccupancyList::new(res).unwrap();
    let truth = scan_poses()[0];
    let other = scan_poses()[1];
    map.insert_scan(
        &lidar().scan(&world, &[], &other, 1, 0),
        &other,
        &SensorModel::default(),
    )
    .unwrap();
    map.insert_scan(
        &lidar().scan(&world, &[], &truth, 1, 1),
        &truth,
        &SensorModel::default(),
    )
    .unwrap();
    // A later scan from the true pose, in its own frame.
    let cloud = lidar().scan(&world, &[], &truth, 2, 0);
    let scan = OccupancyList::from_cloud(&cloud, res).unwrap();
    let guess = Pose::from_xyz_ypr(
        truth.translation().x + 0.6,
        truth.translation().y - 0.4,
        truth.translation().z,
        0.0,
        0.0,
        0.0,
    );
    let params = OverlapSurfaceParams {
        half_width: 1.2,
        stride: 1,
        headings: 8,
    };
    let surface = overlap_surface(&map, &scan, &guess, &params).unwrap();
    assert_eq!(surface.n, 13);
    let (x, y, yaw, best) = surface.peak();
    let t = truth.translation();
    assert!(
        (x - t.x).abs() <= res && (y - t.y).abs() <= res,
        "peak at ({x}, {y})"
    );
    assert!(yaw.abs() < 1e-9);
    // The scan's voxels were all inserted at the true pose: most are still there.
    assert!(
        best as f64 >= 0.5 * scan.len() as f64,
        "{best} of {}",
        scan.len()
    );
    // The heat map's peak pixel is white.
    let img = surface.to_image(3);
    let (c, r) = (
        ((x - surface.x0) / surface.step).round() as u32,
        ((y - surface.y0) / surface.step).round() as u32,
    );
    let v = (surface.n as u32 - 1 - r) * 3;
    assert_eq!(*img.get_pixel(c * 3 + 1, v + 1), heat_colour(1.0));
}

#[test]
fn bar_heights_follow_values_and_report_inlines_pngs() {
    let values = [1.0, 4.0, 2.0, 0.0];
    let img = bar_chart(
        &[Series {
            values: values.to_vec(),
            colour: PALETTE[1],
        }],
        400,
        220,
        false,
    )
    .unwrap();
    // Bar heights in pixels per bin (the tallest column of the series' colour).
    let bin_w = (400 - 24) as f64 / 4.0;
    let heights: Vec<u32> = (0..4)
        .map(|b| {
            let x = (8.0 + 1.0 + (b as f64 + 0.5) * bin_w) as u32;
            (0..220)
                .filter(|&y| img.get_pixel(x, y).0 == PALETTE[1])
                .count() as u32
        })
        .collect();
    assert_eq!(heights[3], 0);
    // Proportional to the values, within a pixel of rounding per end.
    let unit = heights[1] as f64 / 4.0;
    assert!((heights[0] as f64 - unit).abs() <= 2.0, "{heights:?}");
    assert!((heights[2] as f64 - 2.0 * unit).abs() <= 2.0, "{heights:?}");
    assert!(bar_chart(&[], 10, 10, false).is_err());

    let mut report = HtmlReport::new("t");
    report.image("bars", &img).unwrap();
    let html = report.to_html();
    let b64 = html
        .split("data:image/png;base64,")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .unwrap();
    use base64::Engine;
    let png = base64::engine::general_purpose::STANDARD
        .decode(b64)
        .unwrap();
    let back = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!(back, img);
}

#[test]
fn level_chart_bars_shrink_with_the_search() {
    use olmap::align::LevelReport;
    use olmap::render::level_chart;
    let level = |l: usize, evaluated: usize, survivors: usize| LevelReport {
        level: l,
        resolution: 0.1 * 2f64.powi(l as i32),
        angular_step: 0.1,
        scan_voxels: 100,
        evaluated,
        passed: survivors,
        survivors,
        best_overlap: 10,
        seconds: 0.0,
    };
    // Coarsest (level 2) first: many poses evaluated there, few kept at the finest.
    let levels = [level(0, 100, 1), level(1, 1000, 10), level(2, 100_000, 100)];
    let img = level_chart(&levels, 320, 200).unwrap();
    let tallest = |colour: [u8; 3], bin: usize| {
        let bin_w = (320 - 24) as f64 / 3.0;
        let x0 = (8.0 + 1.0 + bin as f64 * bin_w) as u32;
        (x0..x0 + bin_w as u32)
            .map(|x| {
                (0..200)
                    .filter(|&y| img.get_pixel(x, y).0 == colour)
                    .count()
            })
            .max()
            .unwrap()
    };
    let evaluated: Vec<usize> = (0..3).map(|b| tallest(PALETTE[0], b)).collect();
    let kept: Vec<usize> = (0..3).map(|b| tallest(PALETTE[1], b)).collect();
    assert!(
        evaluated[0] > evaluated[1] && evaluated[1] > evaluated[2],
        "{evaluated:?}"
    );
    assert!(kept[0] > kept[1] && kept[1] > kept[2], "{kept:?}");
    // Log scale: ln(1 + 100000) / ln(1 + 100) = 2.49, the tallest bar's ratio within a pixel.
    let ratio = evaluated[0] as f64 / evaluated[2] as f64;
    let want = (100_001f64).ln() / (101f64).ln();
    assert!((ratio - want).abs() < 0.1, "{ratio} vs {want}");
}
