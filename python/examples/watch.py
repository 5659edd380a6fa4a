"""Watch a running session without driving anything: force samples and
mesh frames for a few seconds, then a summary. Works beside any session,
`sim-server demo` included (its session is `demo<PID>`):

    python3 python/examples/watch.py --session S [--seconds 3]
"""
import argparse
import time

import numpy as np

from hapsim import CUTTING, Session

args = argparse.ArgumentParser()
args.add_argument("--session", default="default")
args.add_argument("--seconds", type=float, default=3.0)
args = args.parse_args()

with Session(args.session) as s:
    scene = s.wait_scene()  # the tools and the organ, from the simulation
    print("tools: " + ", ".join(f"{t.name} ({t.kind}, radius {t.radius_m * 1e3:.1f} mm)" for t in scene.tools))
    first = s.wait_mesh()
    samples, peak, cutting, frames = 0, np.zeros(0), 0, set()
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        for f in s.forces():  # every sample since the last call
            samples += 1
            norms = np.linalg.norm(f.force_n, axis=1)
            peak = norms if peak.size == 0 else np.maximum(peak, norms)
            cutting += int((f.flags & CUTTING).any())
        frame = s.mesh()
        frames.add(frame.frame_seq)
        time.sleep(0.01)
    lo, hi = frame.bounds_m()
    moved = np.linalg.norm(frame.positions_m - first.positions_m, axis=1).max()
    triangles = 0 if frame.triangles is None else len(frame.triangles)
    print(
        f"{samples} force samples, {len(frames)} mesh frames, surface {triangles} triangles"
        f" (topology v{first.topology_version} -> v{frame.topology_version}), samples cutting {cutting},"
        f" peak force per tool {np.round(peak, 3).tolist()} N, largest motion {moved * 1e3:.1f} mm"
    )
