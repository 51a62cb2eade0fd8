//! The salvage reader of store files: every record whose own checksum holds is recovered,
//! and every stretch of bytes that could not be read is reported with its offsets
//! ([`ScanStore::read_salvaged`], [`SalvageReport`]).
//!
//! How it reads a version-2 file: the header is used if its checksum holds (the robots'
//! names and the number of records; otherwise the names are lost and the count unknown).
//! From the end of the header (or from byte 0) it reads frame after frame; where no
//! verified frame starts, the stretch up to the next verified frame — found by its
//! `OLRECORD` marker, its length and its checksum — is reported as damaged, with the
//! markers seen in it (records whose bodies are damaged). A version-1 file has one
//! checksum for the whole file: its records are decoded in order until one does not, and
//! if the whole-file checksum fails they are returned but reported as unverified.

use std::collections::BTreeMap;

use serde::Serialize;

use super::codec::{
    check_frame, decode_body, decode_names, decode_scan, FrameFault, RECORD_MARKER, STORE_VERSION_1,
};
use super::{ScanStore, StoredScan};
use crate::error::{ParseError, Result};
use crate::file::cursor::ByteCursor;

/// A stretch of a store file that could not be read.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct StoreDamage {
    /// First unreadable byte (offset from the start of the file).
    pub start: u64,
    /// One past the last unreadable byte.
    pub end: u64,
    /// Index in file order of the first record the stretch held (the records before it
    /// counted as the file holds them), when known (a damaged version-1 file: `None`
    /// where the whole file is in doubt).
    pub record: Option<u64>,
    /// Record markers found in the stretch: records that were there but failed their
    /// checksum (a lower bound of the records lost in it).
    pub records_seen: u64,
    /// What was wrong, in words.
    pub reason: String,
}

/// What a salvage read recovered and what it lost.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SalvageReport {
    /// Bytes in the file.
    pub bytes: u64,
    /// The file's version, if its first bytes say (0 when they are damaged).
    pub version: u32,
    /// Whether the header (magic, version, names, record count) read and checked.
    pub header_intact: bool,
    /// Robot names recovered.
    pub names: usize,
    /// Records the header announced (when it is intact).
    pub records_expected: Option<u64>,
    /// Records recovered.
    pub records_recovered: usize,
    /// Records lost: announced minus recovered when the header is intact, else the record
    /// markers seen in damaged stretches (a lower bound).
    pub records_lost: u64,
    /// Whether every recovered record was verified by a checksum (false for a damaged
    /// version-1 file, whose one checksum covers the whole file).
    pub verified: bool,
    /// The unreadable stretches, in file order (empty for an intact file).
    pub damage: Vec<StoreDamage>,
}

impl SalvageReport {
    /// Whether the file read whole: nothing damaged, nothing lost.
    pub fn intact(&self) -> bool {
        self.damage.is_empty() && self.records_lost == 0 && self.verified
    }
}

impl ScanStore {
    /// Reads a store file, recovering every readable record (module
    /// [`salvage`](self) documentation): returns the records recovered and the report of
    /// what was lost. Only a file with no recognisable header and no verified record is an
    /// error. [`ScanStore::read`] refuses any damage instead.
    pub fn read_salvaged(path: impl AsRef<std::path::Path>) -> Result<(ScanStore, SalvageReport)> {
        let path = path.as_ref();
        let data = crate::file::read_bytes(path)?;
        Self::salvage_from(&data).map_err(|source| crate::Error::Read {
            path: path.to_path_buf(),
            format: super::codec::FORMAT,
            source,
        })
    }

    /// [`ScanStore::read_salvaged`] on bytes in memory.
    pub fn salvage_from(data: &[u8]) -> Result<(ScanStore, SalvageReport), ParseError> {
        if data.is_empty() {
            return Err(ParseError::Empty);
        }
        let mut header = ByteCursor::new(data);
        let names = decode_names(&mut header);
        let version = match &names {
            Ok((v, _)) => *v,
            Err(_) if data.len() >= 12 && &data[..8] == super::STORE_MAGIC => {
                u32::from_le_bytes(data[8..12].try_into().expect("4 bytes"))
            }
            Err(_) => 0,
        };
        if version == STORE_VERSION_1 {
            if let Ok((_, names)) = names {
                return Ok(salvage_v1(data, header, names));
            }
        }
        let mut salvage = Salvage::new(data, version);
        let mut start = 0;
        if let Ok((_, names)) = names {
            let count_pos = header.pos();
            if let (Ok(count), Ok(stored)) = (header.u64("record count"), header.u32("checksum")) {
                if crate::file::crc32::crc32(&data[..count_pos + 8]) == stored {
                    salvage.names = names;
                    salvage.expected = Some(count);
                    start = header.pos();
                }
            }
        }
        salvage.walk(start);
        if salvage.expected.is_none() {
            // The header is damaged: the first stretch (from byte 0) says so.
            if let Some(d) = salvage.damage.first_mut().filter(|d| d.start == 0) {
                d.reason = "the header is damaged (robot names and record count lost)".into();
            }
        }
        if salvage.expected.is_none() && salvage.scans.is_empty() {
            return Err(ParseError::Malformed(
                "no intact header and no intact record: nothing to salvage (not an olmap scan \
                 store, or wholly damaged)"
                    .into(),
            ));
        }
        Ok(salvage.finish())
    }
}

/// The first position at or after `from` where a verified frame starts (`data.len()` if
/// none).
fn next_frame(data: &[u8], from: usize) -> usize {
    let mut pos = from;
    while pos < data.len() {
        match find_marker(data, pos) {
            Some(p) if check_frame(data, p).is_ok() => return p,
            Some(p) => pos = p + 1,
            None => break,
        }
    }
    data.len()
}

/// The first position at or after `from` where the record marker's bytes are.
fn find_marker(data: &[u8], from: usize) -> Option<usize> {
    data.get(from..)?
        .windows(RECORD_MARKER.len())
        .position(|w| w == RECORD_MARKER)
        .map(|p| p + from)
}

/// The state of a version-2 salvage.
struct Salvage<'a> {
    data: &'a [u8],
    version: u32,
    names: BTreeMap<u32, String>,
    expected: Option<u64>,
    scans: BTreeMap<(u32, u32), StoredScan>,
    damage: Vec<StoreDamage>,
    /// Frames met so far (recovered or seen damaged): the next record's index.
    index: u64,
}

impl<'a> Salvage<'a> {
    fn new(data: &'a [u8], version: u32) -> Self {
        Salvage {
            data,
            version,
            names: BTreeMap::new(),
            expected: None,
            scans: BTreeMap::new(),
            damage: Vec::new(),
            index: 0,
        }
    }

    /// Reads frames from `pos` to the end, recording damaged stretches.
    fn walk(&mut self, mut pos: usize) {
        let data = self.data;
        while pos < data.len() {
            let fault = match check_frame(data, pos) {
                Ok(frame) => match decode_body(data, &frame) {
                    Ok(scan) => match self.keep(scan) {
                        Ok(()) => {
                            self.index += 1;
                            pos = frame.end;
                            continue;
                        }
                        Err(reason) => reason,
                    },
                    Err(e) => format!("the record's content is invalid: {e}"),
                },
                Err(FrameFault::NoMarker) => "no record starts here".into(),
                Err(FrameFault::Overrun) => {
                    "a record runs past the end of the file (cut short, or its length is damaged)"
                        .into()
                }
                Err(FrameFault::Checksum { .. }) => "checksum mismatch".into(),
            };
            let next = next_frame(data, pos + 1);
            let mut seen = 0;
            let mut p = pos;
            while let Some(m) = find_marker(data, p).filter(|&m| m < next) {
                seen += 1;
                p = m + 1;
            }
            self.damage.push(StoreDamage {
                start: pos as u64,
                end: next as u64,
                record: (pos > 0 || seen > 0).then_some(self.index),
                records_seen: seen,
                reason: fault,
            });
            // A stretch between records held one record at least (its marker may be what
            // is damaged); the header's, or one at the end (bytes after the last record),
            // may hold none.
            self.index += if pos > 0 && next < data.len() {
                seen.max(1)
            } else {
                seen
            };
            pos = next;
        }
    }

    /// Keeps a verified record; an identical repeat is dropped, a different record under
    /// the same key is refused (the first one read stays).
    fn keep(&mut self, scan: StoredScan) -> std::result::Result<(), String> {
        let key = (scan.robot, scan.seq);
        match self.scans.get(&key) {
            Some(old) if super::identity::same_scan(old, &scan) => Ok(()),
            Some(_) => Err(format!(
                "a second, different record of scan {} of robot {} (the first one is kept)",
                scan.seq, scan.robot
            )),
            None => {
                self.scans.insert(key, scan);
                Ok(())
            }
        }
    }

    fn finish(self) -> (ScanStore, SalvageReport) {
        let recovered = self.scans.len();
        let seen: u64 = self.damage.iter().map(|d| d.records_seen).sum();
        let lost = match self.expected {
            Some(n) => n.saturating_sub(recovered as u64).max(seen),
            None => seen,
        };
        let report = SalvageReport {
            bytes: self.data.len() as u64,
            version: self.version,
            header_intact: self.expected.is_some(),
            names: self.names.len(),
            records_expected: self.expected,
            records_recovered: recovered,
            records_lost: lost,
            verified: true,
            damage: self.damage,
        };
        (
            ScanStore {
                scans: self.scans,
                names: self.names,
            },
            report,
        )
    }
}

/// Version 1: decode records in order until one does not; verified only if the whole-file
/// checksum holds.
fn salvage_v1(
    data: &[u8],
    mut r: ByteCursor<'_>,
    names: BTreeMap<u32, String>,
) -> (ScanStore, SalvageReport) {
    let mut salvage = Salvage::new(data, STORE_VERSION_1);
    salvage.names = names;
    let count_pos = r.pos();
    salvage.expected = r.u64("record count").ok();
    let mut pos = r.pos();
    let mut failure = None;
    let n = salvage.expected.unwrap_or(0);
    for _ in 0..n {
        match decode_scan(&mut r) {
            Ok(scan) => {
                if let Err(reason) = salvage.keep(scan) {
                    failure = Some(reason);
                    break;
                }
                salvage.index += 1;
                pos = r.pos();
            }
            Err(e) => {
                failure = Some(format!("a record does not decode: {e}"));
                break;
            }
        }
    }
    let checksum_ok = failure.is_none()
        && r.remaining() == 4
        && r.u32("checksum")
            .is_ok_and(|c| c == crate::file::crc32::crc32(&data[..pos]));
    if !checksum_ok {
        let reason = failure.unwrap_or_else(|| {
            "the whole-file checksum does not match (version 1 cannot tell which record is \
             damaged: the recovered ones are unverified)"
                .into()
        });
        salvage.damage.push(StoreDamage {
            start: if salvage.index < n { pos } else { count_pos } as u64,
            end: data.len() as u64,
            record: (salvage.index < n).then_some(salvage.index),
            records_seen: 0,
            reason,
        });
    }
    let (store, mut report) = salvage.finish();
    report.verified = checksum_ok;
    (store, report)
}
