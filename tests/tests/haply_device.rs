//! The Haply Inverse3 client against a local test server that speaks the
//! Inverse Service's JSON messages: positions from the server reach the
//! daemon's record, the simulation's force reaches the server as
//! `set_cursor_force`, and the last command at shutdown is zero.

use haptic_daemon::device::force_command;
use serde_json::Value;
use shared::{SessionName, services};
use std::net::TcpListener;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use system_tests::{binary, contact_sample, run_err, scratch_dir};

#[test]
fn the_daemon_drives_an_inverse3_through_the_service_protocol() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let forces: Arc<Mutex<Vec<[f64; 3]>>> = Arc::default();
    let server = {
        let forces = forces.clone();
        std::thread::spawn(move || {
            let (stream, _) = listener.accept().unwrap();
            let mut ws = tungstenite::accept(stream).unwrap();
            let mut k = 0u64;
            loop {
                let x = 0.01 * (k as f64 * 1e-3).sin();
                let state = format!(
                    r#"{{"inverse3":[{{"device_id":"TEST1","state":{{"cursor_position":{{"x":{x},"y":0.0,"z":0.12}},"cursor_velocity":{{"x":0.0,"y":0.0,"z":0.0}}}}}}]}}"#
                );
                if ws.send(tungstenite::Message::text(state)).is_err() {
                    break;
                }
                match ws.read() {
                    Ok(tungstenite::Message::Text(t)) => {
                        let v: Value = serde_json::from_str(&t).unwrap();
                        assert_eq!(v["inverse3"][0]["device_id"], "TEST1");
                        let f = &v["inverse3"][0]["commands"]["set_cursor_force"]["values"];
                        forces.lock().unwrap().push([
                            f["x"].as_f64().unwrap(),
                            f["y"].as_f64().unwrap(),
                            f["z"].as_f64().unwrap(),
                        ]);
                    }
                    _ => break,
                }
                k += 1;
                std::thread::sleep(Duration::from_micros(500));
            }
        })
    };
    let session = format!("haply{}", std::process::id());
    let dir = scratch_dir("haply");
    let record = dir.join("rec.csv");
    let mut daemon = Command::new(binary("haptic-daemon"))
        .args([
            "run",
            "--rt-priority",
            "0",
            "--quiet",
            "--extrapolation",
            "constant",
            "--duration-s",
            "2",
        ])
        .args([
            "--session",
            &session,
            "--device",
            &format!("haply:ws://127.0.0.1:{port}"),
        ])
        .arg("--record")
        .arg(&record)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Act as the simulation: a steady 1 N push along z.
    let node = services::node("test-haply-sim").unwrap();
    let publisher = services::publisher(
        &services::force_service(&node, &SessionName::new(&session).unwrap()).unwrap(),
    )
    .unwrap();
    let mut seq = 0;
    while daemon.try_wait().unwrap().is_none() && seq < 3000 {
        publisher
            .send_copy(contact_sample(seq, [0.0, 0.0, 1.0]))
            .unwrap();
        seq += 1;
        std::thread::sleep(Duration::from_millis(2));
    }
    let out = daemon.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    server.join().unwrap();
    let forces = forces.lock().unwrap();
    assert!(forces.len() > 500, "only {} commands", forces.len());
    assert!(
        forces.iter().any(|f| (f[2] - 1.0).abs() < 1e-9),
        "the 1 N force never reached the device"
    );
    assert_eq!(
        *forces.last().unwrap(),
        [0.0, 0.0, 0.0],
        "the last command must be zero force"
    );
    assert!(
        forces
            .iter()
            .flatten()
            .all(|x| x.is_finite() && x.abs() <= 3.3 + 1e-12)
    );
    let rec = std::fs::read_to_string(&record).unwrap();
    let z: Vec<f64> = rec
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse().unwrap())
        .collect();
    assert!(
        z.iter().filter(|z| (**z - 0.12).abs() < 1e-12).count() > z.len() / 2,
        "positions from the service"
    );
    // The command format is the one the service documents.
    let v: Value = serde_json::from_str(&force_command("X", [1.0, 2.0, 3.0])).unwrap();
    assert_eq!(
        v["inverse3"][0]["commands"]["set_cursor_force"]["values"]["y"],
        2.0
    );
}

#[test]
fn a_missing_service_is_reported_clearly() {
    let err = run_err(Command::new(binary("haptic-daemon")).args([
        "run",
        "--quiet",
        "--duration-s",
        "0.2",
        "--device",
        "haply:ws://127.0.0.1:9",
    ]));
    assert!(
        err.contains("cannot reach the Haply Inverse Service"),
        "{err}"
    );
}
