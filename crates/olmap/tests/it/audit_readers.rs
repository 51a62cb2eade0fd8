//! Regression tests of issue 22's audit of the readers: whatever a file claims, a reader
//! allocates in proportion to the bytes it holds, stops an endless line or a decompression
//! bomb at a documented limit, and refuses values that are not what they say (a NaN
//! viewpoint, a zero angle increment), with a typed error that names what was wrong.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use olmap::cloud::LaserScan;
use olmap::error::{Error, Location, ParseError};
use olmap::io::{self, CloudFormat, ReadOptions};
use olmap::occupancy::{self, OccupancyList};

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// `copies` bzip2 streams, each of `chunk` compressed once, concatenated: a file that
/// decompresses to `copies × chunk.len()` bytes (bzip2 readers read concatenated streams,
/// as `bunzip2` does). Cheap to make however large it expands.
fn bzip2_bomb(chunk: &[u8], copies: usize) -> Vec<u8> {
    let mut enc = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::best());
    enc.write_all(chunk).unwrap();
    let stream = enc.finish().unwrap();
    stream.repeat(copies)
}

#[test]
fn audit_bzip2_bomb_is_capped() {
    let dir = tempfile::tempdir().unwrap();
    // 2 GiB of "0 0 0\n" (valid points) in about 130 KB: refused at the limit, 32 MiB.
    let points = b"0 0 0\n".repeat(1 << 20);
    let bomb = bzip2_bomb(&points, 2048 / 6);
    assert!(bomb.len() < 200_000, "{}", bomb.len());
    let p = write(dir.path(), "bomb.xyz.bz2", &bomb);
    match io::read_cloud(&p) {
        Err(Error::TooLarge { what, limit }) => {
            assert!(what.contains("bomb.xyz.bz2"), "{what}");
            assert!(
                what.contains("decompresses to more than 33554432 bytes"),
                "{what}"
            );
            assert!(
                what.contains(&format!("{} bytes compressed", bomb.len())),
                "{what}"
            );
            assert!(limit.contains("64 times the compressed size"), "{limit}");
        }
        other => panic!("{other:?}"),
    }
    // The limit can be set: the same file is refused at 1 MiB, or read whole when allowed.
    let small = bzip2_bomb(&points[..600_000], 3);
    let p = write(dir.path(), "small.xyz.bz2", &small);
    let one_mib = ReadOptions {
        max_decompressed_bytes: Some(1 << 20),
        ..Default::default()
    };
    assert!(matches!(
        io::read_cloud_with(&p, &one_mib),
        Err(Error::TooLarge { .. })
    ));
    let exact = ReadOptions {
        max_decompressed_bytes: Some(1_800_000),
        ..Default::default()
    };
    assert_eq!(
        io::read_cloud_with(&p, &exact).unwrap().cloud.len(),
        300_000
    );
    // Default rule: 64 times the compressed size, at least 32 MiB.
    assert_eq!(io::max_decompressed_bytes(0), 32 << 20);
    assert_eq!(io::max_decompressed_bytes(1 << 20), 64 << 20);
}

#[test]
fn audit_bzip2_bomb_of_zeros_stops_at_the_line_cap() {
    // 2 GiB of zero bytes in under 2 KB (one line without an end): refused at 1 MiB.
    let dir = tempfile::tempdir().unwrap();
    let bomb = bzip2_bomb(&vec![0u8; 64 << 20], 32);
    let p = write(dir.path(), "zeros.xyz.bz2", &bomb);
    match io::read_cloud(&p) {
        Err(Error::Read {
            source:
                ParseError::Invalid {
                    at: Location::Line(1),
                    reason,
                },
            ..
        }) => assert!(reason.contains("longer than 1 MiB"), "{reason}"),
        other => panic!("{other:?}"),
    }
}

/// An endless stream of `byte`s after `head`.
fn endless(head: &[u8], byte: u8) -> impl std::io::BufRead + use<'_> {
    std::io::BufReader::new(head.chain(std::io::repeat(byte)))
}

fn assert_line_cap<T: std::fmt::Debug>(what: &str, r: Result<T, ParseError>, line: usize) {
    match r {
        Err(ParseError::Invalid {
            at: Location::Line(n),
            reason,
        }) => {
            assert_eq!(n, line, "{what}: {reason}");
            assert!(reason.contains("longer than 1 MiB"), "{what}: {reason}");
        }
        other => panic!("{what}: {other:?}"),
    }
}

#[test]
fn audit_xyz_dev_zero_line_cap() {
    let options = ReadOptions {
        format: Some(CloudFormat::Xyz),
        ..Default::default()
    };
    // `olmap info --format xyz /dev/zero` used to grow one line without bound.
    if Path::new("/dev/zero").exists() {
        match io::read_cloud_with("/dev/zero", &options) {
            Err(Error::Read { path, source, .. }) => {
                assert_eq!(path, Path::new("/dev/zero"));
                assert_line_cap("/dev/zero", Err::<(), _>(source), 1);
            }
            other => panic!("{other:?}"),
        }
    }
    // Every text reader stops an endless line at the cap, at the line it is on.
    for format in [
        CloudFormat::Xyz,
        CloudFormat::Uos,
        CloudFormat::Csv,
        CloudFormat::Pcd,
        CloudFormat::Ply,
    ] {
        let head: &[u8] = match format {
            CloudFormat::Pcd => b"FIELDS x y z\nWIDTH 2\nDATA ascii\n1 2 3\n",
            CloudFormat::Ply => {
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nend_header\n1 2 3\n"
            }
            _ => b"x y z\n1 2 3\n",
        };
        let line = head.iter().filter(|&&b| b == b'\n').count() + 1;
        let r = io::read_cloud_from(endless(head, b'7'), format, &ReadOptions::default());
        assert_line_cap(format.name(), r, line);
    }
    assert_line_cap(
        "pose list",
        olmap::geometry::PoseList::read(endless(b"", b'1')),
        1,
    );
    assert_line_cap(
        "laser scan CSV",
        LaserScan::read_csv(endless(b"# olmap laser scan v1\n", b'1')),
        2,
    );
    assert_line_cap(
        "mirror log",
        olmap::scanner::MirrorLog::read(endless(b"# olmap mirror log v1\n", b' ')),
        2,
    );
    assert_line_cap(
        "3DTK .frames",
        io::slam6d::read_frames(endless(b"", b'1')),
        1,
    );
}

/// A `.bt` whose root is an inner node with a chain of inner first children down to depth
/// 7, where five children are occupied leaves at depth 8: 76 bytes that stand for
/// 5 × 2^24 = 83,886,080 voxels.
fn bt_bomb() -> Vec<u8> {
    let mut bytes = b"# Octomap OcTree binary file\nid OcTree\nsize 13\nres 0.1\ndata\n".to_vec();
    for _ in 0..7 {
        bytes.extend_from_slice(&[0x03, 0x00]); // child 0: an inner node
    }
    bytes.extend_from_slice(&[0xAA, 0x02]); // children 0-4: occupied leaves
    bytes
}

#[test]
fn audit_bt_expansion_bomb_refused() {
    let dir = tempfile::tempdir().unwrap();
    let bomb = bt_bomb();
    assert_eq!(bomb.len(), 76);
    let p = write(dir.path(), "bomb.bt", &bomb);
    match occupancy::read_map(&p) {
        Err(Error::TooLarge { what, limit }) => {
            assert!(what.contains("bomb.bt"), "{what}");
            assert!(what.contains("83886080 voxels"), "{what}");
            assert!(what.contains("5 occupied leaves"), "{what}");
            // The estimate: 10 bytes a voxel, 83,886,080 x 10 bytes = 800 MiB.
            assert!(what.contains("about 800 MiB"), "{what}");
            assert_eq!(limit, format!("{} voxels", occupancy::MAX_BT_VOXELS));
        }
        other => panic!("{other:?}"),
    }
    // One such leaf (2^24 voxels) is within the limit: OctoMap's coarse leaves still read.
    assert_eq!(occupancy::MAX_BT_VOXELS, 1 << 24);
}

#[test]
fn audit_bt_real_map_still_reads_through_read_map() {
    let Some(d) = crate::data() else { return };
    let loaded = occupancy::read_map(d.join("octomap_share_data/geb079.bt")).unwrap();
    // Data README §2.4: 137,745 leaves at 0.08 m, 5,983 at 0.16 m, 1 at 0.32 m.
    assert_eq!(loaded.map.len(), 137_745 + 5_983 * 8 + 64);
    assert_eq!(loaded.map.resolution(), 0.08);
}

#[test]
fn audit_counts_claimed_by_headers_allocate_nothing() {
    // Each header claims 10^12 (or 2^32 - 1) records above a few bytes: the reader runs
    // out of bytes and says so, without reserving memory for the claim.
    let ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n\
                property float x\nproperty float y\nproperty float z\nend_header\n0123456789ab";
    let r = io::read_cloud_from(&ply[..], CloudFormat::Ply, &ReadOptions::default());
    assert!(matches!(r, Err(ParseError::Truncated(_))), "{r:?}");
    let ply_ascii = b"ply\nformat ascii 1.0\nelement vertex 1000000000000\n\
                property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let r = io::read_cloud_from(&ply_ascii[..], CloudFormat::Ply, &ReadOptions::default());
    assert!(matches!(r, Err(ParseError::Truncated(_))), "{r:?}");
    // ScanGraph: one node claiming 2^32 - 1 points, one point present.
    let mut graph = 1u32.to_le_bytes().to_vec();
    graph.extend_from_slice(&u32::MAX.to_le_bytes());
    graph.extend_from_slice(&3i32.to_le_bytes());
    for v in [1.0f64, 2.0, 3.0] {
        graph.extend_from_slice(&v.to_le_bytes());
    }
    match io::scan_graph::read(&graph[..]) {
        Err(ParseError::Truncated(m)) => {
            assert!(
                m.contains("4294967295 points") && m.contains("point 1"),
                "{m}"
            )
        }
        other => panic!("{other:?}"),
    }
    // .olm: 10^12 voxels announced, three keys present.
    let mut olm = occupancy::OLM_MAGIC.to_vec();
    olm.extend_from_slice(&1u32.to_le_bytes());
    olm.extend_from_slice(&0.1f64.to_le_bytes());
    olm.extend_from_slice(&1_000_000_000_000u64.to_le_bytes());
    olm.extend_from_slice(&[1, 1, 1]);
    match OccupancyList::read_olm(&olm[..]) {
        Err(ParseError::Truncated(m)) => assert!(m.contains("key"), "{m}"),
        other => panic!("{other:?}"),
    }
    // .olm version 2 (chunks of 1024 voxels, a checksum over the header): 10^12 voxels
    // announced, the file ends after the header.
    let mut olm = occupancy::OLM_MAGIC.to_vec();
    olm.extend_from_slice(&2u32.to_le_bytes());
    olm.extend_from_slice(&0.1f64.to_le_bytes());
    olm.extend_from_slice(&1_000_000_000_000u64.to_le_bytes());
    olm.extend_from_slice(&1024u32.to_le_bytes());
    let crc = olmap::file::crc32::crc32(&olm);
    olm.extend_from_slice(&crc.to_le_bytes());
    match OccupancyList::read_olm(&olm[..]) {
        Err(ParseError::Truncated(m)) => {
            assert!(m.contains("byte 36") && m.contains("chunk length"), "{m}")
        }
        other => panic!("{other:?}"),
    }
    // Its first chunk claims 20 KiB but the file ends 3 bytes into it.
    olm.extend_from_slice(&20_000u32.to_le_bytes());
    olm.extend_from_slice(&[1, 1, 1]);
    match OccupancyList::read_olm(&olm[..]) {
        Err(ParseError::Invalid {
            at: Location::Byte(36),
            reason,
        }) => assert!(
            reason.contains("chunk 0") && reason.contains("runs past the end"),
            "{reason}"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn audit_olm_and_scan_graph_readers_stream() {
    // They used to read the whole stream before looking at it: an endless one never
    // ended. Now a bad header stops them at once, whatever follows.
    match OccupancyList::read_olm(endless(b"NOT AN OLM FILE", 0)) {
        Err(ParseError::Invalid {
            at: Location::Byte(0),
            reason,
        }) => assert!(reason.contains("magic"), "{reason}"),
        other => panic!("{other:?}"),
    }
    // A ScanGraph node whose first point has the wrong size tag (2, not 3), at byte 8.
    let mut graph = 1u32.to_le_bytes().to_vec();
    graph.extend_from_slice(&5u32.to_le_bytes());
    graph.extend_from_slice(&2i32.to_le_bytes());
    match io::scan_graph::read(endless(&graph, 0)) {
        Err(ParseError::Invalid {
            at: Location::Byte(8),
            reason,
        }) => assert!(reason.contains("size tag 3"), "{reason}"),
        other => panic!("{other:?}"),
    }
    // Damage after the end of a map is found by streaming too (the checksum covers it).
    // The fixture's extreme points (3.4e38 m) have no voxel key: `add_points` skips them.
    let mut map = OccupancyList::new(0.5).unwrap();
    map.add_points(
        &crate::round_trip::synthetic_cloud(200),
        &olmap::geometry::Pose::identity(),
        1,
    );
    let mut bytes = Vec::new();
    map.write_olm(&mut bytes).unwrap();
    assert_eq!(OccupancyList::read_olm(&bytes[..]).unwrap(), map);
    let end = bytes.len() as u64;
    bytes.extend_from_slice(b"tail");
    match OccupancyList::read_olm(&bytes[..]) {
        Err(ParseError::Invalid {
            at: Location::Byte(b),
            reason,
        }) => {
            assert_eq!(b, end);
            assert!(reason.contains("4 unexpected bytes"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

fn pcd_with_viewpoint(viewpoint: &str) -> String {
    format!("FIELDS x y z\nWIDTH 1\nVIEWPOINT {viewpoint}\nDATA ascii\n1 2 3\n")
}

#[test]
fn audit_pcd_nan_viewpoint_refused() {
    for vp in ["nan 0 0 1 0 0 0", "0 inf 0 1 0 0 0", "0 0 0 1 nan 0 0"] {
        let text = pcd_with_viewpoint(vp);
        match io::pcd::read(text.as_bytes()) {
            Err(ParseError::Invalid {
                at: Location::Line(3),
                reason,
            }) => {
                assert!(
                    reason.contains("VIEWPOINT") && reason.contains("finite"),
                    "{reason}"
                )
            }
            other => panic!("{vp}: {other:?}"),
        }
    }
    // A valid viewpoint is the cloud's origin.
    let loaded = io::pcd::read(pcd_with_viewpoint("1 2 3 0 0 0 1").as_bytes()).unwrap();
    assert_eq!(loaded.cloud.origin(), nalgebra::Point3::new(1.0, 2.0, 3.0));
}

#[test]
fn audit_pcd_zero_quaternion_refused() {
    match io::pcd::read(pcd_with_viewpoint("1 2 3 0 0 0 0").as_bytes()) {
        Err(ParseError::Invalid {
            at: Location::Line(3),
            reason,
        }) => assert!(
            reason.contains("VIEWPOINT")
                && reason.contains("quaternion")
                && reason.contains("zero"),
            "{reason}"
        ),
        other => panic!("{other:?}"),
    }
}

#[test]
fn audit_laser_scan_bad_parameters_refused() {
    let csv = |params: &str, rows: &str| {
        format!(
            "# olmap laser scan v1\nangle_min,angle_increment,range_min,range_max,time\n\
             {params}\nrange\n{rows}"
        )
    };
    let cases = [
        ("-1.5,0,0,8,0", "angle_increment must not be 0"),
        ("-1.5,NaN,0,8,0", "angle_increment must be a finite number"),
        ("-1.5,0.1,0,NaN,0", "range_max must be above range_min"),
        ("-1.5,0.1,2,1,0", "range_max must be above range_min"),
        ("-1.5,0.1,-1,8,0", "range_min must be >= 0"),
        ("inf,0.1,0,8,0", "angle_min must be a finite number"),
        ("-1.5,0.1,0,8,nan", "time must be a finite number"),
    ];
    for (params, needle) in cases {
        match LaserScan::read_csv(csv(params, "1.0\n").as_bytes()) {
            Err(ParseError::Invalid {
                at: Location::Line(3),
                reason,
            }) => assert!(reason.contains(needle), "{params}: {reason}"),
            other => panic!("{params}: {other:?}"),
        }
    }
    match LaserScan::read_csv(csv("-1.5,0.1,0,8,0", "1.0\ninf\n-0.5\n").as_bytes()) {
        Err(ParseError::Invalid {
            at: Location::Line(7),
            reason,
        }) => assert!(reason.contains("beam 2 is -0.5"), "{reason}"),
        other => panic!("{other:?}"),
    }
    // Negative increments (clockwise scanners), infinite range_max and NaN ranges are fine.
    let ok = LaserScan::read_csv(csv("1.5,-0.1,0,inf,0", "1.0\nNaN\ninf\n").as_bytes()).unwrap();
    assert_eq!(ok.len(), 3);
    assert!(ok.validate().is_ok());
    // JSON: the same checks.
    let json = |inc: &str, max: &str, ranges: &str| {
        format!(
            "{{\"angle_min\": 0, \"angle_increment\": {inc}, \"range_min\": 0, \
             \"range_max\": {max}, \"ranges\": [{ranges}]}}"
        )
    };
    for (text, needle) in [
        (json("0", "8", "1"), "angle_increment must not be 0"),
        (json("0.1", "8", "1, -2"), "beam 1 is -2"),
        (json("0.1", "-1", "1"), "range_max must be above range_min"),
    ] {
        match LaserScan::read_json(text.as_bytes()) {
            Err(ParseError::Malformed(m)) => assert!(m.contains(needle), "{text}: {m}"),
            other => panic!("{text}: {other:?}"),
        }
    }
    assert!(LaserScan::read_json(json("0.1", "null", "1, null").as_bytes()).is_ok());
}

#[test]
fn audit_json_messages_say_the_location_once() {
    // serde's messages end with "at line L column C"; the error names the line already.
    let text = "{\"angle_min\": 0,\n \"angle_increment\": x}";
    let e = LaserScan::read_json(text.as_bytes())
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("line 2: column 21: invalid JSON"), "{e}");
    assert_eq!(e.matches("line 2").count(), 1, "{e}");
    assert!(
        !e.contains("column 21 column") && e.matches("column").count() == 1,
        "{e}"
    );
}

#[test]
fn audit_error_chain_says_each_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "bad.xyz", b"1 2 3\nfoo\n");
    let e = io::read_cloud(&p).unwrap_err();
    let mut chain: Vec<&(dyn std::error::Error + 'static)> = vec![&e];
    while let Some(next) = chain.last().unwrap().source() {
        chain.push(next);
    }
    // The error returns its cause as its source and names it too: printed as a chain
    // (anyhow's `{:#}`, as the CLI did) the reason came twice.
    assert!(chain.len() >= 2);
    let message = olmap::error::chain_message(chain);
    assert_eq!(message.matches("line 2").count(), 1, "{message}");
    assert!(message.ends_with("line 2: expected at least three numbers 'x y z', found 'foo'"));
}

#[test]
fn audit_pcd_ascii_huge_count_is_refused() {
    // Found by the fuzzer: `COUNT 1 1 1000000000` made the ascii reader list a billion
    // value slots (4 GiB) before reading a line. No line of 1 MiB holds that many values.
    let text = "FIELDS x y z\nCOUNT 1 1 1000000000\nWIDTH 1\nDATA ascii\n1 2 3\n";
    match io::pcd::read(text.as_bytes()) {
        Err(ParseError::Invalid {
            at: Location::Line(4),
            reason,
        }) => assert!(reason.contains("1000000002 values per point"), "{reason}"),
        other => panic!("{other:?}"),
    }
    // The largest count that fits still reads (here a line of 2 + 262,142 values).
    let n = (1 << 19) - 2;
    let mut text = format!("FIELDS x y z\nCOUNT 1 1 {n}\nWIDTH 1\nDATA ascii\n1 2");
    text.push_str(&" 3".repeat(n));
    text.push('\n');
    assert_eq!(io::pcd::read(text.as_bytes()).unwrap().cloud.len(), 1);
}

#[test]
fn audit_whole_file_readers_are_bounded() {
    // The scan list of `olmap map --list` and a ROS map's YAML were read whole with
    // read_to_string / fs::read: a device or a huge file grew memory without bound.
    let dir = tempfile::tempdir().unwrap();
    let mut long = b"scan000.pcd\n".to_vec();
    long.extend(std::iter::repeat_n(b'a', (1 << 20) + 10));
    let list = write(dir.path(), "scans.txt", &long);
    match io::scan_files(&[], Some(&list)) {
        Err(Error::Read {
            format: "scan list",
            source:
                ParseError::Invalid {
                    at: Location::Line(2),
                    reason,
                },
            ..
        }) => assert!(reason.contains("longer than 1 MiB"), "{reason}"),
        other => panic!("{other:?}"),
    }
    let ok = write(dir.path(), "ok.txt", b"# scans\na.pcd\n\n  b.pcd  \n");
    let files = io::scan_files(&[], Some(&ok)).unwrap();
    assert_eq!(files, [dir.path().join("a.pcd"), dir.path().join("b.pcd")]);
    let yaml = write(dir.path(), "map.yaml", &vec![b'#'; (1 << 20) + 1]);
    match olmap::grid2d::read_ros_map(&yaml) {
        Err(Error::TooLarge { what, limit }) => {
            assert!(
                what.contains("map.yaml") && what.contains("ROS map YAML"),
                "{what}"
            );
            assert_eq!(limit, "1048576 bytes");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn audit_pcd_lzf_error_names_the_byte_once() {
    // Found by the fuzzer: "byte 261: binary_compressed: LZF back-reference at byte 261
    // ...", two offsets in one message, of the file and of the LZF block. Now one place:
    // the byte of the bad instruction in the file.
    let head = "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA binary_compressed\n";
    let mut bytes = head.as_bytes().to_vec();
    bytes.extend_from_slice(&4u32.to_le_bytes()); // compressed size
    bytes.extend_from_slice(&12u32.to_le_bytes()); // uncompressed size
                                                   // A literal of one byte, then a 3-byte reference 6 bytes back: only 1 byte exists.
    bytes.extend_from_slice(&[0x00, b'a', 0x20, 0x05]);
    match io::pcd::read(&bytes[..]) {
        Err(ParseError::Invalid {
            at: Location::Byte(b),
            reason,
        }) => {
            assert_eq!(b, head.len() as u64 + 8 + 2);
            assert!(reason.contains("reaches 6 bytes back"), "{reason}");
            assert!(!reason.contains("byte "), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}
