//! Teams of robots: mutual localisation from two-way beacon sightings (thesis §3.3.1,
//! §6.3.3), with the distractor test and the error model of §3.5, and robot clearing
//! (§6.5.1).

mod clearing;
mod mutual;
mod store;

pub use clearing::{clear_robots, ClearingParams};
pub use mutual::{
    expected_position_error, mutual_from_scans, mutual_pose, separations, MutualFix,
    MutualObservation, MutualParams, MutualReject,
};
pub use store::{ScanStore, StoredScan, StoredSighting, STORE_MAGIC, STORE_VERSION};
