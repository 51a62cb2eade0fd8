//! One scan record on the wire.

use olmap::cloud::PointCloud;
use olmap::team::StoredScan;

use super::occupancy::{as_keys, put_keys, read_keys};
use super::{put_name, seal, Kind, Reader};
use crate::error::BadMessage;

/// The record follows in the scan store's record encoding.
const FORMAT_FULL: u8 = 0;
/// The record's cloud is an occupancy list sent as its voxel keys.
const FORMAT_OCCUPANCY: u8 = 1;

/// A scan record as it crosses the network:
/// ```text
/// name_len u16, name (UTF-8, checked by check_name)   the recording robot's name
/// sent     u64  when the robot first published it, ns since the Unix epoch (0 = unknown;
///               not part of the record, used for latency figures only)
/// format   u8   0: the record body follows (StoredScan::encode_record), to the end
///               1: an occupancy list:
///                  resolution f64 (m), header u32 length + the record body with no points,
///                  voxels u32 count, then per voxel the difference from the previous packed
///                  key (the first: the key itself) as an LEB128 varint; a key packs x, y, z
///                  + 2^20 in 21 bits each (x highest), keys strictly ascending; each voxel
///                  stands for its centre, (key + 0.5) * resolution, as f32
/// ```
/// Format 1 is used whenever the record's cloud is exactly an occupancy list at the
/// sender's resolution (every point its voxel's centre, keys ascending, no attributes), and
/// decodes to the bit-identical record: stores stay byte-identical whichever way a record
/// travelled.
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
    /// The sealed payload in the full format.
    pub fn encode(&self) -> Vec<u8> {
        self.encode_at(None)
    }

    /// The sealed payload, as an occupancy list at `resolution` when the cloud is one.
    pub fn encode_at(&self, resolution: Option<f64>) -> Vec<u8> {
        let mut body = Vec::new();
        put_name(&mut body, &self.name);
        body.extend_from_slice(&self.sent_ns.to_le_bytes());
        let keys = resolution.and_then(|r| as_keys(&self.scan.cloud, r).map(|k| (r, k)));
        match keys {
            Some((r, keys)) => {
                body.push(FORMAT_OCCUPANCY);
                body.extend_from_slice(&r.to_le_bytes());
                let header = StoredScan {
                    cloud: PointCloud::from_points(Vec::new())
                        .with_origin(self.scan.cloud.origin()),
                    ..self.scan.clone()
                }
                .encode_record();
                body.extend_from_slice(&(header.len() as u32).to_le_bytes());
                body.extend_from_slice(&header);
                put_keys(&mut body, &keys);
            }
            None => {
                body.push(FORMAT_FULL);
                body.extend_from_slice(&self.scan.encode_record());
            }
        }
        seal(Kind::Record, &body)
    }

    /// Decodes an opened body and checks it against the `(robot, seq)` its key names.
    pub fn decode(body: &[u8], key: (u32, u32)) -> Result<RecordMessage, BadMessage> {
        let bad = BadMessage::Body;
        let mut r = Reader::new(body);
        let name = r.name("robot name").map_err(bad)?;
        let sent = r.take(8, "sent time").map_err(bad)?;
        let sent_ns = u64::from_le_bytes(sent.try_into().expect("8 bytes"));
        let format = r.take(1, "format").map_err(bad)?[0];
        let record = |bytes: &[u8]| {
            StoredScan::decode_record(bytes).map_err(|e| BadMessage::Body(e.to_string()))
        };
        let scan = match format {
            FORMAT_FULL => record(r.take(r.remaining(), "record").map_err(bad)?)?,
            FORMAT_OCCUPANCY => {
                let res = f64::from_le_bytes(
                    r.take(8, "resolution").map_err(bad)?.try_into().expect("8"),
                );
                if !(res.is_finite() && res > 0.0) {
                    return Err(BadMessage::Body(format!("resolution {res} m")));
                }
                let n = r.count(1, usize::MAX, "header bytes").map_err(bad)?;
                let mut scan = record(r.take(n, "record header").map_err(bad)?)?;
                if !scan.cloud.is_empty() {
                    return Err(BadMessage::Body(
                        "an occupancy-list header holds points".into(),
                    ));
                }
                let points = read_keys(&mut r, res).map_err(bad)?;
                r.finish("occupancy list").map_err(bad)?;
                scan.cloud = PointCloud::from_points(points).with_origin(scan.cloud.origin());
                scan
            }
            f => return Err(BadMessage::Body(format!("unknown record format {f}"))),
        };
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
