//! Integration tests of the olmap library (one binary: it links once).

mod align;
mod align_exact;
mod align_synthetic;
mod audit_readers;
mod bad_input;
#[cfg(feature = "bag")]
mod bag;
mod beacon;
mod data_safety;
mod free_space;
mod fuzz;
mod graph;
mod grid2d;
mod incremental;
#[cfg(feature = "las")]
mod las;
mod layers;
mod limits;
mod mapping;
mod mutual;
mod occupancy;
mod pipelines;
mod planar;
mod posegraph3d;
mod real_data;
#[cfg(feature = "render")]
mod render;
mod round_trip;
mod scanner;
mod sim_robots;
mod sim_scanners;
mod sim_world;
mod team;
mod team_store;
mod trust;

use std::path::PathBuf;

/// The simulated lab team: `robots` x `stops`, the given odometry noise.
pub fn sim_lab(
    seed: u64,
    robots: usize,
    stops: usize,
    odometry: olmap::sim::OdometryNoise,
) -> olmap::sim::SimDataset {
    olmap::sim::simulate(
        &olmap::sim::SimConfig {
            world: olmap::sim::WorldKind::Lab,
            seed,
            robots,
            stops,
            odometry,
            ..Default::default()
        },
        |_, _| {},
    )
    .unwrap()
}

/// The shared data folder, or `None` to skip (see `olmap::test_data`).
pub fn data() -> Option<PathBuf> {
    olmap::test_data::dir()
}
