//! The services' unit tests.

use super::*;
use crate::protocol::{MAX_TOOLS, ToolForce, check_version};

fn unique_session(tag: &str) -> SessionName {
    SessionName::new(&format!("t{}-{tag}", std::process::id())).unwrap()
}

#[test]
fn a_force_message_goes_through_and_keeps_every_field() {
    let session = unique_session("force");
    let sim = node("test-sim").unwrap();
    let daemon = node("test-daemon").unwrap();
    let publisher = publisher(&force_service(&sim, &session).unwrap()).unwrap();
    let subscriber = subscriber(&force_service(&daemon, &session).unwrap()).unwrap();
    let mut msg = ForceMsg {
        version: PROTOCOL_VERSION,
        tool_count: 1,
        seq: 7,
        t_ns: crate::monotonic_ns(),
        sim_time_ns: 123,
        step_period_ns: 1_000_000,
        tools: [ToolForce::default(); MAX_TOOLS],
    };
    msg.tools[0].force_n = [0.0, 0.0, 1.5];
    msg.tools[0].stiffness_n_per_m[2][2] = 200.0;
    publisher.send_copy(msg).unwrap();
    let got = subscriber.receive().unwrap().expect("a sample");
    assert_eq!(*got, msg);
    check_version("force", got.version).unwrap();
}

#[test]
fn a_mesh_frame_goes_through_with_its_header() {
    let session = unique_session("mesh");
    let sim = node("test-mesh-sim").unwrap();
    let viewer = node("test-mesh-viewer").unwrap();
    let publisher = slice_publisher(&mesh_service(&sim, &session).unwrap(), 4).unwrap();
    let sub = mesh_service(&viewer, &session)
        .unwrap()
        .subscriber_builder()
        .create()
        .unwrap();
    let positions = [
        [0.0f32, 0.0, 0.0],
        [0.1, 0.0, 0.0],
        [0.0, 0.1, 0.0],
        [0.0, 0.0, 0.1],
    ];
    let mut sample = publisher.loan_slice_uninit(positions.len()).unwrap();
    *sample.user_header_mut() = MeshHeader {
        version: PROTOCOL_VERSION,
        vertex_count: 4,
        frame_seq: 3,
        topology_version: 1,
        t_ns: 42,
    };
    sample.write_from_slice(&positions).send().unwrap();
    let got = sub.receive().unwrap().expect("a frame");
    assert_eq!(got.user_header().frame_seq, 3);
    assert_eq!(got.payload(), &positions[..]);
    let topo = topology_service(&viewer, &session).unwrap();
    assert_eq!(topo.name().as_str(), session.service(stream::TOPOLOGY));
}

#[test]
fn a_peer_of_another_protocol_version_is_refused_with_a_clear_error() {
    let session = unique_session("version");
    let other = node("test-old-peer").unwrap();
    // A peer built from another release created the service with version 999.
    let name = ServiceName::new(&session.service(stream::FORCE)).unwrap();
    let key = AttributeKey::new(VERSION_KEY.as_bytes()).unwrap();
    let value = AttributeValue::new(b"999").unwrap();
    let _old = other
        .service_builder(&name)
        .publish_subscribe::<ForceMsg>()
        .max_publishers(2)
        .max_subscribers(8)
        .history_size(1)
        .subscriber_max_buffer_size(4)
        .enable_safe_overflow(true)
        .create_with_attributes(
            &iceoryx2::service::attribute::AttributeSpecifier::new()
                .define(&key, &value)
                .unwrap(),
        )
        .unwrap();
    let me = node("test-new-peer").unwrap();
    let Err(err) = force_service(&me, &session) else {
        panic!("a version mismatch must be refused");
    };
    assert!(matches!(err, ServiceError::Version { .. }), "{err}");
    assert!(
        err.to_string().contains("another protocol version"),
        "{err}"
    );
}

#[test]
fn a_pose_ready_notification_wakes_a_waiting_listener() {
    let session = unique_session("ready");
    let sim = node("test-ready-sim").unwrap();
    let daemon = node("test-ready-daemon").unwrap();
    let listener = pose_ready_listener(&sim, &session).unwrap();
    let notifier = pose_ready_notifier(&daemon, &session).unwrap();
    // Nothing yet: short waits time out, at their time (not rounded
    // to the kernel tick, and zero does not block).
    let ms = std::time::Duration::from_millis;
    let t0 = std::time::Instant::now();
    assert!(!wait_notified(&listener, std::time::Duration::ZERO));
    assert!(!wait_notified(
        &listener,
        std::time::Duration::from_nanos(500)
    ));
    assert!(!wait_notified(&listener, ms(1)));
    assert!(t0.elapsed() < ms(3), "{:?}", t0.elapsed());
    assert_eq!(notifier.notify().unwrap(), 1, "one listener notified");
    assert!(wait_notified(&listener, ms(5000)));
    // Taken: the next wait times out.
    assert!(!wait_notified(&listener, ms(1)));
}

#[test]
fn sessions_do_not_meet() {
    let (a, b) = (unique_session("a"), unique_session("b"));
    let n = node("test-sessions").unwrap();
    let publisher = publisher(&force_service(&n, &a).unwrap()).unwrap();
    let other = subscriber(&force_service(&n, &b).unwrap()).unwrap();
    publisher.send_copy(ForceMsg::default()).unwrap();
    assert!(other.receive().unwrap().is_none());
}

#[test]
fn a_publisher_past_a_stream_s_limit_is_told_so_by_name() {
    let session = unique_session("full");
    let n = node("test-full").unwrap();
    let poses = pose_service(&n, &session).unwrap();
    let _a = publisher(&poses).unwrap();
    let _b = publisher(&poses).unwrap();
    let Err(err) = publisher(&poses) else {
        panic!("a third pose publisher was created");
    };
    assert!(matches!(err, ServiceError::Full { max: 2, .. }), "{err}");
    assert!(err.to_string().contains("stop one of them"), "{err}");
}
