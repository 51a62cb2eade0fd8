//! Every real point cloud and pose file under the shared data folder reads with the counts,
//! bounding boxes and poses that the data README states (README section in each test).

use nalgebra::Point3;
use olmap::geometry::{Aabb, Pose, PoseError, PoseList};
use olmap::io::{self, csv, slam6d, CloudFormat, ReadOptions};

use crate::data;

fn assert_box(actual: &Aabb, min: [f64; 3], max: [f64; 3], tol: f64, what: &str) {
    for i in 0..3 {
        assert!(
            (actual.min[i] - min[i]).abs() <= tol && (actual.max[i] - max[i]).abs() <= tol,
            "{what}: axis {i}: box {:?}..{:?}, expected {min:?}..{max:?} (tolerance {tol})",
            actual.min,
            actual.max
        );
    }
}

/// A box given in 3DTK's left-handed centimetres, in olmap's right-handed metres
/// (x = z_lh, y = -x_lh, z = y_lh).
fn box_rh_from_lh_cm(min_cm: [f64; 3], max_cm: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    (
        [min_cm[2] / 100.0, -max_cm[0] / 100.0, min_cm[1] / 100.0],
        [max_cm[2] / 100.0, -min_cm[0] / 100.0, max_cm[1] / 100.0],
    )
}

#[test]
fn threedtk_scans_counts_and_boxes() {
    let Some(d) = data() else { return };
    // README §1.3: raw and valid counts, boxes in LH cm (valid boxes to 0.1 cm, raw to 0.01 cm).
    #[allow(clippy::type_complexity)]
    let table: [(&str, usize, usize, [f64; 3], [f64; 3], [f64; 3], [f64; 3]); 3] = [
        (
            "scan000.3d",
            81_360,
            77_987,
            [-1255.3, -222.1, 0.0],
            [118.6, 943.7, 3235.8],
            [-3276.58, -637.05, 0.0],
            [228.57, 2257.76, 3275.89],
        ),
        (
            "scan001.3d",
            81_360,
            78_320,
            [-1118.9, -176.8, 0.0],
            [122.3, 795.8, 3180.4],
            [-3276.58, -753.74, 0.0],
            [3198.83, 2456.91, 3275.89],
        ),
        (
            "scan002.3d",
            81_360,
            78_118,
            [-845.9, -258.3, 0.0],
            [117.3, 690.4, 3114.4],
            [-3276.58, -631.04, 0.0],
            [257.06, 2367.90, 3275.55],
        ),
    ];
    for (name, raw, valid, vmin, vmax, rmin, rmax) in table {
        let path = d.join("3dtk_dat").join(name);
        let all = io::read_cloud(&path).unwrap();
        assert_eq!(all.report.format, CloudFormat::Uos);
        assert_eq!(all.cloud.len(), raw, "{name} raw");
        assert_eq!(all.report.dropped_non_finite, 0);
        let (lo, hi) = box_rh_from_lh_cm(rmin, rmax);
        assert_box(&all.cloud.bounding_box().unwrap(), lo, hi, 1e-3, name);

        let opts = ReadOptions {
            uos_valid_only: true,
            ..Default::default()
        };
        let ok = io::read_cloud_with(&path, &opts).unwrap();
        assert_eq!(ok.cloud.len(), valid, "{name} valid");
        assert_eq!(ok.report.dropped_invalid as usize, raw - valid);
        let (lo, hi) = box_rh_from_lh_cm(vmin, vmax);
        assert_box(&ok.cloud.bounding_box().unwrap(), lo, hi, 1e-3, name);
    }
}

#[test]
fn octomap_scan_dat_and_its_bzip2() {
    let Some(d) = data() else { return };
    // README §2.3: 88,206 points, box (-0.080, -15.103, -1.037)..(27.163, 16.463, 10.109).
    let plain = io::read_cloud(d.join("octomap_share_data/scan.dat")).unwrap();
    assert_eq!(plain.report.format, CloudFormat::Xyz);
    assert_eq!(plain.cloud.len(), 88_206);
    assert_box(
        &plain.cloud.bounding_box().unwrap(),
        [-0.080, -15.103, -1.037],
        [27.163, 16.463, 10.109],
        1e-3,
        "scan.dat",
    );
    // Ranges 0.467-29.05 m from the sensor at the origin.
    let r = plain.cloud.stats().range.unwrap();
    assert!(
        (r.min - 0.467).abs() < 1e-3 && (r.max - 29.05).abs() < 1e-2,
        "{r:?}"
    );
    let packed = io::read_cloud(d.join("octomap_share_data/scan.dat.bz2")).unwrap();
    assert_eq!(packed.report.compression, Some("bzip2"));
    assert_eq!(packed.cloud, plain.cloud);
}

#[test]
fn libpointmatcher_car_clouds() {
    let Some(d) = data() else { return };
    // README §3: counts; boxes are given to 0.01 m, so they are checked to half of that.
    let c400 = io::read_cloud(d.join("libpointmatcher_car/car_cloud400.csv")).unwrap();
    assert_eq!(c400.cloud.len(), 24_989);
    let normals = c400.cloud.normals().expect("car_cloud400 has normals");
    assert!(
        normals.iter().all(|n| (n.norm() - 1.0).abs() < 1e-3),
        "normals are unit vectors"
    );
    assert_box(
        &c400.cloud.bounding_box().unwrap(),
        [-59.57, -59.60, -10.72],
        [67.15, 71.09, 29.30],
        5e-3,
        "car_cloud400",
    );
    let c401 = io::read_cloud(d.join("libpointmatcher_car/car_cloud401.csv")).unwrap();
    assert_eq!(c401.cloud.len(), 25_193);
    assert!(c401.cloud.normals().is_none());
    assert_box(
        &c401.cloud.bounding_box().unwrap(),
        [-58.28, -63.52, -1.54],
        [64.12, 72.60, 21.10],
        5e-3,
        "car_cloud401",
    );
    // The pose list is not a point table: a typed error that names the file.
    let err = io::read_cloud(d.join("libpointmatcher_car/carCloudList.csv")).unwrap_err();
    assert!(err.to_string().contains("carCloudList.csv"), "{err}");
}

#[test]
fn octomap_scan_graph_fixture() {
    let Some(d) = data() else { return };
    // README §2.5: 101 x 101 points on a sphere of radius 4.01 m around the node at (1, 0, -0.5).
    let g = io::read_cloud(d.join("octomap_share_data/spherical_scan.graph")).unwrap();
    assert_eq!(g.report.format, CloudFormat::ScanGraph);
    assert_eq!(g.cloud.len(), 101 * 101);
    let centre = Point3::new(1.0, 0.0, -0.5);
    assert!((g.cloud.origin() - centre).norm() < 1e-12);
    for p in g.cloud.points() {
        let r = (p.cast::<f64>() - centre).norm();
        assert!((r - 4.01).abs() < 1e-3, "point at {r} m from the node");
        assert!(p.x as f64 > centre.x, "the patch is around +x");
    }
}

#[test]
fn every_cloud_file_in_the_data_folder_reads() {
    let Some(d) = data() else { return };
    let mut read = 0;
    for entry in walk(&d) {
        let name = entry.file_name().unwrap().to_string_lossy().to_string();
        let result = io::read_cloud(&entry);
        let is_cloud = matches!(
            name.as_str(),
            "scan000.3d"
                | "scan001.3d"
                | "scan002.3d"
                | "scan.dat"
                | "scan.dat.bz2"
                | "car_cloud400.csv"
                | "car_cloud401.csv"
                | "spherical_scan.graph"
        );
        match result {
            Ok(l) if is_cloud => {
                assert!(!l.cloud.is_empty());
                read += 1;
            }
            // A `.txt` of numbers (the reference pose list) is a valid XYZ file too.
            Ok(_) => {}
            Err(e) => {
                assert!(!is_cloud, "{name}: {e}");
                // Every refusal names the file.
                assert!(e.to_string().contains(&name), "{e}");
            }
        }
    }
    assert_eq!(read, 8);
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

fn assert_pose(p: &Pose, t: [f64; 3], ypr_deg: [f64; 3], tol_m: f64, tol_deg: f64, what: &str) {
    let tt = p.translation();
    let (y, pi, r) = p.yaw_pitch_roll();
    let got = [y.to_degrees(), pi.to_degrees(), r.to_degrees()];
    for i in 0..3 {
        assert!(
            (tt[i] - t[i]).abs() <= tol_m,
            "{what}: t[{i}] = {} expected {}",
            tt[i],
            t[i]
        );
        assert!(
            (got[i] - ypr_deg[i]).abs() <= tol_deg,
            "{what}: angle {i} = {} expected {}",
            got[i],
            ypr_deg[i]
        );
    }
}

#[test]
fn threedtk_frames_give_the_readme_reference_poses() {
    let Some(d) = data() else { return };
    let dir = d.join("3dtk_dat");
    // README §1.6 table (t to 1e-4 m, angles to 1e-3 degrees).
    let expected = [
        ("scan000", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        ("scan001", [1.5680, 0.0363, -0.0908], [0.715, 0.748, 0.251]),
        ("scan002", [3.3779, 0.0805, -0.1565], [0.329, 0.430, 0.137]),
    ];
    let reference = PoseList::read_path(dir.join("reference_poses_rh_m.txt")).unwrap();
    assert_eq!(reference.len(), 3);
    for (i, (scan, t, ypr)) in expected.iter().enumerate() {
        let frames = slam6d::read_frames_path(dir.join(format!("{scan}.frames"))).unwrap();
        let last = frames.last().unwrap().pose;
        assert_pose(&last, *t, *ypr, 1e-4, 1e-3, scan);
        // The reference file is the same conversion printed with six decimals.
        let r = &reference.poses[i];
        assert_eq!(r.name, format!("{i:03}"));
        let e = PoseError::between(&last, &r.pose);
        assert!(
            e.translation_m < 1e-5 && e.rotation_deg < 1e-3,
            "{scan}: {e:?}"
        );
    }
    // README §1.7: the other committed versions, including the legacy two-line layout.
    let history = [
        (
            "scan001.frames.1604b63b",
            [1.5559, 0.0480, -0.1436],
            [-0.014, -2.204, 0.455],
        ),
        (
            "scan002.frames.1604b63b",
            [3.3631, 0.0127, -0.1357],
            [0.162, -2.765, 0.301],
        ),
        (
            "scan001.frames.38966dfc",
            [1.5258, 0.0189, -0.0259],
            [0.876, 1.768, 0.308],
        ),
        (
            "scan001.frames.cf17522d",
            [1.5258, 0.0189, -0.0259],
            [0.876, 1.768, 0.308],
        ),
        (
            "scan002.frames.38966dfc",
            [3.3253, 0.0716, -0.1187],
            [0.410, 1.271, 0.046],
        ),
        (
            "scan002.frames.4cc29d4c",
            [3.3779, 0.0805, -0.1565],
            [0.329, 0.430, 0.137],
        ),
    ];
    for (file, t, ypr) in history {
        let frames = slam6d::read_frames_path(dir.join("frames_history").join(file)).unwrap();
        assert_pose(&frames.last().unwrap().pose, t, ypr, 1e-4, 1e-3, file);
    }
    let legacy =
        slam6d::read_frames_path(dir.join("frames_history/scan001.frames.38966dfc")).unwrap();
    assert_eq!(
        legacy.len(),
        88,
        "README §1.1: the legacy version holds 88 frames"
    );
}

#[test]
fn threedtk_pose_files_give_the_readme_odometry() {
    let Some(d) = data() else { return };
    // README §1.4 table.
    let expected = [
        ("scan000.pose", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        (
            "scan001.pose",
            [1.5692, 0.0311, -0.0751],
            [0.853, 1.357, 0.582],
        ),
        (
            "scan002.pose",
            [3.3797, 0.0800, -0.1535],
            [0.471, 1.113, 0.488],
        ),
    ];
    for (file, t, ypr) in expected {
        let p = slam6d::read_pose_path(d.join("3dtk_dat").join(file)).unwrap();
        assert_pose(&p, t, ypr, 1e-4, 1e-3, file);
    }
    // "scan002.pose equals the first line of scan002.frames exactly".
    let pose = slam6d::read_pose_path(d.join("3dtk_dat/scan002.pose")).unwrap();
    let first = slam6d::read_frames_path(d.join("3dtk_dat/scan002.frames")).unwrap()[0].pose;
    let e = PoseError::between(&pose, &first);
    assert!(e.translation_m < 1e-6 && e.rotation_deg < 1e-3, "{e:?}");
}

#[test]
fn car_pose_table() {
    let Some(d) = data() else { return };
    // README §3: T_400_401 t = (0.0614, 0.1914, -0.0339) m, yaw -8.853, pitch -6.510, roll -9.053 deg.
    let list = csv::read_pose_table_path(d.join("libpointmatcher_car/carCloudList.csv")).unwrap();
    assert_eq!(list.len(), 2);
    let id = list.get("car_cloud400.csv").unwrap();
    assert!(PoseError::between(id, &Pose::identity()).translation_m < 1e-12);
    let t = list.get("car_cloud401.csv").unwrap();
    assert_pose(
        t,
        [0.0614, 0.1914, -0.0339],
        [-8.853, -6.510, -9.053],
        1e-4,
        1e-3,
        "T_400_401",
    );
}
