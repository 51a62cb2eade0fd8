//! How a node reaches its team ([`NetOptions`]) and what it accepts ([`NodeOptions`]).

use std::path::PathBuf;
use std::time::Duration;

use crate::error::{NetError, Result};
use crate::fault::FaultPlan;
use crate::protocol::check_name;

/// How a node joins its team on the network (the CLI's shared net options).
#[derive(Debug, Clone, PartialEq)]
pub struct NetOptions {
    /// The team's name: the key prefix `olmap/TEAM/` (default `olmap`).
    pub team: String,
    /// Endpoints to listen on, e.g. `tcp/127.0.0.1:7447` (default: Zenoh's, any port).
    pub listen: Vec<String>,
    /// Endpoints to connect to, e.g. `tcp/192.168.1.10:7447`.
    pub connect: Vec<String>,
    /// A Zenoh JSON5 configuration file for anything else (TLS, authentication, access
    /// control, scouting); the options above are applied on top of it.
    pub zenoh_config: Option<PathBuf>,
    /// Multicast scouting, to find peers on the LAN without endpoints (default on; tests
    /// turn it off and use explicit loopback endpoints).
    pub scouting: bool,
}

impl Default for NetOptions {
    fn default() -> Self {
        NetOptions {
            team: "olmap".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            zenoh_config: None,
            scouting: true,
        }
    }
}

impl NetOptions {
    /// Options for a test or a single machine: loopback endpoints only, no scouting.
    pub fn loopback(team: &str, listen: Option<u16>, connect: &[u16]) -> NetOptions {
        NetOptions {
            team: team.into(),
            listen: listen
                .map(|p| vec![format!("tcp/127.0.0.1:{p}")])
                .unwrap_or_default(),
            connect: connect
                .iter()
                .map(|p| format!("tcp/127.0.0.1:{p}"))
                .collect(),
            zenoh_config: None,
            scouting: false,
        }
    }

    /// The Zenoh configuration: the file's (or Zenoh's defaults), peer mode unless the
    /// file says otherwise, then the endpoints and scouting set here.
    pub fn zenoh_config(&self) -> Result<zenoh::Config> {
        let mut config = match &self.zenoh_config {
            Some(path) => zenoh::Config::from_file(path).map_err(|e| {
                NetError::InvalidArgument(format!("Zenoh configuration {}: {e}", path.display()))
            })?,
            None => {
                let mut c = zenoh::Config::default();
                c.insert_json5("mode", "\"peer\"")
                    .map_err(NetError::zenoh)?;
                c
            }
        };
        let list = |v: &[String]| serde_json::to_string(v).expect("strings serialise");
        if !self.listen.is_empty() {
            config
                .insert_json5("listen/endpoints", &list(&self.listen))
                .map_err(|e| NetError::InvalidArgument(format!("--listen: {e}")))?;
        }
        if !self.connect.is_empty() {
            config
                .insert_json5("connect/endpoints", &list(&self.connect))
                .map_err(|e| NetError::InvalidArgument(format!("--connect: {e}")))?;
        }
        if !self.scouting {
            config
                .insert_json5("scouting/multicast/enabled", "false")
                .map_err(NetError::zenoh)?;
        }
        Ok(config)
    }
}

/// A node's identity, store and limits.
#[derive(Debug, Clone)]
pub struct NodeOptions {
    /// The node's name (a robot's name for robots), checked by [`check_name`].
    pub name: String,
    /// `robot`, `mapper`, `robot+mapper` (reported in its status).
    pub role: String,
    /// The persistent store (a redb database file, created if missing).
    pub store: PathBuf,
    /// The network.
    pub net: NetOptions,
    /// Largest payload accepted, bytes (default 16 MiB).
    pub max_payload: usize,
    /// Most new records accepted per robot per second (default 50); more are dropped and
    /// fetched later by anti-entropy.
    pub max_rate: u32,
    /// How often the node publishes its digest and status and fetches what it misses
    /// (default 1 s).
    pub period: Duration,
    /// Injected faults (default none).
    pub faults: FaultPlan,
    /// The team's finest resolution, metres (default 0.1): records whose cloud is an
    /// occupancy list at it are sent as voxel keys (see [`crate::RecordMessage`]).
    pub list_resolution: f64,
}

impl NodeOptions {
    /// Defaults for a node `name` with its store at `store`.
    pub fn new(name: &str, role: &str, store: impl Into<PathBuf>, net: NetOptions) -> Self {
        NodeOptions {
            name: name.into(),
            role: role.into(),
            store: store.into(),
            net,
            max_payload: 16 << 20,
            max_rate: 50,
            period: Duration::from_secs(1),
            faults: FaultPlan::default(),
            list_resolution: 0.1,
        }
    }

    /// Checks the name, limits and fault plan.
    pub fn check(&self) -> Result<()> {
        check_name(&self.name).map_err(|e| NetError::InvalidArgument(format!("node name {e}")))?;
        check_name(&self.net.team)
            .map_err(|e| NetError::InvalidArgument(format!("team name {e}")))?;
        if self.max_payload < 1024 {
            return Err(NetError::InvalidArgument(format!(
                "maximum payload {} bytes is under 1 KiB",
                self.max_payload
            )));
        }
        if self.max_rate == 0 {
            return Err(NetError::InvalidArgument(
                "maximum record rate must be at least 1 per second".into(),
            ));
        }
        if self.period < Duration::from_millis(10) || self.period > Duration::from_secs(3600) {
            return Err(NetError::InvalidArgument(format!(
                "anti-entropy period {:?} is not within 10 ms to 1 h",
                self.period
            )));
        }
        self.faults.check().map_err(NetError::InvalidArgument)
    }
}
