"""Press the organ with tool 0 for a second and print the force (the
docs/guide/python.md's example). Run beside `sim-server run [--session S]`:

    python3 python/examples/press.py [--session S] [--depth-m D]
"""
import argparse
import time

from hapsim import Session

args = argparse.ArgumentParser()
args.add_argument("--session", default="default")
args.add_argument("--depth-m", type=float, default=0.01)
args = args.parse_args()

with Session(args.session) as s:
    lo, hi = s.organ_bounds_m()  # where the organ is (m), from a mesh frame
    x, y, top = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]
    peak = 0.0
    for k in range(1000):  # 1 s at 1 kHz: 20 mm above, down to D deep, hold
        z = top + 0.02 - (0.02 + args.depth_m) * min(1.0, k / 500)
        s.publish_pose([x, y, z])
        f = s.latest_force()  # numpy arrays per tool
        if f is not None:
            peak = max(peak, float((f.force_n[0] ** 2).sum() ** 0.5))
        time.sleep(0.001)
    print(f"organ {lo.round(3)} .. {hi.round(3)} m, peak force on tool 0 {peak:.3f} N")
