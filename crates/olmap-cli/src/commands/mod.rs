//! One module per subcommand (`align` serves `align` and `localize`, which share their
//! arguments).

pub mod align;
pub mod bag;
pub mod beacons;
pub mod bench;
pub mod compare_bt;
pub mod convert;
pub mod demo;
pub mod eval;
pub mod export;
pub mod graph;
pub mod grid2d;
pub mod info;
pub mod map;
pub mod merge;
pub mod mutual;
pub mod navgrid;
#[cfg(feature = "net")]
pub mod net;
pub mod poses;
pub mod query;
pub mod render;
pub mod rrd;
pub mod scanner;
pub mod simulate;
pub mod store;
pub mod team;
pub mod voxelize;
