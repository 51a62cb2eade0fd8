//! Scans out of a bag: the scan topic's clouds (`PointCloud2`, or `LaserScan` as planar
//! clouds), moved into a chosen frame with the bag's transforms, with the odometry at each
//! scan's stamp — in memory ([`extract_scans`]), as a folder `olmap map` reads
//! ([`write_extraction`]) or as mapping inputs (`mapping::bag_scan_inputs`).

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::container::{Bag, BagMessage};
use super::error::BagError;
use super::messages::{decode_tf, LaserScan as RosLaserScan, Odometry, PointCloud2, Stamp};
use super::pointcloud2::decode_points;
use super::tf::{TfTree, DEFAULT_TOLERANCE_NS};
use crate::cloud::{LaserScan, PointCloud};
use crate::error::Result;
use crate::geometry::{Pose, PoseList};

/// Message types olmap reads as scans.
pub const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";
/// `sensor_msgs/msg/LaserScan`.
pub const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";
/// `nav_msgs/msg/Odometry`.
pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";

fn same_type(a: &str, b: &str) -> bool {
    super::schema::normalise_type_name(a) == super::schema::normalise_type_name(b)
}

/// What to extract.
#[derive(Debug, Clone)]
pub struct ExtractOptions {
    /// The scan topic; `None` picks the bag's only `PointCloud2` topic, else its only
    /// `LaserScan` topic.
    pub topic: Option<String>,
    /// The odometry: `Some(topic)` of `nav_msgs/Odometry`, `Some("/tf")` for the `/tf`
    /// chain from `odom_frame`; `None` picks the only `Odometry` topic, else `/tf` when it
    /// has dynamic transforms and names `odom_frame`, else no odometry.
    pub odom_topic: Option<String>,
    /// No odometry at all (whatever the bag holds).
    pub no_odometry: bool,
    /// The odometry frame used with `/tf` (default `odom`).
    pub odom_frame: String,
    /// The frame to put the scans in; `None` keeps each message's own frame.
    pub frame: Option<String>,
    /// Keep a scan only when at least this many seconds after the last one kept.
    pub every: Option<f64>,
    /// Stop after this many scans.
    pub max: Option<usize>,
    /// Only the scan with this index on the topic (for `BAG#TOPIC@INDEX`).
    pub index: Option<u64>,
    /// How far outside a dynamic transform's recorded span (ns) a stamp may fall and still
    /// take the nearest sample (default 100 ms).
    pub tolerance_ns: i64,
}

impl Default for ExtractOptions {
    fn default() -> Self {
        ExtractOptions {
            topic: None,
            odom_topic: None,
            no_odometry: false,
            odom_frame: "odom".into(),
            frame: None,
            every: None,
            max: None,
            index: None,
            tolerance_ns: DEFAULT_TOLERANCE_NS,
        }
    }
}

/// One scan out of a bag.
#[derive(Debug, Clone)]
pub struct BagScan {
    /// Its name: the message's index on the topic, six digits (`000042`).
    pub name: String,
    /// The message's index on the topic.
    pub index: u64,
    /// The header stamp.
    pub stamp: Stamp,
    /// The frame the points are in (the message's, or [`ExtractOptions::frame`]).
    pub frame: String,
    /// The valid points; the cloud's origin is the sensor's position in `frame`.
    pub cloud: PointCloud,
    /// The 2D scan, for `LaserScan` topics.
    pub laser: Option<LaserScan>,
    /// `T_odom_frame` at the stamp, when the bag has odometry.
    pub odometry: Option<Pose>,
    /// Points in the message, and how many were dropped as NaN / no return.
    pub records: u64,
    /// Points dropped (NaN, or a `LaserScan` beam without a return).
    pub dropped: u64,
}

impl BagScan {
    /// The scan as a [`crate::io::LoadedCloud`] (format PCD-like report: `ROS 2 bag`).
    pub fn loaded(self) -> crate::io::LoadedCloud {
        let mut report = crate::io::ReadReport::new(crate::io::CloudFormat::Pcd);
        report.encoding = "ROS 2 bag message".into();
        report.records = self.records;
        report.dropped_non_finite = self.dropped;
        report.fields = vec!["x".into(), "y".into(), "z".into()];
        if self.cloud.intensity().is_some() {
            report.fields.push("intensity".into());
        }
        crate::io::LoadedCloud {
            cloud: self.cloud,
            report,
        }
    }
}

/// What [`extract_scans`] found.
#[derive(Debug, Clone)]
pub struct Extraction {
    /// The scans, in bag order.
    pub scans: Vec<BagScan>,
    /// The scan topic and its type.
    pub topic: String,
    /// `sensor_msgs/msg/PointCloud2` or `sensor_msgs/msg/LaserScan`.
    pub type_name: String,
    /// Where the odometry came from (`/odom`, `/tf (odom)`), if anywhere.
    pub odometry_source: Option<String>,
    /// Messages left out (scans, and transform or odometry messages that did not
    /// decode), each with its topic, index and reason.
    pub skipped: Vec<String>,
    /// Scan messages passed over by `every` / `max` / `index`.
    pub thinned: u64,
    /// Why reading stopped early (damaged file), if it did.
    pub stopped_early: Option<String>,
}

/// The transforms and odometry of a bag (first pass).
struct Motion {
    topics: Vec<(String, String)>,
    tf: TfTree,
    odom: TfTree,
    odom_frame: Option<String>,
    odom_source: Option<String>,
    /// Transform and odometry messages that did not decode (skipped, named).
    problems: Vec<String>,
}

fn read_motion(bag: &Bag, opts: &ExtractOptions) -> Result<(Motion, Option<String>), BagError> {
    let mut topics: Vec<(String, String)> = Vec::new();
    // Which odometry topic: decided after the topics are known, so collect every Odometry
    // topic's samples separately first.
    let mut static_tf: Vec<(String, String, Pose)> = Vec::new();
    let mut dynamic_tf: Vec<(String, String, i64, Pose)> = Vec::new();
    let mut odom_by_topic: Vec<(String, String, String, i64, Pose)> = Vec::new();
    let mut problems = Vec::new();
    let result = bag.for_each_message(|m| {
        if !topics.iter().any(|(t, _)| t == m.topic) {
            topics.push((m.topic.to_string(), m.type_name.to_string()));
        }
        if same_type(m.type_name, TF_MESSAGE) {
            let tfs = match decode_tf(m.data) {
                Ok(t) => t,
                Err(e) => {
                    problems.push(m.error(e.to_string()).to_string());
                    return Ok(true);
                }
            };
            for t in tfs {
                if m.topic == "/tf_static" {
                    static_tf.push((t.header.frame_id, t.child_frame_id, t.transform));
                } else if m.topic == "/tf" {
                    dynamic_tf.push((
                        t.header.frame_id,
                        t.child_frame_id,
                        t.header.stamp.nanos(),
                        t.transform,
                    ));
                }
            }
        } else if same_type(m.type_name, ODOMETRY)
            && opts.odom_topic.as_deref().is_none_or(|t| t == m.topic)
        {
            let o = match Odometry::decode(m.data) {
                Ok(o) => o,
                Err(e) => {
                    problems.push(m.error(e.to_string()).to_string());
                    return Ok(true);
                }
            };
            odom_by_topic.push((
                m.topic.to_string(),
                o.header.frame_id,
                o.child_frame_id,
                o.header.stamp.nanos(),
                o.pose,
            ));
        }
        Ok(true)
    });
    let stopped = match result {
        Ok(()) => None,
        Err(e @ BagError::Container { .. }) => Some(e.to_string()),
        Err(e) => return Err(e),
    };
    let mut tf = TfTree::new();
    for (p, c, t) in &static_tf {
        tf.add_static(p, c, *t);
    }
    let mut odom = tf.clone();
    for (p, c, s, t) in &dynamic_tf {
        tf.add_dynamic(p, c, *s, *t);
    }
    let odom_topics: Vec<&(String, String)> = topics
        .iter()
        .filter(|(_, ty)| same_type(ty, ODOMETRY))
        .collect();
    let chosen = match opts.odom_topic.as_deref() {
        _ if opts.no_odometry => None,
        Some("/tf") => None,
        Some(t) => {
            if !odom_topics.iter().any(|(n, _)| n == t) {
                return Err(no_topic(bag, t, &topics, ODOMETRY));
            }
            Some(t.to_string())
        }
        None if odom_topics.len() == 1 => Some(odom_topics[0].0.clone()),
        None => None,
    };
    let (odom_frame, odom_source) = match &chosen {
        Some(topic) => {
            let mut frame = None;
            for (t, parent, child, s, pose) in &odom_by_topic {
                if t == topic {
                    odom.add_dynamic(parent, child, *s, *pose);
                    frame.get_or_insert_with(|| parent.clone());
                }
            }
            (frame, Some(topic.clone()))
        }
        None => {
            let want_tf = opts.odom_topic.as_deref() == Some("/tf");
            let has_odom_frame = tf.frames().contains(&opts.odom_frame);
            if !opts.no_odometry && (want_tf || (!dynamic_tf.is_empty() && has_odom_frame)) {
                odom = tf.clone();
                (
                    Some(opts.odom_frame.clone()),
                    Some(format!("/tf ({})", opts.odom_frame)),
                )
            } else {
                (None, None)
            }
        }
    };
    Ok((
        Motion {
            topics,
            tf,
            odom,
            odom_frame,
            odom_source,
            problems,
        },
        stopped,
    ))
}

fn no_topic(bag: &Bag, topic: &str, topics: &[(String, String)], wanted: &str) -> BagError {
    BagError::NoTopic {
        path: bag.path.clone(),
        topic: format!("{topic}' of type '{wanted}"),
        known: topics
            .iter()
            .map(|(n, t)| format!("{n} [{t}]"))
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// Picks the scan topic: the one asked for, else the only `PointCloud2` topic, else the
/// only `LaserScan` topic.
fn scan_topic(
    bag: &Bag,
    opts: &ExtractOptions,
    topics: &[(String, String)],
) -> Result<(String, String), BagError> {
    let is_scan = |ty: &str| same_type(ty, POINT_CLOUD2) || same_type(ty, LASER_SCAN);
    if let Some(t) = &opts.topic {
        return match topics.iter().find(|(n, _)| n == t) {
            Some((n, ty)) if is_scan(ty) => Ok((n.clone(), ty.clone())),
            Some((_, ty)) => Err(BagError::Request {
                path: bag.path.clone(),
                reason: format!("topic '{t}' holds {ty}; scans are {POINT_CLOUD2} or {LASER_SCAN}"),
            }),
            None => Err(no_topic(bag, t, topics, "PointCloud2 or LaserScan")),
        };
    }
    for ty in [POINT_CLOUD2, LASER_SCAN] {
        let of: Vec<_> = topics.iter().filter(|(_, t)| same_type(t, ty)).collect();
        match of.as_slice() {
            [one] => return Ok((*one).clone()),
            [] => continue,
            many => {
                return Err(BagError::Request {
                    path: bag.path.clone(),
                    reason: format!(
                        "several {ty} topics ({}): choose one with --topic",
                        many.iter()
                            .map(|(n, _)| n.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                })
            }
        }
    }
    Err(BagError::Request {
        path: bag.path.clone(),
        reason: format!(
            "no {POINT_CLOUD2} or {LASER_SCAN} topic (topics: {})",
            topics
                .iter()
                .map(|(n, t)| format!("{n} [{t}]"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    })
}

/// Decodes one scan message into points in its own frame.
fn decode_scan(m: &BagMessage<'_>, laser: bool) -> std::result::Result<BagScan, String> {
    if laser {
        let s = RosLaserScan::decode(m.data).map_err(|e| e.to_string())?;
        if !(s.angle_increment.is_finite() && s.angle_min.is_finite()) {
            return Err("non-finite angle_min or angle_increment".into());
        }
        if !s.intensities.is_empty() && s.intensities.len() != s.ranges.len() {
            return Err(format!(
                "{} intensities for {} ranges",
                s.intensities.len(),
                s.ranges.len()
            ));
        }
        let scan = LaserScan {
            angle_min: s.angle_min.into(),
            angle_increment: s.angle_increment.into(),
            range_min: s.range_min.into(),
            range_max: s.range_max.into(),
            ranges: s.ranges,
            intensities: (!s.intensities.is_empty()).then_some(s.intensities),
            time: s.header.stamp.seconds(),
        };
        scan.validate()?;
        let cloud = scan.to_cloud();
        let records = scan.ranges.len() as u64;
        Ok(BagScan {
            name: String::new(),
            index: m.index,
            stamp: s.header.stamp,
            frame: s.header.frame_id.trim_start_matches('/').to_string(),
            records,
            dropped: records - cloud.len() as u64,
            cloud,
            laser: Some(scan),
            odometry: None,
        })
    } else {
        let msg = PointCloud2::decode(m.data).map_err(|e| e.to_string())?;
        let d = decode_points(&msg)?;
        Ok(BagScan {
            name: String::new(),
            index: m.index,
            stamp: msg.header.stamp,
            frame: msg.header.frame_id.trim_start_matches('/').to_string(),
            records: d.records,
            dropped: d.dropped_non_finite,
            cloud: d.cloud,
            laser: None,
            odometry: None,
        })
    }
}

/// Reads the scans of a bag (two passes: transforms and odometry, then the scans), each
/// handed to `sink` as it is decoded, so that memory holds one scan at a time. A scan
/// message that does not decode, or has no transform or odometry at its stamp, is skipped
/// and listed in [`Extraction::skipped`] (its topic, index and why); a damaged file ends
/// the reading with [`Extraction::stopped_early`] set.
pub fn extract_scans_with(
    bag: &Bag,
    opts: &ExtractOptions,
    mut sink: impl FnMut(BagScan) -> Result<()>,
) -> Result<Extraction> {
    let (mut motion, stopped_first) = read_motion(bag, opts)?;
    let (topic, type_name) = scan_topic(bag, opts, &motion.topics)?;
    let laser = same_type(&type_name, LASER_SCAN);
    let mut ex = Extraction {
        scans: Vec::new(),
        topic: topic.clone(),
        type_name: type_name.clone(),
        odometry_source: motion.odom_source.clone(),
        skipped: std::mem::take(&mut motion.problems),
        thinned: 0,
        stopped_early: stopped_first,
    };
    let mut kept = 0usize;
    let mut last_kept: Option<i64> = None;
    let mut sink_error = None;
    let result = bag.for_each_message(|m| {
        if m.topic != topic {
            return Ok(true);
        }
        if opts.max.is_some_and(|n| kept >= n) {
            return Ok(false);
        }
        if opts.index.is_some_and(|i| i != m.index) {
            ex.thinned += 1;
            return Ok(true);
        }
        let mut scan = match decode_scan(m, laser) {
            Ok(s) => s,
            Err(reason) => {
                ex.skipped.push(m.error(reason).to_string());
                return Ok(true);
            }
        };
        let stamp = scan.stamp.nanos();
        if let (Some(every), Some(last)) = (opts.every, last_kept) {
            if ((stamp - last) as f64) * 1e-9 < every {
                ex.thinned += 1;
                return Ok(true);
            }
        }
        match place(&mut motion, opts, &mut scan, stamp) {
            Ok(()) => {}
            Err(reason) => {
                ex.skipped.push(m.error(reason).to_string());
                return Ok(true);
            }
        }
        scan.name = format!("{:06}", m.index);
        last_kept = Some(stamp);
        kept += 1;
        if let Err(e) = sink(scan) {
            sink_error = Some(e);
            return Ok(false);
        }
        Ok(true)
    });
    if let Some(e) = sink_error {
        return Err(e);
    }
    match result {
        Ok(()) => {}
        Err(e @ BagError::Container { .. }) => {
            ex.stopped_early.get_or_insert(e.to_string());
        }
        Err(e) => return Err(e.into()),
    }
    Ok(ex)
}

/// Moves a scan into the output frame and attaches its odometry.
fn place(
    motion: &mut Motion,
    opts: &ExtractOptions,
    scan: &mut BagScan,
    stamp: i64,
) -> std::result::Result<(), String> {
    let tol = opts.tolerance_ns;
    if let Some(frame) = &opts.frame {
        let frame = frame.trim_start_matches('/');
        if frame != scan.frame {
            let t = motion.tf.lookup(frame, &scan.frame, stamp, tol)?;
            scan.cloud = scan.cloud.transformed(&t);
            scan.frame = frame.to_string();
        }
    }
    if let Some(odom_frame) = &motion.odom_frame {
        let t = motion
            .odom
            .lookup(odom_frame, &scan.frame, stamp, tol)
            .map_err(|e| format!("no odometry: {e}"))?;
        scan.odometry = Some(t);
    }
    Ok(())
}

/// Reads the scans of a bag into memory (see [`extract_scans_with`]).
///
/// ```no_run
/// use olmap::io::bag::{extract_scans, Bag, ExtractOptions};
/// let bag = Bag::open("recording/")?;
/// let ex = extract_scans(&bag, &ExtractOptions { topic: Some("/points".into()), ..Default::default() })?;
/// for s in &ex.scans {
///     println!("{} at {:.3} s: {} points", s.name, s.stamp.seconds(), s.cloud.len());
/// }
/// # Ok::<(), olmap::Error>(())
/// ```
pub fn extract_scans(bag: &Bag, opts: &ExtractOptions) -> Result<Extraction> {
    let mut scans = Vec::new();
    let mut ex = extract_scans_with(bag, opts, |s| {
        scans.push(s);
        Ok(())
    })?;
    ex.scans = scans;
    Ok(ex)
}

/// What [`write_extraction`] wrote.
#[derive(Debug, Clone, Serialize)]
pub struct ExtractReport {
    /// The bag.
    pub bag: String,
    /// The scan topic.
    pub topic: String,
    /// Its type.
    #[serde(rename = "type")]
    pub type_name: String,
    /// Scans written.
    pub scans: usize,
    /// Points written, all scans.
    pub points: u64,
    /// The odometry's source, if any (`odometry.txt` is written only with one).
    pub odometry: Option<String>,
    /// Scan messages left out, with why.
    pub skipped: Vec<String>,
    /// Scan messages passed over by `--every` / `--max`.
    pub thinned: u64,
    /// Why reading stopped early, if it did.
    pub stopped_early: Option<String>,
    /// The output folder.
    pub output: String,
}

/// Extracts a bag's scans into `dir`: `scans/NNNNNN.pcd` (binary PCD, the sensor origin as
/// VIEWPOINT), `scans2d/NNNNNN.csv` for `LaserScan` topics (olmap's 2D scan CSV),
/// `odometry.txt` (a pose list, `T_odom_frame` at each scan's stamp) when the bag has
/// odometry, and `stamps.csv` (`name,index,stamp_ns,seconds,frame,points,dropped`). Scans
/// are written as they are decoded; `stamps.csv` and `odometry.txt` last.
pub fn write_extraction(bag: &Bag, opts: &ExtractOptions, dir: &Path) -> Result<ExtractReport> {
    let scans_dir = dir.join("scans");
    let io = |path: &Path, source| crate::Error::Io {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(&scans_dir).map_err(|e| io(&scans_dir, e))?;
    let mut poses = PoseList::default();
    let mut stamps = String::from("name,index,stamp_ns,seconds,frame,points,dropped\n");
    let mut points = 0u64;
    let mut written = 0usize;
    let mut laser_dir: Option<PathBuf> = None;
    let ex = extract_scans_with(bag, opts, |s| {
        let path = scans_dir.join(format!("{}.pcd", s.name));
        crate::io::write_cloud(&path, &s.cloud, &crate::io::WriteOptions::default())?;
        if let Some(l) = &s.laser {
            let d = laser_dir.get_or_insert_with(|| dir.join("scans2d"));
            std::fs::create_dir_all(&*d).map_err(|e| io(d, e))?;
            let p = d.join(format!("{}.csv", s.name));
            crate::file::write_atomic(&p, "2D scan CSV", |w| l.write_csv(w))?;
        }
        if let Some(o) = s.odometry {
            poses.push(s.name.clone(), o);
        }
        stamps.push_str(&format!(
            "{},{},{},{:.9},{},{},{}\n",
            s.name,
            s.index,
            s.stamp.nanos(),
            s.stamp.seconds(),
            s.frame,
            s.cloud.len(),
            s.dropped
        ));
        points += s.cloud.len() as u64;
        written += 1;
        Ok(())
    })?;
    if ex.odometry_source.is_some() && !poses.is_empty() {
        poses.write_path(dir.join("odometry.txt"))?;
    }
    crate::file::write_atomic(&dir.join("stamps.csv"), "stamps CSV", |w| {
        std::io::Write::write_all(w, stamps.as_bytes())
    })?;
    Ok(ExtractReport {
        bag: bag.path.display().to_string(),
        topic: ex.topic,
        type_name: ex.type_name,
        scans: written,
        points,
        odometry: ex.odometry_source,
        skipped: ex.skipped,
        thinned: ex.thinned,
        stopped_early: ex.stopped_early,
        output: dir.display().to_string(),
    })
}

/// A scan named on the command line as `BAG#TOPIC@INDEX` (`rec/#/points@3`: the fourth
/// message on `/points` of the bag `rec/`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScanSpec {
    /// The bag's path.
    pub bag: PathBuf,
    /// The topic.
    pub topic: String,
    /// The message's index on the topic (0-based).
    pub index: u64,
}

impl ScanSpec {
    /// Parses `BAG#TOPIC@INDEX`; `None` when `s` does not have that form.
    ///
    /// ```
    /// use olmap::io::bag::ScanSpec;
    /// let s = ScanSpec::parse("rec.mcap#/points@12").unwrap();
    /// assert_eq!((s.topic.as_str(), s.index), ("/points", 12));
    /// assert!(ScanSpec::parse("scan000.3d").is_none());
    /// ```
    pub fn parse(s: &str) -> Option<ScanSpec> {
        let (bag, rest) = s.rsplit_once('#')?;
        let (topic, index) = rest.rsplit_once('@')?;
        if bag.is_empty() || !topic.starts_with('/') {
            return None;
        }
        Some(ScanSpec {
            bag: bag.into(),
            topic: topic.into(),
            index: index.parse().ok()?,
        })
    }

    /// Reads the scan, in its message's frame, without odometry.
    pub fn read(&self) -> Result<BagScan> {
        let bag = Bag::open(&self.bag)?;
        let opts = ExtractOptions {
            topic: Some(self.topic.clone()),
            no_odometry: true,
            index: Some(self.index),
            max: Some(1),
            ..Default::default()
        };
        let ex = extract_scans(&bag, &opts)?;
        let skipped = ex.skipped.first().cloned();
        ex.scans.into_iter().next().ok_or_else(|| {
            BagError::Request {
                path: self.bag.clone(),
                reason: skipped.unwrap_or_else(|| {
                    format!("no message {} on topic '{}'", self.index, self.topic)
                }),
            }
            .into()
        })
    }
}
