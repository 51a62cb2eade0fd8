//! `olmap poses`: read pose files of any supported kind and print or convert them.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use olmap::geometry::{Pose, PoseList};
use olmap::io::{csv, slam6d};

/// Arguments of `olmap poses`.
///
/// Understands 3DTK `.pose` (odometry, left-handed cm and degrees) and `.frames`
/// (registration history; the last frame is the final pose), CSV pose tables
/// (`carCloudList.csv`: name + row-major 4x4), and olmap pose lists (name + row-major 3x4 of
/// `T_map_scan` per line; KITTI `poses.txt` too). Everything is shown in right-handed metres
/// and ZYX degrees.
#[derive(Args)]
pub struct PosesArgs {
    /// Pose files. Several 3DTK `.pose`/`.frames` files make one list named by file stem.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// For `.frames` files: list every frame, not only the final one.
    #[arg(long)]
    pub all_frames: bool,
    /// Also write the poses as an olmap pose list (atomically).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(|| "pose".into(), |s| s.to_string_lossy().into_owned())
}

/// Appends the poses of any supported pose file to `list`.
pub fn read_any(path: &Path, all_frames: bool, list: &mut PoseList) -> olmap::Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "pose" => list.push(stem(path), slam6d::read_pose_path(path)?),
        "frames" => {
            let frames = slam6d::read_frames_path(path)?;
            if all_frames {
                for (i, f) in frames.iter().enumerate() {
                    list.push(format!("{}#{i}", stem(path)), f.pose);
                }
            } else {
                list.push(stem(path), frames.last().expect("at least one frame").pose);
            }
        }
        "csv" => list.poses.extend(csv::read_pose_table_path(path)?.poses),
        _ => list.poses.extend(PoseList::read_path(path)?.poses),
    }
    Ok(())
}

fn pose_json(name: &str, p: &Pose) -> serde_json::Value {
    let t = p.translation();
    let (y, pi, r) = p.yaw_pitch_roll();
    let m = p.to_matrix4();
    let rows: Vec<Vec<f64>> = (0..4)
        .map(|i| (0..4).map(|j| m[(i, j)]).collect())
        .collect();
    serde_json::json!({
        "name": name,
        "xyz_m": [t.x, t.y, t.z],
        "yaw_pitch_roll_deg": [y.to_degrees(), pi.to_degrees(), r.to_degrees()],
        "matrix": rows,
    })
}

/// Runs the command.
pub fn run(a: &PosesArgs) -> anyhow::Result<ExitCode> {
    let mut list = PoseList::default();
    for f in &a.files {
        read_any(f, a.all_frames, &mut list)?;
    }
    if let Some(out) = &a.out {
        list.write_path(out)?;
    }
    if a.json {
        let v: Vec<_> = list
            .poses
            .iter()
            .map(|np| pose_json(&np.name, &np.pose))
            .collect();
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "{:<20} {:>10} {:>10} {:>10} {:>9} {:>9} {:>9}",
            "name", "x [m]", "y [m]", "z [m]", "yaw", "pitch", "roll"
        );
        for np in &list.poses {
            let t = np.pose.translation();
            let (y, p, r) = np.pose.yaw_pitch_roll();
            println!(
                "{:<20} {:>10.4} {:>10.4} {:>10.4} {:>9.3} {:>9.3} {:>9.3}",
                np.name,
                t.x + 0.0,
                t.y + 0.0,
                t.z + 0.0,
                y.to_degrees() + 0.0,
                p.to_degrees() + 0.0,
                r.to_degrees() + 0.0
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
