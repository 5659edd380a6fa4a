//! The real-time tick allocates nothing when its force samples come through
//! zenoh (`haptic-daemon run --connect`): a bridge-like zenoh peer in this
//! process answers clock probes and puts force samples, the daemon's link
//! maps and queues them on zenoh's threads, and the counting allocator
//! counts what this thread allocates inside `RtLoop::tick` over 3,000 ticks
//! that drain them.

use haptic_daemon::daemon::{RtLoop, Shared};
use haptic_daemon::device::{HandModel, Path, Simulated};
use haptic_daemon::extrapolate::Method;
use haptic_daemon::safety::SafetyConfig;
use haptic_daemon::transport::Transport;
use shared::alloc_count::{Counting, count};
use shared::protocol::{CONTACT, ForceMsg, PROTOCOL_VERSION};
use shared::remote::{Link, RemoteConfig, clock, codec};
use shared::{SessionName, monotonic_ns, services};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use zenoh::Wait;

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn ticks_fed_through_zenoh_allocate_nothing() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let session = SessionName::new(&format!("noallocz{}", std::process::id())).unwrap();
    let server = RemoteConfig::listen_on(&endpoint).open().unwrap();
    let _clock = clock::serve(&server, &session).unwrap();
    let publisher = server
        .declare_publisher(session.service(services::stream::FORCE))
        .wait()
        .unwrap();
    let link = Link::join(
        &RemoteConfig::connect_to(&endpoint),
        &session,
        Duration::from_secs(10),
    )
    .unwrap();
    let transport = Transport::Remote(Arc::new(link));
    let (source, node) = transport
        .force_source("unused", &session, services::FORCE_BUFFER_LATEST)
        .unwrap();
    assert!(node.is_none(), "no shared memory through zenoh");
    let shared = Arc::new(Shared::new(1 << 15));
    shared.flags.peer_alive.store(true, Ordering::Relaxed);
    let device = Simulated::new(
        Path::Poke {
            start_m: [0.0, 0.0, 0.05],
            direction: [0.0, 0.0, -1.0],
            depth_m: 0.02,
            period_s: 1.0,
        },
        HandModel::default(),
        8.0,
    );
    let mut rt = RtLoop::new(
        device,
        Method::LocalModel,
        SafetyConfig::new(5.0).unwrap(),
        Some(source),
        shared.clone(),
    );
    let put = |seq: u64, sim_ns: u64| {
        let mut msg = ForceMsg {
            version: PROTOCOL_VERSION,
            tool_count: 1,
            seq,
            t_ns: monotonic_ns(),
            sim_time_ns: sim_ns,
            step_period_ns: 500_000,
            ..ForceMsg::default()
        };
        msg.tools[0].force_n = [0.0, 0.0, 0.5];
        msg.tools[0].position_m = [0.0, 0.0, 0.04];
        msg.tools[0].flags = CONTACT;
        publisher.put(codec::encode(&msg)).wait().unwrap();
    };
    // Until the subscription has reached the publisher.
    let start = std::time::Instant::now();
    let mut seq = 0;
    while shared.samples.load(Ordering::Relaxed) == 0 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no sample came through"
        );
        put(seq, seq * 500_000);
        seq += 1;
        std::thread::sleep(Duration::from_millis(1));
        rt.tick(monotonic_ns(), 0);
        while shared.telemetry.pop().is_some() {}
    }
    let before = shared.samples.load(Ordering::Relaxed);
    rt.enable(monotonic_ns()).unwrap();
    let mut allocations = 0;
    for k in 0..3000u64 {
        if k % 3 == 0 {
            put(seq, seq * 500_000);
            seq += 1;
        }
        std::thread::sleep(Duration::from_micros(300));
        allocations += count(|| rt.tick(monotonic_ns(), 0)).1;
        while shared.telemetry.pop().is_some() {}
    }
    assert_eq!(allocations, 0, "{allocations} allocations in 3,000 ticks");
    let got = shared.samples.load(Ordering::Relaxed) - before;
    assert!(got > 500, "only {got} samples came through");
    assert!(rt.last_force_n().iter().all(|x| x.is_finite()));
}
