#!/usr/bin/env python3
"""Lower bounds on the conflict duration of the left turn with a hesitant driver.

With one driver the conflict lasts until one of the two has left the conflict zone, so no
controller ends it before the earlier of two bounds, per speed:

* the driver first: released at once, it drives at its own desired speed (0.9 x its initial
  speed for the hesitant style; its IDM relaxes to it at a_max 1 m/s^2, as in
  sim/src/driver.rs) and leaves the zone 5.25 m past its conflict point; computed from each
  episode's start in the traces;
* the CAV first: from its initial speed along its route in deploy/maps/paper.toml (`cav_left`:
  a straight, then the turn that ends at its crossing with the HDV's lane), at its
  acceleration and braking limits, no faster than the lateral limit allows in the turn, then
  accelerating to 5.25 m past the point; no jerk limit, so a bound.

Usage: python3 docs/results/hesitant_ceiling.py TRACES_DIR (the traces/ directory of
`concord experiment interaction --out DIR`). Limits are the core's defaults (`concord params`).
"""
import csv
import glob
import math
import os
import statistics
import sys
import tomllib

ZONE_HALF_M = 5.25  # the simulator's crossing zones: the conflict point +- 5.25 m
MAP = os.path.join(os.path.dirname(__file__), "..", "..", "deploy", "maps", "paper.toml")
ACCEL, BRAKE, LATERAL = 3.0, 5.0, 4.0  # max_accel_mps2, max_brake_mps2, max_lateral_accel_mps2
HESITANT_A_MAX, HESITANT_DESIRED = 1.0, 0.9  # sim/src/driver.rs, hesitant style
DT = 0.05  # the simulator's step, s


def driver_exit_s(d0, v):
    """Time for a released hesitant driver d0 m before its conflict point at v m/s to leave
    the zone, s."""
    v0, t, x = HESITANT_DESIRED * v, 0.0, 0.0
    while x < d0 + ZONE_HALF_M:
        v += HESITANT_A_MAX * (1.0 - (v / v0) ** 4) * DT
        x += v * DT
        t += DT
    return t


def cav_route():
    """The CAV's straight before its turn, the turn's radius and its length, m, from the map."""
    with open(MAP, "rb") as f:
        lane = next(l for l in tomllib.load(f)["lane"] if l["id"] == "cav_left")
    (x0, y0), line, arc = lane["start"], lane["path"][0]["line_to"], lane["path"][1]["arc"]
    radius = math.dist(line, arc["centre"])
    return math.dist((x0, y0), line), radius, math.radians(abs(arc["sweep_deg"])) * radius


def cav_exit_s(v):
    """Fastest time for the CAV at v m/s to clear its zone within its limits, s."""
    straight, radius, turn = cav_route()
    v_turn = math.sqrt(LATERAL * radius)
    # Straight: accelerate to a peak, brake to v_turn at the turn (bang-bang).
    peak = math.sqrt((straight + v * v / (2 * ACCEL) + v_turn * v_turn / (2 * BRAKE))
                     / (1 / (2 * ACCEL) + 1 / (2 * BRAKE)))
    t = (peak - v) / ACCEL + (peak - v_turn) / BRAKE
    t += turn / v_turn
    return t + (-v_turn + math.sqrt(v_turn * v_turn + 2 * ACCEL * ZONE_HALF_M)) / ACCEL


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    for speed in (6, 8, 10):
        files = glob.glob(os.path.join(sys.argv[1], f"left_turn_concord_logit_{speed}_*.csv"))
        if not files:
            sys.exit(f"no left_turn_concord_logit_{speed}_*.csv traces in {sys.argv[1]}")
        exits = []
        for f in files:
            with open(f) as fh:
                first = next(csv.DictReader(fh))
            exits.append(driver_exit_s(float(first["hdv1_to_conflict_m"]), float(speed)))
        print(f"{speed} m/s: driver first {statistics.mean(exits):.2f} s (mean of "
              f"{len(exits)}), CAV first at least {cav_exit_s(float(speed)):.2f} s")


if __name__ == "__main__":
    main()
