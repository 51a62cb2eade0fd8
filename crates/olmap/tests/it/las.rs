//! LAS/LAZ on the shared real data (data README §7, `las/`): every file reads, LAS and LAZ
//! agree, the local origin keeps millimetres at 10⁵-10⁶ m, olmap's LAS round trip is
//! exact, and lying or cut files are typed errors.

use std::path::{Path, PathBuf};

use olmap::io::{self, CloudFormat, LoadedCloud, ReadOptions, WriteOptions};
use olmap::{Error, ParseError};

const FILES: [&str; 5] = [
    "autzen.las",
    "autzen.laz",
    "autzen.copc.laz",
    "extrabytes.laz",
    "32-1-472-150-76.laz",
];

fn las_dir() -> Option<PathBuf> {
    crate::data().map(|d| d.join("las"))
}

fn read(path: &Path) -> LoadedCloud {
    io::read_cloud(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The file's coordinates in double precision and its header's point count, read with the
/// `las` crate alone (no olmap code).
fn reference(path: &Path) -> (Vec<[f64; 3]>, u64) {
    let mut reader = las::Reader::from_path(path).unwrap();
    let n = reader.header().number_of_points();
    let data = reader.read_all().unwrap();
    let xyz = data
        .x()
        .zip(data.y())
        .zip(data.z())
        .map(|((x, y), z)| [x, y, z])
        .collect();
    (xyz, n)
}

/// The parse error inside a read error.
fn parse_error(e: Error) -> ParseError {
    match e {
        Error::Read { source, .. } => source,
        e => panic!("expected a read error, got {e}"),
    }
}

#[test]
fn every_file_reads_all_its_points() {
    let Some(dir) = las_dir() else { return };
    for name in FILES {
        let path = dir.join(name);
        let loaded = read(&path);
        let (xyz, n) = reference(&path);
        assert_eq!(loaded.report.format, CloudFormat::Las, "{name}");
        assert!(n > 0, "{name}");
        assert_eq!(xyz.len() as u64, n, "{name}");
        assert_eq!(loaded.report.records, n, "{name}");
        assert_eq!(loaded.report.dropped_non_finite, 0, "{name}");
        assert_eq!(loaded.cloud.len() as u64, n, "{name}");
        assert_eq!(loaded.cloud.intensity().map(<[f32]>::len), Some(n as usize));
        let kind = if name.ends_with(".laz") { "LAZ" } else { "LAS" };
        assert!(
            loaded.report.encoding.starts_with(kind),
            "{name}: {}",
            loaded.report.encoding
        );
        assert!(loaded.report.local_origin.is_some(), "{name}");
    }
    // The data README: the tile holds 5,658 points; autzen.las 106 (same in the LAZ).
    assert_eq!(read(&dir.join("32-1-472-150-76.laz")).cloud.len(), 5658);
    let copc = read(&dir.join("autzen.copc.laz"));
    assert_eq!(copc.report.encoding, "LAZ 1.4, point format 7, COPC");
}

#[test]
fn fields_name_what_the_point_format_declares() {
    let Some(dir) = las_dir() else { return };
    // autzen.las: point format 1 (GPS time, no colour); autzen.laz: format 3 (with colour).
    let las = read(&dir.join("autzen.las"));
    assert!(las.report.fields.iter().any(|f| f == "gps_time"));
    assert!(las.cloud.colors().is_none());
    let laz = read(&dir.join("autzen.laz"));
    assert!(laz.report.fields.iter().any(|f| f == "red"));
    assert!(laz.cloud.colors().is_some());
    // extrabytes.laz: 61-byte records, 27 bytes beyond format 3's 34, named in its VLR.
    let eb = read(&dir.join("extrabytes.laz"));
    let reader = las::Reader::from_path(dir.join("extrabytes.laz")).unwrap();
    assert_eq!(reader.header().point_format().extra_bytes, 61 - 34);
    // The five attributes its Extra Bytes VLR describes, by name.
    let standard = laz.report.fields.len();
    assert_eq!(
        eb.report.fields[standard..],
        ["Colors", "Reserved", "Flags", "Intensity", "Time"]
    );
}

#[test]
fn autzen_las_and_laz_hold_the_same_points() {
    let Some(dir) = las_dir() else { return };
    let las = read(&dir.join("autzen.las"));
    let laz = read(&dir.join("autzen.laz"));
    assert_eq!(las.cloud.len(), 106);
    assert_eq!(las.report.local_origin, laz.report.local_origin);
    assert_eq!(las.cloud.len(), laz.cloud.len());
    for (a, b) in las.cloud.points().iter().zip(laz.cloud.points()) {
        assert_eq!(
            [a.x.to_bits(), a.y.to_bits(), a.z.to_bits()],
            [b.x.to_bits(), b.y.to_bits(), b.z.to_bits()]
        );
    }
    assert_eq!(las.cloud.intensity(), laz.cloud.intensity());
}

#[test]
fn the_local_origin_keeps_millimetres_far_from_the_frame_origin() {
    let Some(dir) = las_dir() else { return };
    // autzen: x ≈ 637,000, y ≈ 851,000 (state plane); the tile: y ≈ 6,724,000 (UTM).
    for name in ["autzen.las", "autzen.copc.laz", "32-1-472-150-76.laz"] {
        let path = dir.join(name);
        let loaded = read(&path);
        let (xyz, _) = reference(&path);
        let origin = loaded.report.local_origin.unwrap();
        assert!(
            xyz.iter().all(|p| p[0].abs().max(p[1].abs()) > 300_000.0),
            "{name} should be far from its frame's origin"
        );
        let mut worst = 0.0f64;
        for (p, q) in loaded.cloud.points().iter().zip(&xyz) {
            let back = [
                origin[0] + f64::from(p.x),
                origin[1] + f64::from(p.y),
                origin[2] + f64::from(p.z),
            ];
            for k in 0..3 {
                worst = worst.max((back[k] - q[k]).abs());
            }
        }
        // The files' scale is 0.01: a millimetre is a tenth of their resolution. (Without the
        // local origin, f32 at 6,724,186 m is 0.5 m coarse.)
        assert!(worst < 0.001, "{name}: worst error {worst} m");
    }
}

#[test]
fn olmap_las_round_trip_is_exact() {
    let Some(dir) = las_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    for name in ["autzen.las", "32-1-472-150-76.laz"] {
        let first = read(&dir.join(name));
        for out in ["again.las", "again.laz"] {
            let out = tmp.path().join(out);
            let options = WriteOptions {
                las_local_origin: first.report.local_origin,
                ..Default::default()
            };
            io::write_cloud(&out, &first.cloud, &options).unwrap();
            let second = read(&out);
            let compressed = out.extension().unwrap() == "laz";
            assert_eq!(second.report.encoding.starts_with("LAZ"), compressed);
            assert_eq!(second.report.local_origin, first.report.local_origin);
            assert_eq!(
                second.cloud.points(),
                first.cloud.points(),
                "{name} -> {out:?}"
            );
            assert_eq!(second.cloud.intensity(), first.cloud.intensity());
            // The written file keeps the input's frame: the same coordinates as the original.
            let (a, _) = reference(&dir.join(name));
            let (b, _) = reference(&out);
            for (p, q) in a.iter().zip(&b) {
                for k in 0..3 {
                    assert!((p[k] - q[k]).abs() < 1e-6, "{p:?} {q:?}");
                }
            }
        }
    }
}

#[test]
fn the_signature_wins_over_the_extension() {
    let Some(dir) = las_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let renamed = tmp.path().join("autzen.dat");
    std::fs::copy(dir.join("autzen.las"), &renamed).unwrap();
    assert_eq!(read(&renamed).cloud.len(), 106);
    // Streams too (LAZ is read into memory first).
    let bytes = std::fs::read(dir.join("autzen.laz")).unwrap();
    let loaded =
        io::read_cloud_from(&bytes[..], CloudFormat::Las, &ReadOptions::default()).unwrap();
    assert_eq!(loaded.cloud, read(&dir.join("autzen.laz")).cloud);
}

#[test]
fn cut_and_lying_files_are_typed_errors() {
    let Some(dir) = las_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let las = std::fs::read(dir.join("autzen.las")).unwrap();
    let laz = std::fs::read(dir.join("autzen.laz")).unwrap();
    let copc = std::fs::read(dir.join("autzen.copc.laz")).unwrap();
    let read_bytes = |name: &str, bytes: &[u8]| {
        let path = tmp.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        io::read_cloud(&path).map(|l| l.cloud.len())
    };
    // Cut anywhere: inside the header, the VLRs, the points.
    for cut in [10, 200, 1000, 1994 + 5, las.len() - 1] {
        let e = parse_error(read_bytes("cut.las", &las[..cut]).unwrap_err());
        assert!(matches!(e, ParseError::Truncated(_)), "cut at {cut}: {e}");
    }
    for cut in [100, 700, laz.len() / 2] {
        assert!(read_bytes("cut.laz", &laz[..cut]).is_err(), "cut at {cut}");
    }
    // 4,294,967,295 points announced (the LAS 1.2 count at byte 107) in 5 kB.
    let mut lying = las.clone();
    lying[107..111].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = parse_error(read_bytes("lying.las", &lying).unwrap_err());
    assert!(matches!(e, ParseError::Truncated(_)), "{e}");
    // 10^12 points in LAS 1.4's 64-bit count (byte 247): COPC (compressed) and a LAS 1.4
    // file made with the `las` crate (uncompressed).
    let mut lying = copc.clone();
    lying[247..255].copy_from_slice(&1_000_000_000_000u64.to_le_bytes());
    let e = parse_error(read_bytes("lying.copc.laz", &lying).unwrap_err());
    assert!(matches!(e, ParseError::Truncated(_)), "{e}");
    let mut v14 = las14_file();
    assert_eq!(read_bytes("v14.las", &v14).unwrap(), 3);
    // The legacy 32-bit count (byte 107) wins when non-zero: zero it as LAS 1.4 allows.
    v14[107..111].copy_from_slice(&0u32.to_le_bytes());
    v14[247..255].copy_from_slice(&1_000_000_000_000u64.to_le_bytes());
    let e = parse_error(read_bytes("v14.las", &v14).unwrap_err());
    assert!(matches!(e, ParseError::Truncated(_)), "{e}");
    // A LAZ chunk table announcing 4 billion chunks (LASzip would reserve 64 GB for it).
    let start = u32::from_le_bytes(laz[96..100].try_into().unwrap()) as usize;
    let table = i64::from_le_bytes(laz[start..start + 8].try_into().unwrap()) as usize;
    let mut lying = laz.clone();
    lying[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = parse_error(read_bytes("chunks.laz", &lying).unwrap_err());
    assert!(e.to_string().contains("chunk table"), "{e}");
    // COPC (layered LAZ) whose first chunk announces a 4 GB layer, with the header's size
    // field cut below LAS 1.4's 375 bytes: the `las` crate still reads the VLRs after the
    // whole header, and so must the layer check (found by the fuzzer: LASzip allocated the
    // 4 GB before failing). Layer 0's size follows the chunk's first raw point record
    // (36 bytes in format 7) and its point count.
    let start = u32::from_le_bytes(copc[96..100].try_into().unwrap()) as usize;
    let mut lying = copc.clone();
    lying[94..96].copy_from_slice(&343u16.to_le_bytes());
    let layer0 = start + 8 + 36 + 4;
    lying[layer0..layer0 + 4].copy_from_slice(&0xF000_0000u32.to_le_bytes());
    let e = parse_error(read_bytes("layers.copc.laz", &lying).unwrap_err());
    assert!(e.to_string().contains("LAZ layer 0"), "{e}");
    // Streams give the same errors.
    let e = io::read_cloud_from(&las[..1000], CloudFormat::Las, &ReadOptions::default());
    assert!(matches!(e, Err(ParseError::Truncated(_))));
}

/// A three-point LAS 1.4 file (point format 6) written by the `las` crate.
fn las14_file() -> Vec<u8> {
    let mut builder = las::Builder::from((1, 4));
    builder.point_format = las::point::Format::new(6).unwrap();
    let header = builder.into_header().unwrap();
    let mut writer = las::Writer::new(std::io::Cursor::new(Vec::new()), header).unwrap();
    for i in 0..3 {
        writer
            .write_point(las::Point {
                x: f64::from(i),
                y: 2.0,
                z: 3.0,
                return_number: 1,
                number_of_returns: 1,
                gps_time: Some(0.0),
                ..Default::default()
            })
            .unwrap();
    }
    writer.into_inner().unwrap().into_inner()
}
