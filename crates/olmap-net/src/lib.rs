//! # olmap-net: robots that map together, live, over Zenoh
//!
//! The thesis' team (Ryde, §6.3.2) is robots on a wireless network: each keeps a store of
//! every robot's scans, stores synchronise whenever robots are in range, and any robot can
//! build the joint map from them. This crate runs that team on
//! [Zenoh](https://zenoh.io) (peer-to-peer publish/subscribe/query, the transport of
//! ROS 2's `rmw_zenoh`): the same processes run on one laptop over loopback, on a fleet
//! over Wi-Fi, and beside ROS 2.
//!
//! * [`Node`]: one process's place in the team — a durable store ([`DurableStore`], redb),
//!   a subscriber merging every record published, a queryable serving every record held
//!   (store and forward: data travels robot to robot), a liveliness token, and the
//!   anti-entropy loop.
//! * [`robot`]: replays one robot of a simulated dataset in real time, turning each scan
//!   into what robots exchange (an occupancy list at the team's finest resolution with the
//!   sensor origin, odometry and sightings).
//! * [`mapper`]: merges every record and re-maps the team as records arrive (the batch
//!   team mapper of `olmap team`, so the final map is identical to `olmap team` on the same
//!   records), publishes its status, serves the map, writes its outputs on request and on
//!   exit.
//! * [`watch`]: a live view of the team's nodes.
//! * [`FaultPlan`]: seeded drop, duplication, reordering and partitions, for tests and
//!   demos.
//!
//! ## Protocol (wire-format version 1)
//!
//! **Keys** (all under `olmap/TEAM/`, see [`Keys`]): records on `rec/ROBOT/SEQ`, digests on
//! `digest/NODE`, statuses on `status/NODE`, liveliness tokens on `alive/NODE`; the mapper
//! answers `map` (`.olm` bytes), `poses` (pose-list text) and `write` (writes its outputs).
//!
//! **Payloads**: every payload is sealed in an envelope ([`seal`](protocol::seal)): magic
//! `OLNT`, version, kind, length, body, CRC-32. Receivers check, in order, the size cap,
//! magic, version, kind (against the key), length and checksum, then decode the body with
//! every count checked against the bytes present, and for records that the robot and scan
//! in the record are the ones its key names. A payload failing any check is counted by
//! reason ([`Counters::refused`]), logged once per reason and dropped: never stored, never
//! a crash. A record that differs from the one already held under its key is refused as a
//! conflict (records are immutable).
//!
//! **Records** are keyed `(robot, seq)` and immutable, as in `olmap`'s
//! [`ScanStore`](olmap::team::ScanStore): merging is set union, so duplicates are no-ops and
//! order does not matter. A record's body is the scan store's record encoding
//! ([`StoredScan::encode_record`](olmap::team::StoredScan::encode_record)); the `.store`
//! file stays the export and interchange format ([`Node::export`]).
//!
//! **Reliability**: Zenoh does not retransmit what was in flight when a link died, and large
//! messages sent with the `Drop` congestion setting are silently lost. Records are sent with
//! `CongestionControl::Block`; digests and statuses with `Drop`. Every period each node
//! publishes a digest of what it holds (per robot: the contiguous prefix and the further
//! ranges, [`Digest`]), and any node that sees records it lacks fetches them with a `get`
//! on `rec/ROBOT/*` carrying a [`FetchRequest`]; every node holding them replies. So once
//! links have been up for a few periods, every node holds every record some node it can
//! reach holds.
//!
//! **Security**: a record is only accepted under its own key (`rec/ROBOT/SEQ` must name the
//! robot and scan inside). Limit who may publish under a robot's prefix with Zenoh's access
//! control, and run TLS with user/password authentication through a Zenoh configuration
//! file (`--zenoh-config`, see the README). Payloads over a size cap and records over a
//! per-robot rate are dropped ([`NodeOptions::max_payload`], [`NodeOptions::max_rate`]).

pub mod bench;
pub mod demo;
mod durable;
mod error;
mod fault;
mod lab;
pub mod mapper;
mod node;
pub mod protocol;
pub mod robot;
mod status;
pub mod watch;

pub use durable::DurableStore;
pub use error::{BadMessage, NetError, Result};
pub use fault::{FaultPlan, Faults, Outgoing, HOLD_LIMIT};
pub use lab::demo_lab;
pub use node::{MapFigures, NetOptions, Node, NodeOptions};
pub use protocol::{Digest, FetchRequest, Keys, RecordMessage};
pub use status::{quantile, Counters, NodeStatus, RobotStatus};
