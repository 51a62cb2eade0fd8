//! Circle detection per 2D scan: least squares, retroreflective runs and the range-weighted
//! Hough transform on one simulated SICK scan (180° at 0.5°, 1 cm noise) of an 8 x 6 m
//! room with clutter and two taped cylinders of radius 0.125 m.
//!
//! `cargo bench -p olmap --bench beacon`

use divan::Bencher;
use nalgebra::{Point3, Vector3};
use olmap::beacon::{
    detect_circles_lsq, detect_circles_reflective, detect_circles_rwht, LsqParams,
    ReflectiveParams, RwhtParams,
};
use olmap::cloud::LaserScan;
use olmap::geometry::Pose;
use olmap::sim::{box_room, Material, Object, PlanarScanner, Shape};

fn main() {
    divan::main();
}

const RADIUS: f64 = 0.125;

fn scan() -> LaserScan {
    let room = box_room(Vector3::new(8.0, 6.0, 3.0));
    let mut extra: Vec<Object> = [(4.0, 4.0), (6.5, 1.5)]
        .iter()
        .map(|&(x, y)| Object {
            shape: Shape::Cylinder {
                base: Point3::new(x, y, 0.0),
                radius: RADIUS,
                height: 1.0,
            },
            material: Material::BEACON,
            id: 1,
        })
        .collect();
    for &(x, y) in &[(3.0, 1.0), (5.5, 4.5), (7.0, 3.5)] {
        extra.push(Object {
            shape: Shape::Box {
                center: Point3::new(x, y, 0.4),
                half: Vector3::new(0.3, 0.2, 0.4),
                yaw: 0.5,
            },
            material: Material::FURNITURE,
            id: 0,
        });
    }
    let mut scanner = PlanarScanner::sick_180_half_degree();
    scanner.noise.sigma = 0.01;
    let sensor = Pose::from_xyz_ypr(1.0, 3.0, 0.4, 0.0, 0.0, 0.0);
    scanner.scan(&room, &extra, &sensor, 1, 0)
}

#[divan::bench]
fn lsq(bencher: Bencher) {
    let s = scan();
    let p = LsqParams::default();
    bencher.bench(|| detect_circles_lsq(divan::black_box(&s), RADIUS, &p));
}

#[divan::bench]
fn reflective(bencher: Bencher) {
    let s = scan();
    let p = ReflectiveParams::default();
    bencher.bench(|| detect_circles_reflective(divan::black_box(&s), RADIUS, &p));
}

#[divan::bench]
fn rwht(bencher: Bencher) {
    let s = scan();
    let p = RwhtParams::default();
    bencher.bench(|| detect_circles_rwht(divan::black_box(&s), RADIUS, &p));
}
