//! Teams of robots: mutual localisation from two-way beacon sightings (thesis §3.3.1,
//! §6.3.3), with the distractor test and the error model of §3.5; per-robot scan stores
//! that merge when robots meet (§6.3.2); robot clearing (§6.5.1); and the team mapper
//! (§6.4-6.5) with its solo counterpart.

mod clearing;
#[cfg(feature = "render")]
mod html;
mod live;
mod mapper;
mod mutual;
mod mutual_report;
mod pipeline;
pub mod report;
mod store;

pub use clearing::{clear_robots, ClearingParams};
#[cfg(feature = "render")]
pub use html::write_team_html;
pub use live::LiveTeam;
pub use mapper::{map_solo, map_team, scan_name, RobotFrame, TeamMap, TeamParams};
pub use mutual::{
    expected_position_error, mutual_from_scans, mutual_pose, separations, MutualFix,
    MutualObservation, MutualParams, MutualReject,
};
pub use mutual_report::{observation_of_fix, MutualReport};
pub(crate) use pipeline::{declare_team_outputs, team_run_into};
pub use pipeline::{run_team_in_memory, run_team_pipeline, TeamJob, TeamResult, TeamRun};
pub use report::{SoloRun, TeamReport, TEAM_REPORT_FORMAT, TEAM_REPORT_VERSION};
pub use store::{
    merge_store_files, salvage_store_file, store_info, SalvageReport, ScanStore, StoreDamage,
    StoreInfo, StoreMergeInput, StoreMergeReport, StoreRobotInfo, StoreSalvageReport, StoredScan,
    StoredSighting, RECORD_MARKER, STORE_MAGIC, STORE_VERSION,
};
