#!/usr/bin/env python3
"""An out-of-process hapsim simulation backend in Python, written only from
docs/protocol.md: it proves the protocol is open.

It reads the daemon's tool poses and publishes one force sample per step at
RATE_HZ: the tissue is a half-space z < SURFACE_Z_M of stiffness K_N_PER_M
(the force pushes the tool back up, the contact stiffness is that of the
half-space along z). Needs the iceoryx2 Python package of the same version
as the Rust crate (pip install iceoryx2==0.10.0).

    python3 hapsim_backend.py --session NAME [--duration-s S]
"""

import argparse
import ctypes
import sys
import time

import iceoryx2 as iox2

PROTOCOL_VERSION = 1
MAX_TOOLS = 4
CONTACT = 1
TOOL_PRESENT = 1


class ToolPose(ctypes.Structure):
    _fields_ = [
        ("tip_m", ctypes.c_double * 3),
        ("shaft_dir", ctypes.c_double * 3),
        ("jaw_opening", ctypes.c_double),
        ("buttons", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
    ]


class PoseMsg(ctypes.Structure):
    _fields_ = [
        ("version", ctypes.c_uint32),
        ("tool_count", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("t_ns", ctypes.c_uint64),
        ("tools", ToolPose * MAX_TOOLS),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.PoseMsg.v1"


class ToolForce(ctypes.Structure):
    _fields_ = [
        ("position_m", ctypes.c_double * 3),
        ("force_n", ctypes.c_double * 3),
        ("stiffness_n_per_m", (ctypes.c_double * 3) * 3),
        ("pose_seq", ctypes.c_uint64),
        ("flags", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
    ]


class ForceMsg(ctypes.Structure):
    _fields_ = [
        ("version", ctypes.c_uint32),
        ("tool_count", ctypes.c_uint32),
        ("seq", ctypes.c_uint64),
        ("t_ns", ctypes.c_uint64),
        ("sim_time_ns", ctypes.c_uint64),
        ("step_period_ns", ctypes.c_uint64),
        ("tools", ToolForce * MAX_TOOLS),
    ]

    @staticmethod
    def type_name() -> str:
        return "hapsim.ForceMsg.v1"


assert ctypes.sizeof(PoseMsg) == 280 and ctypes.sizeof(ForceMsg) == 584


def service(node, session, stream, payload, buffer):
    """Opens (or creates) a stream with the protocol's settings."""
    name = iox2.ServiceName.new(f"hapsim/{session}/{stream}")
    verifier = iox2.AttributeVerifier.new().require(
        iox2.AttributeKey.new("hapsim.protocol"),
        iox2.AttributeValue.new(str(PROTOCOL_VERSION)),
    )
    return (
        node.service_builder(name)
        .publish_subscribe(payload)
        .max_publishers(2)
        .max_subscribers(8)
        .history_size(1)
        .subscriber_max_buffer_size(buffer)
        .enable_safe_overflow(True)
        .open_or_create_with_attributes(verifier)
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--session", required=True)
    parser.add_argument("--duration-s", type=float, default=10.0)
    parser.add_argument("--rate-hz", type=float, default=500.0)
    parser.add_argument("--surface-z-m", type=float, default=0.03)
    parser.add_argument("--k-n-per-m", type=float, default=100.0)
    args = parser.parse_args()

    iox2.set_log_level(iox2.LogLevel.Error)
    node = (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new("python-backend"))
        .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
        .create(iox2.ServiceType.Ipc)
    )
    poses = service(node, args.session, "pose", PoseMsg, 1).subscriber_builder().create()
    forces = service(node, args.session, "force", ForceMsg, 1024).publisher_builder().create()

    period_ns = int(1e9 / args.rate_hz)
    # Protocol rules: a pose older than 50 ms drives no tool; after a stall
    # of more than two steps or 5 ms the missed time is dropped (the clock
    # re-anchored), not run fast.
    pose_timeout_ns = 50_000_000
    stall_bound_ns = max(2 * period_ns, 5_000_000)
    start = time.monotonic_ns()
    anchor, anchor_seq = start, 0
    end = start + int(args.duration_s * 1e9)
    latest = None
    seq = 0
    last = start
    sent_in_contact = 0
    while time.monotonic_ns() < end:
        while True:
            sample = poses.receive()
            if sample is None:
                break
            msg = sample.payload().contents
            if msg.version != PROTOCOL_VERSION:
                print(f"pose of protocol version {msg.version}, expected {PROTOCOL_VERSION}", file=sys.stderr)
                return 2
            latest = PoseMsg.from_buffer_copy(msg)
        out = ForceMsg(version=PROTOCOL_VERSION, tool_count=1, seq=seq)
        tool = out.tools[0]
        fresh = latest is not None and time.monotonic_ns() - latest.t_ns <= pose_timeout_ns
        if fresh and latest.tools[0].flags & TOOL_PRESENT:
            p = latest.tools[0].tip_m
            tool.position_m[:] = list(p)
            tool.pose_seq = latest.seq
            depth = args.surface_z_m - p[2]
            if depth > 0:
                tool.force_n[2] = args.k_n_per_m * depth
                tool.stiffness_n_per_m[2][2] = args.k_n_per_m
                tool.flags = CONTACT
                sent_in_contact += 1
        now = time.monotonic_ns()
        out.t_ns = now
        out.sim_time_ns = seq * period_ns
        out.step_period_ns = now - last
        last = now
        forces.send_copy(out)
        seq += 1
        due = anchor + (seq - anchor_seq) * period_ns
        if time.monotonic_ns() - due > stall_bound_ns:
            anchor, anchor_seq = time.monotonic_ns(), seq
            due = anchor
        time.sleep(max(0.0, (due - time.monotonic_ns()) * 1e-9))
    print(f"python backend: {seq} force samples, {sent_in_contact} in contact")
    return 0


if __name__ == "__main__":
    sys.exit(main())
