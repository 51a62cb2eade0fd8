//! Store files as a front end sees them (`olmap store info | merge | salvage`): what a file
//! holds ([`store_info`]), several files merged into one ([`merge_store_files`]), the
//! readable records of a damaged file written to a new one ([`salvage_store_file`]), each
//! with a typed, serialisable report.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::salvage::{SalvageReport, StoreDamage};
use super::ScanStore;
use crate::error::{Error, Location, ParseError, Result};

/// One robot's records in a store.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StoreRobotInfo {
    /// The robot's id.
    pub robot: u32,
    /// Its name (`robotN` when the store does not name it).
    pub name: String,
    /// Records of this robot.
    pub records: usize,
    /// Lowest scan number.
    pub first_seq: u32,
    /// Highest scan number.
    pub last_seq: u32,
    /// Scan numbers missing between the first and the last, as inclusive ranges.
    pub gaps: Vec<[u32; 2]>,
    /// Points in all its scans.
    pub points: usize,
}

impl ScanStore {
    /// One summary per robot with records, ascending.
    pub fn robot_summaries(&self) -> Vec<StoreRobotInfo> {
        self.robots()
            .into_iter()
            .map(|robot| {
                let seqs: Vec<u32> = self.scans_of(robot).map(|s| s.seq).collect();
                let gaps = seqs
                    .windows(2)
                    .filter(|w| w[1] > w[0] + 1)
                    .map(|w| [w[0] + 1, w[1] - 1])
                    .collect();
                StoreRobotInfo {
                    robot,
                    name: self.robot_name(robot),
                    records: seqs.len(),
                    first_seq: seqs.first().copied().unwrap_or(0),
                    last_seq: seqs.last().copied().unwrap_or(0),
                    gaps,
                    points: self.scans_of(robot).map(|s| s.cloud.len()).sum(),
                }
            })
            .collect()
    }
}

/// What a store file holds (`olmap store info`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StoreInfo {
    /// The file.
    pub path: String,
    /// Its size in bytes.
    pub bytes: u64,
    /// Its format version (0 when its first bytes are damaged).
    pub version: u32,
    /// Whether it reads whole with [`ScanStore::read`] (no damage).
    pub intact: bool,
    /// Records (readable ones, when damaged).
    pub records: usize,
    /// Named robots.
    pub names: usize,
    /// Per robot: records, scan-number range, gaps, points.
    pub robots: Vec<StoreRobotInfo>,
    /// Records lost to damage (see [`SalvageReport::records_lost`]).
    pub records_lost: u64,
    /// The damaged stretches with their byte offsets (empty when intact).
    pub damage: Vec<StoreDamage>,
}

/// Describes a store file; a damaged one is described from its readable records, with the
/// damage (an error only when nothing in it reads as a store).
pub fn store_info(path: &Path) -> Result<StoreInfo> {
    let data = crate::file::read_bytes(path)?;
    let read_error = |source| Error::Read {
        path: path.to_path_buf(),
        format: super::codec::FORMAT,
        source,
    };
    let (store, salvage) = ScanStore::salvage_from(&data).map_err(read_error)?;
    let mut damage = salvage.damage;
    let strict = ScanStore::read_from(&data[..]);
    if let (Err(e), true) = (&strict, damage.is_empty()) {
        // Every record verified, yet the file breaks a rule of the format (an order, a
        // count, bytes after the end): say which.
        let start = match e {
            ParseError::Invalid {
                at: Location::Byte(b),
                ..
            } => *b,
            _ => 0,
        };
        damage.push(StoreDamage {
            start,
            end: data.len() as u64,
            record: None,
            records_seen: 0,
            reason: e.to_string(),
        });
    }
    Ok(StoreInfo {
        path: path.display().to_string(),
        bytes: data.len() as u64,
        version: salvage.version,
        intact: strict.is_ok(),
        records: store.len(),
        names: store.names.len(),
        robots: store.robot_summaries(),
        records_lost: salvage.records_lost,
        damage,
    })
}

/// One input of a merge.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StoreMergeInput {
    /// The file.
    pub path: String,
    /// Records in it.
    pub records: usize,
    /// Records it added to the merge (the others were already there, identical).
    pub added: usize,
}

/// What [`merge_store_files`] did (`olmap store merge`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StoreMergeReport {
    /// The merged store written.
    pub output: String,
    /// Its size in bytes.
    pub bytes: u64,
    /// The inputs in order.
    pub inputs: Vec<StoreMergeInput>,
    /// Records in the merged store.
    pub records: usize,
    /// Per robot, in the merged store.
    pub robots: Vec<StoreRobotInfo>,
}

fn file_size(path: &Path) -> u64 {
    std::fs::metadata(path).map_or(0, |m| m.len())
}

/// Merges store files into one (set union, [`ScanStore::merge`]) written atomically to
/// `output` (checked before any input is read). A damaged input is refused with the offset
/// of the damage (salvage it first); two inputs that disagree about a record or a robot's
/// name are an error and nothing is written.
pub fn merge_store_files(inputs: &[PathBuf], output: &Path) -> Result<StoreMergeReport> {
    if inputs.is_empty() {
        return Err(Error::InvalidArgument("no store to merge".into()));
    }
    crate::file::check_output(output, super::codec::FORMAT)?;
    let mut merged = ScanStore::new();
    let mut report = Vec::with_capacity(inputs.len());
    for path in inputs {
        let store = ScanStore::read(path)?;
        let added = merged
            .merge(&store)
            .map_err(|e| Error::InvalidArgument(format!("{}: {e}", path.display())))?;
        report.push(StoreMergeInput {
            path: path.display().to_string(),
            records: store.len(),
            added,
        });
    }
    merged.write(output)?;
    Ok(StoreMergeReport {
        output: output.display().to_string(),
        bytes: file_size(output),
        inputs: report,
        records: merged.len(),
        robots: merged.robot_summaries(),
    })
}

/// What [`salvage_store_file`] recovered and lost (`olmap store salvage`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StoreSalvageReport {
    /// The damaged file read.
    pub input: String,
    /// The store written with the recovered records.
    pub output: String,
    /// Its size in bytes.
    pub output_bytes: u64,
    /// What was recovered and lost, with the damaged stretches.
    #[serde(flatten)]
    pub salvage: SalvageReport,
    /// Per robot, the records recovered.
    pub robots: Vec<StoreRobotInfo>,
}

/// Recovers every readable record of a (damaged) store file and writes them, with the
/// robot names if the header survived, as a new store at `output` (checked before the
/// input is read; written atomically in the current version).
pub fn salvage_store_file(input: &Path, output: &Path) -> Result<StoreSalvageReport> {
    crate::file::check_output(output, super::codec::FORMAT)?;
    let (store, salvage) = ScanStore::read_salvaged(input)?;
    store.write(output)?;
    Ok(StoreSalvageReport {
        input: input.display().to_string(),
        output: output.display().to_string(),
        output_bytes: file_size(output),
        salvage,
        robots: store.robot_summaries(),
    })
}
