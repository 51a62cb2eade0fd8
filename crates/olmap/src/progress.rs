//! Progress of the long pipelines, reported to a caller's callback (the library never
//! prints): which stage is running and how far it is.

/// A stage of a pipeline, with a short label a progress bar can show.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Simulating robots and their scans.
    Simulate,
    /// Reading scan files.
    Read,
    /// Building a map from scans.
    Map,
    /// Building the team's joint map.
    TeamMap,
    /// Mapping every robot alone.
    SoloMaps,
    /// Integrating clouds into one occupancy list.
    Voxelize,
}

impl Stage {
    /// The label of a progress bar: `simulate`, `read`, `map`, `team map`, `solo maps`,
    /// `voxelize`.
    pub fn label(self) -> &'static str {
        match self {
            Stage::Simulate => "simulate",
            Stage::Read => "read",
            Stage::Map => "map",
            Stage::TeamMap => "team map",
            Stage::SoloMaps => "solo maps",
            Stage::Voxelize => "voxelize",
        }
    }
}

/// A progress callback: `(stage, done, total)`, called as work completes.
pub type Progress<'a> = &'a mut dyn FnMut(Stage, usize, usize);
