//! What the benchmark and the live demo share: the demo's simulated lab team and a free
//! loopback port.

use olmap::sim::{simulate, SimConfig, SimDataset};

use crate::error::{NetError, Result};

/// The demo's team: the lab world, degraded odometry (thesis §6.5), `robots` × `stops`.
pub fn demo_lab(seed: u64, robots: usize, stops: usize) -> Result<SimDataset> {
    Ok(simulate(
        &SimConfig::demo_lab(seed, robots, stops),
        |_, _| {},
    )?)
}

/// A loopback TCP port nobody listens on now (bound to 127.0.0.1:0, read, released).
pub(crate) fn free_loopback_port() -> Result<u16> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| NetError::InvalidArgument(format!("no free loopback port: {e}")))
}
