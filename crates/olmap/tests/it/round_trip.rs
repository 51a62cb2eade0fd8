//! Every writer followed by its reader gives the same points back (bit-exact for the binary
//! encodings and for text written in shortest round-trip form).

use nalgebra::{Point3, Vector3};
use olmap::cloud::PointCloud;
use olmap::io::{self, CloudFormat, PcdEncoding, PlyEncoding, WriteOptions};

use crate::data;

/// A deterministic cloud with every attribute, awkward values included (tiny, huge,
/// negative zero, subnormal).
pub fn synthetic_cloud(n: usize) -> PointCloud {
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut pts = Vec::with_capacity(n);
    let mut inten = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut colors = Vec::with_capacity(n);
    for i in 0..n {
        let p = match i {
            0 => Point3::new(-0.0, 1e-40, 3.4e38),
            1 => Point3::new(1e-7, -123_456.79, 0.1),
            _ => Point3::new(
                (next() * 200.0 - 100.0) as f32,
                (next() * 200.0 - 100.0) as f32,
                (next() * 20.0 - 5.0) as f32,
            ),
        };
        pts.push(p);
        inten.push((next() * 1000.0) as f32);
        let n = Vector3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize();
        normals.push(n.cast::<f32>());
        colors.push([
            (next() * 255.0) as u8,
            (next() * 255.0) as u8,
            (next() * 255.0) as u8,
        ]);
    }
    let mut c = PointCloud::from_points(pts).with_origin(Point3::new(0.25, -1.5, 0.75));
    c.set_intensity(Some(inten)).unwrap();
    c.set_normals(Some(normals)).unwrap();
    c.set_colors(Some(colors)).unwrap();
    c
}

fn write_read(cloud: &PointCloud, file: &str, options: WriteOptions) -> PointCloud {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(file);
    io::write_cloud(&path, cloud, &options).unwrap();
    io::read_cloud(&path).unwrap().cloud
}

fn attributes_dropped(c: &PointCloud) -> PointCloud {
    PointCloud::from_points(c.points().to_vec())
}

#[test]
fn full_attribute_formats_are_exact() {
    let cloud = synthetic_cloud(5000);
    for enc in [
        PcdEncoding::Ascii,
        PcdEncoding::Binary,
        PcdEncoding::BinaryCompressed,
    ] {
        let opts = WriteOptions {
            pcd_encoding: enc,
            ..Default::default()
        };
        assert_eq!(write_read(&cloud, "a.pcd", opts), cloud, "PCD {enc:?}");
    }
    for enc in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
        let opts = WriteOptions {
            ply_encoding: enc,
            ..Default::default()
        };
        assert_eq!(write_read(&cloud, "a.ply", opts), cloud, "PLY {enc:?}");
    }
    // CSV keeps every attribute but not the sensor origin.
    let back = write_read(&cloud, "a.csv", WriteOptions::default());
    assert_eq!(back, cloud.clone().with_origin(Point3::origin()));
}

#[test]
fn position_formats_are_exact() {
    let cloud = synthetic_cloud(3000);
    let xyz = write_read(&cloud, "a.xyz", WriteOptions::default());
    assert_eq!(xyz, attributes_dropped(&cloud));
    let kitti = write_read(&cloud, "a.bin", WriteOptions::default());
    assert_eq!(kitti.points(), cloud.points());
    assert_eq!(kitti.intensity(), cloud.intensity());
    // 3DTK stores centimetres in another frame, ScanGraph doubles relative to the origin:
    // exact to float rounding.
    for file in ["a.3d", "a.graph"] {
        let back = write_read(&cloud, file, WriteOptions::default());
        assert_eq!(back.len(), cloud.len());
        for (a, b) in cloud.points().iter().zip(back.points()) {
            let tol = 1e-6 * (1.0 + a.coords.norm());
            assert!((a - b).norm() <= tol, "{file}: {a} vs {b}");
        }
    }
}

#[test]
fn real_scan_survives_every_format() {
    let Some(d) = data() else { return };
    let scan = io::read_cloud(d.join("3dtk_dat/scan000.3d")).unwrap().cloud;
    for format in CloudFormat::ALL {
        let file = format!("scan.{}", format.extensions()[0]);
        let back = write_read(&scan, &file, WriteOptions::default());
        assert_eq!(back.len(), scan.len(), "{format}");
        match format {
            CloudFormat::Uos => {}
            // LAS stores whole millimetres: half of one, plus the f32 spacing.
            CloudFormat::Las => {
                for (a, b) in scan.points().iter().zip(back.points()) {
                    let tol = 0.0005 + 1e-7 * (1.0 + a.coords.abs().max());
                    assert!((a - b).abs().max() <= tol, "{format}: {a} vs {b}");
                }
            }
            _ => assert_eq!(back.points(), scan.points(), "{format}"),
        }
    }
}

#[test]
fn failed_write_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("keep.xyz");
    std::fs::write(&target, "1 2 3\n").unwrap();
    let err = olmap::file::write_atomic(&target, "XYZ text", |w| {
        use std::io::Write;
        w.write_all(b"4 5 6\n")?;
        Err(std::io::Error::other("disk full (simulated)"))
    })
    .unwrap_err();
    assert!(err.to_string().contains("keep.xyz"), "{err}");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "1 2 3\n");
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "temporary file left behind: {names:?}");
    // A file in a folder that does not exist: an error naming it, nothing created.
    let missing = dir.path().join("no/such/dir/out.pcd");
    let err = io::write_cloud(&missing, &synthetic_cloud(3), &WriteOptions::default()).unwrap_err();
    assert!(err.to_string().contains("out.pcd"), "{err}");
}
