//! [`SimulateReport`]: the typed summary of `olmap simulate --json`, a generated dataset.

use serde::{Deserialize, Serialize};

use super::SimDataset;

/// The summary of a simulated dataset written to disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulateReport {
    /// The dataset folder.
    pub output: String,
    /// The world's name.
    pub world: String,
    /// The seed.
    pub seed: u64,
    /// Robots.
    pub robots: usize,
    /// Scans (robots x stops).
    pub scans: u64,
    /// Points of all 3D scans.
    pub points: usize,
    /// Sightings between robots.
    pub sightings: usize,
    /// Sightings that were mutual.
    pub mutual_sightings: usize,
    /// Seconds spent simulating.
    pub simulate_seconds: f64,
    /// Seconds spent in all (simulating and writing).
    pub seconds: f64,
}

impl SimulateReport {
    /// The summary of `data` written to `output`, simulated in `simulate_seconds` and
    /// written by `seconds`.
    pub fn new(output: &str, data: &SimDataset, simulate_seconds: f64, seconds: f64) -> Self {
        let c = &data.config;
        SimulateReport {
            output: output.to_string(),
            world: c.world.name().to_string(),
            seed: c.seed,
            robots: c.robots,
            scans: (c.robots * c.stops) as u64,
            points: data
                .robots
                .iter()
                .flat_map(|r| r.scans.iter().map(|s| s.len()))
                .sum(),
            sightings: data.sightings.len(),
            mutual_sightings: data.sightings.iter().filter(|s| s.mutual).count(),
            simulate_seconds,
            seconds,
        }
    }
}
