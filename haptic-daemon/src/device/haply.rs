//! A Haply Inverse3 through the Haply Inverse Service (JSON over WebSocket,
//! default `ws://localhost:10001`). The service streams a state message per
//! servo cycle, `{"inverse3": [{"device_id": ..., "state": {"cursor_position":
//! {"x","y","z"}, "cursor_velocity": {...}}}], ...}`, and takes a command in
//! reply, `{"inverse3": [{"device_id": ..., "commands": {"set_cursor_force":
//! {"values": {"x","y","z"}}}}]}`.
//!
//! The WebSocket lives on its own thread; the real-time thread only reads
//! and writes atomics (no I/O, no lock, no allocation). If the connection
//! drops, reads fail and the daemon's safety filter ramps the force to zero.

use super::{Device, DeviceError, DeviceSpecs, DeviceState};
use crate::math::V3;
use crate::slots::PoseSlot;
use serde_json::{Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use thiserror::Error;

/// The Inverse3's rated continuous force (N).
pub const INVERSE3_MAX_FORCE_N: f64 = 3.3;

/// Why the Haply client could not start.
#[derive(Debug, Error)]
pub enum HaplyError {
    /// The service did not answer.
    #[error("cannot reach the Haply Inverse Service at {url}: {reason} (is the service running?)")]
    Connect {
        /// The URL.
        url: String,
        /// Why.
        reason: String,
    },
    /// The service answered but reported no Inverse3.
    #[error("the Haply Inverse Service at {url} reports no Inverse3 device ({reason})")]
    NoDevice {
        /// The URL.
        url: String,
        /// What it sent.
        reason: String,
    },
}

struct Link {
    state: PoseSlot,
    velocity: [AtomicU64; 3],
    force: [AtomicU64; 3],
    connected: AtomicBool,
    stop: AtomicBool,
}

/// The Haply Inverse3 device.
pub struct Haply {
    link: Arc<Link>,
    thread: Option<std::thread::JoinHandle<()>>,
    device_id: String,
}

fn store3(to: &[AtomicU64; 3], v: V3) {
    for (a, x) in to.iter().zip(v) {
        a.store(x.to_bits(), Ordering::Relaxed);
    }
}

fn vec3(v: &Value) -> Option<V3> {
    Some([
        v.get("x")?.as_f64()?,
        v.get("y")?.as_f64()?,
        v.get("z")?.as_f64()?,
    ])
}

/// The first Inverse3 in a state message: (device_id, position, velocity).
pub fn parse_state(text: &str) -> Option<(String, V3, V3)> {
    let v: Value = serde_json::from_str(text).ok()?;
    let dev = v.get("inverse3")?.as_array()?.first()?;
    let id = dev.get("device_id")?.as_str()?.to_string();
    let state = dev.get("state")?;
    let p = vec3(state.get("cursor_position")?)?;
    let vel = state
        .get("cursor_velocity")
        .and_then(vec3)
        .unwrap_or([0.0; 3]);
    Some((id, p, vel))
}

/// The command message setting the cursor force of `device_id`.
pub fn force_command(device_id: &str, f: V3) -> String {
    json!({"inverse3": [{"device_id": device_id, "commands": {"set_cursor_force": {"values": {"x": f[0], "y": f[1], "z": f[2]}}}}]})
        .to_string()
}

impl Haply {
    /// Connects to the service at `url` (e.g. `ws://localhost:10001`) and
    /// waits up to 2 s for the first state of an Inverse3.
    pub fn connect(url: &str) -> Result<Self, HaplyError> {
        let connect_err = |reason: String| HaplyError::Connect {
            url: url.to_string(),
            reason,
        };
        let (mut ws, _) = tungstenite::connect(url).map_err(|e| connect_err(e.to_string()))?;
        if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_mut() {
            let _ = s.set_read_timeout(Some(Duration::from_secs(2)));
            let _ = s.set_nodelay(true);
        }
        let first = ws.read().map_err(|e| connect_err(e.to_string()))?;
        let text = first
            .to_text()
            .map_err(|e| connect_err(e.to_string()))?
            .to_string();
        let (device_id, p, vel) = parse_state(&text).ok_or_else(|| HaplyError::NoDevice {
            url: url.to_string(),
            reason: text.chars().take(200).collect(),
        })?;
        let link = Arc::new(Link {
            state: PoseSlot::default(),
            velocity: Default::default(),
            force: Default::default(),
            connected: AtomicBool::new(true),
            stop: AtomicBool::new(false),
        });
        link.state.write(0, p, 1.0, 0);
        store3(&link.velocity, vel);
        let thread = {
            let link = link.clone();
            let id = device_id.clone();
            std::thread::Builder::new()
                .name("haply-ws".into())
                .spawn(move || {
                    // Reply to every state message with the latest force.
                    while !link.stop.load(Ordering::Relaxed) {
                        let f: V3 = std::array::from_fn(|d| {
                            f64::from_bits(link.force[d].load(Ordering::Relaxed))
                        });
                        if ws
                            .send(tungstenite::Message::text(force_command(&id, f)))
                            .is_err()
                        {
                            break;
                        }
                        match ws.read() {
                            Ok(m) => {
                                if let Some((_, p, vel)) = m.to_text().ok().and_then(parse_state) {
                                    link.state.write(0, p, 1.0, 0);
                                    store3(&link.velocity, vel);
                                }
                            }
                            Err(_) => break,
                        }
                    }
                    // Leave the device at zero force.
                    let _ = ws.send(tungstenite::Message::text(force_command(&id, [0.0; 3])));
                    let _ = ws.close(None);
                    link.connected.store(false, Ordering::Relaxed);
                })
                .map_err(|e| connect_err(e.to_string()))?
        };
        Ok(Self {
            link,
            thread: Some(thread),
            device_id,
        })
    }

    /// The device id the service reported.
    pub fn device_id(&self) -> &str {
        &self.device_id
    }
}

impl Device for Haply {
    fn specs(&self) -> DeviceSpecs {
        DeviceSpecs {
            name: "haply-inverse3",
            max_force_n: INVERSE3_MAX_FORCE_N,
            max_stiffness_n_per_m: 2500.0,
            workspace_min_m: [-0.2, -0.2, -0.2],
            workspace_max_m: [0.2, 0.2, 0.2],
        }
    }

    fn enable(&mut self, _now_ns: u64) -> Result<(), DeviceError> {
        Ok(())
    }

    fn disable(&mut self) {
        store3(&self.link.force, [0.0; 3]);
    }

    fn read(&mut self, _now_ns: u64) -> Result<DeviceState, DeviceError> {
        if !self.link.connected.load(Ordering::Relaxed) {
            return Err(DeviceError::Disconnected(
                "the Haply Inverse Service connection closed".into(),
            ));
        }
        let s = self.link.state.read().unwrap_or_default();
        Ok(DeviceState {
            position_m: s.position_m,
            velocity_m_s: std::array::from_fn(|d| {
                f64::from_bits(self.link.velocity[d].load(Ordering::Relaxed))
            }),
            gripper: 1.0,
            buttons: 0,
        })
    }

    fn write_force(&mut self, force_n: V3, _now_ns: u64) -> Result<(), DeviceError> {
        store3(&self.link.force, force_n);
        Ok(())
    }
}

impl Drop for Haply {
    fn drop(&mut self) {
        self.disable();
        self.link.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_and_command_messages() {
        let msg = r#"{"inverse3":[{"device_id":"049D","state":{"cursor_position":{"x":0.01,"y":-0.02,"z":0.15},"cursor_velocity":{"x":0.0,"y":0.1,"z":0.0}}}],"wireless_verse_grip":[]}"#;
        let (id, p, v) = parse_state(msg).unwrap();
        assert_eq!(
            (id.as_str(), p, v),
            ("049D", [0.01, -0.02, 0.15], [0.0, 0.1, 0.0])
        );
        assert!(parse_state(r#"{"inverse3":[]}"#).is_none());
        assert!(parse_state("not json").is_none());
        let cmd: Value = serde_json::from_str(&force_command("049D", [0.5, 0.0, -1.0])).unwrap();
        assert_eq!(cmd["inverse3"][0]["device_id"], "049D");
        assert_eq!(
            cmd["inverse3"][0]["commands"]["set_cursor_force"]["values"]["z"],
            -1.0
        );
    }
}
