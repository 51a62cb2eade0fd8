//! Links between scans taken at the same moment by robots that saw each other (thesis
//! §6.3.3, (6.2)-(6.4)), and what placed each scan: the mapper's view of a team.

use nalgebra::Point3;

use crate::align::{Locus, Region};
use crate::geometry::Pose;

/// A sighting that ties one scan to another scan taken at the same moment by another
/// robot. Scans are robot-frame clouds (origin on the floor under the robot's centre).
#[derive(Debug, Clone, PartialEq)]
pub enum ScanLink {
    /// The robot of scan `other` saw this scan's robot's beacon at `beacon` (in `other`'s
    /// robot frame): this robot's position is fixed, its heading free (6.2).
    SeenBy {
        /// Index of the observer's scan.
        other: usize,
        /// This robot's beacon centre in the observer's robot frame, metres.
        beacon: Point3<f64>,
    },
    /// This scan's robot saw the beacon of scan `other`'s robot at `observed` (in this
    /// robot's frame): this robot lies on a circle around that beacon, its heading tied to
    /// its place on the circle (6.3).
    Saw {
        /// Index of the seen robot's scan.
        other: usize,
        /// That robot's beacon centre in this robot's frame, metres.
        observed: Point3<f64>,
    },
    /// Both saw each other: this scan's pose relative to `other`'s is known (6.4; from
    /// [`crate::team::mutual_pose`]).
    Mutual {
        /// Index of the other robot's scan.
        other: usize,
        /// `T_other_this`.
        relative: Pose,
    },
}

impl ScanLink {
    /// The scan at the other end.
    pub fn other(&self) -> usize {
        match self {
            ScanLink::SeenBy { other, .. }
            | ScanLink::Saw { other, .. }
            | ScanLink::Mutual { other, .. } => *other,
        }
    }

    /// The thesis equation the link's constraint comes from.
    pub fn equation(&self) -> &'static str {
        match self {
            ScanLink::SeenBy { .. } => "(6.2)",
            ScanLink::Saw { .. } => "(6.3)",
            ScanLink::Mutual { .. } => "(6.4)",
        }
    }

    /// The same link as the scan at its other end holds it, `this` being the index of the
    /// scan that holds `self`: seen-by and saw swap, a mutual pose inverts.
    pub(crate) fn reversed(&self, this: usize) -> ScanLink {
        match self {
            ScanLink::SeenBy { beacon, .. } => ScanLink::Saw {
                other: this,
                observed: *beacon,
            },
            ScanLink::Saw { observed, .. } => ScanLink::SeenBy {
                other: this,
                beacon: *observed,
            },
            ScanLink::Mutual { relative, .. } => ScanLink::Mutual {
                other: this,
                relative: relative.inverse(),
            },
        }
    }

    /// Mutual links first (a full pose), then the loci.
    pub(crate) fn rank(&self) -> u8 {
        match self {
            ScanLink::Mutual { .. } => 0,
            ScanLink::SeenBy { .. } => 1,
            ScanLink::Saw { .. } => 2,
        }
    }

    /// The search region and prior this link gives once scan `other` is placed at
    /// `other_pose`: a locus, or for a mutual link a small window around the pose.
    pub(crate) fn region(&self, other_pose: &Pose, team: &TeamLinks) -> (Region, Pose) {
        let m = team.beacon_mount;
        let arr = |p: Point3<f64>| [p.x, p.y, p.z];
        match self {
            ScanLink::SeenBy { beacon, .. } => {
                let mut l = Locus::seen_at(arr(other_pose.transform_point(beacon)), arr(m));
                l.slack = team.locus_slack;
                (Region::Locus(l), Pose::identity())
            }
            ScanLink::Saw { observed, .. } => {
                let mut l = Locus::saw_at(arr(other_pose.transform_point(&m)), arr(*observed));
                l.slack = team.locus_slack;
                (Region::Locus(l), Pose::identity())
            }
            ScanLink::Mutual { relative, .. } => {
                let (xy, z, yaw) = team.mutual_window;
                (Region::Window { xy, z, yaw }, *other_pose * *relative)
            }
        }
    }
}

/// The team side of [`super::build_map_linked`]: which robot took each scan, the links
/// between scans, and how the mapper uses them.
#[derive(Debug, Clone, PartialEq)]
pub struct TeamLinks {
    /// The odometry frame (robot) of each scan: odometry predicts a scan only from placed
    /// scans of the same frame.
    pub frame: Vec<usize>,
    /// The links of each scan (to scans of other robots taken at the same moment).
    pub links: Vec<Vec<ScanLink>>,
    /// Where the beacon's centre sits in a robot's frame, metres (the simulator's default
    /// robot: 0.85 m straight above the origin).
    pub beacon_mount: Point3<f64>,
    /// How far a pose may lie from its locus, metres (sighting noise plus the beacon's
    /// offset from the scanner axis; default 0.1).
    pub locus_slack: f64,
    /// Half-widths `(xy, z, yaw)` of the window around a mutual link's pose (default
    /// 0.3 m, 0.2 m, 5°).
    pub mutual_window: (f64, f64, f64),
    /// Whether a robot joins the map only through a sighting: until one of its scans is
    /// placed, a scan without a link to a placed scan is not searched at all (it stays
    /// out of this map; the thesis joins robot frames by mutual localisation only, and a
    /// global match of a whole robot in a symmetric room can be its mirror image).
    pub hold_unlinked: bool,
}

impl TeamLinks {
    /// No team: every scan in one frame, no links (what [`super::build_map`] uses).
    pub fn none(scans: usize) -> Self {
        TeamLinks {
            frame: vec![0; scans],
            links: vec![Vec::new(); scans],
            beacon_mount: Point3::new(0.0, 0.0, 0.85),
            locus_slack: 0.1,
            mutual_window: (0.3, 0.2, 5f64.to_radians()),
            hold_unlinked: false,
        }
    }
}

/// How a scan found its place in the map.
#[derive(Debug, Clone, PartialEq)]
pub enum Placement {
    /// It defines the map frame.
    Frame,
    /// A search in a window around its odometry prediction.
    Odometry,
    /// A search of the whole map (no usable prior).
    Global,
    /// A search confined by a sighting of or by scan `other` (thesis (6.2)-(6.4)).
    Sighting {
        /// The thesis equation: `(6.2)` seen, `(6.3)` saw, `(6.4)` mutual.
        equation: &'static str,
        /// The linked scan's index.
        other: usize,
    },
    /// A two-way sighting (6.4) with scan `other` alone: the map around the scan was too
    /// thin to confirm it (too little overlap, or a repeating place), and did not
    /// contradict it (the scan's surfaces do not stand in the map's free space). The
    /// thesis' own mutual localisation (§3.3-3.5: a few centimetres and about a degree).
    MutualSighting {
        /// The linked scan's index.
        other: usize,
    },
}

impl Placement {
    /// A short label for reports: `frame`, `odometry`, `global`, `sighting (6.x)`,
    /// `sighting (6.4) alone`.
    pub fn label(&self) -> String {
        match self {
            Placement::Frame => "frame".into(),
            Placement::Odometry => "odometry".into(),
            Placement::Global => "global".into(),
            Placement::Sighting { equation, .. } => format!("sighting {equation}"),
            Placement::MutualSighting { .. } => "sighting (6.4) alone".into(),
        }
    }

    /// The linked scan of a placement by sighting.
    pub fn linked_scan(&self) -> Option<usize> {
        match self {
            Placement::Sighting { other, .. } | Placement::MutualSighting { other } => Some(*other),
            _ => None,
        }
    }
}
