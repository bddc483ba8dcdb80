"""Oracle ceiling for highway-env's intersection: is a seed solvable by any simple ego speed
profile?

    python highway_bridge.py --env intersection-v0 --oracle-ceiling --seeds 100 --json ceil.json
    python highway_bridge.py --env intersection-v0 --seeds 50 --ceiling ceil.json   # a policy

For each seed the environment is reset exactly as a normal ``--policy concord`` run resets it
(``highway_bridge.make_env``: the same configuration, policy frequency, spawn-probability
scaling, ContinuousAction ranges and duration), and for every profile of a family (below) a
``copy.deepcopy`` of it is driven with that profile: the longitudinal acceleration comes from
the profile, the steering follows the ego's planned route lanes (pure pursuit, as the bridge
steers Concord's plans), both converted to the ContinuousAction units of the bridge (``to_unit``
over ``ACCEL_RANGE`` and ``STEERING_RANGE``) and held for one policy period. A profile
*arrives* when the ego meets the environment's arrival rule (``has_arrived``: 25 m into the
exit lane) before the environment truncates the episode, without a crash; a seed is
*reachable* when any profile arrives.

Profile family (``FAMILIES``; ``--family small`` for tests, or a JSON file with the same keys).
``T`` is the policy period; every speed change is commanded as the acceleration that reaches the
target speed at the end of the period, clipped to the rate of the phase.

* ``hold`` profiles ``{hold} w={w} a={a} v={v}``: until time ``w`` the ego yields in one of three
  ways, then it accelerates at ``a`` m/s² to the cruise speed ``v`` and holds it:
  - ``stop``: brakes at once at 3 m/s² (intersection-v0's COMFORT_ACC_MIN) to a standstill
    (17 m on; the ego spawns 60 + 5 N(1, 1) m along its 100 m approach, so this is typically
    10 m before the stop line) and stands;
  - ``line``: holds its speed and brakes at 3 m/s² to stop with its centre at the stop line
    (2.5 m before the end of the approach lane, where the junction starts) and stands there;
  - ``crawl``: slows at 3 m/s² to 2 m/s and creeps on, stopping at the stop line if it gets
    there.
  No hold phase passes the stop line. ``w = 0`` is the same for the three (listed once, as
  ``go``).
* ``const v={v}``: change to speed ``v`` at up to 6 m/s² and hold it.

Default family: w in {0, 0.4, ..., 8} s, a in {1.5, 3, 6} m/s², v in {4.5, 7, 9, 10} m/s, the
three holds, and constant speeds {2, 3, 4.5, 6, 7, 8, 9, 10, 11, 12} m/s (742 profiles).

How it is computed. Until it crashes, the ego's motion under an open-loop profile does not
depend on the traffic (the ego is a plain ``Vehicle``: nobody makes it yield, and a collision's
impact also sets ``crashed``, which ends the episode). So all profiles are first driven in lock
step on a copy of the environment with the ego alone (``plan_tree``; profiles in the same state
choosing the same action share one vehicle), which gives each profile's actions and its
traffic-free arrival step: a profile that cannot arrive before the episode ends even on an
empty road is *too slow* and is not simulated with traffic. The profiles' action sequences form
a tree (all hold profiles of one kind are identical until their ``w``, and every profile until
its speed first differs); the traffic is simulated once per tree node, depth first
(``explore``), deep-copying the environment where branches split, and a crash ends every
profile below it. At every step the ego's state and arrival are checked to be exactly those
computed without traffic (an ``AssertionError`` otherwise). The search tries the profiles in
the order of their traffic-free arrival, the earliest first.

Options (``highway_bridge.py``): ``--oracle-courteous MPS2`` ends a profile as ``forces`` at
the first step in which it makes another vehicle brake harder than MPS2 beyond its braking
without the ego (``highway_bridge.ImposedBraking``); ``--oracle-min-pet S`` ends it as
``close`` at the first step in which it crosses or merges with another vehicle at a
post-encroachment time below S (``highway_bridge.PetTracker``, which rides on the environment's
road, so every branch carries its own history). ``--oracle-first`` stops a seed's search at its
first arriving profile (reachability only; the profiles not tried are ``untried``, so the
per-profile counts cover the profiles tried), ``--oracle-budget N`` stops it after N simulated
steps (a seed without an arrival by then is *undecided*: counted as not reachable and listed
apart), ``--oracle-reuse FILE`` takes the reachable seeds of an oracle run of the same
environment, frequency, family and rules (courteous, PET) at a shorter or equal duration as
they are (the duration only truncates, so a profile arriving in the shorter episode arrives at
the same step of the longer one) and searches the others only, ``--family`` (``default``,
``small`` or a JSON file).

Speed. highway-env's intersection costs about 25 ms of CPU per 0.2 s step here even without the
observation; about half of ``env.step`` is ``RegulatedRoad.enforce_road_rules`` predicting
every pair of vehicles, in which the ego's ``Vehicle.predict_trajectory_constant_speed``
deep-copies the whole road for each pair. Inside ``fast_regulation()`` the oracle (never the
bridge's normal runs) predicts each vehicle once per enforcement and copies the ego without
its road: the same arithmetic, so the same states bit for bit, which ``test_highway_bridge``
checks against ``env.step``. It also steps the unwrapped environment without computing
observations and rewards (``fast_step``; neither changes the state). Measured on this machine
(2 shared cores, nice 10), intersection-v0 at 13 s: the whole default family takes 2-4 min
per seed (5,000-8,000 simulated steps); with ``--oracle-first`` a reachable seed takes 10-40 s
(most of it the traffic-free planning of the 742 profiles) and an unreachable one, which must
try every profile, about 2 min. The route following keeps the ego within 0.4 m of its lane's centre
at 9 m/s (0.6 m at 12 m/s, on the turn). The progress lines print the time per seed and an
estimate of the rest.

Output (``--json``): the settings, per seed whether it is reachable, the profiles that arrive,
each profile's outcome, and per profile how many seeds it arrives on; ``--ceiling FILE`` makes
a normal run report its success as a share of the reachable seeds and list the unreachable
seeds it failed or passed.
"""

import copy
import json
import math
import os
import sys
import time
from contextlib import contextmanager

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import highway_bridge as hb  # noqa: E402

# Braking of the hold phases, m/s² (intersection-v0 sets its traffic's COMFORT_ACC_MIN to -3).
HOLD_BRAKE = 3.0
CRAWL_SPEED = 2.0
CONST_ACCEL = 6.0
# The ego's pure pursuit aims this far ahead on its route: max(min, speed * time).
PURSUIT_MIN_M = 4.0
PURSUIT_TIME_S = 0.6

FAMILIES = {
    "default": {
        "waits_s": [round(0.4 * k, 1) for k in range(21)],
        "holds": ["stop", "line", "crawl"],
        "accels_mps2": [1.5, 3.0, 6.0],
        "cruise_mps": [4.5, 7.0, 9.0, 10.0],
        "const_mps": [2.0, 3.0, 4.5, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0],
    },
    # The default family within the lanes' 10 m/s speed limit (the speed Concord keeps to
    # there: desired_speed_mps in deploy/highway-env.toml).
    "limit": {
        "waits_s": [round(0.4 * k, 1) for k in range(21)],
        "holds": ["stop", "line", "crawl"],
        "accels_mps2": [1.5, 3.0, 6.0],
        "cruise_mps": [4.5, 7.0, 9.0, 10.0],
        "const_mps": [2.0, 3.0, 4.5, 6.0, 7.0, 8.0, 9.0, 10.0],
    },
    "small": {  # for tests: 5 profiles
        "waits_s": [0.0, 2.4],
        "holds": ["line"],
        "accels_mps2": [3.0],
        "cruise_mps": [7.0, 9.0],
        "const_mps": [10.0],
    },
}


def load_family(name):
    if name in FAMILIES:
        return dict(FAMILIES[name])
    with open(name, encoding="utf-8") as f:
        fam = json.load(f)
    missing = set(FAMILIES["default"]) - set(fam)
    if missing:
        raise SystemExit(f"family {name}: missing {sorted(missing)}")
    return fam


def profiles_of(family):
    """The family's profiles: dicts with a name, the hold kind (None: constant), w, a, v."""
    out = []
    for w in family["waits_s"]:
        for hold in (["go"] if w == 0 else family["holds"]):
            for a in family["accels_mps2"]:
                for v in family["cruise_mps"]:
                    out.append({"name": f"{hold} w={w:g} a={a:g} v={v:g}", "hold": hold,
                                "w": float(w), "a": float(a), "v": float(v)})
    for v in family["const_mps"]:
        out.append({"name": f"const v={v:g}", "hold": None, "w": 0.0, "a": CONST_ACCEL,
                    "v": float(v)})
    return out


# ---------------------------------------------------------------------------------------------
# Stepping highway-env


def fast_step(u, action):
    """``env.step`` of the unwrapped environment ``u`` without the observation, the reward and
    the info (which do not change the state): AbstractEnv.step's clock and simulation, then
    IntersectionEnv.step's clearing and spawning. Returns (terminated, truncated)."""
    from highway_env.envs.intersection_env import IntersectionEnv

    u.time += 1 / u.config["policy_frequency"]
    u._simulate(action)
    if isinstance(u, IntersectionEnv):
        u._clear_vehicles()
        u._spawn_vehicle(spawn_probability=u.config["spawn_probability"])
    return bool(u._is_terminated()), bool(u._is_truncated())


@contextmanager
def fast_regulation():
    """Within the block, ``RegulatedRoad.enforce_road_rules`` computes each vehicle's
    constant-speed prediction once per call instead of once per pair, and a plain ``Vehicle``
    (the ego) predicts on a copy of itself without deep-copying the road it is on. Both are the
    same computations on the same numbers (the road is only read), so the states stay
    identical; outside the block highway-env is unchanged."""
    from highway_env.road.regulation import RegulatedRoad
    from highway_env.vehicle.controller import ControlledVehicle
    from highway_env.vehicle.kinematics import Vehicle

    orig_vehicle = Vehicle.__dict__["predict_trajectory_constant_speed"]
    orig_controlled = ControlledVehicle.__dict__["predict_trajectory_constant_speed"]
    orig_enforce = RegulatedRoad.__dict__["enforce_road_rules"]
    cache = {"on": None}

    def light_vehicle_prediction(self, times):
        if self.prediction_type == "zero_steering":
            action = {"acceleration": 0.0, "steering": 0.0}
        elif self.prediction_type == "constant_steering":
            action = {"acceleration": 0.0, "steering": self.action["steering"]}
        else:
            raise ValueError("Unknown predition type")
        dt = np.diff(np.concatenate(([0.0], times)))
        positions, headings = [], []
        v = copy.copy(self)  # shares the road, which Vehicle.step only reads
        v.position = self.position.copy()
        v.action = dict(self.action)
        v.log = []
        v.history = copy.copy(self.history)
        v.act(action)
        for t in dt:
            v.step(t)
            positions.append(v.position.copy())
            headings.append(v.heading)
        return positions, headings

    def memo(fn):
        def prediction(self, times):
            memo_ = cache["on"]
            if memo_ is None:
                return fn(self, times)
            key = (id(self), tuple(times))
            if key not in memo_:
                memo_[key] = (self, fn(self, times))  # the vehicle is kept: ids stay unique
            return memo_[key][1]
        return prediction

    def enforce(self):
        cache["on"] = {}
        try:
            return orig_enforce(self)
        finally:
            cache["on"] = None

    Vehicle.predict_trajectory_constant_speed = memo(light_vehicle_prediction)
    ControlledVehicle.predict_trajectory_constant_speed = memo(orig_controlled)
    RegulatedRoad.enforce_road_rules = enforce
    try:
        yield
    finally:
        Vehicle.predict_trajectory_constant_speed = orig_vehicle
        ControlledVehicle.predict_trajectory_constant_speed = orig_controlled
        RegulatedRoad.enforce_road_rules = orig_enforce


def vehicle_states(u):
    """Every vehicle's state, in road order, and the environment's RNG state: what a replay
    must reproduce exactly."""
    out = []
    for v in u.road.vehicles:
        out.append((type(v).__name__, tuple(float(p) for p in v.position), float(v.heading),
                     float(v.speed), bool(v.crashed), tuple(v.lane_index),
                     float(getattr(v, "target_speed", 0.0))))
    return out, str(u.np_random.bit_generator.state)


# ---------------------------------------------------------------------------------------------
# The ego's route and its controller


def ego_route(u):
    """The ego's planned route as lanes: its lane, then the shortest path to the environment's
    destination (what ``ControlledVehicle.plan_route_to`` plans; ContinuousAction's plain
    ``Vehicle`` has no route of its own)."""
    ego = u.vehicle
    net = u.road.network
    path = net.shortest_path(ego.lane_index[1], u.config["destination"])
    lanes = [net.get_lane(ego.lane_index)]
    for a, b in zip(path[:-1], path[1:]):
        lanes.append(net.get_lane((a, b, 0)))
    return lanes


class RouteFollower:
    """Pure pursuit on the route lanes: aim at the route's centre line
    max(PURSUIT_MIN_M, speed * PURSUIT_TIME_S) ahead of the ego's projection, steer the
    constant-steering arc of highway-env's bicycle model through it (``hb.pursuit_slip``)."""

    def __init__(self, lanes):
        self.lanes = lanes

    def s_on(self, position):
        """(lane index along the route, longitudinal coordinate on it): the first lane whose
        end the ego has not passed."""
        k = 0
        s = self.lanes[0].local_coordinates(position)[0]
        while k + 1 < len(self.lanes) and s > self.lanes[k].length:
            k += 1
            s = self.lanes[k].local_coordinates(position)[0]
        return k, s

    def route_s(self, position):
        """Distance along the route from the start of its first lane."""
        k, s = self.s_on(position)
        return sum(lane.length for lane in self.lanes[:k]) + s

    def point_ahead(self, position, dist):
        k, s = self.s_on(position)
        s += dist
        while k + 1 < len(self.lanes) and s > self.lanes[k].length:
            s -= self.lanes[k].length
            k += 1
        return self.lanes[k].position(s, 0.0)

    def steering(self, vehicle):
        ahead = max(PURSUIT_MIN_M, vehicle.speed * PURSUIT_TIME_S)
        aim = self.point_ahead(vehicle.position, ahead)
        dx, dy = aim[0] - vehicle.position[0], aim[1] - vehicle.position[1]
        dist = math.hypot(dx, dy)
        if dist < 0.5:
            return 0.0
        beta = hb.pursuit_slip(math.atan2(dy, dx) - vehicle.heading, dist)
        return min(max(math.atan(2.0 * math.tan(beta)), hb.STEERING_RANGE[0]),
                   hb.STEERING_RANGE[1])


def profile_accel(p, t, v, gap, period):
    """The profile's acceleration for the period starting at time ``t`` at speed ``v``, with
    ``gap`` m left to the stop line (its centre position, None once past the approach)."""
    def toward(target, rate):
        return min(max((target - v) / period, -rate), rate)

    if p["hold"] is None or t >= p["w"] - 1e-9:
        return toward(p["v"], p["a"])
    if p["hold"] == "stop":
        a = toward(0.0, HOLD_BRAKE)
    elif p["hold"] == "crawl":
        a = toward(CRAWL_SPEED, HOLD_BRAKE)
    else:  # line
        a = 0.0
    if gap is not None:
        # Never past the stop line while holding: brake to stop at it once holding this
        # acceleration one more period would need more than HOLD_BRAKE.
        v1 = max(v + a * period, 0.0)
        gap1 = gap - 0.5 * (v + v1) * period
        if gap <= 0.05:
            a = -v / period
        elif gap1 <= 0.0 or v1 * v1 / (2.0 * gap1) > HOLD_BRAKE:
            a = max(-v * v / (2.0 * gap), -v / period)
    return min(max(a, hb.ACCEL_RANGE[0]), hb.ACCEL_RANGE[1])


def light_copy(v):
    """A copy of vehicle ``v`` sharing its road (which ``Vehicle.step`` only reads)."""
    c = copy.copy(v)
    c.position = v.position.copy()
    c.action = dict(v.action)
    c.log = []
    c.history = copy.copy(v.history)
    return c


def plan_tree(u0, profiles, period):
    """Drive every profile on an empty road (a copy of ``u0`` with the ego alone), all in lock
    step, profiles in the same state and choosing the same action sharing one vehicle.
    Returns the tree of their action sequences (``Node``; each node holds the ego's state after
    its step and the profiles through it) and, per profile, the step it arrives at (None: not
    before the environment truncates the episode). Each step is what ``fast_step`` does to the
    ego: ContinuousAction's action held over the period's simulation frames."""
    c = copy.deepcopy(u0)
    c.road.vehicles = [c.vehicle]
    action_type = c.action_type
    follower = RouteFollower(ego_route(c))
    net = c.road.network
    c.vehicle.road = None
    arrival_s = sum(lane.length for lane in follower.lanes[:-1]) + 25.0  # has_arrived's 25 m
    stop_lane = follower.lanes[0]
    stop_s = stop_lane.length - hb.VEHICLE_LENGTH / 2.0
    frames = int(c.config["simulation_frequency"] // c.config["policy_frequency"])
    dt = 1 / c.config["simulation_frequency"]
    root = Node()
    root.below = list(range(len(profiles)))
    arrival = [None] * len(profiles)
    groups = [(c.vehicle, root)]
    clock = c.time
    step = 0
    while groups:
        clock += 1 / c.config["policy_frequency"]
        nxt = []
        for vehicle, node in groups:
            k, s = follower.s_on(vehicle.position)
            gap = stop_s - s if k == 0 else None
            steer_unit = hb.to_unit(follower.steering(vehicle), *hb.STEERING_RANGE)
            split = {}
            # A profile that cannot arrive before the end even at the highest speed it will
            # reach, max(now, cruise), is too slow (a 3 m margin for the pursuit's shortcut of
            # the turn, under 1 m). The steps left, this one included, last less than
            # duration - clock + 2 periods (the clock may end just short of the duration).
            left = arrival_s - follower.route_s(vehicle.position) - 3.0
            time_left = c.config["duration"] - clock + 2.0 * period
            for idx in node.below:
                if left > max(float(vehicle.speed), profiles[idx]["v"]) * time_left:
                    continue
                accel = profile_accel(profiles[idx], step * period, float(vehicle.speed), gap,
                                      period)
                a = np.array([hb.to_unit(accel, *hb.ACCEL_RANGE), steer_unit],
                             dtype=np.float32)
                split.setdefault(a.tobytes(), (a, []))[1].append(idx)
            for key, (a, members) in split.items():
                v = light_copy(vehicle)
                cmd = action_type.get_action(a)  # (sets the speed range on c's ego)
                v.MIN_SPEED, v.MAX_SPEED = action_type.speed_range
                v.act(cmd)
                for _ in range(frames):
                    v.step(dt)  # without a road: no lane look-up (on_state_update)
                # The lane only decides the arrival (has_arrived: 25 m into an exit lane),
                # which cannot happen before 20 m into the route's exit lane; ``explore``
                # checks that the environment agrees at every step.
                k1, s1 = follower.s_on(v.position)
                if k1 == len(follower.lanes) - 1 and s1 >= 20.0:
                    v.lane_index = net.get_closest_lane_index(v.position, v.heading)
                    v.lane = net.get_lane(v.lane_index)
                child = Node()
                child.state = ego_state(v)
                child.below = members
                node.children[key] = (a, child)
                if c.has_arrived(v):
                    child.ends = list(members)
                    for idx in members:
                        arrival[idx] = step + 1
                elif clock < c.config["duration"]:
                    nxt.append((v, child))
        groups = nxt
        step += 1
    prune(root, arrival)
    return root, arrival


def prune(node, arrival):
    """Drop the profiles that never arrive (and the branches only they use)."""
    node.below = [i for i in node.below if arrival[i] is not None]
    for key in list(node.children):
        child = node.children[key][1]
        prune(child, arrival)
        if not child.below:
            del node.children[key]


def ego_state(v):
    return (float(v.position[0]), float(v.position[1]), float(v.heading), float(v.speed))


# ---------------------------------------------------------------------------------------------
# The tree of action sequences


class Node:
    __slots__ = ("children", "ends", "state", "below")

    def __init__(self):
        self.children = {}  # action bytes -> (action, Node)
        self.ends = []  # profiles arriving at this node
        self.state = None  # the ego's traffic-free state after this node's step
        self.below = []  # every profile through this node


# A profile's outcome on a seed: it arrives, crashes, imposes harder braking than allowed
# (``forces``, with ``--oracle-courteous``), passes closer in time than allowed (``close``,
# with ``--oracle-min-pet``), cannot arrive in time even on an empty road, or was not tried
# (the search stopped at the first arrival).
OUTCOMES = ("arrived", "crash", "forces", "close", "too_slow", "untried")


class OutOfBudget(Exception):
    """The seed's step budget (``--oracle-budget``) ran out before the search ended."""


def explore(env, node, depth, period, outcome, counters, priority, first=False, courteous=None,
            min_pet=None):
    """Depth first from ``node`` with the unwrapped environment ``env`` in its state (consumed),
    children in the order of ``priority`` (the best profile below them first). Fills
    ``outcome[profile] = (kind, time)``; with ``first``, stops at the first arrival and returns
    True. With ``courteous`` (m/s²), a step in which the ego imposes harder braking on another
    vehicle (``highway_bridge.ImposedBraking``) ends every profile below it as ``forces``; the
    first step does not count (what the traffic does then answers where the environment placed
    the ego, e.g. close in front of a follower, not anything the ego did). With ``min_pet``
    (s), a step in which the ego and another vehicle cross or merge with a post-encroachment
    time below it (``highway_bridge.PetTracker``, carried on the environment's road) ends
    every profile below it as ``close``."""
    items = sorted(node.children.values(), key=lambda ac: min(priority[i] for i in ac[1].below))
    for n, (action, child) in enumerate(items):
        e = env if n == len(items) - 1 else copy.deepcopy(env)
        if e is not env:
            counters["copies"] += 1
        if counters["steps"] >= counters["budget"]:
            raise OutOfBudget()
        if courteous is None:
            fast_step(e, action)
        else:
            imposed = hb.ImposedBraking()
            imposed.t = depth * period
            with imposed.attached(e):
                fast_step(e, action)
        counters["steps"] += 1
        t = (depth + 1) * period
        if e.vehicle.crashed:
            for idx in child.below:
                outcome[idx] = ("crash", t)
            continue
        if courteous is not None and imposed.max_decel > courteous:
            for idx in child.below:
                outcome[idx] = ("forces", t)
            continue
        if min_pet is not None and e.road.pet_tracker.min_pet < min_pet:
            for idx in child.below:
                outcome[idx] = ("close", t)
            continue
        if ego_state(e.vehicle) != child.state or e.has_arrived(e.vehicle) != bool(child.ends):
            raise AssertionError(f"the ego left its traffic-free course at {t:.1f} s: "
                                 f"{ego_state(e.vehicle)} != {child.state}")
        for idx in child.ends:
            outcome[idx] = ("arrived", t)
        if first and child.ends:
            return True
        if child.children and explore(e, child, depth + 1, period, outcome, counters, priority,
                                      first, courteous, min_pet):
            return True
    return False


def oracle_seed(env, seed, profiles, period, first=False, budget=None, courteous=None,
                min_pet=None):
    """Every profile on ``seed``: whether the seed is reachable, each profile's outcome
    (``arrived``, ``crash`` with its time, ``too_slow``: does not arrive within the duration
    even on an empty road; with ``first``, the search stops at the first arrival and the
    profiles it did not try are ``untried``) and the work it took. Profiles are tried in the
    order of their traffic-free arrival time, the earliest first."""
    started = time.process_time()
    env.reset(seed=seed)
    u0 = env.unwrapped
    root, arrival = plan_tree(u0, profiles, period)
    outcome = [("too_slow", None) if a is None else ("untried", None) for a in arrival]
    priority = [(a if a is not None else math.inf, i) for i, a in enumerate(arrival)]
    counters = {"steps": 0, "copies": 0, "budget": budget or math.inf}
    exhausted = False
    if root.below:
        try:
            start = copy.deepcopy(u0)
            if min_pet is not None:
                start.road.pet_tracker = hb.PetTracker(start.vehicle)
            explore(start, root, 0, period, outcome, counters, priority, first, courteous,
                    min_pet)
        except OutOfBudget:
            exhausted = True
    arrived = [i for i, o in enumerate(outcome) if o[0] == "arrived"]
    return {
        "seed": seed,
        "reachable": bool(arrived),
        # True: the step budget ran out with no arrival found, so the seed is undecided
        # (counted as not reachable, listed apart).
        "undecided": exhausted and not arrived,
        "arrived_profiles": [profiles[i]["name"] for i in arrived],
        "earliest_arrival_s": min((outcome[i][1] for i in arrived), default=None),
        "counts": {k: sum(o[0] == k for o in outcome)
                   for k in OUTCOMES},
        "outcomes": [list(o) for o in outcome],
        "simulated_steps": counters["steps"],
        "copies": counters["copies"],
        "cpu_s": time.process_time() - started,
    }


def reusable(path, env_name, duration_s, policy_frequency, family, courteous=None,
             min_pet=None):
    """The reachable seeds of an earlier oracle run (``--oracle-reuse``) of the same
    environment, policy frequency, family, ``courteous`` and ``min_pet`` at a duration no
    longer than ``duration_s``: {seed: its row}. A profile that arrives within a shorter
    episode arrives at the same step of a longer one (the duration only truncates: the ego's
    actions and the traffic up to the arrival are the same), so those seeds are reachable
    without a search."""
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    o = doc["oracle"]
    if (o["env"], o["policy_frequency_hz"], o["family"]) != (env_name, policy_frequency, family):
        raise SystemExit(f"--oracle-reuse {path}: another environment, frequency or family")
    if (o.get("max_imposed_decel_mps2"), o.get("min_pet_s")) != (courteous, min_pet):
        raise SystemExit(f"--oracle-reuse {path}: other --oracle-courteous or --oracle-min-pet")
    if o["duration_s"] > duration_s:
        raise SystemExit(f"--oracle-reuse {path}: measured at a longer duration "
                         f"({o['duration_s']} s)")
    return {r["seed"]: r for r in doc["seeds"] if r["reachable"]}, o["duration_s"]


def run_oracle(env_name, spec, seeds, family, policy_frequency=5, progress=None, first=False,
               budget=None, reuse=None, checkpoint=None, courteous=None, min_pet=None):
    """The oracle over ``seeds``; the JSON document ``--oracle-ceiling --json`` writes.
    ``reuse``: the result of ``reusable``, whose seeds are taken as they are; ``checkpoint``
    is called with the document so far after every seed."""
    if not env_name.startswith("intersection"):
        raise SystemExit("the oracle's profile family is defined for the intersection only")
    period = 1.0 / policy_frequency
    profiles = profiles_of(family)
    env = hb.make_env(env_name, "concord", policy_frequency, spec)
    known, known_duration = reuse or ({}, None)
    rows = []
    started = time.monotonic()
    try:
        with fast_regulation(), hb.PetTracker.recording():
            for n, seed in enumerate(seeds):
                t0 = time.monotonic()
                if seed in known:
                    r = dict(known[seed])
                    # Profiles too slow for the shorter episode may arrive in this one.
                    r["outcomes"] = [o if o[0] != "too_slow" else ["untried", None]
                                     for o in r["outcomes"]]
                    r["counts"] = {k: sum(o[0] == k for o in r["outcomes"])
                                   for k in OUTCOMES}
                    r["reused_from_duration_s"] = known_duration
                    r["simulated_steps"] = r["copies"] = 0
                    r["cpu_s"] = 0.0
                else:
                    r = oracle_seed(env, seed, profiles, period, first, budget, courteous,
                                    min_pet)
                r["wall_s"] = time.monotonic() - t0
                rows.append(r)
                if progress:
                    elapsed = time.monotonic() - started
                    per_seed = elapsed / (n + 1)
                    progress(f"oracle {env_name} seed {seed:3d}: "
                             f"{'reachable' if r['reachable'] else 'UNDECIDED' if r['undecided'] else 'UNREACHABLE':11s} "
                             f"{r['counts']['arrived']:3d} of {len(profiles)} profiles arrive "
                             f"({r['counts']['crash']} crash, "
                             f"{r['counts'].get('forces', 0)} forcing, "
                             f"{r['counts'].get('close', 0)} close, {r['counts']['too_slow']} too "
                             f"slow, {r['counts']['untried']} untried), "
                             f"{r['simulated_steps']} steps, {r['wall_s']:5.1f} s; "
                             f"{per_seed:5.1f} s per seed, about "
                             f"{per_seed * (len(seeds) - n - 1) / 60:5.1f} min left")
                if checkpoint:
                    checkpoint(document(env_name, spec, family, profiles, policy_frequency,
                                        first, budget, rows, time.monotonic() - started,
                                        courteous, min_pet))
    finally:
        env.close()
    return document(env_name, spec, family, profiles, policy_frequency, first, budget, rows,
                    time.monotonic() - started, courteous, min_pet)


def document(env_name, spec, family, profiles, policy_frequency, first, budget, rows, wall_s,
             courteous=None, min_pet=None):
    per_profile = [0] * len(profiles)
    for r in rows:
        for i, o in enumerate(r["outcomes"]):
            per_profile[i] += o[0] == "arrived"
    reachable = [r["seed"] for r in rows if r["reachable"]]
    return {
        "oracle": {"env": env_name, "duration_s": spec["duration_s"],
                   "policy_frequency_hz": policy_frequency, "family": family,
                   "first_arrival_only": first, "step_budget": budget,
                   "max_imposed_decel_mps2": courteous, "min_pet_s": min_pet,
                   "profiles": [p["name"] for p in profiles],
                   "hold_brake_mps2": HOLD_BRAKE, "crawl_speed_mps": CRAWL_SPEED,
                   "pursuit": [PURSUIT_MIN_M, PURSUIT_TIME_S]},
        "summary": {"seeds": len(rows), "reachable": len(reachable),
                    "unreachable_seeds": [r["seed"] for r in rows if not r["reachable"]],
                    "undecided_seeds": [r["seed"] for r in rows if r["undecided"]],
                    "profile_arrivals": dict(zip((p["name"] for p in profiles), per_profile)),
                    "wall_s": wall_s},
        "seeds": rows,
    }


def group_counts(doc):
    """Arrivals per family member: by hold kind, wait, acceleration, cruise speed (the number
    of seeds on which at least one profile of that kind arrives)."""
    profiles = profiles_of(doc["oracle"]["family"])
    groups = {}
    for r in doc["seeds"]:
        hit = set()
        for p, o in zip(profiles, r["outcomes"]):
            if o[0] != "arrived":
                continue
            hit.add(("kind", p["hold"] or "const"))
            if p["hold"] is not None:
                hit.add(("w", p["w"]))
                hit.add(("a", p["a"]))
            hit.add(("v", p["v"]))
        for h in hit:
            groups[h] = groups.get(h, 0) + 1
    return groups


def report_lines(doc):
    s = doc["summary"]
    o = doc["oracle"]
    lines = [f"oracle {o['env']} duration {o['duration_s']:g} s: {s['reachable']} of "
             f"{s['seeds']} seeds reachable; unreachable {s['unreachable_seeds']}"
             + (f" (of which undecided, step budget spent: {s['undecided_seeds']})"
                if s.get("undecided_seeds") else "")]
    g = group_counts(doc)
    for key, label in (("kind", "hold kind"), ("w", "wait w (s)"), ("a", "accel a (m/s²)"),
                       ("v", "speed v (m/s)")):
        vals = sorted(k[1] for k in g if k[0] == key)
        if vals:
            lines.append(f"seeds reached by some profile with {label}: "
                         + ", ".join(f"{v}: {g[(key, v)]}" for v in vals))
    best = sorted(s["profile_arrivals"].items(), key=lambda kv: -kv[1])[:10]
    lines.append("profiles arriving on the most seeds: "
                 + "; ".join(f"{n} {c}" for n, c in best))
    return lines


def main_oracle(args, spec, seeds):
    family = load_family(args.family)
    print(f"oracle: {len(profiles_of(family))} profiles per seed, {len(seeds)} seeds",
          flush=True)
    reuse = (reusable(args.oracle_reuse, args.env, spec["duration_s"], args.policy_frequency,
                      family, args.oracle_courteous, args.oracle_min_pet)
             if args.oracle_reuse else None)
    def write(doc):
        if args.oracle_reuse:
            doc["oracle"]["reused"] = args.oracle_reuse
        if args.json:  # after every seed, so that a long run stopped early keeps its seeds
            with open(args.json + ".tmp", "w", encoding="utf-8") as f:
                json.dump(doc, f, indent=1)
            os.replace(args.json + ".tmp", args.json)

    doc = run_oracle(args.env, spec, seeds, family, args.policy_frequency,
                     progress=lambda line: print(line, flush=True), first=args.oracle_first,
                     budget=args.oracle_budget, reuse=reuse, checkpoint=write,
                     courteous=args.oracle_courteous, min_pet=args.oracle_min_pet)
    write(doc)
    for line in report_lines(doc):
        print(line)
    return doc
