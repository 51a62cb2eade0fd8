//! Teams of robots: mutual localisation from two-way beacon sightings (thesis §3.3.1,
//! §6.3.3), with the distractor test and the error model of §3.5; per-robot scan stores
//! that merge when robots meet (§6.3.2); robot clearing (§6.5.1); and the team mapper
//! (§6.4-6.5) with its solo counterpart.

mod clearing;
mod mapper;
mod mutual;
mod store;

pub use clearing::{clear_robots, ClearingParams};
pub use mapper::{map_solo, map_team, scan_name, RobotFrame, TeamMap, TeamParams};
pub use mutual::{
    expected_position_error, mutual_from_scans, mutual_pose, separations, MutualFix,
    MutualObservation, MutualParams, MutualReject,
};
pub use store::{ScanStore, StoredScan, StoredSighting, STORE_MAGIC, STORE_VERSION};
