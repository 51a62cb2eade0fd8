//! `olmap poses`: read pose files of any supported kind and print or convert them.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;
use olmap::geometry::{NamedPoseJson, PoseList};

/// Arguments of `olmap poses`.
///
/// Understands 3DTK `.pose` (odometry, left-handed cm and degrees) and `.frames`
/// (registration history; the last frame is the final pose), CARMEN 2D laser logs (the
/// `FLASER` poses, named scan000000, …), CSV pose tables
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

/// Runs the command.
pub fn run(a: &PosesArgs) -> anyhow::Result<ExitCode> {
    if let Some(out) = &a.out {
        olmap::file::check_output(out, "pose list")?;
    }
    let mut list = PoseList::default();
    for f in &a.files {
        list.poses
            .extend(olmap::io::read_poses_with(f, a.all_frames)?.poses);
    }
    if let Some(out) = &a.out {
        list.write_path(out)?;
    }
    if a.json {
        let v: Vec<_> = list
            .poses
            .iter()
            .map(|np| NamedPoseJson::new(&np.name, &np.pose))
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
