//! Simulated datasets on disk: a versioned JSON manifest, per-robot scans, pose files and
//! a sightings table. Written by [`crate::sim::simulate`] + [`write_dataset`], read back by
//! [`read_dataset`] (any tool can read the files directly: they are ordinary PCD, pose
//! lists and CSV).
//!
//! Layout of a dataset folder:
//! ```text
//! manifest.json             format "olmap-sim-dataset", version 1, seed, world, robots, files
//! sightings.csv             one row per sighting (see below)
//! robot0/truth.txt          ground truth T_world_robot per scan (olmap pose list)
//! robot0/odometry.txt       odometry T_odom_robot per scan (starts at the identity)
//! robot0/scans/scan000.pcd  3D scan in the robot frame (binary PCD, VIEWPOINT = sensor)
//! robot0/scans2d/scan000.csv  optional 2D laser scan (olmap laser-scan CSV)
//! robot0/raw/scan000.mirror   optional raw rotating-mirror log
//! robot1/...
//! ```
//! The robot frame has its origin on the floor under the robot's centre, x forward, z up.
//! `sightings.csv` has the header
//! `observer,target,stop,time_s,range_m,bearing_rad,elevation_rad,beacon_x_m,beacon_y_m,beacon_z_m,mutual`:
//! robot indices (manifest order), the stop both were at, the measured range, bearing and
//! elevation from the observer's detecting sensor, the beacon's centre in the observer's
//! robot frame, and whether the sighting was two-way (`1`/`0`).

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::Sighting;
use crate::error::{Error, ParseError, Result};
use crate::file::text::json_message;
use crate::file::OutputSet;
use crate::geometry::PoseList;

/// The `format` value of a dataset manifest.
pub const DATASET_FORMAT: &str = "olmap-sim-dataset";
/// The manifest version this olmap writes and reads.
pub const DATASET_VERSION: u32 = 1;

/// One robot's files, relative to the dataset folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotFiles {
    /// The robot's name (also its folder).
    pub name: String,
    /// Ground-truth pose list.
    pub truth: String,
    /// Odometry pose list.
    pub odometry: String,
    /// 3D scans in stop order.
    pub scans: Vec<String>,
    /// 2D scans in stop order (empty when not simulated).
    #[serde(default)]
    pub scans2d: Vec<String>,
    /// Raw mirror-scanner logs in stop order (empty when not simulated).
    #[serde(default)]
    pub raw_logs: Vec<String>,
}

/// The manifest: what was simulated, with which parameters, and where the files are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetManifest {
    /// Always [`DATASET_FORMAT`].
    pub format: String,
    /// [`DATASET_VERSION`].
    pub version: u32,
    /// The olmap version that wrote it.
    pub generator: String,
    /// The simulation seed.
    pub seed: u64,
    /// The world generator's name (`office`, `lab`, `corridor`, `box-room`).
    pub world: String,
    /// Stops (scans) per robot.
    pub stops: usize,
    /// Time between stops, seconds.
    pub stop_interval_s: f64,
    /// Every simulation parameter, for the record.
    pub parameters: serde_json::Value,
    /// The robots' files.
    pub robots: Vec<RobotFiles>,
    /// The sightings table.
    pub sightings: String,
}

/// A dataset read back: the manifest, each robot's poses, the sightings, and the folder
/// (scan paths are `dir.join(..)` of the manifest's entries).
#[derive(Debug, Clone)]
pub struct DatasetOnDisk {
    /// The folder.
    pub dir: PathBuf,
    /// The manifest.
    pub manifest: DatasetManifest,
    /// Ground truth per robot (manifest order); empty for a robot whose truth file was
    /// skipped (see `skipped`).
    pub truth: Vec<PoseList>,
    /// Odometry per robot; empty for a robot whose odometry file was skipped.
    pub odometry: Vec<PoseList>,
    /// All sightings.
    pub sightings: Vec<Sighting>,
    /// Pose files left out because they are missing, unreadable or of the wrong length:
    /// a dataset is still mapped without them (a robot without odometry is mapped
    /// without priors; without every robot's truth there is no evaluation).
    pub skipped: Vec<SkippedInput>,
}

/// An input of a dataset left out, and why: the caller warns about it and goes on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SkippedInput {
    /// The file.
    pub path: String,
    /// Why it was left out (the error reading it).
    pub reason: String,
}

impl DatasetOnDisk {
    /// Whether every robot's ground truth was read (the maps can be evaluated).
    pub fn has_truth(&self) -> bool {
        let truth_files: Vec<PathBuf> = self
            .manifest
            .robots
            .iter()
            .map(|r| self.dir.join(&r.truth))
            .collect();
        !self.skipped.iter().any(|s| {
            truth_files
                .iter()
                .any(|t| t.display().to_string() == s.path)
        })
    }
}

impl DatasetOnDisk {
    /// Absolute paths of robot `r`'s 3D scans.
    pub fn scan_paths(&self, r: usize) -> Vec<PathBuf> {
        self.manifest.robots[r]
            .scans
            .iter()
            .map(|s| self.dir.join(s))
            .collect()
    }
}

/// The header line of `sightings.csv`.
pub const SIGHTINGS_HEADER: &str = "observer,target,stop,time_s,range_m,bearing_rad,elevation_rad,beacon_x_m,beacon_y_m,beacon_z_m,mutual";

/// Writes sightings as CSV (floats in Rust's shortest exact form: reading gives back the
/// same numbers).
pub fn write_sightings<W: Write>(mut w: W, sightings: &[Sighting]) -> std::io::Result<()> {
    writeln!(w, "{SIGHTINGS_HEADER}")?;
    for s in sightings {
        writeln!(
            w,
            "{},{},{},{:?},{:?},{:?},{:?},{:?},{:?},{:?},{}",
            s.observer,
            s.target,
            s.stop,
            s.time,
            s.range,
            s.bearing,
            s.elevation,
            s.beacon.x,
            s.beacon.y,
            s.beacon.z,
            u8::from(s.mutual)
        )?;
    }
    Ok(())
}

/// Reads sightings written by [`write_sightings`].
pub fn read_sightings<R: BufRead>(r: R) -> Result<Vec<Sighting>, ParseError> {
    let mut out = Vec::new();
    let mut header_seen = false;
    for (i, line) in r.lines().enumerate() {
        let line = line?;
        let n = i + 1;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if !header_seen {
            if line != SIGHTINGS_HEADER {
                return Err(ParseError::line(
                    n,
                    format!("expected the header '{SIGHTINGS_HEADER}'"),
                ));
            }
            header_seen = true;
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 11 {
            return Err(ParseError::line(
                n,
                format!("expected 11 comma-separated fields, found {}", f.len()),
            ));
        }
        let int = |k: usize, what: &str| {
            f[k].parse::<usize>().map_err(|_| {
                ParseError::line(n, format!("{what}: '{}' is not a whole number", f[k]))
            })
        };
        let num = |k: usize, what: &str| {
            f[k].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    ParseError::line(n, format!("{what}: '{}' is not a finite number", f[k]))
                })
        };
        let mutual = match f[10] {
            "1" => true,
            "0" => false,
            other => {
                return Err(ParseError::line(
                    n,
                    format!("mutual: expected 0 or 1, found '{other}'"),
                ))
            }
        };
        out.push(Sighting {
            observer: int(0, "observer")?,
            target: int(1, "target")?,
            stop: int(2, "stop")?,
            time: num(3, "time_s")?,
            range: num(4, "range_m")?,
            bearing: num(5, "bearing_rad")?,
            elevation: num(6, "elevation_rad")?,
            beacon: nalgebra::Point3::new(
                num(7, "beacon_x_m")?,
                num(8, "beacon_y_m")?,
                num(9, "beacon_z_m")?,
            ),
            mutual,
        });
    }
    if !header_seen {
        return Err(ParseError::Empty);
    }
    Ok(out)
}

fn read_text<T>(
    path: &Path,
    format: &'static str,
    parse: impl FnOnce(std::io::BufReader<std::fs::File>) -> Result<T, ParseError>,
) -> Result<T> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    parse(std::io::BufReader::new(f)).map_err(|source| Error::Read {
        path: path.to_path_buf(),
        format,
        source,
    })
}

/// Reads a dataset folder: the manifest (format and version checked), every robot's pose
/// lists (one pose per scan, checked) and the sightings (robot indices checked). A pose
/// list that is missing, unreadable or of the wrong length is left out and listed in
/// [`DatasetOnDisk::skipped`]; a bad manifest or sightings table is an error.
pub fn read_dataset(dir: impl AsRef<Path>) -> Result<DatasetOnDisk> {
    let dir = dir.as_ref();
    let manifest_path = dir.join("manifest.json");
    let manifest: DatasetManifest = read_text(&manifest_path, "dataset manifest", |r| {
        serde_json::from_reader(r).map_err(|e| {
            ParseError::line(
                e.line(),
                format!("column {}: {}", e.column(), json_message(&e)),
            )
        })
    })?;
    let bad = |reason: String| Error::Read {
        path: manifest_path.clone(),
        format: "dataset manifest",
        source: ParseError::Malformed(reason),
    };
    if manifest.format != DATASET_FORMAT {
        return Err(bad(format!(
            "format is '{}', expected '{DATASET_FORMAT}'",
            manifest.format
        )));
    }
    if manifest.version != DATASET_VERSION {
        return Err(bad(format!(
            "version {} is not supported (this olmap reads version {DATASET_VERSION})",
            manifest.version
        )));
    }
    let mut truth = Vec::new();
    let mut odometry = Vec::new();
    let mut skipped = Vec::new();
    for r in &manifest.robots {
        for (what, file, lists) in [
            ("truth", &r.truth, &mut truth),
            ("odometry", &r.odometry, &mut odometry),
        ] {
            let path = dir.join(file);
            let list = PoseList::read_path(&path).and_then(|list| {
                if list.len() == r.scans.len() {
                    Ok(list)
                } else {
                    Err(bad(format!(
                        "robot {}: {} scans but {} {what} poses",
                        r.name,
                        r.scans.len(),
                        list.len()
                    )))
                }
            });
            match list {
                Ok(list) => lists.push(list),
                Err(e) => {
                    skipped.push(SkippedInput {
                        path: path.display().to_string(),
                        reason: e.to_string(),
                    });
                    lists.push(PoseList::default());
                }
            }
        }
    }
    let sightings_path = dir.join(&manifest.sightings);
    let sightings = read_text(&sightings_path, "sightings CSV", read_sightings)?;
    let n = manifest.robots.len();
    if let Some(s) = sightings.iter().find(|s| s.observer >= n || s.target >= n) {
        return Err(Error::Read {
            path: sightings_path,
            format: "sightings CSV",
            source: ParseError::Malformed(format!(
                "sighting of robot {} by robot {}: the manifest has {n} robots",
                s.target, s.observer
            )),
        });
    }
    Ok(DatasetOnDisk {
        dir: dir.to_path_buf(),
        manifest,
        truth,
        odometry,
        sightings,
        skipped,
    })
}

/// Writes a simulated dataset into `dir`, which must not exist or be empty. The folder is
/// written in a staging folder beside it and renamed when complete (an
/// [`OutputSet`](crate::file::OutputSet)): it appears whole or not at all. Same dataset,
/// same bytes.
pub fn write_dataset(dir: impl AsRef<Path>, data: &super::SimDataset) -> Result<()> {
    let dir = dir.as_ref();
    check_dataset_output(dir)?;
    let mut set = OutputSet::new();
    set.dir(dir, "dataset folder")?;
    write_dataset_into(&set.path(dir)?, data)?;
    set.commit()
}

/// Checks, before simulating, that [`write_dataset`] can write to `dir`: it does not exist
/// or is empty, and its parent folder exists and is writable.
pub fn check_dataset_output(dir: &Path) -> Result<()> {
    if dir.exists() {
        let empty = std::fs::read_dir(dir)
            .map_err(|e| Error::io(dir, e))?
            .next()
            .is_none();
        if !empty {
            return Err(Error::InvalidArgument(format!(
                "{} exists and is not empty; choose a new folder for the dataset",
                dir.display()
            )));
        }
    }
    OutputSet::new().dir(dir, "dataset folder")
}

/// Writes the dataset's files into the folder `dir` (existing or not), each atomically.
pub(crate) fn write_dataset_into(dir: &Path, data: &super::SimDataset) -> Result<()> {
    let mkdir = |p: &Path| std::fs::create_dir_all(p).map_err(|e| Error::io(p, e));
    mkdir(dir)?;
    let options = crate::io::WriteOptions {
        format: Some(crate::io::CloudFormat::Pcd),
        pcd_encoding: crate::io::PcdEncoding::Binary,
        ..Default::default()
    };
    let mut robots = Vec::new();
    for robot in &data.robots {
        let base = PathBuf::from(&robot.name);
        mkdir(&dir.join(&base).join("scans"))?;
        let scan_name = |k: usize| format!("scan{k:03}");
        let mut truth = PoseList::default();
        let mut odometry = PoseList::default();
        let mut files = RobotFiles {
            name: robot.name.clone(),
            truth: format!("{}/truth.txt", robot.name),
            odometry: format!("{}/odometry.txt", robot.name),
            scans: Vec::new(),
            scans2d: Vec::new(),
            raw_logs: Vec::new(),
        };
        for (k, cloud) in robot.scans.iter().enumerate() {
            let rel = format!("{}/scans/{}.pcd", robot.name, scan_name(k));
            crate::io::write_cloud(dir.join(&rel), cloud, &options)?;
            files.scans.push(rel);
            truth.push(scan_name(k), robot.truth[k]);
            odometry.push(scan_name(k), robot.odometry[k]);
        }
        truth.write_path(dir.join(&files.truth))?;
        odometry.write_path(dir.join(&files.odometry))?;
        if !robot.scans2d.is_empty() {
            mkdir(&dir.join(&base).join("scans2d"))?;
        }
        for (k, scan) in robot.scans2d.iter().enumerate() {
            let rel = format!("{}/scans2d/{}.csv", robot.name, scan_name(k));
            crate::file::write_atomic(&dir.join(&rel), "laser scan CSV", |w| scan.write_csv(w))?;
            files.scans2d.push(rel);
        }
        if !robot.raw_logs.is_empty() {
            mkdir(&dir.join(&base).join("raw"))?;
        }
        for (k, log) in robot.raw_logs.iter().enumerate() {
            let rel = format!("{}/raw/{}.mirror", robot.name, scan_name(k));
            crate::file::write_atomic(&dir.join(&rel), "mirror log", |w| log.write(w))?;
            files.raw_logs.push(rel);
        }
        robots.push(files);
    }
    crate::file::write_atomic(&dir.join("sightings.csv"), "sightings CSV", |w| {
        write_sightings(w, &data.sightings)
    })?;
    let manifest = DatasetManifest {
        format: DATASET_FORMAT.into(),
        version: DATASET_VERSION,
        generator: format!("olmap {}", env!("CARGO_PKG_VERSION")),
        seed: data.config.seed,
        world: data.config.world.name().into(),
        stops: data.config.stops,
        stop_interval_s: data.config.stop_interval,
        parameters: data.config.parameters(),
        robots,
        sightings: "sightings.csv".into(),
    };
    crate::file::write_atomic(&dir.join("manifest.json"), "dataset manifest", |w| {
        serde_json::to_writer_pretty(&mut *w, &manifest).map_err(std::io::Error::other)?;
        writeln!(w)
    })
}
