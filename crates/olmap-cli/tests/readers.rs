//! The `olmap` program on files that lie, never end or are broken: issue 22's audit of the
//! readers, end to end.

use std::process::{Command, Output};

fn olmap(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_olmap"))
        .args(args)
        .output()
        .expect("the olmap binary runs")
}

/// The `error: ...` line of a failed run.
fn error_line(out: &Output) -> String {
    assert!(!out.status.success(), "expected a failure");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
        .lines()
        .find(|l| l.starts_with("error: "))
        .unwrap_or_else(|| panic!("no error line in {stderr:?}"))
        .to_string()
}

#[test]
fn audit_cli_errors_say_each_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str, bytes: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p.to_str().unwrap().to_string()
    };
    let pcd = path("bad.pcd", b"FIELDS x y z\nWIDTH 1\nDATA ascii\n1 2 x\n");
    let xyz = path("bad.xyz", b"1 2 3\nfoo\n");
    let scan = path("bad.csv", b"# olmap laser scan v1\nfoo\n");
    let json = path("bad.json", b"{\"angle_min\": 0,\n \"ranges\": [1,2");
    let missing = dir.path().join("missing.olm");
    let missing = missing.to_str().unwrap();
    let out_ply = dir.path().join("o.ply");
    let out_png = dir.path().join("o.png");
    // (arguments, a clause the message must hold exactly once)
    let cases: [(Vec<&str>, &str); 5] = [
        (vec!["align", &pcd, &pcd], "line 4: field 'z'"),
        (
            vec!["convert", &xyz, out_ply.to_str().unwrap()],
            "line 2: expected at least three numbers",
        ),
        (
            vec!["beacons", &scan, "--radius", "0.1"],
            "line 2: expected 'angle_min",
        ),
        (
            vec!["beacons", &json, "--radius", "0.1"],
            "EOF while parsing",
        ),
        (
            vec!["render", missing, "-o", out_png.to_str().unwrap()],
            "No such file or directory",
        ),
    ];
    for (args, clause) in cases {
        let line = error_line(&olmap(&args));
        assert_eq!(line.matches(clause).count(), 1, "{args:?}: {line}");
    }
}

#[test]
fn audit_cli_info_dev_zero_is_refused() {
    if !std::path::Path::new("/dev/zero").exists() {
        return;
    }
    let line = error_line(&olmap(&["info", "--format", "xyz", "/dev/zero"]));
    assert!(
        line.contains("/dev/zero") && line.contains("line 1") && line.contains("longer than 1 MiB"),
        "{line}"
    );
}

#[test]
fn audit_cli_bt_bomb_is_refused_with_the_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let mut bt = b"# Octomap OcTree binary file\nid OcTree\nsize 13\nres 0.1\ndata\n".to_vec();
    for _ in 0..7 {
        bt.extend_from_slice(&[0x03, 0x00]);
    }
    bt.extend_from_slice(&[0xAA, 0x02]);
    let p = dir.path().join("bomb.bt");
    std::fs::write(&p, &bt).unwrap();
    let line = error_line(&olmap(&["info", p.to_str().unwrap()]));
    assert!(
        line.contains("bomb.bt") && line.contains("83886080 voxels") && line.contains("MiB"),
        "{line}"
    );
}

/// Issue 22, item 4 (no `panicked` on stderr for any input): one byte of the real COPC
/// file changed (offset 1736, in its compressed points) makes the LASzip decoder of the
/// `laz` crate index out of range. olmap caught that panic and reported the file as
/// corrupt, but the panic hook printed "thread 'main' panicked at ..." above the error
/// first; now the error is all that is printed.
#[test]
fn a_laz_file_the_decoder_panics_on_prints_only_the_error() {
    let Some(data) = olmap::test_data::dir() else {
        return;
    };
    let mut bytes = std::fs::read(data.join("las/autzen.copc.laz")).unwrap();
    assert_ne!(bytes[1736], 197, "the sample changed: pick another byte");
    bytes[1736] = 197;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("damaged.copc.laz");
    std::fs::write(&file, &bytes).unwrap();
    let out = olmap(&["info", file.to_str().unwrap()]);
    let line = error_line(&out);
    assert!(line.contains("corrupt LAS/LAZ data"), "{line}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim_end(), line, "only the error is printed");
}
