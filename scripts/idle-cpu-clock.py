#!/usr/bin/env python3
"""How much CPU time this machine charges a thread that does nothing.

A thread sleeps in poll() with a 1 ms timeout on a pipe nobody writes, 9,000
times, reading its own CPU clock (CLOCK_THREAD_CPUTIME_ID, what the run
summary's `step_cpu_us` uses) around each sleep. On bare metal the charge is
the syscall and the wake-up (plus this interpreter's few tens of us); on a
shared VM, interrupts and the hypervisor can be charged to the sleeping
thread as well. The tail of this distribution is the floor under any
CPU-clock tail measured on the same machine (docs/results/tools.md).

Usage: scripts/idle-cpu-clock.py [--iterations N]  (run under `chrt -f 70`
to see it for a SCHED_FIFO thread).
"""
import argparse
import os
import select
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=9000)
    n = parser.parse_args().iterations
    if n < 1000:
        parser.error("--iterations must be at least 1000 (the p99.9 needs them)")
    read_end, _write_end = os.pipe()
    poller = select.poll()
    poller.register(read_end, select.POLLIN)
    charged_us = []
    for _ in range(n):
        before = time.thread_time_ns()
        poller.poll(1)
        charged_us.append((time.thread_time_ns() - before) / 1000)
    charged_us.sort()
    at = lambda q: charged_us[min(n - 1, int(n * q))]
    print(
        "CPU time charged per idle 1 ms poll (us): p50 %.1f p99 %.1f p99.9 %.1f max %.1f"
        % (at(0.5), at(0.99), at(0.999), charged_us[-1])
    )


if __name__ == "__main__":
    main()
