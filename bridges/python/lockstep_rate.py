"""Lock-step throughput through the Python bridge: simulation steps per second when every step
publishes a scene with 16 agents (``--agents``) and waits for the decision that answers it.

    ../../.venv/bin/python lockstep_rate.py [--steps 3000] [--rate 100] [--tick]

Each step moves 16 agents along the paper junction's approaches (8 m/s, wrapping around), so
the core plans against a full scene every time. By default the core decides on arrival
(``concord run --on-arrival``); ``--tick`` measures the core deciding on its ``--rate`` tick
instead. Prints steps per second and the percentiles of one step's round trip.
"""

import argparse
import math
import os
import time

import concord_wire as wire
from concord_link import ROOT, ConcordProcess, agent

# Approaches of the paper junction: (start x, start y, heading), 40 m out.
APPROACHES = ((-40.0, -5.0, 0.0), (40.0, 5.0, math.pi), (-5.0, 40.0, -math.pi / 2),
              (5.0, -40.0, math.pi / 2))


def frame_at(seq, t, agents):
    f = wire.SceneFrame()
    f.sequence = seq
    f.stamp_ns = time.monotonic_ns()
    f.ego = agent(40.0 - (8.0 * t) % 30.0, 5.0, math.pi, 8.0, 0)
    f.ego_route_lane = 0
    for k in range(agents):
        x0, y0, h = APPROACHES[k % 4]
        s = (8.0 * t + 12.0 * (k // 4)) % 60.0
        f.agents[k] = agent(x0 + s * math.cos(h), y0 + s * math.sin(h), h, 8.0, k + 1)
    return f


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--concord", default=os.path.join(ROOT, "target", "release", "concord"))
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--rate", type=float, default=100.0, help="concord run --rate, Hz")
    ap.add_argument("--agents", type=int, default=16, help="agents per scene (at most 32)")
    ap.add_argument("--tick", action="store_true", help="decide on the tick, not on arrival")
    args = ap.parse_args()
    core = ConcordProcess(args.concord, ["--geometry", "paper-intersection"], args.rate,
                          tag="rate", on_arrival=not args.tick)
    try:
        trips = []
        started = time.monotonic()
        for seq in range(1, args.steps + 1):
            t0 = time.monotonic()
            core.link.publish_scene(frame_at(seq, seq * 0.05, args.agents))
            if core.link.wait_for_decision(seq, timeout_s=2.0) is None:
                raise SystemExit(f"no decision for step {seq}")
            trips.append(time.monotonic() - t0)
            if seq % 1000 == 0:
                print(f"  {seq}/{args.steps} steps", flush=True)
        elapsed = time.monotonic() - started
    finally:
        core.close()
    trips.sort()
    q = lambda p: 1e3 * trips[min(len(trips) - 1, int(p * len(trips)))]
    mode = f"tick at {args.rate:g} Hz" if args.tick else "on arrival"
    print(f"{args.steps} lock-step steps with {args.agents} agents, deciding {mode}: "
          f"{args.steps / elapsed:.0f} steps/s; round trip p50 {q(0.5):.2f} ms, "
          f"p99 {q(0.99):.2f} ms, max {1e3 * trips[-1]:.2f} ms")


if __name__ == "__main__":
    main()
