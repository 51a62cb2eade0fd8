//! One module per subcommand.

pub mod align;
pub mod beacons;
pub mod bench;
pub mod convert;
pub mod demo;
pub mod grid2d;
pub mod info;
pub mod map;
pub mod mapping;
pub mod mutual;
pub mod poses;
pub mod render;
pub mod rrd;
pub mod scanner;
pub mod simulate;
pub mod team;
pub mod voxelize;
