//! `olmap bag`: ROS 2 bags (rosbag2 folders or `.mcap` files): what one holds, and its scans
//! extracted into a folder `olmap map` reads.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use olmap::io::bag::{bag_info, write_extraction, Bag, ExtractOptions};

/// Arguments of `olmap bag`.
#[derive(Args)]
pub struct BagArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: BagCommand,
}

/// The `olmap bag` subcommands.
#[derive(Subcommand)]
pub enum BagCommand {
    /// Topics with type, message count, first/last stamp; frames named in the messages;
    /// messages that do not decode; where a damaged file stops (exit status 3 then, after
    /// printing what was readable).
    Info(InfoArgs),
    /// Scans (PointCloud2 or LaserScan) to DIR/scans/NNNNNN.pcd with DIR/odometry.txt and
    /// DIR/stamps.csv: the folder `olmap map DIR/scans --odometry DIR/odometry.txt` reads
    /// (exit status 3 when scan messages were skipped or the file is damaged; the readable
    /// scans are written).
    Extract(ExtractArgs),
}

/// Arguments of `olmap bag info`.
#[derive(Args)]
pub struct InfoArgs {
    /// The bag: a rosbag2 folder (metadata.yaml + .mcap files) or one .mcap file.
    pub bag: PathBuf,
    /// Print JSON: {"topics": [{"name", "type", "count", "first_stamp", "last_stamp",
    /// "encoding"}], "messages", "frames", "files", "problems", "stopped_early"}; stamps in
    /// seconds since the epoch.
    #[arg(long)]
    pub json: bool,
}

/// Which scans and odometry to take from a bag (shared with `olmap map BAG`).
#[derive(Args, Clone, Default)]
pub struct BagSelectArgs {
    /// The scan topic (sensor_msgs/PointCloud2 or LaserScan). Default: the bag's only
    /// PointCloud2 topic, else its only LaserScan topic.
    #[arg(long)]
    pub topic: Option<String>,
    /// The odometry: a nav_msgs/Odometry topic, or `/tf` for the transform chain from
    /// --odom-frame. Default: the bag's only Odometry topic, else /tf when it has dynamic
    /// transforms, else none. The odometry written is T_odom_frame of each scan's frame
    /// (after --frame) at the scan's header stamp, interpolated.
    #[arg(long)]
    pub odom_topic: Option<String>,
    /// The odometry frame with `--odom-topic /tf`.
    #[arg(long, default_value = "odom")]
    pub odom_frame: String,
    /// Put the scans in this frame (e.g. base_link), with the bag's /tf_static and /tf.
    /// Default: each message's own frame (the sensor at the origin).
    #[arg(long)]
    pub frame: Option<String>,
    /// Keep a scan only when at least this many seconds after the last one kept.
    #[arg(long)]
    pub every: Option<f64>,
    /// Stop after this many scans.
    #[arg(long)]
    pub max: Option<usize>,
}

impl BagSelectArgs {
    /// The library's options.
    pub fn options(&self) -> anyhow::Result<ExtractOptions> {
        if let Some(e) = self.every {
            anyhow::ensure!(
                e.is_finite() && e >= 0.0,
                "--every must be seconds >= 0, got {e}"
            );
        }
        Ok(ExtractOptions {
            topic: self.topic.clone(),
            odom_topic: self.odom_topic.clone(),
            odom_frame: self.odom_frame.clone(),
            frame: self.frame.clone(),
            every: self.every,
            max: self.max,
            ..Default::default()
        })
    }
}

/// Arguments of `olmap bag extract`.
#[derive(Args)]
pub struct ExtractArgs {
    /// The bag: a rosbag2 folder (metadata.yaml + .mcap files) or one .mcap file.
    pub bag: PathBuf,
    /// The output folder (created; files in it are replaced).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Which scans and odometry.
    #[command(flatten)]
    pub select: BagSelectArgs,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap bag`.
pub fn run(a: &BagArgs) -> anyhow::Result<ExitCode> {
    match &a.command {
        BagCommand::Info(a) => info(a),
        BagCommand::Extract(a) => extract(a),
    }
}

fn info(a: &InfoArgs) -> anyhow::Result<ExitCode> {
    let bag = Bag::open(&a.bag)?;
    let info = bag_info(&bag)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        println!(
            "{}: {} messages in {} file(s)",
            info.path,
            info.messages,
            info.files.len()
        );
        for t in &info.topics {
            println!(
                "  {:<28} {:<36} {:>7} msgs  {:.3} .. {:.3} s",
                t.name, t.type_name, t.count, t.first_stamp, t.last_stamp
            );
        }
        if !info.frames.is_empty() {
            println!("  frames: {}", info.frames.join(", "));
        }
        for p in &info.problems {
            println!("  problem: {p}");
        }
    }
    if let Some(s) = &info.stopped_early {
        eprintln!("warning: reading stopped early: {s}");
    }
    Ok(
        if info.stopped_early.is_some() || !info.problems.is_empty() {
            ExitCode::from(3)
        } else {
            ExitCode::SUCCESS
        },
    )
}

fn extract(a: &ExtractArgs) -> anyhow::Result<ExitCode> {
    let bag = Bag::open(&a.bag)?;
    let report = write_extraction(&bag, &a.select.options()?, &a.output)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{} scans ({} points) from {} [{}] -> {}/scans{}",
            report.scans,
            report.points,
            report.topic,
            report.type_name,
            report.output,
            match &report.odometry {
                Some(o) => format!(", odometry from {o} -> {}/odometry.txt", report.output),
                None => ", no odometry".into(),
            }
        );
        if report.thinned > 0 {
            println!(
                "  {} scan messages passed over (--every / --max)",
                report.thinned
            );
        }
    }
    for s in &report.skipped {
        eprintln!("warning: skipped {s}");
    }
    if let Some(s) = &report.stopped_early {
        eprintln!("warning: reading stopped early: {s}");
    }
    if report.scans == 0 {
        anyhow::bail!("no scan could be extracted from {}", a.bag.display());
    }
    Ok(
        if report.stopped_early.is_some() || !report.skipped.is_empty() {
            ExitCode::from(3)
        } else {
            ExitCode::SUCCESS
        },
    )
}
