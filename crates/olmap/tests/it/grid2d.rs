//! 2D occupancy grids (thesis §3.3.3): Bresenham cells against a brute-force line check,
//! the ray-trace update rules, a simulated enclosure mapped to within the thesis' 2 %
//! geometric error, the position-bucket rule, and the ROS map PGM + YAML round trip.

use std::path::Path;
use std::time::Instant;

use nalgebra::{Point3, Vector3};
use olmap::cloud::LaserScan;
use olmap::geometry::Pose;
use olmap::grid2d::{
    bresenham, read_ros_map, write_ros_map, OccupancyGrid2d, SensorModel2d, Thresholds, Trinary,
    TrinaryGrid,
};
use olmap::occupancy::PositionBuckets;
use olmap::sim::{room_shell, Material, Object, PlanarScanner, Shape, World};

// ---------------------------------------------------------------------------------------
// Bresenham

/// Whether the closed unit square of cell `(i, j)` meets the segment `a`-`b` (cell-index
/// coordinates: cell `(i, j)` covers `[i, i+1] x [j, j+1]`), by clipping the segment
/// against the square (Liang-Barsky).
fn segment_touches_cell(a: (f64, f64), b: (f64, f64), i: i64, j: i64) -> bool {
    let eps = 1e-9;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let d = (b.0 - a.0, b.1 - a.1);
    for (p, q) in [
        (-d.0, a.0 - (i as f64 - eps)),
        (d.0, (i as f64 + 1.0 + eps) - a.0),
        (-d.1, a.1 - (j as f64 - eps)),
        (d.1, (j as f64 + 1.0 + eps) - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    t0 <= t1
}

fn check_line(a: (i64, i64), b: (i64, i64)) {
    let cells: Vec<(i64, i64)> = bresenham(a, b).collect();
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let n = dx.abs().max(dy.abs());
    assert_eq!(cells.len() as i64, n + 1, "{a:?} -> {b:?}");
    assert_eq!(cells[0], a);
    assert_eq!(*cells.last().unwrap(), b);
    assert_eq!(bresenham(a, b).len(), cells.len());
    let centre = |c: (i64, i64)| (c.0 as f64 + 0.5, c.1 as f64 + 0.5);
    let (ca, cb) = (centre(a), centre(b));
    let x_major = dx.abs() >= dy.abs();
    for (k, &c) in cells.iter().enumerate() {
        // Every cell touches the segment between the end cells' centres.
        assert!(
            segment_touches_cell(ca, cb, c.0, c.1),
            "{a:?} -> {b:?}: cell {c:?} misses the segment"
        );
        // One cell per step along the major axis, the minor coordinate within half a cell
        // of the ideal line (exact integer test: |2 (minor - minor_a) n - 2 k dminor| <= n).
        let (major_step, minor_off, dminor) = if x_major {
            ((c.0 - a.0).abs(), c.1 - a.1, dy)
        } else {
            ((c.1 - a.1).abs(), c.0 - a.0, dx)
        };
        assert_eq!(major_step, k as i64, "{a:?} -> {b:?}");
        assert!(
            (2 * minor_off * n - 2 * k as i64 * dminor).abs() <= n,
            "{a:?} -> {b:?}: cell {c:?} off the line"
        );
        if k > 0 {
            let p = cells[k - 1];
            assert!((c.0 - p.0).abs() <= 1 && (c.1 - p.1).abs() <= 1 && c != p);
        }
    }
    // The line does not depend on its direction.
    let mut back: Vec<(i64, i64)> = bresenham(b, a).collect();
    back.reverse();
    assert_eq!(back, cells, "{a:?} <-> {b:?}");
    // Every cell of the brute-force supercover that the line's minor coordinate could
    // reach is the line's: the line is a subset of the supercover, and the supercover's
    // cells along each major step include the line's cell.
    let cover: Vec<(i64, i64)> = (a.0.min(b.0)..=a.0.max(b.0))
        .flat_map(|i| (a.1.min(b.1)..=a.1.max(b.1)).map(move |j| (i, j)))
        .filter(|&(i, j)| segment_touches_cell(ca, cb, i, j))
        .collect();
    for c in &cells {
        assert!(cover.contains(c));
    }
}

#[test]
fn bresenham_matches_a_brute_force_line_check() {
    let r = 6;
    for ax in -r..=r {
        for ay in -r..=r {
            for bx in -r..=r {
                for by in -r..=r {
                    check_line((ax, ay), (bx, by));
                }
            }
        }
    }
    // Long lines, far from the origin, with negative coordinates.
    for (a, b) in [
        ((-1000, -7), (523, 311)),
        ((40_000, -40_000), (39_000, -38_123)),
        ((-5, -300), (-6, 301)),
        ((17, -3), (-250, -3)),
    ] {
        check_line(a, b);
    }
}

#[test]
fn bresenham_known_cases() {
    let line = |a, b| bresenham(a, b).collect::<Vec<_>>();
    assert_eq!(line((0, 0), (0, 0)), [(0, 0)]);
    assert_eq!(line((0, 0), (3, 0)), [(0, 0), (1, 0), (2, 0), (3, 0)]);
    assert_eq!(line((0, 0), (0, -2)), [(0, 0), (0, -1), (0, -2)]);
    assert_eq!(
        line((-1, -1), (-4, -4)),
        [(-1, -1), (-2, -2), (-3, -3), (-4, -4)]
    );
    assert_eq!(
        line((0, 0), (5, 2)),
        [(0, 0), (1, 0), (2, 1), (3, 1), (4, 2), (5, 2)]
    );
    // The mirrored line gives the mirrored cells when there is no tie.
    assert_eq!(
        line((0, 0), (-5, 2)),
        [(0, 0), (-1, 0), (-2, 1), (-3, 1), (-4, 2), (-5, 2)]
    );
}

// ---------------------------------------------------------------------------------------
// The update rules on hand-made scans

fn scan(angle_min: f64, step: f64, ranges: Vec<f32>) -> LaserScan {
    LaserScan {
        angle_min,
        angle_increment: step,
        range_min: 0.1,
        range_max: 30.0,
        ranges,
        intensities: None,
        time: 0.0,
    }
}

#[test]
fn sensor_model_defaults_follow_the_log_odds_derivation() {
    let m = SensorModel2d::default();
    assert!((m.l_occ - 0.847_298).abs() < 1e-5);
    assert!((m.l_free + 0.847_298).abs() < 1e-5);
    assert!((SensorModel2d::probability(m.l_min) - 0.12).abs() < 1e-6);
    assert!((SensorModel2d::probability(m.l_max) - 0.97).abs() < 1e-6);
    assert_eq!(m.max_range, 8.0);
    let t = Thresholds::default();
    assert_eq!(
        t.classify(SensorModel2d::probability(m.l_occ)),
        Trinary::Occupied
    );
    assert_eq!(
        t.classify(SensorModel2d::probability(m.l_free)),
        Trinary::Unknown
    );
    assert_eq!(
        t.classify(SensorModel2d::probability(2.0 * m.l_free)),
        Trinary::Free
    );
    assert!(SensorModel2d::from_probabilities(0.7, 0.6, 0.1, 0.9, 8.0).is_err());
    assert!(SensorModel2d::from_probabilities(1.0, 0.3, 0.1, 0.9, 8.0).is_err());
    let bad = SensorModel2d {
        max_range: f64::INFINITY,
        ..m
    };
    let mut g = OccupancyGrid2d::new(0.1).unwrap();
    assert!(g
        .insert_scan(&scan(0.0, 0.1, vec![1.0]), &Pose::identity(), &bad)
        .is_err());
}

#[test]
fn one_beam_clears_the_cells_before_its_return_and_marks_the_return() {
    let model = SensorModel2d::default();
    let mut g = OccupancyGrid2d::new(0.1).unwrap();
    // Sensor at (0.25, 0.25), beam along +y hitting at 1.0 m: end point (0.25, 1.25).
    let pose = Pose::from_xyz_ypr(0.25, 0.25, 0.3, std::f64::consts::FRAC_PI_2, 0.0, 0.0);
    let stats = g
        .insert_scan(&scan(0.0, 0.1, vec![1.0]), &pose, &model)
        .unwrap();
    assert_eq!(stats.beams, 1);
    assert_eq!(stats.hits, 1);
    assert_eq!(stats.cells_traversed, 11);
    assert_eq!(stats.free_updates, 10);
    assert_eq!(stats.occupied_updates, 1);
    let cell = |x, y| g.cell_of(x, y).unwrap();
    for k in 0..10 {
        let y = 0.25 + 0.1 * k as f64;
        assert_eq!(g.log_odds(cell(0.25, y)), model.l_free, "y {y}");
    }
    assert_eq!(g.log_odds(cell(0.25, 1.25)), model.l_occ);
    assert_eq!(g.log_odds(cell(0.35, 0.75)), 0.0);
    assert_eq!(g.log_odds(cell(0.25, 1.35)), 0.0);
    // The lattice is the world's: cell corners at multiples of the resolution.
    let (ox, oy) = g.origin();
    assert!(((ox / 0.1).round() * 0.1 - ox).abs() < 1e-9);
    assert!(((oy / 0.1).round() * 0.1 - oy).abs() < 1e-9);
    let (cx, cy) = g.cell_center(cell(0.25, 1.25).0, cell(0.25, 1.25).1);
    assert!((cx - 0.25).abs() < 1e-9 && (cy - 1.25).abs() < 1e-9);
}

#[test]
fn no_return_and_far_returns_clear_only_up_to_max_range_and_short_ones_are_ignored() {
    let model = SensorModel2d {
        max_range: 2.0,
        ..SensorModel2d::default()
    };
    let mut g = OccupancyGrid2d::new(0.1).unwrap();
    // Beams along +x (no return), +y (return at 5 m, beyond max_range), -x (0.05 m, below
    // range_min) and -y (NaN).
    let s = scan(
        0.0,
        std::f64::consts::FRAC_PI_2,
        vec![f32::INFINITY, 5.0, 0.05, f32::NAN],
    );
    let pose = Pose::from_xyz_ypr(0.05, 0.05, 0.0, 0.0, 0.0, 0.0);
    let stats = g.insert_scan(&s, &pose, &model).unwrap();
    assert_eq!(stats.beams, 2);
    assert_eq!(stats.hits, 0);
    assert_eq!(stats.occupied_updates, 0);
    for d in [0.0, 0.5, 1.0, 1.95, 2.04] {
        assert!(g.occupancy(0.05 + d, 0.05) < 0.5, "+x {d}");
        assert!(g.occupancy(0.05, 0.05 + d) < 0.5, "+y {d}");
    }
    for d in [2.2, 3.0, 4.95, 5.05] {
        assert_eq!(g.occupancy(0.05 + d, 0.05), 0.5, "+x {d}");
        assert_eq!(g.occupancy(0.05, 0.05 + d), 0.5, "+y {d}");
    }
    for d in [0.3, 1.0] {
        assert_eq!(g.occupancy(0.05 - d, 0.05), 0.5);
        assert_eq!(g.occupancy(0.05, 0.05 - d), 0.5);
    }
    // The scan's own range_max limits too: no return then clears up to 1 m only.
    let mut g = OccupancyGrid2d::new(0.1).unwrap();
    let mut s = scan(0.0, 0.1, vec![f32::INFINITY]);
    s.range_max = 1.0;
    g.insert_scan(&s, &pose, &SensorModel2d::default()).unwrap();
    assert!(g.occupancy(0.95, 0.05) < 0.5);
    assert_eq!(g.occupancy(1.25, 0.05), 0.5);
}

#[test]
fn a_scan_observes_each_cell_once_and_hits_win_over_passes() {
    let model = SensorModel2d::default();
    let mut g = OccupancyGrid2d::new(0.1).unwrap();
    // Two beams along the same line: one ends at 0.5 m, the other passes through to 1 m.
    let pose = Pose::from_xyz_ypr(0.05, 0.05, 0.0, 0.0, 0.0, 0.0);
    let s = scan(0.0, 0.0, vec![0.5, 1.0, 1.0]);
    let stats = g.insert_scan(&s, &pose, &model).unwrap();
    assert_eq!(stats.cells_traversed, 6 + 11 + 11);
    assert_eq!(stats.occupied_updates, 2);
    assert_eq!(stats.free_updates, 9);
    assert_eq!(g.log_odds(g.cell_of(0.55, 0.05).unwrap()), model.l_occ);
    assert_eq!(g.log_odds(g.cell_of(0.25, 0.05).unwrap()), model.l_free);
    // Log odds stay within [l_min, l_max] however many scans.
    for _ in 0..50 {
        g.insert_scan(&s, &pose, &model).unwrap();
    }
    assert_eq!(g.log_odds(g.cell_of(0.55, 0.05).unwrap()), model.l_max);
    assert_eq!(g.log_odds(g.cell_of(0.25, 0.05).unwrap()), model.l_min);
}

#[test]
fn growing_keeps_the_cells_and_a_fixed_grid_clips() {
    let model = SensorModel2d::default();
    let mut g = OccupancyGrid2d::new(0.05).unwrap();
    let s = scan(-0.3, 0.01, vec![1.5; 61]);
    g.insert_scan(
        &s,
        &Pose::from_xyz_ypr(1.0, 1.0, 0.0, 0.0, 0.0, 0.0),
        &model,
    )
    .unwrap();
    let before: Vec<((f64, f64), f32)> = g
        .cells()
        .filter(|&(_, l)| l != 0.0)
        .map(|((i, j), l)| (g.cell_center(i, j), l))
        .collect();
    assert!(before.len() > 100);
    let (w0, h0) = (g.width(), g.height());
    // Far away in the other direction: the grid grows both ways.
    g.insert_scan(
        &s,
        &Pose::from_xyz_ypr(-20.0, -7.0, 0.0, 3.0, 0.0, 0.0),
        &model,
    )
    .unwrap();
    assert!(g.width() > w0 && g.height() > h0);
    for ((x, y), l) in before {
        assert_eq!(g.log_odds(g.cell_of(x, y).unwrap()), l, "({x}, {y})");
    }
    let ((x0, y0), (x1, y1)) = g.extent();
    assert!(x0 <= -21.6 && y0 <= -7.6 && x1 >= 2.5 && y1 >= 1.5);
    // A fixed 1 m square: the beams are cut at its edge, nothing else changes.
    let mut f = OccupancyGrid2d::fixed(0.05, (0.5, 0.5), 20, 20).unwrap();
    let stats = f
        .insert_scan(
            &s,
            &Pose::from_xyz_ypr(1.0, 1.0, 0.0, 0.0, 0.0, 0.0),
            &model,
        )
        .unwrap();
    assert_eq!(stats.occupied_updates, 0);
    // The sector of the fan inside the square: 0.6 rad x 0.5 m, about 30 cells.
    assert!(stats.free_updates >= 25, "{stats:?}");
    assert_eq!((f.width(), f.height(), f.origin()), (20, 20, (0.5, 0.5)));
    assert!(f.occupancy(1.4, 1.0) < 0.5);
    assert_eq!(f.occupancy(2.5, 1.0), 0.5);
}

// ---------------------------------------------------------------------------------------
// A simulated enclosure

/// Inner corner and size of the enclosure (off the 5 cm lattice on purpose, so the
/// measured size is not exact by construction).
const MIN: [f64; 2] = [0.37, -0.21];
const SIZE: [f64; 2] = [7.33, 5.42];
/// Two boxes, as (min, max) relative to MIN, clear of the middle bands.
const BOXES: [[f64; 4]; 2] = [[1.5, 0.3, 2.3, 1.0], [5.0, 4.0, 5.6, 4.8]];

fn enclosure() -> World {
    let mut objects: Vec<Object> = room_shell(
        Point3::new(MIN[0], MIN[1], 0.0),
        Vector3::new(SIZE[0], SIZE[1], 2.5),
        0.1,
        false,
    )
    .into_iter()
    .map(|shape| Object {
        shape,
        material: Material::WALL,
        id: 0,
    })
    .collect();
    for b in BOXES {
        objects.push(Object {
            shape: Shape::aabb_box(
                Point3::new(MIN[0] + b[0], MIN[1] + b[1], 0.0),
                Point3::new(MIN[0] + b[2], MIN[1] + b[3], 1.0),
            ),
            material: Material::FURNITURE,
            id: 0,
        });
    }
    World::new("enclosure", objects)
}

/// Scanner poses (x, y relative to MIN, yaw), 0.3 m above the floor.
fn enclosure_poses() -> Vec<Pose> {
    [
        (1.0, 2.5, 0.0),
        (3.5, 2.7, 1.2),
        (6.2, 2.5, 3.1),
        (3.6, 1.0, 1.6),
        (3.7, 4.4, -1.5),
        (0.9, 4.6, -0.7),
        (6.5, 0.7, 2.4),
        (2.0, 3.8, -2.6),
    ]
    .iter()
    .map(|&(x, y, yaw)| Pose::from_xyz_ypr(MIN[0] + x, MIN[1] + y, 0.3, yaw, 0.0, 0.0))
    .collect()
}

fn enclosure_scans(world: &World, poses: &[Pose]) -> Vec<LaserScan> {
    let mut scanner = PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.01;
    poses
        .iter()
        .enumerate()
        .map(|(k, p)| scanner.scan(world, &[], p, 7, k as u64))
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    assert!(!v.is_empty());
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Wall positions along one axis measured in the map: for every row (axis 0) or column
/// (axis 1) through the middle band, the first occupied cell met going out from the middle
/// on either side; returns the medians of their centres.
fn measure_walls(map: &TrinaryGrid, axis: usize, band: (f64, f64), middle: f64) -> (f64, f64) {
    let r = map.resolution;
    let (n_along, n_across) = if axis == 0 {
        (map.width, map.height)
    } else {
        (map.height, map.width)
    };
    let o_along = map.origin[axis];
    let o_across = map.origin[1 - axis];
    let at = |along: usize, across: usize| {
        if axis == 0 {
            map.get(along, across).unwrap()
        } else {
            map.get(across, along).unwrap()
        }
    };
    let mid = ((middle - o_along) / r).floor() as usize;
    let (mut lows, mut highs) = (Vec::new(), Vec::new());
    for across in 0..n_across {
        let c = o_across + (across as f64 + 0.5) * r;
        if c < band.0 || c > band.1 {
            continue;
        }
        assert_eq!(at(mid, across), Trinary::Free, "the middle is free");
        if let Some(k) = (0..mid).rev().find(|&k| at(k, across) == Trinary::Occupied) {
            lows.push(o_along + (k as f64 + 0.5) * r);
        }
        if let Some(k) = (mid..n_along).find(|&k| at(k, across) == Trinary::Occupied) {
            highs.push(o_along + (k as f64 + 0.5) * r);
        }
    }
    assert!(lows.len() > 20 && highs.len() > 20);
    (median(lows), median(highs))
}

/// The enclosure's four wall positions measured in a map, through the middle bands that
/// miss the boxes: `((x_lo, x_hi), (y_lo, y_hi))`.
fn enclosure_walls(map: &TrinaryGrid) -> ((f64, f64), (f64, f64)) {
    (
        measure_walls(map, 0, (MIN[1] + 1.8, MIN[1] + 3.6), MIN[0] + 0.5 * SIZE[0]),
        measure_walls(map, 1, (MIN[0] + 3.0, MIN[0] + 4.5), MIN[1] + 0.5 * SIZE[1]),
    )
}

fn inside_box(x: f64, y: f64, margin: f64) -> bool {
    BOXES.iter().any(|b| {
        x > MIN[0] + b[0] - margin
            && x < MIN[0] + b[2] + margin
            && y > MIN[1] + b[1] - margin
            && y < MIN[1] + b[3] + margin
    })
}

#[test]
fn a_simulated_enclosure_is_mapped_within_two_percent() {
    let world = enclosure();
    let poses = enclosure_poses();
    let scans = enclosure_scans(&world, &poses);
    let model = SensorModel2d::default();
    let mut grid = OccupancyGrid2d::new(0.05).unwrap();
    let start = Instant::now();
    let mut cells = 0usize;
    for (s, p) in scans.iter().zip(&poses) {
        let stats = grid.insert_scan(s, p, &model).unwrap();
        assert_eq!(stats.beams, 361);
        // A closed room returns every beam but those beyond the scanner's 8 m.
        assert!(stats.hits > 330, "{stats:?}");
        cells += stats.cells_traversed;
    }
    let secs = start.elapsed().as_secs_f64();
    eprintln!(
        "grid2d: {} scans, {cells} cells traversed in {:.2} ms: {:.1} M cells/s; grid {} x {}",
        scans.len(),
        secs * 1e3,
        cells as f64 / secs / 1e6,
        grid.width(),
        grid.height()
    );
    let map = grid.to_trinary(Thresholds::default());

    // Wall-to-wall dimensions from the occupied cells through the middle bands.
    let ((x_lo, x_hi), (y_lo, y_hi)) = enclosure_walls(&map);
    let (w, h) = (x_hi - x_lo, y_hi - y_lo);
    let (ew, eh) = ((w - SIZE[0]) / SIZE[0], (h - SIZE[1]) / SIZE[1]);
    eprintln!(
        "grid2d: enclosure {:.3} x {:.3} m measured {w:.3} x {h:.3} m: errors {:+.2} % and \
         {:+.2} %; walls at x {x_lo:.3} {x_hi:.3}, y {y_lo:.3} {y_hi:.3}",
        SIZE[0],
        SIZE[1],
        100.0 * ew,
        100.0 * eh
    );
    assert!(ew.abs() < 0.02 && eh.abs() < 0.02);
    // Each wall within a cell of where it is.
    for (got, want) in [
        (x_lo, MIN[0]),
        (x_hi, MIN[0] + SIZE[0]),
        (y_lo, MIN[1]),
        (y_hi, MIN[1] + SIZE[1]),
    ] {
        assert!((got - want).abs() <= 0.05, "wall at {got}, truly {want}");
    }

    // Free inside, occupied only on surfaces, unknown outside.
    let (mut inside, mut inside_free) = (0usize, 0usize);
    for j in 0..map.height {
        for i in 0..map.width {
            let t = map.get(i, j).unwrap();
            let (x, y) = grid.cell_center(i, j);
            let (u, v) = (x - MIN[0], y - MIN[1]);
            let margin = 0.15;
            let in_room = u > margin && v > margin && u < SIZE[0] - margin && v < SIZE[1] - margin;
            let outside =
                u < -margin || v < -margin || u > SIZE[0] + margin || v > SIZE[1] + margin;
            if in_room && !inside_box(x, y, margin) {
                inside += 1;
                inside_free += (t == Trinary::Free) as usize;
                assert_ne!(t, Trinary::Occupied, "occupied cell at ({x:.3}, {y:.3})");
            }
            if outside {
                assert_eq!(grid.log_odds((i, j)), 0.0, "observed outside at ({x}, {y})");
                assert_eq!(t, Trinary::Unknown);
            }
            if t == Trinary::Occupied {
                let near_wall = u
                    .abs()
                    .min(v.abs())
                    .min((u - SIZE[0]).abs())
                    .min((v - SIZE[1]).abs())
                    < 0.1;
                assert!(
                    near_wall || inside_box(x, y, 0.1),
                    "occupied cell off every surface at ({x:.3}, {y:.3})"
                );
            }
        }
    }
    let free_fraction = inside_free as f64 / inside as f64;
    eprintln!(
        "grid2d: {:.2} % of {inside} inner cells free; counts {:?}",
        100.0 * free_fraction,
        map.counts()
    );
    assert!(free_fraction > 0.97, "{free_fraction}");
}

#[test]
fn the_enclosure_mapped_from_mutual_localisation_poses_is_within_two_percent() {
    use olmap::beacon::ReflectiveParams;
    use olmap::sim::RobotModel;
    use olmap::team::{mutual_from_scans, MutualParams};
    // Robot A stands at one end facing into the room and defines the map frame; robot B
    // drives around, and at each stop both scan and B's pose comes from the two-way
    // beacon sighting alone (no odometry, no scan matching).
    let world = enclosure();
    // Beacons 0.2 m across: the 0.5° scanner puts three returns on them up to ~6 m.
    let model = RobotModel {
        beacon_radius: 0.1,
        ..RobotModel::front_beacon(0.2)
    };
    let robot_a = Pose::from_xyz_ypr(MIN[0] + 0.6, MIN[1] + 2.7, 0.0, 0.0, 0.0, 0.0);
    let stops = [
        (2.0, 2.6, 0.4),
        (3.5, 4.2, -0.5),
        (4.5, 1.8, 0.7),
        (6.3, 2.7, 0.2),
        (5.5, 3.8, -0.8),
        (3.0, 1.5, 0.6),
        (5.6, 1.0, -0.3),
        (2.8, 3.5, 0.0),
    ];
    let mut scanner = PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.01;
    let detect = ReflectiveParams {
        max_rms: 0.02,
        ..Default::default()
    };
    let sensor = model.scanner2d_pose();
    let sensor_a = robot_a * sensor;
    let mut grid = OccupancyGrid2d::new(0.05).unwrap();
    let model2d = SensorModel2d::default();
    let mut worst = 0.0f64;
    for (k, &(x, y, turn)) in stops.iter().enumerate() {
        let (bx, by) = (MIN[0] + x, MIN[1] + y);
        let facing_a = (robot_a.translation().y - by).atan2(robot_a.translation().x - bx);
        let robot_b = Pose::from_xyz_ypr(bx, by, 0.0, facing_a + turn, 0.0, 0.0);
        let sensor_b = robot_b * sensor;
        let scan_a = scanner.scan(
            &world,
            &model.objects(1, &robot_b),
            &sensor_a,
            3,
            2 * k as u64,
        );
        let scan_b = scanner.scan(
            &world,
            &model.objects(0, &robot_a),
            &sensor_b,
            3,
            2 * k as u64 + 1,
        );
        let fix = mutual_from_scans(
            &scan_a,
            &scan_b,
            0.075,
            0.15,
            &detect,
            &MutualParams::default(),
        )
        .unwrap_or_else(|e| panic!("stop {k}: {e}"));
        let t_a_b = Pose::from_xyz_ypr(fix.x, fix.y, 0.0, fix.heading, 0.0, 0.0);
        let estimate = sensor_a * t_a_b;
        worst = worst.max((estimate.translation() - sensor_b.translation()).norm());
        grid.insert_scan(&scan_b, &estimate, &model2d).unwrap();
        if k == 0 {
            grid.insert_scan(&scan_a, &sensor_a, &model2d).unwrap();
        }
    }
    let map = grid.to_trinary(Thresholds::default());
    let ((x_lo, x_hi), (y_lo, y_hi)) = enclosure_walls(&map);
    let (w, h) = (x_hi - x_lo, y_hi - y_lo);
    let (ew, eh) = ((w - SIZE[0]) / SIZE[0], (h - SIZE[1]) / SIZE[1]);
    eprintln!(
        "mutual-pose map: worst pose error {worst:.3} m; measured {w:.3} x {h:.3} m: errors \
         {:+.2} % and {:+.2} %",
        100.0 * ew,
        100.0 * eh
    );
    assert!(ew.abs() < 0.02 && eh.abs() < 0.02);
}

// ---------------------------------------------------------------------------------------
// Position buckets

#[test]
fn the_bucket_rule_takes_new_positions_only() {
    let world = enclosure();
    let p0 = Pose::from_xyz_ypr(MIN[0] + 2.0, MIN[1] + 2.5, 0.3, 0.0, 0.0, 0.0);
    let turned = Pose::from_xyz_ypr(MIN[0] + 2.0, MIN[1] + 2.5, 0.3, 2.0, 0.0, 0.0);
    let nudged = Pose::from_xyz_ypr(MIN[0] + 2.3, MIN[1] + 2.6, 0.3, -1.0, 0.0, 0.0);
    let far = Pose::from_xyz_ypr(MIN[0] + 5.0, MIN[1] + 2.5, 0.3, 3.0, 0.0, 0.0);
    let poses = [p0, p0, turned, nudged, far, nudged, p0];
    let scans = enclosure_scans(&world, &poses);
    let model = SensorModel2d::default();
    let mut grid = OccupancyGrid2d::new(0.05).unwrap();
    let mut buckets = PositionBuckets::new(0.5).unwrap();
    let mut taken = Vec::new();
    let mut reference = OccupancyGrid2d::new(0.05).unwrap();
    for (k, (s, p)) in scans.iter().zip(&poses).enumerate() {
        let before: Vec<f32> = grid.cells().map(|(_, l)| l).collect();
        match grid
            .insert_scan_bucketed(s, p, &model, &mut buckets)
            .unwrap()
        {
            Some(stats) => {
                assert!(stats.hits > 300);
                reference.insert_scan(s, p, &model).unwrap();
                taken.push(k);
            }
            None => {
                let after: Vec<f32> = grid.cells().map(|(_, l)| l).collect();
                assert_eq!(after, before, "a skipped scan leaves the grid alone");
            }
        }
    }
    assert_eq!(taken, [0, 4]);
    assert_eq!(buckets.positions().len(), 2);
    // The bucketed grid is the grid of the scans taken.
    let a: Vec<_> = grid.cells().collect();
    let b: Vec<_> = reference.cells().collect();
    assert_eq!(a, b);
    // A radius of zero takes every scan.
    let mut all = PositionBuckets::new(0.0).unwrap();
    let mut g = OccupancyGrid2d::new(0.05).unwrap();
    let n = scans
        .iter()
        .zip(&poses)
        .filter(|(s, p)| {
            g.insert_scan_bucketed(s, p, &model, &mut all)
                .unwrap()
                .is_some()
        })
        .count();
    assert_eq!(n, poses.len());
}

// ---------------------------------------------------------------------------------------
// ROS map files

#[test]
fn ros_map_round_trip_keeps_cells_origin_and_resolution() {
    let world = enclosure();
    let poses = enclosure_poses();
    let scans = enclosure_scans(&world, &poses[..3]);
    let mut grid = OccupancyGrid2d::new(0.05).unwrap();
    for (s, p) in scans.iter().zip(&poses) {
        grid.insert_scan(s, p, &SensorModel2d::default()).unwrap();
    }
    let map = grid.to_trinary(Thresholds::default());
    let c = map.counts();
    assert!(
        c.free > 1000 && c.occupied > 100 && c.unknown > 100,
        "{c:?}"
    );
    let dir = tempfile::tempdir().unwrap();
    let pgm = dir.path().join("enclosure map.pgm");
    let yaml = write_ros_map(&pgm, &map).unwrap();
    assert_eq!(yaml, dir.path().join("enclosure map.yaml"));
    let back = read_ros_map(&yaml).unwrap();
    assert_eq!(back, map);
    assert_eq!(back.origin[0], grid.origin().0);
    assert_eq!(back.resolution, 0.05);

    // The image: P5, first row = top (highest y), ROS values.
    let bytes = std::fs::read(&pgm).unwrap();
    let header = format!("{} {}\n255\n", map.width, map.height);
    let start = bytes
        .windows(header.len())
        .position(|w| w == header.as_bytes())
        .unwrap()
        + header.len();
    assert!(bytes.starts_with(b"P5\n"));
    assert_eq!(bytes.len() - start, map.width * map.height);
    let top_row = &bytes[start..start + map.width];
    for (i, &v) in top_row.iter().enumerate() {
        assert_eq!(v, map.get(i, map.height - 1).unwrap().pgm_value());
    }
    assert!(bytes[start..].iter().all(|v| [0, 205, 254].contains(v)));
    let text = std::fs::read_to_string(&yaml).unwrap();
    for line in [
        "image: \"enclosure map.pgm\"",
        "resolution: 0.05",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
        "mode: trinary",
    ] {
        assert!(text.lines().any(|l| l == line), "{line} in\n{text}");
    }
}

fn write(path: &Path, text: &[u8]) {
    std::fs::write(path, text).unwrap();
}

fn read_err(yaml: &Path) -> String {
    read_ros_map(yaml).unwrap_err().to_string()
}

#[test]
fn ros_map_reader_handles_ros_files_and_names_the_bad_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A hand-written map as map_saver writes it, with comments, negate and a yawed origin.
    let mut pgm = b"P5\n# CREATOR: map_saver.cpp 0.100 m/pix\n3 2\n255\n".to_vec();
    pgm.extend_from_slice(&[0, 205, 254, 254, 100, 0]);
    write(&d.join("m.pgm"), &pgm);
    write(
        &d.join("m.yaml"),
        b"image: m.pgm\nresolution: 0.100000\norigin: [-1.0, 2.5, 0.5]  # pose\n\
          negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
    );
    let m = read_ros_map(d.join("m.yaml")).unwrap();
    assert_eq!((m.width, m.height, m.resolution), (3, 2, 0.1));
    assert_eq!(m.origin, [-1.0, 2.5, 0.5]);
    // Top image row is the upper grid row.
    use Trinary::*;
    assert_eq!(m.cells, [Free, Unknown, Occupied, Occupied, Unknown, Free]);
    write(
        &d.join("n.yaml"),
        b"image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n\
          occupied_thresh: 0.65\nfree_thresh: 0.196\n",
    );
    let n = read_ros_map(d.join("n.yaml")).unwrap();
    assert_eq!(n.cells, [Occupied, Unknown, Free, Free, Occupied, Occupied]);

    // Malformed YAML: the error names the file and the line.
    let cases: [(&str, &[u8], &str); 6] = [
        (
            "a.yaml",
            b"image: m.pgm\nresolution: 0.1\norigin: [0, 0]\n",
            "line 3",
        ),
        ("b.yaml", b"image: m.pgm\nresolution: fine\n", "line 2"),
        (
            "c.yaml",
            b"image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n",
            "missing key",
        ),
        ("d.yaml", b"image: m.pgm\njust words\n", "line 2"),
        (
            "e.yaml",
            b"image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n\
              occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: scale\n",
            "line 7",
        ),
        ("f.yaml", b"resolution: 0.1\nresolution: 0.2\n", "line 2"),
    ];
    for (name, text, want) in cases {
        let path = d.join(name);
        write(&path, text);
        let e = read_err(&path);
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }

    // Malformed images: the error names the image.
    let good_yaml = |img: &str| {
        format!(
            "image: {img}\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n"
        )
    };
    let images: [(&str, &[u8], &str); 4] = [
        ("short.pgm", b"P5\n3 2\n255\n\x00\x00", "ends early"),
        ("ascii.pgm", b"P2\n1 1\n255\n0\n", "unsupported"),
        ("png.pgm", b"\x89PNG\r\n", "byte 0"),
        ("wide.pgm", b"P5\n1 1\n65535\n\x00\x00", "16-bit"),
    ];
    for (img, bytes, want) in images {
        write(&d.join(img), bytes);
        let y = d.join(format!("{img}.yaml"));
        write(&y, good_yaml(img).as_bytes());
        let e = read_err(&y);
        assert!(e.contains(img) && e.contains(want), "{img}: {e}");
    }
    let y = d.join("missing.yaml");
    write(&y, good_yaml("nowhere.pgm").as_bytes());
    assert!(read_err(&y).contains("nowhere.pgm"));
}
