//! Simulator ray casting: a 100,000-ray spherical scan (500 azimuths x 200 elevations)
//! from a free spot in the lab and the office, through `World::cast_many` on rayon pools of
//! one and two threads and through a plain single-threaded loop over `World::cast`.
//!
//! `cargo bench -p olmap --bench sim`

use divan::counter::ItemsCount;
use divan::Bencher;
use nalgebra::{Point3, Vector3};
use olmap::sim::{free_spot, lab, office, SimRng, World};

fn main() {
    divan::main();
}

const AZIMUTHS: usize = 500;
const ELEVATIONS: usize = 200;
const RANGE: f64 = 30.0;

fn world(name: &str) -> World {
    match name {
        "lab" => lab(1),
        "office" => office(1),
        _ => unreachable!("{name}"),
    }
}

/// The scan's rays from a free spot, 0.8 m up, over the whole sphere.
fn scan(world: &World) -> Vec<(Point3<f64>, Vector3<f64>)> {
    let (x, y) = free_spot(world, &mut SimRng::new(7), 0.3).expect("a free spot");
    let origin = Point3::new(x, y, 0.8);
    let mut rays = Vec::with_capacity(AZIMUTHS * ELEVATIONS);
    for i in 0..AZIMUTHS {
        let az = std::f64::consts::TAU * i as f64 / AZIMUTHS as f64;
        for j in 0..ELEVATIONS {
            let el = std::f64::consts::PI * ((j as f64 + 0.5) / ELEVATIONS as f64 - 0.5);
            let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            rays.push((origin, d));
        }
    }
    rays
}

#[divan::bench(args = ["lab", "office"], consts = [1, 2])]
fn cast_many<const THREADS: usize>(bencher: Bencher, name: &str) {
    let w = world(name);
    let rays = scan(&w);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(THREADS)
        .build()
        .unwrap();
    bencher
        .counter(ItemsCount::new(rays.len()))
        .bench(|| pool.install(|| w.cast_many(&[], &rays, RANGE)));
}

#[divan::bench(args = ["lab", "office"])]
fn cast_loop(bencher: Bencher, name: &str) {
    let w = world(name);
    let rays = scan(&w);
    bencher.counter(ItemsCount::new(rays.len())).bench(|| {
        rays.iter()
            .filter(|(o, d)| w.cast(o, d, RANGE).is_some())
            .count()
    });
}

/// A whole dataset in memory: 4 robots x 20 stops in the lab with the enhanced mirror
/// scanner (about 65,000 rays per scan), sightings included; counted in scans.
#[divan::bench(sample_count = 3, sample_size = 1)]
fn lab_dataset_4x20(bencher: Bencher) {
    let config = olmap::sim::SimConfig::default();
    bencher
        .counter(ItemsCount::new(config.robots * config.stops))
        .bench(|| olmap::sim::simulate(&config, |_, _| {}).unwrap());
}
