//! One scan record on the wire.

use olmap::team::StoredScan;

use super::{put_name, seal, Kind, Reader};
use crate::error::BadMessage;

/// A scan record as it crosses the network: the recording robot's name and the record
/// itself in the scan store's record encoding ([`StoredScan::encode_record`]):
/// ```text
/// name_len u16, name (UTF-8, checked by check_name)
/// sent     u64  when the robot first published it, ns since the Unix epoch (0 = unknown;
///               not part of the record, used for latency figures only)
/// record   the record body (the rest)
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct RecordMessage {
    /// The recording robot's name.
    pub name: String,
    /// When the recording robot first published it, ns since the Unix epoch (0 unknown).
    pub sent_ns: u64,
    /// The record.
    pub scan: StoredScan,
}

impl RecordMessage {
    /// The sealed payload.
    pub fn encode(&self) -> Vec<u8> {
        let record = self.scan.encode_record();
        let mut body = Vec::with_capacity(record.len() + 2 + self.name.len());
        put_name(&mut body, &self.name);
        body.extend_from_slice(&self.sent_ns.to_le_bytes());
        body.extend_from_slice(&record);
        seal(Kind::Record, &body)
    }

    /// Decodes an opened body and checks it against the `(robot, seq)` its key names.
    pub fn decode(body: &[u8], key: (u32, u32)) -> Result<RecordMessage, BadMessage> {
        let mut r = Reader::new(body);
        let name = r.name("robot name").map_err(BadMessage::Body)?;
        let sent = r.take(8, "sent time").map_err(BadMessage::Body)?;
        let sent_ns = u64::from_le_bytes(sent.try_into().expect("8 bytes"));
        let rest = r.take(r.remaining(), "record").map_err(BadMessage::Body)?;
        let scan = StoredScan::decode_record(rest).map_err(|e| BadMessage::Body(e.to_string()))?;
        if (scan.robot, scan.seq) != key {
            return Err(BadMessage::Key(format!(
                "the key names scan {} of robot {}, the payload holds scan {} of robot {}",
                key.1, key.0, scan.seq, scan.robot
            )));
        }
        Ok(RecordMessage {
            name,
            sent_ns,
            scan,
        })
    }
}
