//! Bad input gets a typed error that names the file and the reason; never a panic.

use olmap::io::{self, CloudFormat, WriteOptions};
use olmap::Error;

use crate::round_trip::synthetic_cloud;

fn write(dir: &std::path::Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn valid_bytes(format: CloudFormat) -> Vec<u8> {
    let mut buf = Vec::new();
    io::write_cloud_to(
        &mut buf,
        &synthetic_cloud(50),
        format,
        &WriteOptions::default(),
    )
    .unwrap();
    buf
}

#[test]
fn empty_files_are_refused_with_their_name() {
    let dir = tempfile::tempdir().unwrap();
    for format in CloudFormat::ALL {
        let name = format!("empty.{}", format.extensions()[0]);
        let p = write(dir.path(), &name, b"");
        let err = io::read_cloud(&p).unwrap_err();
        assert!(matches!(err, Error::Read { .. }), "{name}: {err:?}");
        assert!(err.to_string().contains(&name), "{err}");
    }
}

#[test]
fn truncated_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for format in [
        CloudFormat::Pcd,
        CloudFormat::Ply,
        CloudFormat::KittiBin,
        CloudFormat::ScanGraph,
    ] {
        let bytes = valid_bytes(format);
        let name = format!("cut.{}", format.extensions()[0]);
        let p = write(dir.path(), &name, &bytes[..bytes.len() - 7]);
        let err = io::read_cloud(&p).unwrap_err();
        assert!(matches!(err, Error::Read { .. }), "{name}: {err:?}");
        assert!(err.to_string().contains(&name), "{err}");
    }
}

#[test]
fn headers_that_lie_about_counts() {
    let dir = tempfile::tempdir().unwrap();
    let pcd = String::from_utf8_lossy(&valid_bytes(CloudFormat::Pcd)).into_owned();
    // Binary PCD claiming many more points than it holds.
    let bytes = valid_bytes(CloudFormat::Pcd);
    let text_end = bytes
        .windows(12)
        .position(|w| w == b"DATA binary\n")
        .unwrap();
    let header = String::from_utf8_lossy(&bytes[..text_end])
        .replace("POINTS 50", "POINTS 5000000")
        .replace("WIDTH 50", "WIDTH 5000000");
    let mut lying = header.into_bytes();
    lying.extend_from_slice(&bytes[text_end..]);
    let p = write(dir.path(), "lying.pcd", &lying);
    let err = io::read_cloud(&p).unwrap_err();
    assert!(err.to_string().contains("lying.pcd"), "{err}");
    // WIDTH x HEIGHT disagreeing with POINTS.
    let p = write(
        dir.path(),
        "dims.pcd",
        pcd.replacen("HEIGHT 1", "HEIGHT 2", 1).as_bytes(),
    );
    assert!(io::read_cloud(&p).is_err());
    // PLY announcing more vertices than present.
    // (Edit the header bytes only: the binary body must stay byte for byte.)
    let mut ply = valid_bytes(CloudFormat::Ply);
    let at = ply
        .windows(17)
        .position(|w| w == b"element vertex 50")
        .unwrap();
    ply[at + 16] = b'1';
    let p = write(dir.path(), "lying.ply", &ply);
    let err = io::read_cloud(&p).unwrap_err();
    assert!(err.to_string().contains("lying.ply"), "{err}");
}

#[test]
fn wrong_field_types_and_garbage() {
    let dir = tempfile::tempdir().unwrap();
    let pcd = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F Q\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n";
    let p = write(dir.path(), "type.pcd", pcd.as_bytes());
    let err = io::read_cloud(&p).unwrap_err().to_string();
    assert!(err.contains("type.pcd") && err.contains("line"), "{err}");
    let ply = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let p = write(dir.path(), "type.ply", ply.as_bytes());
    assert!(io::read_cloud(&p).is_err());
    let garbage: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    for format in CloudFormat::ALL {
        let name = format!("garbage.{}", format.extensions()[0]);
        let p = write(dir.path(), &name, &garbage);
        // KITTI has no header: 4096 bytes of noise are 256 records. Everything else refuses.
        match io::read_cloud(&p) {
            Ok(_) => assert_eq!(format, CloudFormat::KittiBin, "{name} accepted garbage"),
            Err(e) => assert!(e.to_string().contains(&name), "{e}"),
        }
    }
    let p = write(dir.path(), "text.xyz", b"1 2 3\nhello world\n");
    let err = io::read_cloud(&p).unwrap_err().to_string();
    assert!(err.contains("line 2"), "{err}");
}

#[test]
fn directories_unknown_extensions_and_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("folder.pcd");
    std::fs::create_dir(&sub).unwrap();
    assert!(matches!(
        io::read_cloud(&sub),
        Err(Error::IsDirectory { .. })
    ));
    let p = write(dir.path(), "cloud.foo", b"1 2 3\n");
    let err = io::read_cloud(&p).unwrap_err();
    assert!(matches!(err, Error::UnknownFormat { .. }), "{err:?}");
    assert!(
        err.to_string().contains("cloud.foo") && err.to_string().contains(".pcd"),
        "{err}"
    );
    // A PLY under an unknown name is recognised by its signature.
    let p = write(dir.path(), "cloud.foo2", &valid_bytes(CloudFormat::Ply));
    assert_eq!(io::read_cloud(&p).unwrap().report.format, CloudFormat::Ply);
    let err = io::read_cloud(dir.path().join("absent.pcd")).unwrap_err();
    assert!(matches!(err, Error::Io { .. }) && err.to_string().contains("absent.pcd"));
    let err = io::write_cloud(
        dir.path().join("out.foo"),
        &synthetic_cloud(2),
        &WriteOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(err, Error::UnknownFormat { .. }));
}
