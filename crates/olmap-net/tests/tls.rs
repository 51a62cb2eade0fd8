//! A TLS team on loopback with generated certificates (mutual TLS): its members exchange
//! records; a peer whose certificate another authority signed gets nothing in and nothing
//! out. Certificates are made with the `openssl` command; without it the test says so and
//! does nothing.

#![cfg(feature = "tls")]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::{free_port, record};
use olmap_net::{NetOptions, Node, NodeOptions};

fn openssl(dir: &Path, args: &[&str]) -> bool {
    Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .is_ok_and(|o| o.status.success())
}

/// A certificate authority `NAME-ca.pem` and a node certificate `NAME.pem` / `NAME.key`
/// it signed, for 127.0.0.1.
fn authority(dir: &Path, name: &str) -> bool {
    std::fs::write(
        dir.join("ext.cnf"),
        "subjectAltName=IP:127.0.0.1,DNS:localhost\n",
    )
    .unwrap();
    let ca_key = format!("{name}-ca.key");
    let ca = format!("{name}-ca.pem");
    let key = format!("{name}.key");
    let csr = format!("{name}.csr");
    let cert = format!("{name}.pem");
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-keyout",
            &ca_key,
            "-out",
            &ca,
            "-days",
            "2",
            "-subj",
            &format!("/CN={name} test CA"),
        ],
    ) && openssl(
        dir,
        &[
            "req",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-keyout",
            &key,
            "-out",
            &csr,
            "-subj",
            "/CN=localhost",
        ],
    ) && openssl(
        dir,
        &[
            "x509",
            "-req",
            "-in",
            &csr,
            "-CA",
            &ca,
            "-CAkey",
            &ca_key,
            "-CAcreateserial",
            "-out",
            &cert,
            "-days",
            "2",
            "-extfile",
            "ext.cnf",
        ],
    )
}

/// A Zenoh configuration for mutual TLS with `name`'s certificates.
fn config(dir: &Path, name: &str) -> std::path::PathBuf {
    let p = |f: String| dir.join(f).to_string_lossy().replace('\\', "/");
    let text = format!(
        r#"{{
  mode: "peer",
  scouting: {{ multicast: {{ enabled: false }} }},
  transport: {{ link: {{ tls: {{
    root_ca_certificate: "{ca}",
    listen_private_key: "{key}",
    listen_certificate: "{cert}",
    enable_mtls: true,
    connect_private_key: "{key}",
    connect_certificate: "{cert}",
  }} }} }},
}}"#,
        ca = p(format!("{name}-ca.pem")),
        key = p(format!("{name}.key")),
        cert = p(format!("{name}.pem")),
    );
    let path = dir.join(format!("{name}.json5"));
    std::fs::write(&path, text).unwrap();
    path
}

fn node(
    dir: &Path,
    name: &str,
    authority: &str,
    listen: Option<u16>,
    connect: Option<u16>,
) -> Node {
    let net = NetOptions {
        team: "tls".into(),
        listen: listen
            .map(|p| vec![format!("tls/127.0.0.1:{p}")])
            .unwrap_or_default(),
        connect: connect
            .map(|p| vec![format!("tls/127.0.0.1:{p}")])
            .unwrap_or_default(),
        zenoh_config: Some(config(dir, authority)),
        scouting: false,
    };
    let mut o = NodeOptions::new(name, "test", dir.join(format!("{name}.redb")), net);
    o.period = Duration::from_millis(100);
    Node::start(o).unwrap()
}

#[test]
fn a_tls_team_exchanges_records_and_a_peer_without_its_certificate_gets_nothing() {
    let dir = tempfile::tempdir().unwrap();
    if !(authority(dir.path(), "team") && authority(dir.path(), "intruder")) {
        eprintln!(
            "skipped: the openssl command is missing or failed; no certificates to test TLS with"
        );
        return;
    }
    let port = free_port();
    let mapper = node(dir.path(), "mapper", "team", Some(port), None);
    let robot = node(dir.path(), "robot0", "team", None, Some(port));
    let intruder = node(dir.path(), "robot7", "intruder", None, Some(port));
    std::thread::sleep(Duration::from_millis(500));
    for s in 0..3 {
        robot.record("robot0", record(0, s, 200)).unwrap();
        intruder.record("robot7", record(7, s, 200)).unwrap();
    }
    assert!(
        mapper.wait_for(3, Duration::from_secs(20)),
        "the TLS team did not exchange records: the mapper holds {}",
        mapper.held()
    );
    // Several anti-entropy periods later, nothing crossed between the team and the intruder.
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(mapper.held(), 3);
    assert!((0..3).all(|s| mapper.holds(0, s)) && !mapper.holds(7, 0));
    assert_eq!(intruder.held(), 3, "the intruder received team records");
    assert!(!intruder.holds(0, 0));
    intruder.close();
    robot.close();
    mapper.close();
}
