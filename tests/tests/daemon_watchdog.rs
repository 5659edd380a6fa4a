//! The haptic daemon against a force publisher in another process: the
//! forces arrive; when the publisher is killed (SIGKILL) the rendered force
//! ramps to zero within the sample-age watchdog plus the ramp, never exceeds
//! the limit and is never NaN, and the daemon keeps running to its end.

use shared::{SessionName, monotonic_ns, services};
use std::process::{Command, Stdio};
use std::time::Duration;
use system_tests::{binary, contact_sample, finish, read_json, scratch_dir};

const CHILD_ENV: &str = "HAPSIM_TEST_PUBLISHER_SESSION";

/// Not a test on its own: the body of the publisher child process (the
/// parent runs this same test binary with the environment variable set).
#[test]
fn publisher_child() {
    let Ok(session) = std::env::var(CHILD_ENV) else {
        return;
    };
    let session = SessionName::new(&session).unwrap();
    let node = services::node("test-publisher").unwrap();
    let publisher =
        services::publisher(&services::force_service(&node, &session).unwrap()).unwrap();
    let mut seq = 0;
    loop {
        publisher
            .send_copy(contact_sample(seq, [0.0, 0.0, 1.0]))
            .unwrap();
        seq += 1;
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn forces_arrive_and_ramp_to_zero_when_the_simulation_is_killed() {
    let session = format!("wd{}", std::process::id());
    let dir = scratch_dir("watchdog");
    let (record, json) = (dir.join("rec.csv"), dir.join("out.json"));
    let daemon = Command::new(binary("haptic-daemon"))
        .args([
            "run",
            "--device",
            "simulated",
            "--extrapolation",
            "constant",
            "--rt-priority",
            "0",
            "--quiet",
        ])
        .args([
            "--session",
            &session,
            "--duration-s",
            "3",
            "--max-force",
            "4",
        ])
        .arg("--record")
        .arg(&record)
        .arg("--json")
        .arg(&json)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start haptic-daemon");
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "publisher_child", "--nocapture"])
        .env(CHILD_ENV, &session)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start the publisher");
    std::thread::sleep(Duration::from_millis(1500));
    // SAFETY: plain kill(2) on our own child's pid.
    unsafe { libc::kill(child.id() as i32, libc::SIGKILL) };
    let killed_ns = monotonic_ns();
    let _ = child.wait();
    finish(daemon, Duration::from_secs(30), "haptic-daemon");

    let text = std::fs::read_to_string(&record).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    assert!(header.starts_with(
        "t_ns,seq,pos_x_m,pos_y_m,pos_z_m,force_x_n,force_y_n,force_z_n,sample_age_ns"
    ));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .map(|f| f.parse::<f64>().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();
    assert!(rows.len() > 2000, "{} rows for 3 s at 1 kHz", rows.len());
    let (mut arrived, mut after_max) = (false, 0.0f64);
    for r in &rows {
        let (t, f) = (r[0] as u64, [r[5], r[6], r[7]]);
        assert!(f.iter().all(|x| x.is_finite()), "NaN force at t {t}");
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!(norm <= 4.0 + 1e-12, "force {norm} above the limit");
        if t + 200_000_000 < killed_ns && (f[2] - 1.0).abs() < 1e-9 {
            arrived = true;
        }
        // 50 ms sample age + 10 ms ramp + 20 ms for scheduling on a busy machine.
        if t > killed_ns + 80_000_000 {
            after_max = after_max.max(norm);
        }
    }
    assert!(
        arrived,
        "the 1 N force never reached the device before the kill"
    );
    assert_eq!(
        after_max, 0.0,
        "force still {after_max} N after the watchdog and the ramp"
    );
    let v: serde_json::Value = read_json(&json);
    for key in ["ticks", "rate_hz", "max_force_n", "device_max_force_n"] {
        assert!(v[key].is_number(), "missing {key}");
    }
    for key in ["p50", "p99", "p999", "max"] {
        assert!(
            v["lateness_us"][key].is_number(),
            "missing lateness_us.{key}"
        );
    }
    assert!(v["max_force_n"].as_f64().unwrap() <= 4.0 + 1e-12);
}
