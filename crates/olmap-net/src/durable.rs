//! [`DurableStore`]: a node's scan store on disk in an embedded ACID database (redb), so
//! that a node killed at any instant restarts with every record it had acknowledged.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use olmap::team::{ScanStore, StoredScan};
use redb::{Database, ReadableDatabase, ReadableTable, TableDefinition};

use crate::error::{BadMessage, NetError, Result};
use crate::protocol::{Digest, RobotHoldings};

/// Records by `(robot, seq)`, each in the record encoding of
/// [`StoredScan::encode_record`].
const RECORDS: TableDefinition<(u32, u32), &[u8]> = TableDefinition::new("records");
/// Robot names by id.
const NAMES: TableDefinition<u32, &str> = TableDefinition::new("names");

/// A scan store kept in a redb database file: every insert is one committed transaction
/// (record and robot name together), so a record is either wholly on disk or absent
/// whenever the process dies. An in-memory [`ScanStore`] mirrors it for mapping and
/// digests; [`DurableStore::export`] writes the `.store` interchange file.
pub struct DurableStore {
    db: Database,
    path: PathBuf,
    store: ScanStore,
}

impl std::fmt::Debug for DurableStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DurableStore")
            .field("path", &self.path)
            .field("records", &self.store.len())
            .finish()
    }
}

impl DurableStore {
    /// Opens the database at `path`, creating it if missing, and loads every record
    /// (each decoded and checked as on the wire; a record that does not decode is an
    /// error naming it, never skipped silently).
    pub fn open(path: impl AsRef<Path>) -> Result<DurableStore> {
        let path = path.as_ref().to_path_buf();
        let err = |e: &dyn std::fmt::Display| NetError::Store {
            path: path.clone(),
            reason: e.to_string(),
        };
        let db = Database::create(&path).map_err(|e| err(&e))?;
        let mut store = ScanStore::new();
        {
            let txn = db.begin_write().map_err(|e| err(&e))?;
            txn.open_table(RECORDS).map_err(|e| err(&e))?;
            txn.open_table(NAMES).map_err(|e| err(&e))?;
            txn.commit().map_err(|e| err(&e))?;
        }
        let txn = db.begin_read().map_err(|e| err(&e))?;
        let names = txn.open_table(NAMES).map_err(|e| err(&e))?;
        for row in names.iter().map_err(|e| err(&e))? {
            let (robot, name) = row.map_err(|e| err(&e))?;
            store
                .set_robot_name(robot.value(), name.value())
                .map_err(|e| err(&e))?;
        }
        let records = txn.open_table(RECORDS).map_err(|e| err(&e))?;
        for row in records.iter().map_err(|e| err(&e))? {
            let (key, bytes) = row.map_err(|e| err(&e))?;
            let (robot, seq) = key.value();
            let scan = StoredScan::decode_record(bytes.value()).map_err(|e| {
                err(&format!(
                    "record of scan {seq} of robot {robot} does not decode: {e}"
                ))
            })?;
            if (scan.robot, scan.seq) != (robot, seq) {
                return Err(err(&format!(
                    "the record under key ({robot}, {seq}) holds scan {} of robot {}",
                    scan.seq, scan.robot
                )));
            }
            store.insert(scan).map_err(|e| err(&e))?;
        }
        drop(records);
        drop(names);
        drop(txn);
        Ok(DurableStore { db, path, store })
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The records held, in memory.
    pub fn store(&self) -> &ScanStore {
        &self.store
    }

    /// Records `scan`, recorded by robot `name`: `Ok(true)` when new (committed to disk
    /// before this returns), `Ok(false)` when an identical record was held. A different
    /// record under the same key, or another name for a known robot, is refused as a
    /// [`BadMessage::Conflict`] (the first record stays); a failing disk is a
    /// [`NetError`].
    pub fn insert(&mut self, name: &str, scan: &StoredScan) -> Result<Result<bool, BadMessage>> {
        let robot = scan.robot;
        let known_name = self
            .store
            .robots()
            .contains(&robot)
            .then(|| self.store.robot_name(robot));
        if let Some(old) = known_name.as_deref().filter(|old| *old != name) {
            return Ok(Err(BadMessage::Conflict(format!(
                "robot {robot} is named '{old}', a record calls it '{name}'"
            ))));
        }
        let mut trial = ScanStore::new();
        trial
            .insert(scan.clone())
            .map_err(|e| NetError::InvalidArgument(e.to_string()))?;
        if let Err(e) = trial.set_robot_name(robot, name) {
            return Ok(Err(BadMessage::Body(e.to_string())));
        }
        if self.store.get(robot, scan.seq).is_some() {
            // Merging checks the record bit for bit against the one held and changes
            // nothing on a conflict.
            return Ok(match self.store.merge(&trial) {
                Ok(_) => Ok(false),
                Err(e) => Err(BadMessage::Conflict(e.to_string())),
            });
        }
        let err = |e: &dyn std::fmt::Display| NetError::Store {
            path: self.path.clone(),
            reason: e.to_string(),
        };
        let bytes = scan.encode_record();
        let txn = self.db.begin_write().map_err(|e| err(&e))?;
        {
            let mut records = txn.open_table(RECORDS).map_err(|e| err(&e))?;
            records
                .insert((robot, scan.seq), bytes.as_slice())
                .map_err(|e| err(&e))?;
            let mut names = txn.open_table(NAMES).map_err(|e| err(&e))?;
            names.insert(robot, name).map_err(|e| err(&e))?;
        }
        txn.commit().map_err(|e| err(&e))?;
        self.store.merge(&trial).map_err(|e| err(&e))?;
        Ok(Ok(true))
    }

    /// What this node holds, per robot, as a digest published under `node`.
    pub fn digest(&self, node: &str) -> Digest {
        let robots: BTreeMap<u32, RobotHoldings> = self
            .store
            .robots()
            .into_iter()
            .map(|r| {
                (
                    r,
                    RobotHoldings::from_sorted(self.store.scans_of(r).map(|s| s.seq)),
                )
            })
            .collect();
        Digest {
            node: node.to_string(),
            robots,
        }
    }

    /// Writes the records as a `.store` file (atomically; the interchange format that
    /// `olmap team` reads).
    pub fn export(&self, path: impl AsRef<Path>) -> Result<()> {
        Ok(self.store.write(path)?)
    }
}
