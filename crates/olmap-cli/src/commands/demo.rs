//! `olmap demo`: the main job on built-in generated data.
//!
//! At this stage of the project the demo exercises the foundation: it generates a 3D scan of
//! a furnished room by ray casting (no download needed), writes it in several formats,
//! reads every file back, checks that the points survived, and describes the result. The
//! cooperative multi-robot pipeline replaces this body once the simulator and the mappers
//! exist.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{ensure, Context};
use clap::Args;
use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::geometry::Pose;
use olmap::io::{self, PcdEncoding, PlyEncoding, WriteOptions};
use olmap::occupancy::{self, OccupancyList, SensorModel};

use crate::report::cloud_text;

/// Arguments of `olmap demo`.
#[derive(Args)]
pub struct DemoArgs {
    /// Folder for the generated files (created if missing).
    #[arg(long, default_value = "olmap-demo")]
    pub out: PathBuf,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Distance along a ray to the first hit with an axis-aligned box, entering from outside
/// (`inside = false`) or leaving it from inside.
fn ray_box(
    o: &Point3<f64>,
    d: &Vector3<f64>,
    lo: [f64; 3],
    hi: [f64; 3],
    inside: bool,
) -> Option<f64> {
    let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..3 {
        if d[i].abs() < 1e-12 {
            if o[i] < lo[i] || o[i] > hi[i] {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo[i] - o[i]) / d[i], (hi[i] - o[i]) / d[i]);
        t_in = t_in.max(a.min(b));
        t_out = t_out.min(a.max(b));
    }
    if t_in > t_out {
        return None;
    }
    let t = if inside { t_out } else { t_in };
    (t > 1e-9).then_some(t)
}

/// Distance along a ray to a vertical cylinder (centre `c`, radius `r`, z in `[0, h]`).
fn ray_cylinder(o: &Point3<f64>, d: &Vector3<f64>, c: [f64; 2], r: f64, h: f64) -> Option<f64> {
    let (ox, oy) = (o.x - c[0], o.y - c[1]);
    let a = d.x * d.x + d.y * d.y;
    if a < 1e-12 {
        return None;
    }
    let b = 2.0 * (ox * d.x + oy * d.y);
    let cc = ox * ox + oy * oy - r * r;
    let disc = b * b - 4.0 * a * cc;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / (2.0 * a);
    let z = o.z + t * d.z;
    (t > 1e-9 && (0.0..=h).contains(&z)).then_some(t)
}

/// A scan of a 10 x 8 x 3 m room with a pillar and a table, from a sensor at 1.2 m height:
/// 0.5 degree azimuth steps, 1 degree elevation steps from -40 to +40 degrees.
fn room_scan() -> PointCloud {
    let sensor = Point3::new(3.0, 3.0, 1.2);
    let mut pts = Vec::new();
    for e in -40..=40 {
        let el = (e as f64).to_radians();
        for a in 0..720 {
            let az = (a as f64 * 0.5).to_radians();
            let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let hits = [
                ray_box(&sensor, &d, [0.0, 0.0, 0.0], [10.0, 8.0, 3.0], true),
                ray_box(&sensor, &d, [5.0, 5.2, 0.0], [6.2, 6.0, 0.75], false),
                ray_cylinder(&sensor, &d, [6.5, 2.5], 0.3, 3.0),
            ];
            if let Some(t) = hits.into_iter().flatten().min_by(f64::total_cmp) {
                // Points in the sensor frame (sensor axes aligned with the room).
                pts.push((d * t).cast::<f32>().into());
            }
        }
    }
    PointCloud::from_points(pts)
}

/// Runs the command.
pub fn run(args: &DemoArgs) -> anyhow::Result<ExitCode> {
    let start = Instant::now();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let scan = room_scan();
    let down = scan.voxel_downsample(0.1)?;
    let outputs: [(&str, &PointCloud, WriteOptions); 4] = [
        (
            "room.pcd",
            &scan,
            WriteOptions {
                pcd_encoding: PcdEncoding::BinaryCompressed,
                ..Default::default()
            },
        ),
        (
            "room.ply",
            &scan,
            WriteOptions {
                ply_encoding: PlyEncoding::BinaryLittleEndian,
                ..Default::default()
            },
        ),
        ("room.xyz", &scan, WriteOptions::default()),
        ("room_voxel_0.1m.pcd", &down, WriteOptions::default()),
    ];
    let mut files = Vec::new();
    for (name, cloud, opts) in outputs {
        let path = args.out.join(name);
        io::write_cloud(&path, cloud, &opts)?;
        let back = io::read_cloud(&path)?;
        ensure!(
            back.cloud.points() == cloud.points(),
            "{}: the points read back differ from the points written",
            path.display()
        );
        let bytes = std::fs::metadata(&path)?.len();
        files.push((path, back, bytes));
    }
    // The scan as an occupancy list: ray traced at 5 cm.
    let mut map = OccupancyList::new(0.05)?;
    let insert = map.insert_scan(&scan, &Pose::identity(), &SensorModel::default())?;
    let map_path = args.out.join("room.olm");
    occupancy::write_map(&map_path, &map)?;
    let reread = occupancy::read_map(&map_path)?.map;
    ensure!(
        reread == map,
        "{}: the map read back differs",
        map_path.display()
    );
    let seconds = start.elapsed().as_secs_f64();
    if args.json {
        let list: Vec<_> = files
            .iter()
            .map(|(p, l, bytes)| {
                serde_json::json!({
                    "path": p.display().to_string(),
                    "format": l.report.format.name(),
                    "points": l.cloud.len(),
                    "bytes": bytes,
                })
            })
            .collect();
        let v = serde_json::json!({
            "scan_points": scan.len(),
            "voxel_points": down.len(),
            "files": list,
            "map": {
                "path": map_path.display().to_string(),
                "resolution": map.resolution(),
                "voxels": map.len(),
                "voxels_traversed": insert.voxels_traversed,
            },
            "seconds": seconds,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!(
            "olmap demo: a generated 3D scan of a furnished 10 x 8 x 3 m room (foundation stage:"
        );
        println!("the cooperative multi-robot pipeline joins this demo as it is built)\n");
        for (p, l, bytes) in &files {
            let s = l.cloud.stats();
            let o = l.cloud.origin();
            print!(
                "{}",
                cloud_text(&p.display().to_string(), &s, &l.report, [o.x, o.y, o.z])
            );
            println!("  {:<14}{bytes} bytes, read back identical\n", "file");
        }
        println!(
            "{}\n  occupancy list at {} m: {} voxels from {} rays ({} voxel steps traced), read back identical\n",
            map_path.display(),
            map.resolution(),
            map.len(),
            insert.rays,
            insert.voxels_traversed
        );
        println!("done in {seconds:.2} s; files in {}", args.out.display());
    }
    Ok(ExitCode::SUCCESS)
}
