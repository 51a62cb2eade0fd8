//! Data safety (issue 22): atomic writes that follow no planted link, write through links
//! and devices, survive concurrent writers and clean up after killed ones; output sets
//! that are checked before computing and appear whole or not at all.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use olmap::file::{write_atomic, OutputSet, STALE_AFTER};
use olmap::mapping::{run_map_job, MapJob, MapParams, OdometrySource};
use olmap::sim::{simulate, OdometryNoise, SimConfig, WorldKind};
use olmap::team::{run_team_pipeline, ScanStore, TeamJob, TeamParams, TeamReport};
use olmap::Error;

fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn write_text(path: &Path, text: &str) -> olmap::Result<()> {
    write_atomic(path, "text", |w| w.write_all(text.as_bytes()))
}

#[cfg(unix)]
#[test]
fn audit_tmp_symlink_not_followed() {
    // The audit: the temporary name was `.NAME.olmap-tmp-PID`, created with
    // `File::create`, so a link planted there had its target overwritten.
    let dir = tempfile::tempdir().unwrap();
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    let target = dir.path().join("out.txt");
    let planted = dir
        .path()
        .join(format!(".out.txt.olmap-tmp-{}", std::process::id()));
    std::os::unix::fs::symlink(&victim, &planted).unwrap();
    write_text(&target, "new content").unwrap();
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "new content");
    assert!(planted.symlink_metadata().unwrap().file_type().is_symlink());
    // The temporary names are not predictable: they differ from write to write, and no
    // temporary file is left.
    assert_eq!(names_in(dir.path()).len(), 3, "{:?}", names_in(dir.path()));
}

#[cfg(unix)]
#[test]
fn audit_output_symlink_is_written_through() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.txt");
    std::fs::write(&real, "old").unwrap();
    let link = dir.path().join("link.txt");
    std::os::unix::fs::symlink("real.txt", &link).unwrap();
    write_text(&link, "new").unwrap();
    assert!(link.symlink_metadata().unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_to_string(&real).unwrap(), "new");
    // A dangling link: the file it names is created, the link stays.
    let dangling = dir.path().join("dangling.txt");
    std::os::unix::fs::symlink("made.txt", &dangling).unwrap();
    write_text(&dangling, "made").unwrap();
    assert!(dangling
        .symlink_metadata()
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(
        std::fs::read_to_string(dir.path().join("made.txt")).unwrap(),
        "made"
    );
    // Permissions of the replaced file are kept.
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
    write_text(&real, "again").unwrap();
    let mode = std::fs::metadata(&real).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o640);
}

#[cfg(unix)]
#[test]
fn audit_output_device_is_written_through_not_replaced() {
    let null = Path::new("/dev/null");
    if !null.exists() {
        return;
    }
    use std::os::unix::fs::FileTypeExt;
    write_text(null, "discarded").unwrap();
    assert!(std::fs::symlink_metadata(null)
        .unwrap()
        .file_type()
        .is_char_device());
    // In an output set too (written through at once, nothing staged).
    let mut set = OutputSet::new();
    set.file(null, "text").unwrap();
    assert_eq!(set.path(null).unwrap(), null);
    write_text(&set.path(null).unwrap(), "discarded").unwrap();
    set.commit().unwrap();
    assert!(std::fs::symlink_metadata(null)
        .unwrap()
        .file_type()
        .is_char_device());
    // A folder is refused, with its name.
    let dir = tempfile::tempdir().unwrap();
    assert!(matches!(
        write_text(dir.path(), "x"),
        Err(Error::IsDirectory { .. })
    ));
}

/// Content of `len` bytes that tells who wrote it and shows any mixture: a header line
/// with the writer's id, then bytes that are a function of the id and the position.
fn signed_content(id: u32, len: usize) -> Vec<u8> {
    let mut v = format!("{id:08}\n").into_bytes();
    let mut i = 0u32;
    while v.len() < len {
        v.push((id.wrapping_mul(31).wrapping_add(i) % 251) as u8);
        i += 1;
    }
    v
}

fn check_signed(bytes: &[u8], len: usize) -> Result<u32, String> {
    if bytes.len() != len {
        return Err(format!("{} bytes, expected {len}", bytes.len()));
    }
    let id: u32 = std::str::from_utf8(&bytes[..8])
        .map_err(|e| e.to_string())?
        .parse()
        .map_err(|e| format!("header: {e}"))?;
    if bytes != signed_content(id, len) {
        return Err(format!("a mixture (header says writer {id})"));
    }
    Ok(id)
}

#[test]
fn audit_concurrent_writers_leave_one_complete_file() {
    const LEN: usize = 1 << 20;
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("shared.bin");
    std::fs::write(&target, signed_content(0, LEN)).unwrap();
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        let reader = s.spawn(|| {
            let mut reads = 0;
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                let bytes = std::fs::read(&target).unwrap();
                check_signed(&bytes, LEN).unwrap();
                reads += 1;
            }
            reads
        });
        let writers: Vec<_> = (1..=4u32)
            .map(|w| {
                let target = &target;
                s.spawn(move || {
                    for k in 0..8u32 {
                        let content = signed_content(w * 100 + k, LEN);
                        write_atomic(target, "bytes", |f| f.write_all(&content)).unwrap();
                    }
                })
            })
            .collect();
        for w in writers {
            w.join().unwrap();
        }
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        assert!(reader.join().unwrap() > 0);
    });
    let last = check_signed(&std::fs::read(&target).unwrap(), LEN).unwrap();
    assert!((101..=407).contains(&last) && last % 100 < 8, "{last}");
    assert_eq!(names_in(dir.path()), ["shared.bin"]);
}

#[test]
fn audit_killed_writers_temporaries_are_removed_later() {
    let dir = tempfile::tempdir().unwrap();
    let old = SystemTime::now() - STALE_AFTER - Duration::from_secs(60);
    let stale_file = dir.path().join(".map.olm.olmap-tmp-1234");
    std::fs::write(&stale_file, "half a map").unwrap();
    std::fs::File::options()
        .write(true)
        .open(&stale_file)
        .unwrap()
        .set_modified(old)
        .unwrap();
    let stale_stage = dir.path().join(".olmap-stage-00000000deadbeef");
    std::fs::create_dir(&stale_stage).unwrap();
    std::fs::write(stale_stage.join("team.olm"), "staged").unwrap();
    std::fs::File::open(&stale_stage)
        .unwrap()
        .set_modified(old)
        .unwrap();
    // A fresh one may belong to a writer at work: kept.
    let fresh = dir.path().join(".poses.txt.olmap-tmp-5678");
    std::fs::write(&fresh, "in progress").unwrap();
    // A user's file that merely looks similar is not touched.
    let user = dir.path().join("notes.olmap-tmp-old.txt");
    std::fs::write(&user, "mine").unwrap();
    std::fs::File::options()
        .write(true)
        .open(&user)
        .unwrap()
        .set_modified(old)
        .unwrap();
    write_text(&dir.path().join("out.txt"), "x").unwrap();
    assert_eq!(
        names_in(dir.path()),
        [
            ".poses.txt.olmap-tmp-5678",
            "notes.olmap-tmp-old.txt",
            "out.txt"
        ]
    );
}

#[test]
fn audit_output_set_failure_leaves_the_old_set() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
    std::fs::write(&a, "old a").unwrap();
    std::fs::write(&b, "old b").unwrap();
    {
        let mut set = OutputSet::new();
        set.file(&a, "text").unwrap();
        set.file(&b, "text").unwrap();
        write_text(&set.path(&a).unwrap(), "new a").unwrap();
        // The second write fails (a full disk, a bug): the set is dropped uncommitted.
        let err = write_atomic(&set.path(&b).unwrap(), "text", |_| {
            Err(std::io::Error::other("disk full (simulated)"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
    }
    assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
    assert_eq!(std::fs::read_to_string(&b).unwrap(), "old b");
    assert_eq!(names_in(dir.path()), ["a.txt", "b.txt"]);

    // A declared output that was not written is an error at the commit, nothing moves.
    let mut set = OutputSet::new();
    set.file(&a, "text").unwrap();
    set.file(&b, "text").unwrap();
    write_text(&set.path(&a).unwrap(), "new a").unwrap();
    assert!(set.commit().is_err());
    assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a");
    assert_eq!(names_in(dir.path()), ["a.txt", "b.txt"]);

    // Checks at declaration: a missing folder, a folder as a file, the same file twice.
    let mut set = OutputSet::new();
    let err = set
        .file(&dir.path().join("nodir/r.json"), "JSON")
        .unwrap_err();
    assert!(err.to_string().contains("does not exist"), "{err}");
    assert!(err.to_string().contains("r.json"), "{err}");
    assert!(matches!(
        set.file(dir.path(), "text"),
        Err(Error::IsDirectory { .. })
    ));
    set.file(&a, "text").unwrap();
    assert!(matches!(
        set.file(&dir.path().join(".").join("a.txt"), "text"),
        Err(Error::InvalidArgument(_))
    ));
}

#[test]
fn audit_output_set_commits_are_serialised() {
    // Two processes (here threads) committing sets into one folder end with one writer's
    // complete set, never a.txt of one and b.txt of the other.
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.txt"), dir.path().join("b.txt"));
    for round in 0..20 {
        std::thread::scope(|s| {
            for w in 0..3 {
                let (a, b) = (&a, &b);
                s.spawn(move || {
                    let mut set = OutputSet::new();
                    set.file(a, "text").unwrap();
                    set.file(b, "text").unwrap();
                    let id = format!("{round}-{w}");
                    write_text(&set.path(a).unwrap(), &id).unwrap();
                    write_text(&set.path(b).unwrap(), &id).unwrap();
                    set.commit().unwrap();
                });
            }
        });
        assert_eq!(
            std::fs::read_to_string(&a).unwrap(),
            std::fs::read_to_string(&b).unwrap(),
            "round {round}"
        );
    }
    assert_eq!(names_in(dir.path()), ["a.txt", "b.txt"]);
}

fn small_team_store() -> (ScanStore, olmap::geometry::PoseList) {
    let data = simulate(
        &SimConfig {
            world: WorldKind::Lab,
            seed: 2,
            robots: 2,
            stops: 3,
            odometry: OdometryNoise::degraded(),
            ..Default::default()
        },
        |_, _| {},
    )
    .unwrap();
    let store = data.to_store().unwrap();
    let truth = data.truth_list(&store);
    (store, truth)
}

fn team_run(
    store: &ScanStore,
    truth: &olmap::geometry::PoseList,
    out: &Path,
    solo: bool,
) -> olmap::Result<TeamReport> {
    run_team_pipeline(
        &TeamJob {
            store,
            truth: Some(truth),
            params: &TeamParams::default(),
            out,
            solo,
        },
        &mut |_, _, _| {},
    )
    .map(|r| r.report)
}

fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(snapshot(&p));
        } else {
            out.push((p.clone(), std::fs::read(&p).unwrap()));
        }
    }
    out.sort();
    out
}

#[test]
fn audit_team_outputs_all_or_nothing() {
    let (store, truth) = small_team_store();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("t");
    let first = team_run(&store, &truth, &out, true).unwrap();
    assert!(out.join("solo").is_dir());
    let before = snapshot(&out);

    // A write failing in the middle of the set (here a robot whose name is not a file
    // name, so its solo map cannot be written after the team files were): the folder
    // holds the first run's complete set, and nothing else.
    let mut bad = ScanStore::new();
    bad.set_robot_name(0, "robot0").unwrap();
    bad.set_robot_name(1, "no/such/folder").unwrap();
    for scan in store.iter() {
        bad.insert(scan.clone()).unwrap();
    }
    assert!(team_run(&bad, &truth, &out, true).is_err());
    assert_eq!(snapshot(&out), before);

    // An output path that cannot be written fails before any mapping.
    let blocked = tmp.path().join("blocked");
    std::fs::create_dir_all(blocked.join("team.olm")).unwrap();
    let err = team_run(&store, &truth, &blocked, false).unwrap_err();
    assert!(matches!(err, Error::IsDirectory { .. }), "{err}");

    // A run without --solo replaces the set: no older solo/ is left beside its report.
    let second = team_run(&store, &truth, &out, false).unwrap();
    assert!(!out.join("solo").exists());
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    assert_eq!(serde_json::from_str::<TeamReport>(&text).unwrap(), second);
    assert_ne!(second, first);
    let mut names = names_in(&out);
    names.retain(|n| n != "report.html");
    assert_eq!(
        names,
        [
            "report.json",
            "team.bt",
            "team.olm",
            "team.ply",
            "team.store",
            "team_poses.txt"
        ]
    );
}

#[test]
fn audit_map_report_dir_checked_before_compute() {
    // The audit: `olmap map … --report nodir/r.json` computed everything, wrote the map
    // and poses, then failed. Now the report's folder is checked first: the scans (here
    // missing files) are never read, and nothing is written.
    let dir = tempfile::tempdir().unwrap();
    let job = MapJob {
        scans: vec![
            dir.path().join("missing0.pcd"),
            dir.path().join("missing1.pcd"),
        ],
        odometry: OdometrySource::None,
        read: Default::default(),
        first: None,
        params: MapParams::default(),
        output: dir.path().join("m.olm"),
        poses_out: Some(dir.path().join("p.txt")),
        free_space_out: None,
        scans_out: None,
        report: Some(dir.path().join("nodir/r.json")),
        graph_out: None,
    };
    let err = run_map_job(&job, &mut |_, _, _| {}).unwrap_err();
    assert!(
        matches!(&err, Error::Write { path, .. } if path.ends_with("nodir/r.json")),
        "{err}"
    );
    assert!(err.to_string().contains("does not exist"), "{err}");
    assert!(
        names_in(dir.path()).is_empty(),
        "{:?}",
        names_in(dir.path())
    );
    // The same for the poses, and for a scans folder whose parent is a file.
    let mut bad = job.clone();
    bad.report = None;
    bad.poses_out = Some(dir.path().join("m.olm/p.txt"));
    assert!(run_map_job(&bad, &mut |_, _, _| {}).is_err());
    std::fs::write(dir.path().join("file"), "x").unwrap();
    let mut bad = job;
    bad.report = None;
    bad.scans_out = Some(dir.path().join("file/scans"));
    let err = run_map_job(&bad, &mut |_, _, _| {}).unwrap_err();
    assert!(err.to_string().contains("file"), "{err}");
    assert_eq!(names_in(dir.path()), ["file"]);
}
