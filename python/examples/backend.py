#!/usr/bin/env python3
"""An out-of-process hapsim simulation backend in Python, written from
docs/protocol.md (its payload structures are the hapsim package's, in
python/): it proves the protocol is open.

It reads the daemon's tool poses and publishes one force sample per step at
RATE_HZ: the tissue is a half-space z < SURFACE_Z_M of stiffness K_N_PER_M
(the force pushes the tool back up, the contact stiffness is that of the
half-space along z). Needs the iceoryx2 Python package of the same version
as the Rust crate (pip install iceoryx2==0.10.0).

    python3 python/examples/backend.py --session NAME [--duration-s S]
"""

import argparse
import os
import sys
import time

import iceoryx2 as iox2

# The payloads and stream settings of the hapsim Python package (python/,
# itself written from docs/protocol.md), from the checkout.
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
from hapsim.protocol import CONTACT, PROTOCOL_VERSION, TOOL_PRESENT, ForceMsg, PoseMsg  # noqa: E402
from hapsim import ipc  # noqa: E402
from hapsim.session import open_stream  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--session", required=True)
    parser.add_argument("--duration-s", type=float, default=10.0)
    parser.add_argument("--rate-hz", type=float, default=500.0)
    parser.add_argument("--surface-z-m", type=float, default=0.03)
    parser.add_argument("--k-n-per-m", type=float, default=100.0)
    args = parser.parse_args()

    iox2.set_log_level(iox2.LogLevel.Error)
    node = ipc.node("python-backend")
    poses = open_stream(node, args.session, "pose", PoseMsg, 1).subscriber_builder().create()
    forces = open_stream(node, args.session, "force", ForceMsg, 1024).publisher_builder().create()

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
