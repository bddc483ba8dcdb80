"""Build Concord map files from highway-env's road networks (highway-env 1.12.1).

    ../../.venv/bin/python highway_maps.py roundabout [--out FILE]

Each movement of the map is a sequence of highway-env lanes (``MOVEMENTS``), and its centre
line is theirs: a straight lane's two ends, an arc's or a sine's points every
``CURVE_STEP_M`` and its end (which replaces a point closer to it than half a step), at the
same places for every movement, so that movements
sharing a lane share its vertices exactly and the core finds where they join at the first
vertex they share. highway-env's lanes do not always meet: its roundabout's entries end 5.6 m
from the ring lane they lead into, its exits begin as far from the ring (its vehicles bridge
the gaps with their steering controller). Where a lane does not meet the next, a connector
joins them without a corner: a quadratic Bezier curve tangent to both, from a vertex of the
first (its end or one within ``REACH_M`` of it) to a vertex of the next (its start or one
within ``REACH_M`` of it), the pair whose curve turns least per metre (``connect``). A movement's stop line is where it leaves its entry lane. At most 64
vertices per lane (the core's ``MAX_LANE_POINTS``). ``concord map FILE --route ego`` prints
what the core derives from the result.

roundabout (``roundabout-v0``, ``RoundaboutEnv._make_road``): a two-lane ring of radius 20
and 24 m about the origin with four entries and exits, in highway-env's y-down frame. The ego
enters from the south and leaves to the north (``plan_route_to("nxs")``); the lanes are the
movements that meet that route: the ego's, the ring's (both ring lanes, from the north entry
"ne" on, leaving east or north), and the east entry's (leaving north, or south). highway-env's
cars do not signal, so a car on the ring is matched to the first of the movements its lane
carries: leaving east, the one that cuts across the ego's path from the inner lane, until it
has passed that exit. Entries
join the outer ring lane, as highway-env's cars do. Every movement has priority level 0: the
roundabout is a plain highway-env ``Road``, without the right of way its intersection
enforces (its cars only follow their leader, and enter the ring whatever comes), so the core
weighs every conflict first come, first served. (With the rule of the road instead, the ring
before the entries, the ego once trusted a car entering from the east to give way, and it
did not: tuning seed 95.)
"""

import argparse
import math
import os
import sys
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
MAX_LANE_POINTS = 64  # concord_core::scene::MAX_LANE_POINTS
# Vertices of curved lanes every so many metres (a 4 m chord of the 20 m ring is 0.1 m off it).
CURVE_STEP_M = {"CircularLane": 4.0, "SineLane": 2.5}
# A connector starts and ends within this distance of the gap it bridges, m.
REACH_M = 12.0
# Vertices of a connector at most this far apart, m.
CONNECTOR_STEP_M = 2.0
# Lanes closer than this meet, m.
MEETS_M = 0.05
# How far along its first lane a movement starts, m (the roundabout's approaches are 127.5 m).
START_S_M = 70.0

# roundabout-v0: id, turn, priority, highway-env lanes (from, to, index).
_ENTRY_S = [("ser", "ses", 0), ("ses", "se", 0)]
_ENTRY_E = [("eer", "ees", 0), ("ees", "ee", 0)]
_EXIT_N = [("nx", "nxs", 0), ("nxs", "nxr", 0)]
_EXIT_E = [("ex", "exs", 0), ("exs", "exr", 0)]
_EXIT_S = [("sx", "sxs", 0), ("sxs", "sxr", 0)]


def _ring(start, end, lane):
    nodes = ["se", "ex", "ee", "nx", "ne", "wx", "we", "sx"]
    i, out = nodes.index(start), []
    while nodes[i] != end:
        out.append((nodes[i], nodes[(i + 1) % 8], lane))
        i = (i + 1) % 8
    return out


MOVEMENTS = {
    "roundabout": [
        ("ego", "straight", 0, _ENTRY_S + _ring("se", "nx", 1) + _EXIT_N),
        ("ring_inner_east", "straight", 0, _ring("ne", "ex", 0) + _EXIT_E),
        ("ring_inner_north", "straight", 0, _ring("ne", "nx", 0) + _EXIT_N),
        ("ring_outer_east", "straight", 0, _ring("ne", "ex", 1) + _EXIT_E),
        ("ring_outer_north", "straight", 0, _ring("ne", "nx", 1) + _EXIT_N),
        ("east_north", "right", 0, _ENTRY_E + _ring("ee", "nx", 1) + _EXIT_N),
        ("east_south", "left", 0, _ENTRY_E + _ring("ee", "sx", 1) + _EXIT_S),
    ],
}
ENVS = {"roundabout": "roundabout-v0"}


def lane_vertices(lane, since=0.0):
    """(place along the lane, point, heading) of ``lane``'s vertices from ``since`` m on."""
    step = CURVE_STEP_M.get(type(lane).__name__)
    marks = [since] if step is None else [
        k * step for k in range(int(math.ceil(since / step - 1e-9)), int(lane.length / step) + 1)]
    if marks and step is not None and lane.length - marks[-1] < 0.5 * step and len(marks) > 1:
        marks.pop()  # the end replaces a point closer to it than half a step
    if not marks or lane.length - marks[-1] > 1e-6:
        marks.append(lane.length)
    if since > 0.0 and marks[0] > since + 1e-6:
        marks.insert(0, since)
    return [(m, np.asarray(lane.position(m, 0.0), float), float(lane.heading_at(m))) for m in marks]


def turn(a, b):
    """|b - a| for headings, rad."""
    return abs(math.atan2(math.sin(b - a), math.cos(b - a)))


def bezier(p, hp, q, hq):
    """The quadratic Bezier curve from ``p`` (heading ``hp``) to ``q`` (heading ``hq``), tangent
    to both, as points at most ``CONNECTOR_STEP_M`` apart after ``p`` (``q`` last); None when
    the two tangents do not meet ahead of ``p`` and behind ``q``."""
    dp, dq = np.array([math.cos(hp), math.sin(hp)]), np.array([math.cos(hq), math.sin(hq)])
    # p + t dp = q - u dq: the tangents meet t ahead of p and u behind q.
    det = dp[0] * dq[1] - dp[1] * dq[0]
    if abs(det) < 1e-9:
        return None
    rhs = q - p
    t = (rhs[0] * dq[1] - rhs[1] * dq[0]) / det
    u = (dp[0] * rhs[1] - dp[1] * rhs[0]) / det
    if t <= 0.0 or u <= 0.0:
        return None
    c = p + t * dp
    n = max(2, int(math.ceil((t + u) / CONNECTOR_STEP_M)))
    ts = np.linspace(0.0, 1.0, n + 1)[1:]
    return [(1 - w) ** 2 * p + 2 * (1 - w) * w * c + w ** 2 * q for w in ts]


def sharpest(points):
    """Largest turn per metre between consecutive pieces of ``points``, rad/m."""
    d = np.diff(np.array(points), axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    turns = np.abs(np.angle(np.exp(1j * np.diff(h))))
    return float(np.max(turns / np.minimum(np.linalg.norm(d[1:], axis=1),
                                           np.linalg.norm(d[:-1], axis=1))))


def connect(prev, nxt):
    """The connector from the vertices ``prev`` (the lanes so far) into those of the next lane
    ``nxt``: (how many of ``prev`` to keep, the connector's points, index of the first of
    ``nxt`` after it). It is a quadratic Bezier curve tangent to both lanes, from a vertex of
    the first within ``REACH_M`` of its end to one of the next within ``REACH_M`` of its start,
    the pair whose curve turns least per metre (counting the vertex on either side)."""
    end, start = prev[-1][1], nxt[0][1]
    if np.linalg.norm(end - start) < MEETS_M:
        return len(prev), [], 1
    best = None
    for i in range(len(prev) - 1, 0, -1):
        if np.linalg.norm(prev[i][1] - end) > REACH_M:
            break
        for j in range(len(nxt) - 1):
            _, q, hq = nxt[j]
            if np.linalg.norm(q - start) > REACH_M:
                break
            curve = bezier(prev[i][1], prev[i][2], q, hq)
            if curve is None:
                continue
            cost = sharpest([prev[i - 1][1], prev[i][1], *curve, nxt[j + 1][1]])
            if best is None or cost < best[0]:
                best = (cost, i + 1, curve[:-1], j)
    if best is None:
        raise SystemExit("no connector between two lanes")
    return best[1], best[2], best[3]


def movement(network, lanes):
    """Centre line (n x 2) and stop line (m along it) of a movement through ``lanes``."""
    verts = lane_vertices(network.get_lane(lanes[0]), START_S_M)
    stop = None
    for k, index in enumerate(lanes[1:], start=1):
        nxt = lane_vertices(network.get_lane(index))
        keep, curve, first = connect(verts, nxt)
        verts = verts[:keep]
        if k == 2 and stop is None:
            stop = len(verts) - 1  # leaving the entry lane (the second of an entry)
        verts += [(None, p, None) for p in curve] + nxt[first:]
    points = np.array([v[1] for v in verts])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    return points, (cum[stop] if stop is not None else 0.5 * cum[-1])


def build(name):
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the environments)

    env = gym.make(ENVS[name])
    env.reset(seed=0)
    network = env.unwrapped.road.network
    lanes = []
    for lane_id, turn_name, priority, seq in MOVEMENTS[name]:
        points, stop = movement(network, seq)
        if len(points) > MAX_LANE_POINTS:
            raise SystemExit(f"{lane_id}: {len(points)} vertices, more than {MAX_LANE_POINTS}")
        lanes.append({"id": lane_id, "turn": turn_name, "priority": priority, "stop_s": stop,
                      "points": points, "lanes": seq})
    env.close()
    return lanes


def write_toml(out, name, header, lanes):
    with open(out, "w", encoding="utf-8") as f:
        for line in header:
            f.write(f"# {line}".rstrip() + "\n")
        f.write(f'name = "{name}"\nrule = "levels"\n')
        for lane in lanes:
            via = " ".join(f"{a}>{b}[{i}]" for a, b, i in lane["lanes"])
            pts = ", ".join(f"[{x:.3f}, {y:.3f}]" for x, y in lane["points"])
            f.write(f'\n[[lane]]\nid = "{lane["id"]}"  # {via}\nturn = "{lane["turn"]}"\n'
                    f'priority = {lane["priority"]}\nwidth_m = 4.0\n'
                    f'stop_s_m = {lane["stop_s"]:.3f}\npoints = [{pts}]\n')


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map", choices=sorted(MOVEMENTS))
    ap.add_argument("--out", default=None,
                    help="output file (default deploy/maps/highway-env-MAP.toml)")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    out = args.out or os.path.join(ROOT, "deploy", "maps", f"highway-env-{args.map}.toml")
    lanes = build(args.map)
    header = [
        f"highway-env's `{ENVS[args.map]}` (1.12.1) in its own coordinates (y points south),",
        f"built by `bridges/python/highway_maps.py {args.map}` from its road network: do not",
        "edit by hand, rerun it. Each lane is a movement through highway-env's lanes (named after",
        "its id), joined by straight connectors where they do not meet (highway_maps.py says",
        "how). Every movement has priority level 0: highway-env's roundabout has no right of",
        "way. The ego's route: lane \"ego\".",
    ]
    write_toml(out, f"highway-env-{args.map}", header, lanes)
    print(f"wrote {out}: {len(lanes)} lanes ("
          + ", ".join(f"{l['id']} {len(l['points'])}" for l in lanes) + " vertices)")


if __name__ == "__main__":
    sys.exit(main())
