//! Read throughput of every point-cloud format (MB/s and points/s).
//!
//! `cargo bench -p olmap --bench io_read`. Synthetic: one million points with intensity,
//! encoded in memory in each format and parsed from memory (no disk in the loop). Real: the
//! shared data files read from disk (page cache warm after the first sample).

use std::sync::OnceLock;

use divan::counter::{BytesCount, ItemsCount};
use divan::Bencher;
use nalgebra::Point3;
use olmap::cloud::PointCloud;
use olmap::io::{self, CloudFormat, PcdEncoding, PlyEncoding, ReadOptions, WriteOptions};

fn main() {
    divan::main();
}

const POINTS: usize = 1_000_000;

const CASES: [&str; 10] = [
    "pcd_ascii",
    "pcd_binary",
    "pcd_binary_compressed",
    "ply_ascii",
    "ply_binary_le",
    "xyz",
    "uos_3d",
    "csv",
    "kitti_bin",
    "scan_graph",
];

fn lidar_like_cloud() -> PointCloud {
    // A deterministic spinning-lidar-like cloud: 64 rings, ranges 1-60 m.
    let mut pts = Vec::with_capacity(POINTS);
    let mut inten = Vec::with_capacity(POINTS);
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    for i in 0..POINTS {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        let u = (s >> 11) as f64 / (1u64 << 53) as f64;
        let az = (i % 15_625) as f64 / 15_625.0 * std::f64::consts::TAU;
        let el = ((i / 15_625) as f64 / 64.0 * 40.0 - 30.0).to_radians();
        let r = 1.0 + 59.0 * u;
        pts.push(Point3::new(
            (r * el.cos() * az.cos()) as f32,
            (r * el.cos() * az.sin()) as f32,
            (r * el.sin()) as f32,
        ));
        inten.push((u * 255.0) as f32);
    }
    let mut c = PointCloud::from_points(pts);
    c.set_intensity(Some(inten)).unwrap();
    c
}

/// A case name with its format and the encoded bytes.
type Encoded = (String, (CloudFormat, Vec<u8>));

fn encoded(case: &str) -> &'static (CloudFormat, Vec<u8>) {
    static ALL: OnceLock<Vec<Encoded>> = OnceLock::new();
    let all = ALL.get_or_init(|| {
        let cloud = lidar_like_cloud();
        CASES
            .iter()
            .map(|&name| {
                let mut opts = WriteOptions::default();
                let format = match name {
                    "pcd_ascii" => {
                        opts.pcd_encoding = PcdEncoding::Ascii;
                        CloudFormat::Pcd
                    }
                    "pcd_binary" => CloudFormat::Pcd,
                    "pcd_binary_compressed" => {
                        opts.pcd_encoding = PcdEncoding::BinaryCompressed;
                        CloudFormat::Pcd
                    }
                    "ply_ascii" => {
                        opts.ply_encoding = PlyEncoding::Ascii;
                        CloudFormat::Ply
                    }
                    "ply_binary_le" => CloudFormat::Ply,
                    "xyz" => CloudFormat::Xyz,
                    "uos_3d" => CloudFormat::Uos,
                    "csv" => CloudFormat::Csv,
                    "kitti_bin" => CloudFormat::KittiBin,
                    "scan_graph" => CloudFormat::ScanGraph,
                    other => unreachable!("{other}"),
                };
                let mut buf = Vec::new();
                io::write_cloud_to(&mut buf, &cloud, format, &opts).unwrap();
                (name.to_string(), (format, buf))
            })
            .collect()
    });
    &all.iter().find(|(n, _)| n == case).unwrap().1
}

/// Parse one million points from memory.
#[divan::bench(args = CASES, sample_count = 5, sample_size = 1)]
fn synthetic_1m(bencher: Bencher, case: &str) {
    let (format, bytes) = encoded(case);
    bencher
        .counter(BytesCount::new(bytes.len()))
        .counter(ItemsCount::new(POINTS))
        .bench(|| io::read_cloud_from(&bytes[..], *format, &ReadOptions::default()).unwrap());
}

const REAL: [&str; 5] = [
    "3dtk_dat/scan000.3d",
    "octomap_share_data/scan.dat",
    "octomap_share_data/scan.dat.bz2",
    "libpointmatcher_car/car_cloud400.csv",
    "octomap_share_data/spherical_scan.graph",
];

/// Read the real data files from disk.
#[divan::bench(args = REAL, sample_count = 10, sample_size = 1)]
fn real_file(bencher: Bencher, file: &str) {
    let Some(dir) = olmap::test_data::dir() else {
        return;
    };
    let path = dir.join(file);
    let bytes = std::fs::metadata(&path).unwrap().len() as usize;
    let points = io::read_cloud(&path).unwrap().report.records as usize;
    bencher
        .counter(BytesCount::new(bytes))
        .counter(ItemsCount::new(points))
        .bench(|| io::read_cloud(&path).unwrap());
}

/// Baseline for the binary readers: copying the binary PCD bytes into a new buffer (the
/// least any reader that returns owned points must do).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn baseline_copy_pcd_binary_bytes(bencher: Bencher) {
    let (_, bytes) = encoded("pcd_binary");
    bencher
        .counter(BytesCount::new(bytes.len()))
        .counter(ItemsCount::new(POINTS))
        .bench(|| bytes.to_vec());
}

/// Baseline for the text readers: parsing the XYZ text's numbers with `str::parse::<f64>`
/// and nothing else (no line handling, no cloud).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn baseline_parse_xyz_numbers(bencher: Bencher) {
    let (_, bytes) = encoded("xyz");
    let text = std::str::from_utf8(bytes).unwrap();
    bencher
        .counter(BytesCount::new(bytes.len()))
        .counter(ItemsCount::new(POINTS))
        .bench(|| {
            text.split_ascii_whitespace()
                .map(|t| t.parse::<f64>().unwrap())
                .sum::<f64>()
        });
}

#[cfg(feature = "bag")]
/// A one-million-point `PointCloud2` message (x y z float32 + 4 bytes padding, the common
/// driver layout), CDR-encoded.
fn point_cloud2_message(with_intensity: bool) -> &'static [u8] {
    use olmap::io::bag::messages::{Header, PointCloud2, PointField};
    static PLAIN: OnceLock<Vec<u8>> = OnceLock::new();
    static INTENSITY: OnceLock<Vec<u8>> = OnceLock::new();
    let cell = if with_intensity { &INTENSITY } else { &PLAIN };
    cell.get_or_init(|| {
        let cloud = lidar_like_cloud();
        let mut data = Vec::with_capacity(16 * POINTS);
        for (k, p) in cloud.points().iter().enumerate() {
            for v in [p.x, p.y, p.z, cloud.intensity().map_or(0.0, |i| i[k])] {
                data.extend_from_slice(&v.to_le_bytes());
            }
        }
        let mut names = vec!["x", "y", "z"];
        if with_intensity {
            names.push("intensity");
        }
        PointCloud2 {
            header: Header::default(),
            height: 1,
            width: POINTS as u32,
            fields: names
                .iter()
                .enumerate()
                .map(|(k, n)| PointField {
                    name: (*n).into(),
                    offset: 4 * k as u32,
                    datatype: 7,
                    count: 1,
                })
                .collect(),
            is_bigendian: false,
            point_step: 16,
            row_step: 16 * POINTS as u32,
            data: &data,
            is_dense: true,
        }
        .encode()
    })
}

#[cfg(feature = "bag")]
/// `PointCloud2` decoding from memory on one core: the CDR message to an olmap cloud
/// (`x y z` float32, the fast path; and with `intensity`, the general path).
#[divan::bench(args = [false, true], sample_count = 10, sample_size = 1)]
fn point_cloud2_1m(bencher: Bencher, with_intensity: bool) {
    use olmap::io::bag::{messages::PointCloud2, pointcloud2::decode_points};
    let bytes = point_cloud2_message(with_intensity);
    bencher
        .counter(BytesCount::new(bytes.len()))
        .counter(ItemsCount::new(POINTS))
        .bench(|| decode_points(&PointCloud2::decode(bytes).unwrap()).unwrap());
}

#[cfg(feature = "bag")]
/// `olmap bag extract` of the shared `ros2_bags/3dtk_points` bag (3 scans, 234k points,
/// odometry, to a temporary folder).
#[divan::bench(sample_count = 5, sample_size = 1)]
fn bag_extract_3dtk_points(bencher: Bencher) {
    use olmap::io::bag::{write_extraction, Bag, ExtractOptions};
    let Some(dir) = olmap::test_data::dir() else {
        return;
    };
    let bag = Bag::open(dir.join("ros2_bags/3dtk_points")).unwrap();
    let out = tempfile::tempdir().unwrap();
    bencher.bench(|| write_extraction(&bag, &ExtractOptions::default(), out.path()).unwrap());
}
