//! The team mapper (thesis §6.4-6.5): the robots' scan stores merged into one batch map,
//! sightings confining the search of the scans they tie together ((6.2)-(6.4)), robots
//! cleared from the scans that saw them (§6.5.1); and the same mapper per robot without
//! sightings, for comparison (Figure 6.11).

use nalgebra::Point3;

use super::clearing::{clear_robots, ClearingParams};
use super::mutual::{mutual_pose, MutualObservation, MutualParams};
use super::store::{ScanStore, StoredScan, StoredSighting};
use crate::error::{Error, Result};
use crate::geometry::{Pose, PoseList};
use crate::mapping::{
    build_map, build_map_linked, MapBuild, MapParams, ScanInput, ScanLink, TeamLinks,
};

/// Parameters of [`map_team`].
#[derive(Debug, Clone)]
pub struct TeamParams {
    /// The batch mapper's parameters (registration, odometry windows, fusion).
    pub map: MapParams,
    /// Use the sightings (false: the solo mapper, every robot ignoring the others).
    pub sightings: bool,
    /// Clear the robots a scan saw before it joins the map (thesis §6.5.1; `None` = off;
    /// default radius 0.35 m, height 2 m: the simulator's 0.25 m bodies plus a margin).
    pub clearing: Option<ClearingParams>,
    /// The distractor test of mutual sightings.
    pub mutual: MutualParams,
    /// The beacon's centre in a robot's frame, metres (default: the simulator's robot,
    /// 0.85 m above the origin).
    pub beacon_mount: Point3<f64>,
    /// How far a pose may lie from a sighting's locus, metres (default 0.1).
    pub locus_slack: f64,
    /// Half-widths `(xy, z, yaw)` of the window around a mutual sighting's pose (default
    /// 0.3 m, 0.2 m, 5°).
    pub mutual_window: (f64, f64, f64),
    /// Two scans of different robots are simultaneous (a sighting ties them) when their
    /// times differ by at most this, seconds (default 1).
    pub max_time_gap: f64,
}

impl Default for TeamParams {
    fn default() -> Self {
        let none = TeamLinks::none(0);
        TeamParams {
            map: MapParams {
                register_band: Some((0.1, 2.8)),
                ..MapParams::default()
            },
            sightings: true,
            clearing: Some(ClearingParams {
                radius: 0.35,
                height: 2.0,
            }),
            mutual: MutualParams::default(),
            beacon_mount: none.beacon_mount,
            locus_slack: none.locus_slack,
            mutual_window: none.mutual_window,
            max_time_gap: 1.0,
        }
    }
}

/// A robot's frame in the joint map.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotFrame {
    /// The robot's id in the store.
    pub robot: u32,
    /// Its name.
    pub name: String,
    /// `T_map_odom`: its odometry frame in the joint map (from its first placed scan), if
    /// any of its scans was placed.
    pub pose: Option<Pose>,
    /// Its scans placed / stored.
    pub placed: usize,
    /// Its scans in the store.
    pub scans: usize,
    /// What first tied the robot to the map: `frame`, `odometry`, `global` or
    /// `sighting (6.x)` (the placement of its first placed scan).
    pub linked_by: Option<String>,
}

/// The result of [`map_team`].
#[derive(Debug, Clone)]
pub struct TeamMap {
    /// The joint map and every placed scan, named `ROBOT/scanNNN`, in the frame of the
    /// first robot's first scan.
    pub build: MapBuild,
    /// `(robot, seq)` of each input scan, by input index ([`crate::mapping::PlacedScan::index`]).
    pub keys: Vec<(u32, u32)>,
    /// Every robot's frame.
    pub frames: Vec<RobotFrame>,
    /// Links found: `(equation, count)` for (6.2), (6.3), (6.4).
    pub links: Vec<(&'static str, usize)>,
    /// Mutual sightings rejected by the distractor test.
    pub rejected_mutual: usize,
    /// Points removed by robot clearing.
    pub cleared_points: usize,
    /// Robots that no sighting tied to the team, each mapped alone in the frame of its
    /// first scan (scan names as in the joint map).
    pub alone: Vec<(u32, MapBuild)>,
}

impl TeamMap {
    /// The placed scans' poses, named `ROBOT/scanNNN`.
    pub fn poses(&self) -> PoseList {
        poses_of(&self.build.placed)
    }

    /// `T_a_b`: robot `b`'s odometry frame in robot `a`'s, when both are in the map.
    pub fn relative(&self, a: u32, b: u32) -> Option<Pose> {
        let frame = |r: u32| self.frames.iter().find(|f| f.robot == r)?.pose;
        Some(frame(a)?.inverse() * frame(b)?)
    }
}

/// The poses of placed scans, by name, in joining order.
pub(super) fn poses_of(placed: &[crate::mapping::PlacedScan]) -> PoseList {
    let mut list = PoseList::default();
    for p in placed {
        list.push(p.name.clone(), p.pose);
    }
    list
}

/// The name a scan has in the joint map.
pub fn scan_name(store: &ScanStore, robot: u32, seq: u32) -> String {
    joint_name(&store.robot_name(robot), seq)
}

/// `ROBOT/scanNNN`.
pub(super) fn joint_name(robot_name: &str, seq: u32) -> String {
    format!("{robot_name}/scan{seq:03}")
}

/// Maps a team's merged scan store as one batch map (thesis §6.4-6.5). The frame is the
/// first robot's first scan. With [`TeamParams::sightings`], every sighting links the two
/// simultaneous scans: the seen robot's position is fixed (6.2), the observer lies on a
/// circle around the seen beacon (6.3), a two-way sighting gives the whole relative pose
/// (6.4, after the distractor test). A robot joins the map only through a sighting: a
/// robot that no sighting ties to the team is mapped alone in its own frame
/// ([`TeamMap::alone`]). Once joined, its scans with no usable sighting are placed by
/// odometry windows in its frame or globally. Robots seen in a scan are cleared from it
/// first. Without sightings this is the batch mapper on all scans.
///
/// Use [`map_solo`] for each robot alone.
pub fn map_team(
    store: &ScanStore,
    params: &TeamParams,
    progress: impl FnMut(usize, usize),
) -> Result<TeamMap> {
    let scans: Vec<&StoredScan> = store.iter().collect();
    if scans.is_empty() {
        return Err(Error::EmptyInput {
            what: "the scan store".into(),
        });
    }
    let keys: Vec<(u32, u32)> = scans.iter().map(|s| (s.robot, s.seq)).collect();
    let robots = store.robots();
    let frame: Vec<usize> = scans
        .iter()
        .map(|s| robots.iter().position(|&r| r == s.robot).expect("listed"))
        .collect();
    let mut team = TeamLinks {
        frame,
        links: vec![Vec::new(); scans.len()],
        beacon_mount: params.beacon_mount,
        locus_slack: params.locus_slack,
        mutual_window: params.mutual_window,
        hold_unlinked: params.sightings,
    };
    let mut rejected_mutual = 0;
    if params.sightings {
        rejected_mutual = link_sightings(&scans, params, &mut team.links);
    }
    let mut cleared_points = 0;
    let mut inputs = Vec::with_capacity(scans.len());
    for s in &scans {
        let (input, removed) = team_scan_input(s, &store.robot_name(s.robot), params)?;
        cleared_points += removed;
        inputs.push(input);
    }
    let mut build = build_map_linked(&inputs, &params.map, &team, progress)?;
    let frames: Vec<RobotFrame> = robots
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let mine = |i: usize| team.frame[i] == k;
            let first = build.placed.iter().find(|p| mine(p.index));
            RobotFrame {
                robot: r,
                name: store.robot_name(r),
                pose: first.map(|p| match scans[p.index].odometry {
                    Some(odo) => p.pose * odo.inverse(),
                    None => p.pose,
                }),
                placed: build.placed.iter().filter(|p| mine(p.index)).count(),
                scans: (0..scans.len()).filter(|&i| mine(i)).count(),
                linked_by: first.map(|p| p.via.label()),
            }
        })
        .collect();
    let mut alone = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        if f.placed > 0 || !params.sightings {
            continue;
        }
        let own: Vec<usize> = (0..scans.len()).filter(|&i| team.frame[i] == k).collect();
        let placed_scan = |i: usize| build.placed.iter().any(|p| p.index == i);
        // Sighted by (or seeing) a placed scan, but no link search was trusted: the
        // searches' own doubts say why; otherwise no sighting ever tied it.
        let sighted = own
            .iter()
            .any(|&i| team.links[i].iter().any(|l| placed_scan(l.other())));
        for r in build.rejected.iter_mut().filter(|r| own.contains(&r.index)) {
            if sighted {
                r.reasons.insert(
                    0,
                    format!(
                        "no search along {}'s sightings was trusted: mapped alone in its own \
                         frame",
                        f.name
                    ),
                );
            } else {
                r.reasons = vec![format!(
                    "no sighting ties {} to the team: mapped alone in its own frame",
                    f.name
                )];
            }
        }
        let mine: Vec<ScanInput> = own.iter().map(|&i| inputs[i].clone()).collect();
        alone.push((f.robot, build_map(&mine, &params.map, |_, _| {})?));
    }
    let links = ["(6.2)", "(6.3)", "(6.4)"]
        .into_iter()
        .map(|eq| {
            let n = team.links.iter().flatten().filter(|l| l.equation() == eq);
            (eq, n.count())
        })
        .collect();
    Ok(TeamMap {
        build,
        keys,
        frames,
        links,
        rejected_mutual,
        cleared_points,
        alone,
    })
}

/// Turns every sighting into links between the two simultaneous scans; returns how many
/// two-way sightings failed the distractor test (their one-way links stay).
fn link_sightings(
    scans: &[&StoredScan],
    params: &TeamParams,
    links: &mut [Vec<ScanLink>],
) -> usize {
    // The scan of `robot` taken nearest to `time`, within the gap.
    let at = |robot: u32, time: f64| {
        nearest_in_time(
            scans.iter().map(|s| (s.robot, s.time)).enumerate(),
            robot,
            time,
            params.max_time_gap,
        )
    };
    let mut rejected = 0;
    for (o, obs) in scans.iter().enumerate() {
        for g in &obs.sightings {
            let Some(t) = at(g.target, obs.time) else {
                continue;
            };
            let ok = sighting_links((o, obs), g, (t, scans[t]), params, |i, l| links[i].push(l));
            rejected += usize::from(!ok);
        }
    }
    rejected
}

/// The scan (index) of `robot` taken nearest to `time`, at most `gap` seconds away, among
/// `(index, (robot, time))`; the first of equals.
pub(super) fn nearest_in_time(
    scans: impl Iterator<Item = (usize, (u32, f64))>,
    robot: u32,
    time: f64,
    gap: f64,
) -> Option<usize> {
    scans
        .filter(|(_, (r, t))| *r == robot && (t - time).abs() <= gap)
        .min_by(|a, b| (a.1 .1 - time).abs().total_cmp(&(b.1 .1 - time).abs()))
        .map(|(i, _)| i)
}

/// The links that sighting `g`, made at scan `o` of the robot of scan `t` (taken at the
/// same moment), gives: `t` seen by `o` (6.2), `o` saw `t` (6.3), and when the sighting was
/// two-way, handled once from the lower robot id, the relative pose both ways (6.4).
/// `add(scan, link)` receives each. Returns false when the two-way sighting failed the
/// distractor test (its one-way links are given).
pub(super) fn sighting_links(
    (o, obs): (usize, &StoredScan),
    g: &StoredSighting,
    (t, target): (usize, &StoredScan),
    params: &TeamParams,
    mut add: impl FnMut(usize, ScanLink),
) -> bool {
    // Each link on `t`, and its reverse on `o`.
    let mut both = |link: ScanLink| {
        let reverse = link.reversed(t);
        add(t, link);
        add(o, reverse);
    };
    both(ScanLink::SeenBy {
        other: o,
        beacon: g.beacon,
    });
    let back = target.sightings.iter().find(|b| b.target == obs.robot);
    if let (true, Some(back)) = (g.mutual && obs.robot < g.target, back) {
        let Some(t_o_t) = mutual_relative(g, back, params) else {
            return false;
        };
        both(ScanLink::Mutual {
            other: o,
            relative: t_o_t,
        });
    }
    true
}

/// A stored scan as the team mapper registers it: named `ROBOT/scanNNN` (`robot_name` is
/// the robot's), the robots it saw cleared from its cloud when the parameters say so.
/// Returns the input and the points cleared.
pub(super) fn team_scan_input(
    s: &StoredScan,
    robot_name: &str,
    params: &TeamParams,
) -> Result<(ScanInput, usize)> {
    let mut cloud = s.cloud.clone();
    let mut removed = 0;
    if let (true, Some(c)) = (params.sightings, &params.clearing) {
        let at: Vec<(f64, f64)> = s
            .sightings
            .iter()
            .map(|g| (g.beacon.x, g.beacon.y))
            .collect();
        let (kept, n) = clear_robots(&cloud, &at, c)?;
        cloud = kept;
        removed = n;
    }
    Ok((
        ScanInput {
            name: joint_name(robot_name, s.seq),
            cloud,
            odometry: s.odometry,
        },
        removed,
    ))
}

/// `T_observer_target` (robot frames, same floor) from a two-way sighting, (6.4) with the
/// distractor test; `None` when it fails.
fn mutual_relative(
    forward: &StoredSighting,
    back: &StoredSighting,
    params: &TeamParams,
) -> Option<Pose> {
    let o = MutualObservation::from_3d(
        forward.range,
        forward.bearing,
        forward.elevation,
        back.range,
        back.bearing,
        back.elevation,
    );
    let fix = mutual_pose(&o, &params.mutual).ok()?;
    Some(Pose::from_xyz_ypr(fix.x, fix.y, 0.0, fix.heading, 0.0, 0.0))
}

/// Every robot mapping alone (thesis §6.5, "single robot mapping"): [`map_team`] on each
/// robot's own records without sightings. Returns `(robot, map)` per robot.
pub fn map_solo(
    store: &ScanStore,
    params: &TeamParams,
    mut progress: impl FnMut(usize, usize),
) -> Result<Vec<(u32, TeamMap)>> {
    let solo = TeamParams {
        sightings: false,
        ..params.clone()
    };
    let total = store.len();
    let mut done = 0;
    let mut out = Vec::new();
    for r in store.robots() {
        let own = store.robot_store(r);
        let n = own.len();
        let built = map_team(&own, &solo, |k, _| progress(done + k, total))?;
        done += n;
        out.push((r, built));
    }
    Ok(out)
}
