//! A remote session over TLS with mutual authentication, configured as
//! `docs/guide/remote.md` shows (zenoh configuration files given with
//! `--zenoh-config`): a lab CA (made here with openssl) signs the bridge's
//! certificate and a station's. The station's viewer, presenting its
//! certificate, gets a snapshot of the organ; a viewer that trusts the
//! bridge but presents no certificate, one whose certificate another CA
//! signed, and one speaking plain TCP to the TLS port get nothing ("no
//! bridge answers"), and the bridge keeps serving.

use std::path::Path;
use std::process::{Command, Stdio};
use system_tests::{Peer, binary, read_json, scratch_dir, spawn_sim_server, wait_for};

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("openssl (scripts/setup.sh installs it)");
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A CA, and `name`'s key and certificate signed by it (SAN localhost and
/// 127.0.0.1).
fn certificates(dir: &Path, names: &[&str]) {
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:prime256v1",
            "-nodes",
            "-keyout",
            "ca-key.pem",
            "-out",
            "ca.pem",
            "-days",
            "2",
            "-subj",
            "/CN=hapsim test CA",
        ],
    );
    std::fs::write(
        dir.join("ext.cnf"),
        "subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n",
    )
    .unwrap();
    for name in names {
        let (key, csr, pem) = (
            format!("{name}-key.pem"),
            format!("{name}.csr"),
            format!("{name}.pem"),
        );
        openssl(
            dir,
            &[
                "req",
                "-newkey",
                "ec",
                "-pkeyopt",
                "ec_paramgen_curve:prime256v1",
                "-nodes",
                "-keyout",
                &key,
                "-out",
                &csr,
                "-subj",
                "/CN=localhost",
            ],
        );
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca-key.pem",
                "-CAcreateserial",
                "-out",
                &pem,
                "-days",
                "2",
                "-extfile",
                "ext.cnf",
            ],
        );
    }
}

/// A viewer snapshot through `remote`, waiting at most `wait_s` for the bridge.
fn snapshot(
    dir: &Path,
    session: &str,
    remote: &[&str],
    tag: &str,
    wait_s: &str,
) -> std::process::Output {
    Command::new(binary("viewer"))
        .args(["--session", session, "--view", "top", "--wait-s", wait_s])
        .args(remote)
        .arg("--snapshot")
        .arg(dir.join(format!("{tag}.png")))
        .arg("--json")
        .arg(dir.join(format!("{tag}.json")))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("start the viewer")
}

#[test]
fn only_a_station_with_a_certificate_of_the_lab_sees_the_session() {
    let session = format!("tls-{}", std::process::id());
    let dir = scratch_dir("remote-tls");
    certificates(&dir, &["bridge", "station"]);
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let d = dir.display();
    let rogue = dir.join("rogue");
    std::fs::create_dir_all(&rogue).unwrap();
    certificates(&rogue, &["station"]);
    let tls_with = |side: &str, mtls: bool, extra: &str| {
        format!(
            r#"{{
  mode: "peer",
  {side}
  scouting: {{ multicast: {{ enabled: false }} }},
  transport: {{ link: {{
    rx: {{ max_message_size: 67108864 }},
    tls: {{
      root_ca_certificate: "{d}/ca.pem",
      enable_mtls: {mtls},
      {extra}
    }},
  }} }},
}}"#
        )
    };
    let tls = |side: &str, extra: &str| tls_with(side, true, extra);
    let write = |name: &str, text: String| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path.display().to_string()
    };
    let bridge_cfg = write(
        "bridge.json5",
        tls(
            &format!(r#"listen: {{ endpoints: ["tls/127.0.0.1:{port}"] }},"#),
            &format!(
                r#"listen_certificate: "{d}/bridge.pem", listen_private_key: "{d}/bridge-key.pem","#
            ),
        ),
    );
    let connect = format!(
        r#"listen: {{ endpoints: [] }}, connect: {{ endpoints: ["tls/localhost:{port}"] }},"#
    );
    let station_cfg = write(
        "station.json5",
        tls(
            &connect,
            &format!(
                r#"connect_certificate: "{d}/station.pem", connect_private_key: "{d}/station-key.pem", verify_name_on_connect: true,"#
            ),
        ),
    );
    // Trusts the bridge, presents no certificate.
    let stranger_cfg = write(
        "stranger.json5",
        tls_with(&connect, false, "verify_name_on_connect: true,"),
    );
    // A certificate of another CA.
    let rogue_cfg = write(
        "rogue.json5",
        tls(
            &connect,
            &format!(
                r#"connect_certificate: "{d}/rogue/station.pem", connect_private_key: "{d}/rogue/station-key.pem", verify_name_on_connect: true,"#
            ),
        ),
    );
    // Bounded: a failing assertion must not leave it running.
    let mut sim = spawn_sim_server(&session, &["--duration-s", "120"]);
    wait_for(&session, Peer::Simulation);
    let mut bridge = Command::new(binary("sim-server"))
        .args([
            "bridge",
            "--session",
            &session,
            "--zenoh-config",
            &bridge_cfg,
            "--duration-s",
            "120",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the bridge");
    let station = snapshot(
        &dir,
        &session,
        &["--zenoh-config", &station_cfg],
        "station",
        "10",
    );
    let stranger = snapshot(
        &dir,
        &session,
        &["--zenoh-config", &stranger_cfg],
        "stranger",
        "3",
    );
    let rogue_out = snapshot(
        &dir,
        &session,
        &["--zenoh-config", &rogue_cfg],
        "rogue",
        "3",
    );
    let plain = snapshot(
        &dir,
        &session,
        &["--connect", &format!("tcp/127.0.0.1:{port}")],
        "plain",
        "3",
    );
    let again = snapshot(
        &dir,
        &session,
        &["--zenoh-config", &station_cfg],
        "again",
        "10",
    );
    let bridge_alive = bridge.try_wait().unwrap().is_none();
    let _ = bridge.kill();
    let _ = bridge.wait();
    let _ = sim.kill();
    let _ = sim.wait();
    assert!(
        station.status.success(),
        "the station with the lab's certificate: {}",
        String::from_utf8_lossy(&station.stderr)
    );
    let snap = read_json(&dir.join("station.json"));
    assert!(snap["triangles"].as_u64().unwrap() > 1000, "{snap}");
    assert!(bridge_alive, "the refused peers stopped the bridge");
    assert!(
        again.status.success(),
        "the station after the refusals: {}",
        String::from_utf8_lossy(&again.stderr)
    );
    for (who, out) in [
        ("without a certificate", &stranger),
        ("with another CA's certificate", &rogue_out),
        ("over plain TCP", &plain),
    ] {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "a viewer {who} joined: {err}");
        assert!(err.contains("no bridge answers"), "a viewer {who}: {err}");
    }
}
