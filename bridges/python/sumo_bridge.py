"""SUMO co-simulation: Concord drives one vehicle in a SUMO network; SUMO's own drivers are the
other road users.

    python sumo_bridge.py [--scenario left_turn|stream|minor|corridor] [--net NET]
        [--speeds 6,8,10] [--seeds 30] [--first-seed 0] [--policy concord|sumo|both]
        [--duration 40] [--json FILE]

The bridge runs SUMO in-process (libsumo, from the ``libsumo`` and ``eclipse-sumo`` wheels
pinned in requirements.txt) in lock-step with ``concord run --map NET --route ROUTE``, which
reads its lanes, conflicts and right of way from the same ``.net.xml``. Each 0.05 s step
(``--step``): every SUMO vehicle within ``--radius`` m of the ego goes into a scene frame
(centre of its footprint from SUMO's front-bumper position, heading from SUMO's compass angle,
velocity, acceleration, turn signal from its blinkers), the bridge publishes it over iceoryx2
and waits for the decision answering it, and changes the ego's speed by the plan's change of speed
over one step (``vehicle.setSpeed`` with speed mode 32: SUMO applies it without its own safety checks
or right-of-way rules, so what happens is Concord's doing). The ego follows its route's lanes
through the junction, the same polylines Concord plans along. ``--policy sumo`` lets SUMO's
own driver model (Krauss, with SUMO's junction right of way) drive the ego instead: the
baseline.

Scenarios (``--scenario``), on the paper's junction (``deploy/maps/sumo/paper.net.xml``; ego
route ``EC>CS``, the westbound left turn, starting 40 m from the junction's centre at the
initial speed):

* ``left_turn``: one car on the priority road eastbound (``WC>CE``), starting as far from the
  centre ±5 m, at the same speed, which it holds (its maximum speed is set to it, and its
  Krauss imperfection to 0, so that every braking of it is a reaction);
* ``stream``: 2–6 such cars, each the next a time headway of 1.5–5 s behind;
* ``minor``: one car on the minor road northbound (``SC>CN``), which gives way to the ego;
* ``corridor``, across two junctions (``deploy/maps/sumo/corridor.net.xml``: two T-junctions
  80 m apart on one major road; Concord's route ``SJ1>J1J2>J2N`` has one leg per junction):
  the ego comes from the south arm, 40 m from J1, turns right onto the major road, merging
  with an eastbound car that reaches J1 about when it does, and turns left into the north arm
  at J2 across a westbound car that reaches J2 about when it does (both at the initial speed,
  held as above).

Each episode reports: collision (SUMO's collision check, junctions included; on a lane SUMO
counts a gap below the follower's ``minGap``, 2.5 m, as one), success (the ego's rear past the
last junction of its route within ``--duration``), time to clear (until then), PET between the
ego and every other vehicle (``pet.PetGrid`` at every step, and when the smallest happened),
the largest deceleration of any SUMO vehicle within 30 m of the ego, the time the ego stood
(below 0.1 m/s) before clearing, its mean speed and its jerk (RMS and largest, from the change
of its acceleration between steps) until then. The summary prints means, the smallest PET
and the largest deceleration and jerk per policy and speed; ``--json`` writes every episode.
"""

import argparse
import json
import math
import os
import random
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)

import concord_wire as wire  # noqa: E402
from concord_link import ConcordProcess, agent_row, sample, wire_agent  # noqa: E402
from pet import PetGrid  # noqa: E402

MAPS = os.path.join(ROOT, "deploy", "maps", "sumo")
DEFAULT_NET = os.path.join(MAPS, "paper.net.xml")
CORRIDOR_NET = os.path.join(MAPS, "corridor.net.xml")
# Routes on the paper's junction: the ego's westbound left turn, the priority road eastbound,
# the minor road northbound. Each approach lane ends 11.5 m from the centre and is 88.5 m long
# (on the corridor's too).
EGO_ROUTE = ("EC", "CS")
PRIORITY_ROUTE = ("WC", "CE")
MINOR_ROUTE = ("SC", "CN")
APPROACH_END_M = 88.5
START_FROM_CENTRE_M = 40.0
JUNCTION_EDGE_M = 11.5
# The corridor (two junctions 80 m apart): the ego from the south arm turns right at J1 onto
# the major road, merging ahead of or behind its eastbound traffic, then left at J2 into the
# north arm, across its westbound traffic.
CORRIDOR_EGO_ROUTE = ("SJ1", "J1J2", "J2N")
CORRIDOR_EAST_ROUTE = ("WJ1", "J1J2", "J2E")
CORRIDOR_WEST_ROUTE = ("EJ2", "J2J1", "J1W")
CORRIDOR_GAP_M = 80.0
# Each scenario's network, the ego's route and the named routes of the other cars.
PAPER_ROUTES = {"priority": PRIORITY_ROUTE, "minor": MINOR_ROUTE}
SCENARIOS = {
    "left_turn": (DEFAULT_NET, EGO_ROUTE, PAPER_ROUTES),
    "stream": (DEFAULT_NET, EGO_ROUTE, PAPER_ROUTES),
    "minor": (DEFAULT_NET, EGO_ROUTE, PAPER_ROUTES),
    "corridor": (CORRIDOR_NET, CORRIDOR_EGO_ROUTE,
                 {"east": CORRIDOR_EAST_ROUTE, "west": CORRIDOR_WEST_ROUTE}),
}
# A SUMO vehicle within this distance of the ego is "near" it for the braking metric, m.
NEAR_M = 30.0
# Speed mode for the ego under Concord: no safe-speed, acceleration or right-of-way checks.
SPEED_MODE_UNCHECKED = 32
STANDING_MPS = 0.1
SIGNAL_LEFT_BIT, SIGNAL_RIGHT_BIT = 2, 1  # SUMO's VEH_SIGNAL_BLINKER_LEFT / _RIGHT


def sumo_args(net, seed, step):
    return ["-n", net, "--step-length", str(step), "--no-step-log", "true",
            "--no-warnings", "true", "--collision.action", "warn",
            "--collision.check-junctions", "true", "--seed", str(seed)]


def start_pos(from_centre):
    """Position along an approach lane of a car ``from_centre`` m from the junction's centre."""
    return APPROACH_END_M - (from_centre - JUNCTION_EDGE_M)


def heading_of(angle_deg):
    """Mathematical heading, rad, of SUMO's compass angle (0 = north, clockwise)."""
    return math.radians(90.0 - angle_deg)


def state(ls, vid):
    """(centre x, centre y, heading, speed, acceleration, length, width, signal) of a vehicle."""
    fx, fy = ls.vehicle.getPosition(vid)
    h = heading_of(ls.vehicle.getAngle(vid))
    length = ls.vehicle.getLength(vid)
    cx, cy = fx - 0.5 * length * math.cos(h), fy - 0.5 * length * math.sin(h)
    signals = ls.vehicle.getSignals(vid)
    signal = wire.TURN_SIGNALS.index("off")
    if signals & SIGNAL_LEFT_BIT:
        signal = wire.TURN_SIGNALS.index("left")
    elif signals & SIGNAL_RIGHT_BIT:
        signal = wire.TURN_SIGNALS.index("right")
    return (cx, cy, h, ls.vehicle.getSpeed(vid), ls.vehicle.getAcceleration(vid), length,
            ls.vehicle.getWidth(vid), signal)


def to_wire(s, agent_id):
    """The wire agent of a vehicle's ``state``."""
    x, y, h, v, a, _, _, signal = s
    c, sn = math.cos(h), math.sin(h)
    return wire_agent(x, y, v * c, v * sn, h, agent_id, a * c, a * sn, signal)


def add_traffic(ls, scenario, speed, rng):
    """The scenario's SUMO vehicles; returns their ids."""
    for name, edges in SCENARIOS[scenario][2].items():
        ls.route.add(name, list(edges))
    first = START_FROM_CENTRE_M + rng.uniform(-5.0, 5.0)
    if scenario == "corridor":
        # Eastbound at J1 as the ego gets there; westbound at J2 as the ego gets there, which
        # is the ego's path to J2 beyond its start further from J2.
        cars = [("east", first),
                ("west", START_FROM_CENTRE_M + CORRIDOR_GAP_M + rng.uniform(-15.0, 15.0))]
    elif scenario == "minor":
        cars = [("minor", first)]
    elif scenario == "left_turn":
        cars = [("priority", first)]
    elif scenario == "stream":
        cars, behind = [("priority", first)], first
        for _ in range(rng.randint(2, 6) - 1):
            behind += rng.uniform(1.5, 5.0) * speed
            cars.append(("priority", behind))
    else:
        raise ValueError(f"unknown scenario {scenario!r}")
    ids = []
    for k, (route, from_centre) in enumerate(cars):
        vid = f"hdv{k}"
        pos = start_pos(from_centre)
        if pos >= 0.0:
            ls.vehicle.add(vid, route, depart="now", departPos=f"{pos:.3f}",
                           departSpeed=f"{speed:.3f}")
        else:  # further back than the network reaches: enters when it would get there
            ls.vehicle.add(vid, route, depart=f"{-pos / speed:.3f}", departPos="0",
                           departSpeed=f"{speed:.3f}")
        ls.vehicle.setMaxSpeed(vid, speed)
        # No random dawdling: every braking of these cars is a reaction to someone.
        ls.vehicle.setImperfection(vid, 0.0)
        ids.append(vid)
    return ids


class ConcordDriver:
    """The ego's speed from Concord, one decision per step in lock-step."""

    def __init__(self, args):
        road = ["--map", args.net, "--route", ">".join(SCENARIOS[args.scenario][1])]
        self.trace = open(args.trace, "w", encoding="utf-8") if args.trace else None
        self.core_args = (args.concord, road, args.rate, args.config, args.core_log, False, "sumo")
        self.core = None
        self.timeout = args.timeout
        self.step = args.step
        self.sequence = 0
        self.origin_ns = time.monotonic_ns()
        self.ids = {}

    def reset(self):
        """A fresh core per episode, so an episode's outcome does not depend on the ones before."""
        self.close()
        self.core = ConcordProcess(*self.core_args)
        self.ids = {}

    def act(self, ls, ego, others, t):
        """Publishes the scene at simulation time ``t`` and commands the ego's speed; returns
        False when no decision came within the timeout (the ego then brakes at 4 m/s²)."""
        f = wire.SceneFrame()
        self.sequence += 1
        f.sequence = self.sequence
        f.stamp_ns = self.origin_ns + int(round(t * 1e9))
        f.ego = to_wire(ego, 0)
        for k, (vid, s) in enumerate(others[:wire.MAX_AGENTS]):
            f.agents[k] = to_wire(s, self.ids.setdefault(vid, len(self.ids) + 1))
        self.core.link.publish_scene(f)
        d = self.core.link.wait_for_decision(f.sequence, timeout_s=self.timeout)
        if self.trace is not None:
            self.write_trace(f, d, t)
        if d is None or d.n_points == 0:
            ls.vehicle.setSpeed("ego", max(ego[3] - 4.0 * self.step, 0.0))
            return False
        # The planned change of speed over the step, not the planned speed itself: the plan's
        # speed is along the lane (Frenet ds), below the ego's speed whenever its heading
        # differs from the lane's tangent at its centre (on a curve, by up to half a car
        # length's turn), and commanding it would brake the ego a little at every step.
        change = sample(d, self.step)[3] - sample(d, 0.0)[3]
        ls.vehicle.setSpeed("ego", max(ego[3] + change, 0.0))
        return True

    def write_trace(self, f, d, t):
        """One JSON line per frame: the decision and the exact scene, which ``cargo run
        --release --example replay_trace`` replays through the core (CONCORD_REPLAY_MAP)."""
        self.trace.write(json.dumps({
            "t": round(t, 3), "seq": f.sequence,
            "maneuver": None if d is None else wire.MANEUVERS[d.maneuver],
            "plan_v": [] if d is None else [round(d.trajectory[k].speed, 2)
                                            for k in (0, 10, 20, 30, 40, 50) if k < d.n_points],
            "scene": {"time": f.stamp_ns - self.origin_ns, "lane": 0, "ego": agent_row(f.ego),
                      "agents": [agent_row(a) for a in f.agents if a.valid]},
        }) + "\n")

    def close(self):
        if self.core is not None:
            self.core.close()
            self.core = None
        if self.trace is not None:
            self.trace.flush()


def run_episode(ls, args, policy, driver, scenario, speed, seed):
    rng = random.Random(seed * 1000 + int(round(speed * 10)))
    ls.load(sumo_args(args.net, seed, args.step))
    ego_route = SCENARIOS[scenario][1]
    ls.route.add("ego", list(ego_route))
    ls.vehicle.add("ego", "ego", depart="now", departPos=f"{start_pos(START_FROM_CENTRE_M):.3f}",
                   departSpeed=f"{speed:.3f}")
    add_traffic(ls, scenario, speed, rng)
    if policy == "concord":
        ls.vehicle.setSpeedMode("ego", SPEED_MODE_UNCHECKED)
        driver.reset()
    pet = PetGrid()
    e = {"policy": policy, "scenario": scenario, "speed_mps": speed, "seed": seed,
         "collision": False, "success": False, "time_to_clear_s": None, "min_pet_s": None,
         "max_decel_near_mps2": 0.0, "standing_s": 0.0, "avg_speed_mps": None,
         "decisions_missed": 0, "jerk_rms_mps3": None, "max_jerk_mps3": None}
    ls.simulationStep()  # inserts the vehicles
    speeds, accels, t = [], [], ls.simulation.getTime()
    cleared_at = None
    while t < args.duration:
        if "ego" not in ls.vehicle.getIDList():
            break
        ego = state(ls, "ego")
        others = []
        for vid in ls.vehicle.getIDList():
            if vid == "ego":
                continue
            s = state(ls, vid)
            d = math.hypot(s[0] - ego[0], s[1] - ego[1])
            if d <= args.radius:
                others.append((d, vid, s))
                if d <= NEAR_M:
                    e["max_decel_near_mps2"] = max(e["max_decel_near_mps2"], -s[4])
        others.sort(key=lambda o: o[0])
        pet.observe(args.step, [(vid, False, (s[0], s[1]), s[2], s[5], s[6]) for _, vid, s in others]
                    + [("ego", True, (ego[0], ego[1]), ego[2], ego[5], ego[6])])
        if cleared_at is None:
            speeds.append(ego[3])
            accels.append(ego[4])
            if ego[3] < STANDING_MPS:
                e["standing_s"] += args.step
            road = ls.vehicle.getRoadID("ego")
            if road == ego_route[-1] and ls.vehicle.getLanePosition("ego") > ego[5]:
                cleared_at = t
        elif t > cleared_at + args.after_clear:
            break
        if policy == "concord" and not driver.act(ls, ego, [(vid, s) for _, vid, s in others], t):
            e["decisions_missed"] += 1
        ls.simulationStep()
        t = ls.simulation.getTime()
        if any("ego" in (c.collider, c.victim) for c in ls.simulation.getCollisions()):
            e["collision"] = True
            break
    e["success"] = cleared_at is not None and not e["collision"]
    e["time_to_clear_s"] = cleared_at
    e["min_pet_s"] = None if math.isinf(pet.min_pet) else round(pet.min_pet, 3)
    e["min_pet_at_s"] = None if pet.min_pet_t is None else round(pet.min_pet_t, 3)
    e["avg_speed_mps"] = round(sum(speeds) / len(speeds), 3) if speeds else None
    jerks = [(b - a) / args.step for a, b in zip(accels, accels[1:])]
    if jerks:
        e["jerk_rms_mps3"] = round(math.sqrt(sum(j * j for j in jerks) / len(jerks)), 3)
        e["max_jerk_mps3"] = round(max(abs(j) for j in jerks), 3)
    e["max_decel_near_mps2"] = round(e["max_decel_near_mps2"], 3)
    e["standing_s"] = round(e["standing_s"], 3)
    return e


def summarize(episodes):
    """Per (policy, speed): episodes, collisions, success, mean time to clear, smallest and
    median PET, largest and mean deceleration near the ego, mean standing, mean speed, mean RMS
    jerk and the largest jerk."""
    rows = []
    for key in sorted({(e["policy"], e["speed_mps"]) for e in episodes}):
        es = [e for e in episodes if (e["policy"], e["speed_mps"]) == key]
        clear = [e["time_to_clear_s"] for e in es if e["time_to_clear_s"] is not None]
        pets = sorted(e["min_pet_s"] for e in es if e["min_pet_s"] is not None)
        decel = [e["max_decel_near_mps2"] for e in es]
        rows.append({
            "policy": key[0], "speed_mps": key[1], "episodes": len(es),
            "collisions": sum(e["collision"] for e in es),
            "success": sum(e["success"] for e in es),
            "time_to_clear_s": round(sum(clear) / len(clear), 2) if clear else None,
            "min_pet_s": pets[0] if pets else None,
            "median_pet_s": pets[len(pets) // 2] if pets else None,
            "pet_below_1_5": sum(p < 1.5 for p in pets),
            "max_decel_near_mps2": max(decel) if decel else None,
            "mean_decel_near_mps2": round(sum(decel) / len(decel), 2) if decel else None,
            "decel_above_3": sum(d > 3.0 for d in decel),
            "standing_s": round(sum(e["standing_s"] for e in es) / len(es), 2),
            "avg_speed_mps": round(sum(e["avg_speed_mps"] or 0.0 for e in es) / len(es), 2),
            "jerk_rms_mps3": round(sum(e["jerk_rms_mps3"] or 0.0 for e in es) / len(es), 2),
            "max_jerk_mps3": max((e["max_jerk_mps3"] or 0.0 for e in es), default=None),
            "decisions_missed": sum(e["decisions_missed"] for e in es),
        })
    return rows


def summary_line(r):
    return (f"{r['policy']:<8} {r['speed_mps']:>4.0f} m/s: {r['episodes']} episodes, "
            f"{r['collisions']} collisions, {r['success']} cleared, time to clear "
            f"{r['time_to_clear_s']} s, PET min {r['min_pet_s']} median {r['median_pet_s']} "
            f"({r['pet_below_1_5']} below 1.5 s), others' braking near the ego max "
            f"{r['max_decel_near_mps2']} mean {r['mean_decel_near_mps2']} m/s² "
            f"({r['decel_above_3']} above 3), standing {r['standing_s']} s, speed "
            f"{r['avg_speed_mps']} m/s, jerk RMS {r['jerk_rms_mps3']} max {r['max_jerk_mps3']} "
            f"m/s³, decisions missed {r['decisions_missed']}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--net", default=None,
                    help="SUMO network (.net.xml; default: the scenario's, "
                         "deploy/maps/sumo/paper.net.xml or corridor.net.xml)")
    ap.add_argument("--scenario", default="left_turn", choices=list(SCENARIOS))
    ap.add_argument("--speeds", default="6,8,10", help="initial speeds, m/s, comma-separated")
    ap.add_argument("--seeds", type=int, default=30, help="episodes per speed and policy")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="first seed (tuning 0-99; report held-out runs from 500)")
    ap.add_argument("--policy", default="both", choices=["concord", "sumo", "both"])
    ap.add_argument("--duration", type=float, default=40.0, help="episode limit, s")
    ap.add_argument("--after-clear", type=float, default=2.0,
                    help="simulated time after the ego has cleared the junction, s (PET of "
                         "cars behind it)")
    ap.add_argument("--step", type=float, default=0.05, help="simulation step, s")
    ap.add_argument("--radius", type=float, default=100.0,
                    help="SUMO vehicles within this distance of the ego are in the scene, m")
    ap.add_argument("--concord", default=os.path.join(ROOT, "target", "release", "concord"))
    ap.add_argument("--config", default=None, help="concord run --config FILE")
    ap.add_argument("--rate", type=float, default=100.0, help="concord run --rate, Hz")
    ap.add_argument("--timeout", type=float, default=1.0, help="wait for a decision, s")
    ap.add_argument("--core-log", default=None, help="append concord run's output here")
    ap.add_argument("--json", default=None, help="write every episode and the summary here")
    ap.add_argument("--trace", default=None,
                    help="write every frame and decision of Concord's episodes here (JSON lines)")
    args = ap.parse_args(argv)
    args.net = args.net or SCENARIOS[args.scenario][0]
    if not os.path.exists(args.net):
        ap.error(f"no network {args.net}")
    policies = ["concord", "sumo"] if args.policy == "both" else [args.policy]
    if "concord" in policies and not os.access(args.concord, os.X_OK):
        ap.error(f"no concord binary at {args.concord} (cargo build --release)")
    speeds = [float(s) for s in args.speeds.split(",")]
    import libsumo as ls

    ls.start(["sumo", *sumo_args(args.net, args.first_seed, args.step)])
    driver = ConcordDriver(args) if "concord" in policies else None
    episodes = []
    total = len(policies) * len(speeds) * args.seeds
    started = time.monotonic()
    try:
        for policy in policies:
            for speed in speeds:
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    e = run_episode(ls, args, policy, driver, args.scenario, speed, seed)
                    episodes.append(e)
                    print(f"[{len(episodes)}/{total}, {time.monotonic() - started:.0f} s] "
                          f"{policy} {speed:g} m/s seed {seed}: "
                          f"{'collision' if e['collision'] else 'cleared' if e['success'] else 'time limit'}"
                          f", clear {e['time_to_clear_s']} s, PET {e['min_pet_s']} s, "
                          f"braking near {e['max_decel_near_mps2']} m/s²", flush=True)
    finally:
        if driver is not None:
            driver.close()
        ls.close()
    rows = summarize(episodes)
    for r in rows:
        print(summary_line(r))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump({"net": os.path.relpath(args.net, ROOT), "scenario": args.scenario,
                       "summary": rows, "episodes": episodes}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
