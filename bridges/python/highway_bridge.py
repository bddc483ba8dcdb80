"""Drive Concord in lock-step with highway-env (1.12.1) and report collisions, success and speed.

    python highway_bridge.py --env intersection-v0 --seeds 50                  # Concord
    python highway_bridge.py --env intersection-v0 --seeds 50 --policy idle   # a baseline
    python highway_bridge.py --env merge-v0 --seeds 50                         # Concord
    python highway_bridge.py --env intersection-v2 --seeds 50 --duration 20   # longer episodes
    python highway_bridge.py --env intersection-v0 --oracle-ceiling --oracle-first \
        --seed-list 0-99,500-599 --json ceiling.json                          # the oracle
    python highway_bridge.py --env intersection-v0 --seed-list 0-99,500-599 --ceiling ceiling.json
    python highway_bridge.py --env intersection-v0 --rescore run.json --ceiling ceiling.json

Environments (``--env``): ``intersection-v0``, ``intersection-v1`` (its own dynamical action
kept), ``merge-v0`` and ``roundabout-v0`` (on a map built from its road network), and
``intersection-v2`` and
``merge-v1``: highway-env's ``ConnectedLaneIntersectionEnv`` and ``ConnectedLaneMergeEnv``, the
same roads, traffic, configuration and arrival rules as their v0 with highway-env 1.12's
``neighbour_vehicles_connected_lanes`` (a vehicle looking for its leader also searches the
lanes connected to its own, so it sees a car just past a lane boundary). The core runs the same
geometry and configuration file for both variants; merge-v1 is built with merge-v0's reward fix
(``make_merge_env``).

For ``--policy concord`` the bridge starts ``concord run --geometry highway-env-intersection``
(``highway-env-merge`` for merge-v0, each with its ``deploy/`` configuration) under a private
service prefix and, for every environment step: turns the observation into a
``SceneFrame`` (the ego and up to 32 tracked vehicles, in highway-env's own coordinates, which
the built-in geometry uses), publishes it over iceoryx2, waits for the decision answering that
frame's sequence number (the simulation does not advance until it arrives; after
``--timeout`` seconds the episode is abandoned and counted as a failure), follows the decision's
trajectory for one policy period and steps the environment.

Following the trajectory. highway-env's ``ContinuousAction`` without steering drives straight
ahead (its steering is hard-wired to 0), so a left turn cannot be driven longitudinally only;
``DiscreteMetaAction`` steers along the route but moves its speed set-point one step per action
(at most ~1.7 m/s² per step with a fine grid of set-points), too coarse to follow a plan. The
bridge therefore uses ``ContinuousAction`` with both axes: the acceleration of the planned
change of speed over one policy period, and the steering of the constant-steering arc from the
ego's pose to the planned position ``--lookahead`` seconds ahead (pure pursuit solved for the
bicycle model's slip angle). Both are held for the period, as highway-env holds an action.
highway-env reports velocities along the body heading, ignoring that slip; for the ego the
bridge knows its steering and reports the true direction of motion, or every plan in a turn
would start with a phantom outward drift.

Perception. Kinematics observations (absolute x, y, vx, vy, heading of up to 33 vehicles,
unnormalised, including those behind) carry no identities; a nearest-neighbour tracker with a
constant-velocity prediction gives each vehicle a stable id. Accelerations of other vehicles
are sent as 0 unless ``--estimate-accel`` (finite differences of tracked velocities). Turn
signals: highway-env's vehicles do not signal, but each follows a route, and with
``observe_intentions`` the observation reports the direction to its end; the bridge turns that
into the left or right signal a driver would show (``turn_signal``), and the core matches a
signalling car to that movement on a shared approach. ``--no-turn-signals`` sends them all off.

Baseline policies (``idle``, ``faster``, ``slower``) send that constant ``DiscreteMetaAction``
(highway-env's default action space, which steers along the route) and do not need Concord.

merge-v0. The ego spawns at x = 30 on the right-hand lane (y = 4) of a two-lane road at 30 m/s;
one car comes down the on-ramp and changes into the ego's lane on the auxiliary lane from
x = 230, and the traffic around the ego, spawned at 28–32.5 m/s, slows to the lanes' 20 m/s
speed limit. The core's ``highway-env-merge`` geometry models the ramp as a lane that tapers
into the ego's lane at x = 250 (``deploy/maps/highway-env-merge.toml``); the core only
decides along its lane, so the ego never changes lanes (it steers along the planned
trajectory, as in the intersection). merge-v0 ends an episode on a collision or once the ego
passes x = 370 and has no time limit of its own, so an episode counts as *arrived* when the ego
passes x = 370 without a collision; the bridge stops an episode after 40 s simulated (highway-v0's
duration; at merge-v0's lowest reward speed, 20 m/s, the ego arrives after 17 s) and counts it
as not arrived. merge-v0's reward cannot be computed for a ``ContinuousAction`` (it tests
``action in [0, 2]``), so the bridge builds the environment with that one test fixed (see
``make_merge_env``); nothing else changes. The obstacle that closes the auxiliary lane is left
out of the observations: it is part of the road, not traffic. The baselines' constant actions
are looked up by name, since merge-v0's action space has the lane changes too (IDLE is 1 in
both, FASTER and SLOWER are 3 and 4 in merge-v0).

roundabout-v0. The core runs ``concord run --map deploy/maps/highway-env-roundabout.toml
--route ego``, a map built from the environment's road network by ``highway_maps.py`` (every
movement meeting the ego's route, first come first served: highway-env's roundabout has no
right of way). The ego starts 55 m along its route on the south approach at 8 m/s and heads
for the north exit; the episode ends on a collision or at the environment's 11 s. An episode
counts as *arrived* when the ego has left the ring onto the north exit (y < -25.5) without a
collision; highway-env's own success is the absence of a collision, which the collision rate
gives. Turn signals are not sent: on a ring the direction to a car's destination turns as it
circles and says little. roundabout-v0's reward rejects a continuous action as merge-v0's does
(``continuous_safe``).

intersection-v1. ``ContinuousIntersectionEnv``: intersection-v0's road and traffic, with its
own action configuration kept (``ContinuousAction`` with a dynamical bicycle model: tyre
friction and slip, accelerations within ±5 m/s², steering within ±60°). The bridge scales its
commands to the environment's ranges (``ConcordPolicy.reset``) and reports the ego's velocity
along its body, as observed, since the slip of that model follows from its tyre forces, not
from the steering alone. The constant DiscreteMetaAction baselines do not apply to it.

Scene time. Frames are stamped with the simulation clock (a fixed monotonic origin plus the
episode's simulated time), not the wall clock: lock-step runs faster or slower than real time,
and the core's 10 Hz histories must see simulated seconds. Each episode starts the clock again
at the origin, which the core takes for a restarted source and clears its histories.

Policy frequency. highway-env attempts one vehicle spawn per environment step with probability
``spawn_probability`` (0.6). At a policy frequency f other than the default 1 Hz the bridge
scales it to 0.6 / f, so that traffic arrives at the same mean rate per simulated second; the
initial traffic of a seed is the same at every frequency. Baselines run with the same settings.

``--trace FILE`` logs one JSON line per decision: the frame, the maneuver, P_n, the commanded
action and the OPM conflicts of the advice request (for replaying a scene through the core).

Duration. ``--duration S`` sets the episode length: intersection's own ``duration``
configuration (13 s by default), which truncates the episode at the first step whose clock
reaches it; highway-env's clock is a float sum of the 0.2 s steps, which passes 13 only after
66 steps, so a 13 s episode that neither arrives nor crashes lasts 13.2 s (20 s: 20.2 s, 6 s:
6.0 s). For the merges it is the bridge's own time limit (40 s by default), counted exactly.

Per episode (``--json``: ``episodes``), besides collision, arrival and speed:

* ``outcome``: how it ended, one of ``arrived`` (the arrival rule, without a collision),
  ``crash``, ``decision_timeout`` (Concord did not answer within ``--timeout``) and
  ``time_limit`` (the duration ran out); the summary counts each kind (they add up to the
  number of episodes).
* ``standing_s``: the time the ego stands, i.e. the number of environment steps that end with
  the ego slower than ``STANDING_SPEED_MPS`` = 0.3 m/s, times the period (a stopping ego
  rarely reaches exactly 0: DiscreteMetaAction's speed controller approaches its set-point
  exponentially, and ContinuousAction's speed floor lets the speed dip a few cm/s below 0);
  summary: mean, median and max over the episodes.
* ``others_max_decel_mps2`` (and ``others_max_decel_t_s``): the hardest braking of any other
  vehicle while it is within ``NEAR_EGO_M`` = 30 m of the ego (centre to centre, at the start
  or the end of the step): each vehicle is identified by Python object identity in
  ``env.unwrapped.road.vehicles``, its deceleration is the finite difference of its speed
  between two environment steps, and crashed vehicles are left out (see ``OthersMonitor``).
  For scale: intersection-v0 gives its traffic COMFORT_ACC_MIN = -3 m/s², but highway-env's IDM
  brakes at up to its ACC_MAX, 6 m/s², when a gap closes, and every car that
  ``RegulatedRoad`` tells to yield (target speed 0) brakes at that 6 m/s² at first, so braking
  above 3 m/s² near the ego is common even when the ego stands. Summary: the max over
  episodes, the mean of the per-episode maxima, and the number of episodes in which a vehicle
  near the ego braked harder than ``HARD_BRAKING_MPS2`` = 3 m/s².
* ``min_distance_m``: the smallest centre-to-centre distance between the ego and any other
  vehicle at the reset and the end of each step (cars on the adjacent opposite lane pass 4 m
  apart; two 5 m x 2 m cars touch at 2 m side by side).
* ``min_pet_s`` (and ``min_pet_t_s``): the smallest post-encroachment time between the ego
  and another vehicle crossing or merging with it, s (None: no encroachment; ``PetTracker``
  defines it). Summary: the episodes with an encroachment, the smallest PET, the median of
  the episode minima and the episodes below 0.5, 1.0 and 1.5 s.
* ``crash_other_speed_mps``: in a collision, the speed along its own heading of the nearest
  other crashed vehicle, m/s (None without a collision). Negative: it was driving backwards
  (highway-env's IDM lets a car reverse, down to its MIN_SPEED of -40 m/s, when it stands
  closer to its leader than its desired gap); the summary counts those collisions apart as
  ``collisions_reversing``. ``crash_other_had_crashed``: that vehicle had already crashed into
  another before the step (highway-env lets a crashed car slide on along its frozen heading
  while it slows); the summary counts those as ``collisions_with_crashed``.

Oracle ceiling (``--oracle-ceiling``, intersection only; highway_oracle.py documents it): for
each seed the environment is reset exactly as a ``--policy concord`` run resets it
(``make_env``: same configuration, policy frequency, spawn scaling, ContinuousAction ranges and
duration), and a family of ego speed profiles (wait at a standstill, at the stop line or
crawling until w, then accelerate at a to a cruise speed; constant speeds) is driven on deep
copies of it, steering along the ego's route; a seed is *reachable* when any profile arrives
before the duration ends without a crash. ``--oracle-first`` stops at a seed's first arriving
profile (reachability only), ``--oracle-budget N`` bounds the simulated steps per seed (a seed
whose budget runs out without an arrival is reported as undecided), ``--oracle-reuse FILE``
takes the reachable seeds of an oracle run at a shorter duration as reachable (the same profile
arrives at the same step) and searches the others only, ``--oracle-courteous MPS2`` and
``--oracle-min-pet S`` count only profiles that never make another vehicle brake harder than
MPS2 because of the ego and never pass another vehicle with a PET below S, ``--family`` picks
the profile family, ``--seed-list 0-99,500-599`` any seeds. The oracle prints a line per seed
with its time and an estimate of the rest, then the reachable seeds and how many seeds each
kind of profile reaches; ``--json FILE`` writes it all. ``--ceiling FILE`` (that JSON) makes a
normal run also report its success as a share of the reachable seeds, and list the reachable
seeds it failed and the unreachable seeds it failed or passed (seeds the oracle left undecided
are left out and listed); the file must have been measured with the same environment, duration
and policy frequency. Against a ceiling whose profiles kept rules (``--oracle-courteous``,
``--oracle-min-pet``) it also counts the arrivals that kept the same rules, judged as the
oracle judges its profiles (the fair share for a policy that keeps them), and lists the
reachable seeds it arrived on breaking them. ``--rescore FILE`` reports a run stored with
``--json`` again, against ``--ceiling`` when given, without running it.

Results: per policy, collision rate, success rate (arrived without collision), mean ego speed
(over all steps of all episodes) and the number of minimum-risk decisions, then the outcome
counts, standing time, others' braking, closest distance, the arrivals that kept courtesy
(imposed braking at most 3 m/s²) and PET (at least 1.5 s) and (with ``--ceiling``) the ceiling
lines; the last line is a one-line summary, and ``--json FILE`` writes every number and each
episode's outcome.
"""

import argparse
import contextlib
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)

import concord_wire as wire  # noqa: E402
from concord_link import ConcordProcess, agent_row, sample, wire_agent  # noqa: E402
from pet import PetGrid, wrap  # noqa: E402

# Lane indices of the maps deploy/maps/highway-env-intersection.toml and
# deploy/maps/highway-env-merge.toml (concord_map::highway_env_intersection, ::highway_env_merge).
HWI_EGO_LEFT = 0
HWM_EGO_RIGHT = 0
# merge-v0 ends the episode once the ego passes this x (MergeEnv._is_terminated).
MERGE_END_X = 370.0


def intersection_progress(x, y):
    """Arc length along the ego's left-turn route of intersection-v0 (0 at the far end of the
    approach, 100 at the junction, ~120.4 where the turn ends, arrival 25 m later)."""
    if y >= 11.0:
        return 111.0 - y
    angle = math.atan2(y - 11.0, x + 11.0)  # on the turn: 0 at its start, -pi/2 at its end
    if angle > -math.pi / 2 and x > -11.0:
        return 100.0 + 13.0 * min(-angle, math.pi / 2)
    return 100.0 + 13.0 * math.pi / 2 + (-11.0 - x)


def merge_progress(x, y):
    """Distance along merge-v0's main road (x; the ego spawns at 30 m, arrival beyond 370 m)."""
    return x


def continuous_safe(base):
    """``base`` with one fix: highway-env's ``_rewards`` of merge-v0 and roundabout-v0 test
    ``action in [0, 2]`` for the lane-change penalty, which raises for a ``ContinuousAction``
    array (already in ``reset``). A continuous action changes no lane, so it is passed on as
    no action. Dynamics, traffic and termination are highway-env's; the bridge does not use
    the reward."""

    class ContinuousSafe(base):
        def _rewards(self, action):
            return super()._rewards(action if np.ndim(action) == 0 else None)

    ContinuousSafe.__name__ = f"ContinuousSafe{base.__name__}"
    return ContinuousSafe


def make_merge_env(config, connected_lanes=False):
    """merge-v0 (``highway_env.envs.merge_env:MergeEnv``, as ``gym.make("merge-v0")`` builds it;
    with ``connected_lanes``, merge-v1's ``ConnectedLaneMergeEnv``), ``continuous_safe``."""
    import gymnasium as gym
    from highway_env.envs.merge_env import ConnectedLaneMergeEnv, MergeEnv

    base = ConnectedLaneMergeEnv if connected_lanes else MergeEnv
    return gym.wrappers.OrderEnforcing(continuous_safe(base)(config=config))


def make_merge_v1_env(config):
    """merge-v1 (``ConnectedLaneMergeEnv``: merge-v0 with highway-env 1.12's
    ``neighbour_vehicles_connected_lanes``), with ``continuous_safe``'s reward fix."""
    return make_merge_env(config, connected_lanes=True)


def make_roundabout_env(config):
    """roundabout-v0 (``RoundaboutEnv``), ``continuous_safe``."""
    import gymnasium as gym
    from highway_env.envs.roundabout_env import RoundaboutEnv

    return gym.wrappers.OrderEnforcing(continuous_safe(RoundaboutEnv)(config=config))


# roundabout-v0's map, built from its road network by highway_maps.py; the ego's route is its
# lane "ego" (index 0).
ROUNDABOUT_MAP = os.path.join(ROOT, "deploy", "maps", "highway-env-roundabout.toml")
# roundabout-v0's ego has left the ring once it is this far north (y < -25.5: on the north exit's
# S-bend behind it, on its straight).
ROUNDABOUT_EXIT_Y = -25.5


def _route_polyline(path, lane_id):
    import tomllib

    with open(path, "rb") as f:
        lanes = tomllib.load(f)["lane"]
    return np.array(next(l["points"] for l in lanes if l["id"] == lane_id), dtype=float)


_ROUNDABOUT_ROUTE = None


def roundabout_progress(x, y):
    """Arc length along the roundabout ego's route (its map lane), at the nearest point, m."""
    global _ROUNDABOUT_ROUTE
    if _ROUNDABOUT_ROUTE is None:
        _ROUNDABOUT_ROUTE = _route_polyline(ROUNDABOUT_MAP, "ego")
    pts = _ROUNDABOUT_ROUTE
    seg = np.diff(pts, axis=0)
    length = np.linalg.norm(seg, axis=1)
    rel = np.array([x, y]) - pts[:-1]
    u = np.clip(np.sum(rel * seg, axis=1) / np.maximum(length ** 2, 1e-12), 0.0, 1.0)
    dist = np.linalg.norm(rel - seg * u[:, None], axis=1)
    k = int(np.argmin(dist))
    return float(np.sum(length[:k]) + u[k] * length[k])


def roundabout_arrived(env):
    return bool(env.vehicle.position[1] < ROUNDABOUT_EXIT_Y)


def intersection_arrived(env):
    return bool(env.has_arrived(env.vehicle))


def merge_arrived(env):
    return bool(env.vehicle.position[0] > MERGE_END_X)


# Per environment: the core's geometry and configuration file (under deploy/), the ego's route
# lane, route progress and arrival, the top of ContinuousAction's speed range, the bridge's own
# time limit (None: the environment's), the default episode duration that ``--duration``
# overrides and whether it is the environment's ``duration`` configuration (intersection) or
# the bridge's time limit (merge), how to build the environment (None: gym.make) and whether
# spawns are scaled to the policy frequency (see "Policy frequency" above). The v1/v2 variants
# are the same road, traffic and rules with highway-env 1.12's
# ``neighbour_vehicles_connected_lanes`` (a car also sees the vehicles on the lanes connected
# to its own when looking for its leader, so it no longer runs into a car just past a lane
# boundary); the core's geometry and configuration are the same.
_INTERSECTION = {
    "road": ["--geometry", "highway-env-intersection"],
    "config": "highway-env.toml",
    "route_lane": HWI_EGO_LEFT,
    # The ego's approach road, where followers queue behind it (ImposedBraking).
    "approach": ("o0", "ir0"),
    "progress": intersection_progress,
    "arrived": intersection_arrived,
    "max_speed": 20.0,
    "time_limit_s": None,
    "duration_s": 13.0,  # IntersectionEnv's "duration"
    "duration_in_config": True,
    "make": None,
    "scale_spawn": True,
}
_MERGE = {
    "road": ["--geometry", "highway-env-merge"],
    "config": "highway-env-merge.toml",
    "route_lane": HWM_EGO_RIGHT,
    "progress": merge_progress,
    "arrived": merge_arrived,
    "max_speed": 40.0,  # Vehicle.MAX_SPEED; the ego spawns at 30 m/s
    "time_limit_s": 40.0,
    "duration_s": 40.0,  # the bridge's time limit (merge-v0 has none)
    "duration_in_config": False,
    "make": make_merge_env,
    "scale_spawn": False,
}
_ROUNDABOUT = {
    "road": ["--map", ROUNDABOUT_MAP, "--route", "ego"],
    "config": "highway-env.toml",
    "route_lane": 0,
    "progress": roundabout_progress,
    "arrived": roundabout_arrived,
    "max_speed": 16.0,  # the top of its DiscreteMetaAction target speeds
    "time_limit_s": None,
    "duration_s": 11.0,  # RoundaboutEnv's "duration"
    "duration_in_config": True,
    "make": make_roundabout_env,
    "scale_spawn": False,  # no traffic spawns after the reset
    # highway-env's destinations say little on a ring (the direction to an exit turns as a
    # car circles): no turn signals.
    "signals": False,
}
ENVS = {
    "intersection-v0": dict(_INTERSECTION),
    # ContinuousIntersectionEnv: the same road and traffic, and its own action configuration
    # kept (a dynamical bicycle model with tyre slip; see ``env_action``).
    "intersection-v1": dict(_INTERSECTION, own_action=True),
    "intersection-v2": dict(_INTERSECTION),  # ConnectedLaneIntersectionEnv
    "merge-v0": dict(_MERGE),
    "merge-v1": dict(_MERGE, make=make_merge_v1_env),  # ConnectedLaneMergeEnv
    "roundabout-v0": dict(_ROUNDABOUT),
}


def with_duration(spec, duration):
    """``spec`` with the episode duration ``duration`` s (None: the default)."""
    spec = dict(spec)
    if duration is not None:
        spec["duration_s"] = float(duration)
        if not spec["duration_in_config"]:
            spec["time_limit_s"] = float(duration)
    return spec


# Constant DiscreteMetaAction baselines, by action name (intersection-v0 has the longitudinal
# actions only, merge-v0 the lane changes too, so the indices differ).
DISCRETE = {"slower": "SLOWER", "idle": "IDLE", "faster": "FASTER"}
POLICIES = ("concord",) + tuple(DISCRETE)

def make_env(env_name, policy, policy_frequency, spec):
    """The environment exactly as a run of ``policy`` uses it (also the oracle's, see
    highway_oracle.py): ``env_config`` and the environment's builder."""
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers the environments)

    cfg = env_config(policy, policy_frequency, spec)
    return spec["make"](cfg) if spec["make"] else gym.make(env_name, config=cfg)


# highway-env's kinematic model (vehicle/kinematics.py): length 5 m, slip angle
# beta = atan(tan(delta) / 2), heading rate = v sin(beta) / (length / 2).
VEHICLE_LENGTH = 5.0
VEHICLE_WIDTH = 2.0
ACCEL_RANGE = (-8.0, 6.0)  # m/s²: Concord's emergency braking, up to the traffic's COMFORT_ACC_MAX
STEERING_RANGE = (-math.pi / 3, math.pi / 3)  # MDPVehicle.MAX_STEERING_ANGLE
OBSERVED = 33  # the ego and wire.MAX_AGENTS others


def env_config(policy, policy_frequency, spec=None):
    """highway-env configuration for ``policy`` (only the action type differs between them)."""
    spec = spec or ENVS["intersection-v0"]
    cfg = {
        "observation": {
            "type": "Kinematics",
            "vehicles_count": OBSERVED,
            # cos_d, sin_d: the direction to each vehicle's destination (highway-env's
            # "intentions"), from which the bridge derives turn signals (see ``turn_signal``).
            "features": ["presence", "x", "y", "vx", "vy", "heading", "cos_d", "sin_d"],
            "absolute": True,
            "normalize": False,
            "clip": False,
            "see_behind": True,
            "order": "sorted",
            "observe_intentions": True,
            # merge-v0's obstacle closing the auxiliary lane is part of the road, not traffic.
            "include_obstacles": False,
        },
        "policy_frequency": policy_frequency,
    }
    if spec["scale_spawn"]:
        cfg["spawn_probability"] = 0.6 / policy_frequency
    if spec.get("duration_in_config"):
        cfg["duration"] = spec["duration_s"]
    if policy == "concord" and not spec.get("own_action"):
        cfg["action"] = {
            "type": "ContinuousAction",
            "longitudinal": True,
            "lateral": True,
            "acceleration_range": list(ACCEL_RANGE),
            "steering_range": list(STEERING_RANGE),
            "speed_range": [0.0, spec["max_speed"]],
            "clip": True,
        }
    return cfg


class Tracker:
    """Stable ids for observed vehicles: each track is predicted one period ahead at constant
    velocity and greedily matched to the nearest detection within a gate."""

    GATE_M = 4.0

    def __init__(self):
        self.next_id = 1
        self.tracks = {}  # id -> (x, y, vx, vy)

    def reset(self):
        self.tracks = {}

    def update(self, detections, dt):
        """``detections``: rows (x, y, vx, vy, heading). Returns a list of (id, previous
        velocity or None) in detection order."""
        pairs = []
        for tid, (x, y, vx, vy) in self.tracks.items():
            px, py = x + vx * dt, y + vy * dt
            for k, d in enumerate(detections):
                dist = math.hypot(d[0] - px, d[1] - py)
                if dist < self.GATE_M + 0.1 * math.hypot(vx, vy):
                    pairs.append((dist, tid, k))
        pairs.sort()
        taken_t, taken_d = set(), {}
        for _, tid, k in pairs:
            if tid in taken_t or k in taken_d:
                continue
            taken_t.add(tid)
            taken_d[k] = tid
        out, tracks = [], {}
        for k, d in enumerate(detections):
            tid = taken_d.get(k)
            prev = None
            if tid is None:
                tid = self.next_id
                self.next_id += 1
            else:
                prev = self.tracks[tid][2:]
            tracks[tid] = (d[0], d[1], d[2], d[3])
            out.append((tid, prev))
        self.tracks = tracks
        return out


# Turn-signal codes of the wire.
SIGNAL_OFF, SIGNAL_LEFT, SIGNAL_RIGHT = (wire.TURN_SIGNALS.index(n)
                                        for n in ("off", "left", "right"))
# A destination more than this far off the heading is a turn, rad (a car about to turn sees
# its destination 40-65 degrees off; a car going straight, within a few degrees).
SIGNAL_ANGLE_RAD = 0.35


def turn_signal(heading, cos_d, sin_d):
    """The turn signal a driver heading ``heading`` shows on the way to a destination in
    direction (cos_d, sin_d): highway-env vehicles do not signal, but they know their route,
    and its ``observe_intentions`` reports the direction to its end. highway-env's frame is
    y-down, a mirror image, so a driver's left is a negative angle in its numbers."""
    if cos_d == 0.0 and sin_d == 0.0:
        return SIGNAL_OFF  # no route
    angle = math.atan2(math.cos(heading) * sin_d - math.sin(heading) * cos_d,
                       math.cos(heading) * cos_d + math.sin(heading) * sin_d)
    if angle < -SIGNAL_ANGLE_RAD:
        return SIGNAL_LEFT
    if angle > SIGNAL_ANGLE_RAD:
        return SIGNAL_RIGHT
    return SIGNAL_OFF


def follow(decision, x, y, heading, speed, period, lookahead, ranges=(ACCEL_RANGE, STEERING_RANGE)):
    """Acceleration (m/s²) and steering (rad) that follow ``decision`` for one ``period``,
    within ``ranges`` (the action's acceleration and steering ranges)."""
    (a_lo, a_hi), (d_lo, d_hi) = ranges
    start, target = sample(decision, 0.0), sample(decision, period)
    if target is None:
        return a_lo, 0.0
    # The planned change of speed, not the gap to the planned speed: the plan's speed is
    # along the lane (Frenet ds), which is below the ego's speed whenever its course differs
    # from the lane's, and at short periods that gap would read as hard braking.
    accel = (target[3] - start[3]) / period
    accel = max(accel, -speed / period)  # stop at 0, never reverse
    accel = min(max(accel, a_lo), a_hi)
    aim = sample(decision, max(period, lookahead))
    dx, dy = aim[0] - x, aim[1] - y
    dist = math.hypot(dx, dy)
    steering = 0.0
    if dist > 0.5:
        steering = math.atan(2.0 * math.tan(pursuit_slip(math.atan2(dy, dx) - heading, dist)))
    steering = min(max(steering, d_lo), d_hi)
    return accel, steering


def pursuit_slip(bearing, dist):
    """Slip angle beta of the constant-steering arc that reaches a point ``dist`` m away at
    ``bearing`` rad from the heading. In highway-env's bicycle model the centre of gravity
    moves along heading + beta on a circle of curvature 2 sin(beta) / length, and a circle
    with initial direction heading + beta through the point has curvature
    2 sin(bearing - beta) / dist; beta solves sin(beta) / length = sin(bearing - beta) / dist
    (increasing in beta, so bisection finds it)."""
    bearing = wrap(bearing)
    lo, hi = -1.2, 1.2
    f = lambda b: math.sin(b) / VEHICLE_LENGTH - math.sin(bearing - b) / dist  # noqa: E731
    if f(lo) > 0.0:
        return lo
    if f(hi) < 0.0:
        return hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if f(mid) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def to_unit(value, lo, hi):
    """Inverse of highway-env's lmap from [-1, 1] to [lo, hi]."""
    return float(np.clip(2.0 * (value - lo) / (hi - lo) - 1.0, -1.0, 1.0))


class ConcordPolicy:
    """One decision per environment step, in lock-step."""

    def __init__(self, args, spec, period):
        self.core_args = (args.concord, spec["road"], args.rate,
                          args.config, args.core_log, bool(args.trace), "hw")
        self.restart = not args.keep_core
        self.core = ConcordProcess(*self.core_args)
        self.trace = open(args.trace, "w", encoding="utf-8") if args.trace else None
        self.route_lane = spec["route_lane"]
        self.period = period
        self.lookahead = args.lookahead
        self.timeout = args.timeout
        self.estimate_accel = args.estimate_accel
        self.signals = spec.get("signals", True) and not args.no_turn_signals
        self.tracker = Tracker()
        self.sequence = 0
        self.origin_ns = time.monotonic_ns()
        self.ego_accel = 0.0
        self.ego_steering = 0.0
        self.ranges = (ACCEL_RANGE, STEERING_RANGE)
        self.kinematic = True

    def reset(self, action_type=None):
        """A new episode. The core's Monte Carlo RNG is seeded with seed XOR cycle, so by default
        each episode gets a fresh core, and a seed's outcome does not depend on the seeds run
        before it (``--keep-core`` keeps one core for the whole run). ``action_type``: the
        environment's ``ContinuousAction``, whose ranges the actions are scaled to (the
        bridge's own, or an environment's that the bridge keeps, e.g. intersection-v1's)."""
        if action_type is not None:
            self.ranges = (tuple(action_type.acceleration_range),
                           tuple(action_type.steering_range))
            self.kinematic = not action_type.dynamical
        if self.restart and self.core is not None:
            self.core.close()
            self.core = None
        if self.core is None:
            self.core = ConcordProcess(*self.core_args)
        self.tracker.reset()
        self.ego_accel = 0.0
        self.ego_steering = 0.0

    def frame(self, obs, sim_time):
        rows = [r for r in obs if r[0] > 0.5]
        ego, others = rows[0], rows[1:1 + wire.MAX_AGENTS]
        self.sequence += 1
        f = wire.SceneFrame()
        f.sequence = self.sequence
        f.stamp_ns = self.origin_ns + int(round(sim_time * 1e9))
        _, ex, ey, evx, evy, eh = (float(v) for v in ego[:6])
        # highway-env reports velocity along the body heading, but its bicycle model moves the
        # centre of gravity along heading + slip, beta = atan(tan(steering) / 2). Reported as
        # is, a car in a steady turn would seem to drift outwards at v sin(beta) (1.7 m/s at
        # 9 m/s on the 13 m left turn), and every plan would start with that drift. The bridge
        # knows the steering it commanded, so it reports the true velocity (and acceleration)
        # direction; the heading stays the body's.
        # A dynamical model's (intersection-v1's) slip follows from its tyre forces, not the
        # steering alone: its velocity is reported along the body, as observed.
        speed = math.hypot(evx, evy)
        slip = math.atan(0.5 * math.tan(self.ego_steering)) if self.kinematic else 0.0
        course = eh + slip
        evx, evy = speed * math.cos(course), speed * math.sin(course)
        f.ego = wire_agent(ex, ey, evx, evy, eh, 0,
                           self.ego_accel * math.cos(course), self.ego_accel * math.sin(course))
        ids = self.tracker.update([tuple(float(v) for v in r[1:6]) for r in others], self.period)
        for k, (r, (tid, prev)) in enumerate(zip(others, ids)):
            _, x, y, vx, vy, h, cos_d, sin_d = (float(v) for v in r)
            signal = turn_signal(h, cos_d, sin_d) if self.signals else SIGNAL_OFF
            ax = ay = 0.0
            if self.estimate_accel and prev is not None:
                ax, ay = (vx - prev[0]) / self.period, (vy - prev[1]) / self.period
                norm = math.hypot(ax, ay)
                if norm > 6.0:
                    ax, ay = ax * 6.0 / norm, ay * 6.0 / norm
            f.agents[k] = wire_agent(x, y, vx, vy, h, tid, ax, ay, signal)
        f.ego_route_lane = self.route_lane
        return f, (ex, ey, eh, math.hypot(evx, evy))

    def act(self, obs, sim_time):
        """The action for this step and the decision, or (None, None) on a timeout."""
        f, (x, y, h, v) = self.frame(obs, sim_time)
        self.core.link.publish_scene(f)
        d = self.core.link.wait_for_decision(f.sequence, timeout_s=self.timeout)
        if d is None:
            return None, None
        accel, steering = follow(d, x, y, h, v, self.period, self.lookahead, self.ranges)
        self.ego_accel, self.ego_steering = accel, steering
        if self.trace:
            self.write_trace(f, d, sim_time, accel, steering)
        return np.array([to_unit(accel, *self.ranges[0]), to_unit(steering, *self.ranges[1])],
                        dtype=np.float32), d

    def write_trace(self, f, d, sim_time, accel, steering):
        from concord_link import ConcordLink

        request = None
        for r in ConcordLink._drain(self.core.requests, wire.AdviceRequest):
            if r.scene_sequence == f.sequence:
                request = r
        rec = {
            "t": round(sim_time, 3), "seq": f.sequence,
            "ego": [round(f.ego.x, 2), round(f.ego.y, 2), round(math.hypot(f.ego.vx, f.ego.vy), 2)],
            "maneuver": wire.MANEUVERS[d.maneuver], "source": wire.SOURCES[d.source],
            "p": [round(p, 3) for p in d.p_corrected], "accel": round(accel, 2),
            "steer": round(steering, 3),
            "plan_v": [round(d.trajectory[k].speed, 2) for k in (0, 10, 20, 30, 40, 50)
                       if k < d.n_points],
            "agents": [[a.id, round(a.x, 1), round(a.y, 1), round(math.hypot(a.vx, a.vy), 1),
                        a.turn_signal] for a in f.agents if a.valid],
            # Exact scene, for replaying it through the core:
            # [id, x, y, vx, vy, ax, ay, heading, turn signal].
            "scene": {"time": f.stamp_ns - self.origin_ns, "lane": f.ego_route_lane,
                      "ego": agent_row(f.ego),
                      "agents": [agent_row(a) for a in f.agents if a.valid]},
        }
        if request is not None:
            rec["ego_s"] = round(request.ego.s_m, 2)
            rec["conflicts"] = [
                {"id": c.agent_id, "de": round(c.ego_dist_m, 1), "da": round(c.agent_dist_m, 1),
                 "te": round(c.ego_ttc_s, 2), "ta": round(c.agent_ttc_s, 2),
                 "risky": c.risky} for c in request.conflicts[:request.n_conflicts]]
            rec["objects"] = [
                {"id": o.state.id, "lane": o.process.lane, "s": round(o.process.s_m, 1),
                 "l": round(o.process.l_m, 2)} for o in request.objects[:request.n_objects]]
            rec["leader_gap"] = (None if request.leader_gap_m > 1e300
                                 else round(request.leader_gap_m, 1))
        self.trace.write(json.dumps(rec) + "\n")

    def close(self):
        if self.trace:
            self.trace.close()
        if self.core is not None:
            self.core.close()


# An ego slower than this is standing, m/s (highway-env's vehicles rarely stop exactly: see
# "Per episode" in the module's documentation).
STANDING_SPEED_MPS = 0.3
# Other vehicles' braking is measured while they are this close to the ego (centre to centre), m.
NEAR_EGO_M = 30.0
# A deceleration harder than this is "hard braking", m/s²: the COMFORT_ACC_MIN that
# intersection-v0 gives its traffic (IDM may brake at up to its ACC_MAX, 6 m/s², when a gap
# closes or a car is told to yield by RegulatedRoad).
HARD_BRAKING_MPS2 = 3.0
# A vehicle slower than -REVERSING_MPS along its heading drives backwards, m/s.
REVERSING_MPS = 0.1
OUTCOMES = ("arrived", "time_limit", "crash", "decision_timeout")
# PET thresholds the summary counts episodes below, s (the interaction targets ask 1.5 s).
PET_REPORT_S = (0.5, 1.0, 1.5)


class OthersMonitor:
    """Per environment step, the other vehicles' braking near the ego and their distance to it.

    Vehicles are identified by Python object identity in ``road.vehicles`` (a vehicle that
    leaves and a new one never share an entry: the object is kept with its speed). A vehicle's
    deceleration over a step is the finite difference of its speed between the two
    environment steps, -(v1 - v0) / period (highway-env's IDM acceleration is constant over
    each 1/15 s frame, so this is its mean over the step's frames); it counts when the vehicle
    is within ``NEAR_EGO_M`` of the ego at the start or the end of the step and has not
    crashed (a crashed car's speed decays by highway-env's crash model, not by braking)."""

    def __init__(self, u, period):
        self.period = period
        self.prev = {}
        self.max_decel = 0.0
        self.max_decel_t = None
        self.min_distance = math.inf
        self.observe(u, None)

    def observe(self, u, t):
        ego = u.vehicle
        cur = {}
        for v in u.road.vehicles:
            if v is ego:
                continue
            d = float(np.linalg.norm(v.position - ego.position))
            self.min_distance = min(self.min_distance, d)
            cur[id(v)] = (v, float(v.speed), d)
            old = self.prev.get(id(v))
            if t is None or old is None or old[0] is not v or v.crashed:
                continue
            if min(old[2], d) <= NEAR_EGO_M:
                decel = -(float(v.speed) - old[1]) / self.period
                if decel > self.max_decel:
                    self.max_decel, self.max_decel_t = decel, t
        self.prev = cur


# Who brakes for the ego, in ImposedBraking's split.
IMPOSED_PARTS = ("queue", "regulation", "leader", "off_path")


class ImposedBraking:
    """The braking the ego imposes on other vehicles: each frame, for a vehicle that the ego
    holds up by highway-env's own rules, the braking it does with the ego beyond what it would
    do without (the simulator's analogue of the braking the core's courtesy rule bounds;
    braking for other vehicles, which highway-env's regulation makes hard and frequent, is
    left out). A vehicle braking at 5.6 m/s² for its own leader that the ego makes brake at
    6 m/s² counts 0.4; one that would keep its speed and brakes at 4 m/s² for the ego counts
    4. ``max_whole`` keeps the whole braking of such a vehicle (6 in the first example), the
    measure's earlier form, which overstates. The ego holds a vehicle up when:

    * the ego is its leader (``road.neighbour_vehicles`` on its lane finds the ego first, as
      its IDM does): the IDM acceleration with the ego as leader against the one with its
      next leader;
    * it yields to the ego: ``RegulatedRoad`` made it yield (target speed 0) at an enforcement
      where a conflict with the ego was possible and it, not the ego, had to give way: the IDM
      acceleration yielding against the one at its lane's speed limit.

    Braking in the episode's first step (``t`` = 0) is left out: it answers where the
    environment placed the ego (close in front of a follower, say), not anything it did. It
    patches ``IDMVehicle.act`` and ``RegulatedRoad.enforce_road_rules`` while ``attached``
    (the same arithmetic first, the vehicles' own calls after: the simulation is unchanged).

    With ``approach`` (the ego's approach road, (from, to) node names) the braking is also
    split by who brakes, in ``max_part``:

    * ``queue``: a vehicle on that road (behind the ego, which it follows or yields to) while
      the ego has not entered the junction (its centre at most half a car length past the
      road's end, where it waits at its line): any car waiting there makes followers brake,
      and highway-env's IDM brakes up to its 6 m/s² limit behind a standing car;
    * ``regulation``: any other vehicle that ``RegulatedRoad`` made yield to the ego, which
      highway-env does by setting its target speed to 0, so its IDM brakes at its 6 m/s²
      limit at once, however far it is from the conflict;
    * ``leader``: any other vehicle that has the ego as its leader on its own path (the ego
      merged in front of it, or it follows the ego through the junction; ``on_path``);
    * ``off_path``: any other vehicle whose leader search finds the ego off its path: on a
      lane it will not take (intersection-v2 searches every lane that leaves the end of the
      vehicle's lane, whatever its route), or driving the other way, more than 135° off the
      lane's heading (the search matches any vehicle within the lane's half width plus 1 m,
      whatever its heading)."""

    def __init__(self, approach=None):
        self.approach = approach
        self.max_decel = 0.0
        self.max_decel_t = None
        self.max_part = dict.fromkeys(IMPOSED_PARTS, 0.0)
        # Where each part's largest braking happened: [t s, x m, y m, that vehicle's speed m/s].
        self.max_part_at = dict.fromkeys(IMPOSED_PARTS)
        self.max_whole = 0.0
        self.t = 0.0
        self.road = None
        self.ego = None

    @contextlib.contextmanager
    def attached(self, u):
        from highway_env.road.regulation import RegulatedRoad
        from highway_env.vehicle.behavior import IDMVehicle

        self.road, self.ego = u.road, u.vehicle
        monitor = self
        orig_act = IDMVehicle.__dict__["act"]
        orig_enforce = RegulatedRoad.__dict__["enforce_road_rules"]

        def act(v, action=None):
            if v.road is monitor.road and not v.crashed:
                monitor.weigh(v)
            return orig_act(v, action)

        def enforce(road):
            orig_enforce(road)
            if road is monitor.road:
                ego = monitor.ego
                for v in road.vehicles:
                    yielding = getattr(v, "is_yielding", False)
                    if yielding and v.yield_timer == 0:
                        v.yields_to_ego = bool(
                            RegulatedRoad.is_conflict_possible(v, ego)
                            and RegulatedRoad.respect_priorities(v, ego) is v)
                    elif not yielding:
                        v.yields_to_ego = False

        IDMVehicle.act = act
        RegulatedRoad.enforce_road_rules = enforce
        try:
            yield self
        finally:
            IDMVehicle.act = orig_act
            RegulatedRoad.enforce_road_rules = orig_enforce

    def weigh(self, v):
        ego, road = self.ego, self.road
        front, rear = road.neighbour_vehicles(v, v.lane_index)
        yields = getattr(v, "is_yielding", False) and getattr(v, "yields_to_ego", False)
        if front is not ego and not yields:
            return
        clip = lambda a: float(np.clip(a, -v.ACC_MAX, v.ACC_MAX))  # noqa: E731
        with_ego = clip(v.acceleration(ego_vehicle=v, front_vehicle=front, rear_vehicle=rear))
        others = road.vehicles
        road.vehicles = [x for x in others if x is not ego]
        target = v.target_speed
        try:
            front2, rear2 = road.neighbour_vehicles(v, v.lane_index)
            if yields:
                v.target_speed = v.lane.speed_limit
            without = clip(v.acceleration(ego_vehicle=v, front_vehicle=front2, rear_vehicle=rear2))
        finally:
            road.vehicles = others
            v.target_speed = target
        if self.t > 0.0 and with_ego < 0.0 and with_ego < without - 1e-6:
            share = min(without, 0.0) - with_ego
            if share > self.max_decel:
                self.max_decel, self.max_decel_t = share, self.t
            part = ("queue" if self.queued(v) else "regulation" if yields
                    else "leader" if self.on_path(v) else "off_path")
            if share > self.max_part[part]:
                self.max_part[part] = share
                self.max_part_at[part] = [self.t, *map(float, v.position), float(v.speed)]
            self.max_whole = max(self.max_whole, -with_ego)

    def queued(self, v):
        """Whether ``v`` waits behind the ego on the ego's approach road while the ego has not
        entered the junction (see the class)."""
        if self.approach is None or tuple(v.lane_index[:2]) != tuple(self.approach):
            return False
        ego = self.ego
        if tuple(ego.lane_index[:2]) == tuple(self.approach):
            return True
        if ego.lane_index[0] != self.approach[1]:
            return False
        return ego.lane.local_coordinates(ego.position)[0] <= ego.LENGTH / 2

    def on_path(self, v):
        """Whether the ego is on the path ``v`` drives, heading its way: on its lane or the
        next lane of its route, as highway-env's leader search matches a vehicle on a lane
        (within the lane's half width plus 1 m), and not driving the other way: within 135° of
        that lane's heading there (an ego crossing in front, about 90° off, is on the path)."""
        ego, graph = self.ego, self.road.network.graph
        path = [v.lane_index] + [r for r in (v.route or []) if r[0] == v.lane_index[1]][:1]
        for a, b, k in path:
            lanes = graph.get(a, {}).get(b, [])
            if not lanes:
                continue
            lane = lanes[min(k or 0, len(lanes) - 1)]
            s, lat = lane.local_coordinates(ego.position)
            if (lane.on_lane(ego.position, s, lat, margin=1)
                    and abs(wrap(ego.heading - lane.heading_at(s))) < 0.75 * math.pi):
                return True
        return False


class PetTracker(PetGrid):
    """Post-encroachment time between the ego and every other vehicle of a highway-env road
    (``pet.PetGrid``), at the simulation's frame rate (15 Hz in the intersection: 1/15 s
    resolution). Attached to the road (``road.pet_tracker``), it is copied with the
    environment (the oracle's branches)."""

    def __init__(self, ego):
        super().__init__()
        self.ego = ego
        self.keys = 0

    def observe(self, road, dt):
        """One frame of ``dt`` s has been simulated on ``road``."""
        vehicles = []
        for v in road.vehicles:
            key = getattr(v, "pet_key", None)
            if key is None:
                key = v.pet_key = self.keys
                self.keys += 1
            vehicles.append((key, v is self.ego, v.position, float(v.heading),
                             VEHICLE_LENGTH, VEHICLE_WIDTH))
        super().observe(dt, vehicles)

    @staticmethod
    @contextlib.contextmanager
    def recording():
        """While in the block, every ``Road.step`` feeds the road's ``pet_tracker``, if any
        (highway-env is otherwise unchanged)."""
        from highway_env.road.road import Road

        orig = Road.__dict__["step"]

        def step(road, dt):
            orig(road, dt)
            tracker = getattr(road, "pet_tracker", None)
            if tracker is not None:
                tracker.observe(road, dt)

        Road.step = step
        try:
            yield
        finally:
            Road.step = orig


def crash_other(u, crashed_before=()):
    """The crashed vehicle nearest the ego: its speed along its heading, m/s, and whether it
    is one of ``crashed_before`` (vehicles that had crashed before the step); None: none."""
    hit = [v for v in u.road.vehicles if v is not u.vehicle and v.crashed]
    if not hit:
        return None
    v = min(hit, key=lambda v: np.linalg.norm(v.position - u.vehicle.position))
    return float(v.speed), any(v is w for w in crashed_before)


def outcome_kind(e):
    """How an episode ended: a collision, an arrival, Concord's decision timeout or the time
    limit (the environment's duration or the bridge's own)."""
    if e["crashed"]:
        return "crash"
    if e["arrived"]:
        return "arrived"
    if e["timed_out"]:
        return "decision_timeout"
    return "time_limit"


def run_episode(env, policy, name, seed, period, spec, verbose=False):
    """One seed. Returns the episode's outcome as a dict."""
    obs, _ = env.reset(seed=seed)
    u = env.unwrapped
    if name == "concord":
        policy.reset(u.action_type)
    speeds, min_risk, decisions, steps, timed_out = [], 0, 0, 0, False
    maneuvers = {}
    crashed = arrived = False
    standing_steps = 0
    crash = None
    monitor = OthersMonitor(u, period)
    imposed = ImposedBraking(spec.get("approach"))
    pet = u.road.pet_tracker = PetTracker(u.vehicle)
    limit = spec["time_limit_s"]
    discrete = None if name == "concord" else u.action_type.actions_indexes[DISCRETE[name]]
    with PetTracker.recording():
        while True:
            sim_time = steps * period
            if name == "concord":
                action, d = policy.act(obs, sim_time)
                if action is None:
                    timed_out = True
                    break
                decisions += 1
                if wire.SOURCES[d.source] == "minimum_risk":
                    min_risk += 1
                m = wire.MANEUVERS[d.maneuver]
                maneuvers[m] = maneuvers.get(m, 0) + 1
            else:
                action = discrete
            imposed.t = steps * period
            crashed_before = [v for v in u.road.vehicles if v.crashed]
            with imposed.attached(u):
                obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            speeds.append(float(u.vehicle.speed))
            if float(u.vehicle.speed) < STANDING_SPEED_MPS:
                standing_steps += 1
            monitor.observe(u, steps * period)
            crashed = bool(u.vehicle.crashed)
            if crashed and crash is None:
                crash = crash_other(u, crashed_before)
            arrived = spec["arrived"](u)
            if verbose and name == "concord":
                print(f"  seed {seed} t={steps * period:5.2f} pos=({u.vehicle.position[0]:6.1f},"
                      f"{u.vehicle.position[1]:6.1f}) v={u.vehicle.speed:4.1f} {m} "
                      f"{wire.SOURCES[d.source]}", file=sys.stderr)
            if terminated or truncated or (limit is not None and steps * period >= limit - 1e-9):
                break
    e = {
        "seed": seed,
        "steps": steps,
        "decisions": decisions,
        "crashed": crashed,
        "arrived": arrived and not crashed,
        "timed_out": timed_out,
        "mean_speed": float(np.mean(speeds)) if speeds else 0.0,
        "speed_sum": float(np.sum(speeds)),
        "sim_time_s": steps * period,
        "minimum_risk": min_risk,
        "maneuvers": maneuvers,
        "final_position": [float(v) for v in u.vehicle.position],
        "final_progress_m": float(spec["progress"](*u.vehicle.position)),
        # Steps that ended with the ego below STANDING_SPEED_MPS, times the period.
        "standing_s": standing_steps * period,
        # Largest deceleration of another vehicle near the ego (OthersMonitor), m/s², and when.
        "others_max_decel_mps2": monitor.max_decel,
        "others_max_decel_t_s": monitor.max_decel_t,
        # Largest braking the ego imposed on another vehicle beyond the braking it would do
        # without the ego (ImposedBraking), m/s², and when; and that vehicle's whole braking.
        "imposed_decel_mps2": imposed.max_decel,
        "imposed_decel_t_s": imposed.max_decel_t,
        "imposed_whole_decel_mps2": imposed.max_whole,
        # The same split by who brakes (ImposedBraking with the env's approach; None: not
        # split): followers queued behind the ego at its line, vehicles the regulation made
        # yield to it, vehicles it leads on their path, vehicles that brake for it off their
        # path.
        **{f"imposed_{k}_decel_mps2": imposed.max_part[k] if imposed.approach else None
           for k in IMPOSED_PARTS},
        # When and where each part's largest braking happened: [t, x, y, speed] of the
        # braking vehicle (None: none), to find it in a --trace.
        **{f"imposed_{k}_at": imposed.max_part_at[k] for k in IMPOSED_PARTS},
        # Smallest centre-to-centre distance between the ego and another vehicle, m (None: the
        # ego was alone).
        "min_distance_m": None if math.isinf(monitor.min_distance) else monitor.min_distance,
        # Smallest post-encroachment time between the ego and another vehicle (PetTracker), s,
        # and when (None: no crossing or merging encroachment).
        "min_pet_s": None if math.isinf(pet.min_pet) else pet.min_pet,
        "min_pet_t_s": pet.min_pet_t,
        "crash_other_speed_mps": crash[0] if crash else None,
        "crash_other_had_crashed": crash[1] if crash else None,
    }
    e["outcome"] = outcome_kind(e)
    return e


def split_imposed(episodes):
    """The imposed braking's split (``ImposedBraking.queued``): the largest of each part and
    the episodes harder than the threshold in each; empty when the episodes are not split."""
    if any(e.get("imposed_queue_decel_mps2") is None for e in episodes):
        return {}
    out = {}
    for part in IMPOSED_PARTS:
        d = [e[f"imposed_{part}_decel_mps2"] for e in episodes]
        out[f"{part}_max_mps2"] = float(np.max(d))
        out[f"{part}_episodes_harder_than_threshold"] = sum(x > HARD_BRAKING_MPS2 for x in d)
    return out


def summarize(env_name, name, episodes):
    n = len(episodes)
    steps = sum(e["steps"] for e in episodes)
    standing = [e["standing_s"] for e in episodes]
    decel = [e["others_max_decel_mps2"] for e in episodes]
    imposed = [e["imposed_decel_mps2"] for e in episodes]
    whole = [e["imposed_whole_decel_mps2"] for e in episodes]
    dist = [e["min_distance_m"] for e in episodes if e["min_distance_m"] is not None]
    pets = [e["min_pet_s"] for e in episodes if e.get("min_pet_s") is not None]
    return {
        "env": env_name,
        "policy": name,
        "seeds": n,
        "collision_rate": sum(e["crashed"] for e in episodes) / n,
        "collisions_reversing": sum(e["crashed"] and (e.get("crash_other_speed_mps") or 0.0)
                                    < -REVERSING_MPS for e in episodes),
        "collisions_with_crashed": sum(bool(e["crashed"] and e.get("crash_other_had_crashed"))
                                       for e in episodes),
        "success_rate": sum(e["arrived"] for e in episodes) / n,
        "timeouts": sum(e["timed_out"] for e in episodes),
        "mean_speed_mps": sum(e["speed_sum"] for e in episodes) / max(steps, 1),
        "steps": steps,
        "decisions": sum(e["decisions"] for e in episodes),
        "minimum_risk_decisions": sum(e["minimum_risk"] for e in episodes),
        "outcomes": {k: sum(e["outcome"] == k for e in episodes) for k in OUTCOMES},
        "standing_s": {"mean": float(np.mean(standing)), "median": float(np.median(standing)),
                       "max": float(np.max(standing)), "threshold_mps": STANDING_SPEED_MPS},
        "others_braking": {
            "max_mps2": float(np.max(decel)),
            "mean_of_episode_max_mps2": float(np.mean(decel)),
            "episodes_harder_than_threshold": sum(d > HARD_BRAKING_MPS2 for d in decel),
            "threshold_mps2": HARD_BRAKING_MPS2, "near_ego_m": NEAR_EGO_M},
        "imposed_braking": {
            "max_mps2": float(np.max(imposed)),
            "mean_of_episode_max_mps2": float(np.mean(imposed)),
            "episodes_harder_than_threshold": sum(d > HARD_BRAKING_MPS2 for d in imposed),
            "threshold_mps2": HARD_BRAKING_MPS2,
            "whole_max_mps2": float(np.max(whole)),
            "whole_episodes_harder_than_threshold": sum(d > HARD_BRAKING_MPS2 for d in whole),
            **split_imposed(episodes)},
        "min_distance_m": {"min": float(np.min(dist)) if dist else None,
                           "median": float(np.median(dist)) if dist else None},
        "pet_s": {"episodes": len(pets),
                  "min": float(np.min(pets)) if pets else None,
                  "median": float(np.median(pets)) if pets else None,
                  "episodes_below": {str(x): sum(p < x for p in pets) for x in PET_REPORT_S}},
        # Arrivals that kept the interaction rules, judged as the oracle judges its profiles.
        "arrived_keeping_rules": {
            "courteous": sum(e["arrived"] and within_rules(e, {"max_imposed_decel_mps2":
                                                                HARD_BRAKING_MPS2})
                             for e in episodes),
            "courteous_and_pet": sum(e["arrived"] and within_rules(e, KEPT_RULES)
                                     for e in episodes),
            **KEPT_RULES},
    }


def load_ceiling(path, env_name, spec, policy_frequency):
    """The oracle's JSON (``--oracle-ceiling --json FILE``), checked against this run's
    environment, duration and policy frequency: ({seed: reachable}, the rules its profiles
    kept: ``max_imposed_decel_mps2`` and ``min_pet_s``, None where it kept none)."""
    with open(path, encoding="utf-8") as f:
        data = json.load(f)
    o = data["oracle"]
    mismatch = [(k, o[k], v) for k, v in (("env", env_name), ("duration_s", spec["duration_s"]),
                                          ("policy_frequency_hz", policy_frequency))
                if o[k] != v]
    if mismatch:
        raise SystemExit(f"--ceiling {path} was measured with other settings: "
                         + ", ".join(f"{k} {a} (this run {b})" for k, a, b in mismatch))
    # A seed whose search ran out of budget without an arrival is undecided (None).
    reachable = {int(r["seed"]): (None if r.get("undecided") and not r["reachable"]
                                  else bool(r["reachable"])) for r in data["seeds"]}
    return reachable, {k: o.get(k) for k in CEILING_RULES}


# The rules an oracle's profiles may have kept (``--oracle-courteous``, ``--oracle-min-pet``).
CEILING_RULES = ("max_imposed_decel_mps2", "min_pet_s")
# The rules every run's summary counts arrivals against: the interaction rules' courtesy
# limit and PET target (3 m/s², 1.5 s).
KEPT_RULES = {"max_imposed_decel_mps2": HARD_BRAKING_MPS2, "min_pet_s": 1.5}


def within_rules(e, rules):
    """Whether episode ``e`` kept the oracle's ``rules`` as the oracle judges its profiles:
    imposed braking (``ImposedBraking``, the first step left out as there) at most
    ``max_imposed_decel_mps2``, and no crossing or merge with a PET below ``min_pet_s``."""
    courteous, min_pet = rules.get("max_imposed_decel_mps2"), rules.get("min_pet_s")
    return ((courteous is None or e["imposed_decel_mps2"] <= courteous)
            and (min_pet is None or e["min_pet_s"] is None or e["min_pet_s"] >= min_pet))


def ceiling_report(episodes, reachable, rules=None):
    """Success against the oracle's ceiling, over the seeds of this run that the oracle has;
    with the ``rules`` its profiles kept, also the arrivals that kept them too: the fair
    share against a ceiling that a policy keeping those rules can reach."""
    rules = rules or dict.fromkeys(CEILING_RULES)
    known = [e for e in episodes if reachable.get(e["seed"]) is not None]
    reach = [e for e in known if reachable[e["seed"]]]
    unreach = [e for e in known if not reachable[e["seed"]]]
    kept = [e for e in reach if e["arrived"] and within_rules(e, rules)]
    return {
        "seeds_in_ceiling": len(known),
        "missing_seeds": [e["seed"] for e in episodes if e["seed"] not in reachable],
        "reachable": len(reach),
        "arrived_on_reachable": sum(e["arrived"] for e in reach),
        "success_of_reachable": (sum(e["arrived"] for e in reach) / len(reach)) if reach else None,
        "reachable_failed": [e["seed"] for e in reach if not e["arrived"]],
        "unreachable_failed": [e["seed"] for e in unreach if not e["arrived"]],
        "unreachable_passed": [e["seed"] for e in unreach if e["arrived"]],
        "undecided": [e["seed"] for e in episodes
                      if e["seed"] in reachable and reachable[e["seed"]] is None],
        "rules": rules,
        "arrived_within_rules_on_reachable": len(kept),
        "success_within_rules_of_reachable": (len(kept) / len(reach)) if reach else None,
        "reachable_arrived_breaking_rules": [e["seed"] for e in reach if e["arrived"]
                                             and not within_rules(e, rules)],
    }


def detail_lines(s):
    """The new summary numbers, printed before the final summary line."""
    o, st, b, d = s["outcomes"], s["standing_s"], s["others_braking"], s["min_distance_m"]
    lines = [
        "outcomes: " + ", ".join(f"{k} {o[k]}" for k in OUTCOMES)
        + f" (crashes with a car driving backwards: {s['collisions_reversing']}, with a car "
        f"that had already crashed: {s['collisions_with_crashed']})",
        f"standing (ego < {st['threshold_mps']} m/s): mean {st['mean']:.2f} s, median "
        f"{st['median']:.2f} s, max {st['max']:.2f} s per episode",
        f"others' braking within {b['near_ego_m']:.0f} m of the ego: max {b['max_mps2']:.2f} "
        f"m/s², mean of episode maxima {b['mean_of_episode_max_mps2']:.2f} m/s², episodes "
        f"harder than {b['threshold_mps2']:.0f} m/s²: {b['episodes_harder_than_threshold']}",
        f"braking the ego imposed (leader or regulation, beyond the braking without the ego): "
        f"max {s['imposed_braking']['max_mps2']:.2f} m/s², mean of episode maxima "
        f"{s['imposed_braking']['mean_of_episode_max_mps2']:.2f} m/s², episodes harder than "
        f"{s['imposed_braking']['threshold_mps2']:.0f} m/s²: "
        f"{s['imposed_braking']['episodes_harder_than_threshold']} (counting the vehicle's "
        f"whole braking: {s['imposed_braking']['whole_episodes_harder_than_threshold']})",
    ]
    i = s["imposed_braking"]
    if "queue_max_mps2" in i:
        lines.append(
            f"  by who brakes (max m/s², episodes harder than {i['threshold_mps2']:.0f} m/s²): "
            + "; ".join(f"{what} {i[k + '_max_mps2']:.2f}, "
                        f"{i[k + '_episodes_harder_than_threshold']}"
                        for k, what in zip(IMPOSED_PARTS, (
                            "followers queued behind the ego at its line",
                            "vehicles the regulation made yield to it",
                            "vehicles it leads on their path (merged in front of them, or in "
                            "the junction)",
                            "vehicles whose leader search finds it off their path (a lane they "
                            "do not take, or driving the other way)"))))
    if d["min"] is not None:
        lines.append(f"closest other vehicle (centre to centre): min {d['min']:.2f} m, median "
                     f"of episode minima {d['median']:.2f} m")
    p = s.get("pet_s")
    if p and p["episodes"]:
        lines.append(f"post-encroachment time (ego and another vehicle crossing or merging): "
                     f"{p['episodes']} episodes with an encroachment, min {p['min']:.2f} s, "
                     f"median of episode minima {p['median']:.2f} s, episodes below "
                     + ", ".join(f"{x} s: {n}" for x, n in p["episodes_below"].items()))
    k = s.get("arrived_keeping_rules")
    if k is not None:
        lines.append(f"arrivals keeping the rules: courteous (imposed braking <= "
                     f"{k['max_imposed_decel_mps2']:g} m/s²) {k['courteous']}, and PET >= "
                     f"{k['min_pet_s']:g} s too {k['courteous_and_pet']}")
    c = s.get("ceiling")
    if c is not None:
        share = ("n/a" if c["success_of_reachable"] is None
                 else f"{100 * c['success_of_reachable']:.1f} %")
        lines.append(f"ceiling: {c['reachable']} of {c['seeds_in_ceiling']} seeds reachable, "
                     f"arrived on {c['arrived_on_reachable']} of them: success {share} of "
                     f"reachable")
        lines.append(f"ceiling: reachable seeds failed {c['reachable_failed']}")
        r = c.get("rules") or {}
        kept = [f"imposed braking <= {r['max_imposed_decel_mps2']:g} m/s²"
                if r.get("max_imposed_decel_mps2") is not None else None,
                f"PET >= {r['min_pet_s']:g} s" if r.get("min_pet_s") is not None else None]
        kept = [k for k in kept if k]
        if kept:
            share = ("n/a" if c["success_within_rules_of_reachable"] is None
                     else f"{100 * c['success_within_rules_of_reachable']:.1f} %")
            lines.append(f"ceiling: within its rules ({', '.join(kept)}) on "
                         f"{c['arrived_within_rules_on_reachable']} of them: {share} of reachable; "
                         f"arrived breaking them {c['reachable_arrived_breaking_rules']}")
        lines.append(f"ceiling: unreachable seeds failed {c['unreachable_failed']}, passed "
                     f"{c['unreachable_passed']}")
        if c["undecided"]:
            lines.append(f"ceiling: seeds the oracle left undecided (left out) {c['undecided']}")
        if c["missing_seeds"]:
            lines.append(f"ceiling: seeds not in the ceiling file {c['missing_seeds']}")
    return lines


def rescore(args, spec, reachable, rules):
    """``--rescore FILE``: the summary of a run stored with ``--json`` recomputed, against
    ``--ceiling`` when given, without running it again (a ceiling takes longer than a run)."""
    with open(args.rescore, encoding="utf-8") as f:
        stored = json.load(f)
    s0 = stored["summary"]
    mismatch = [(k, s0.get(k), v) for k, v in (("env", args.env),
                                               ("duration_s", spec["duration_s"]),
                                               ("policy_frequency_hz", args.policy_frequency))
                if s0.get(k) != v]
    if mismatch:
        raise SystemExit(f"--rescore {args.rescore} was run with other settings: "
                         + ", ".join(f"{k} {a} (this call {b})" for k, a, b in mismatch))
    episodes = stored["episodes"]
    s = summarize(s0["env"], s0["policy"], episodes)
    for k in ("policy_frequency_hz", "duration_s", "wall_time_s"):
        s[k] = s0[k]
    if reachable is not None:
        s["ceiling"] = ceiling_report(episodes, reachable, rules)
    return report(s, episodes, stored["args"], args.json)


def report(s, episodes, run_args, path):
    """Prints the summary ``s`` (detail lines, then the one-line summary) and, with ``path``,
    writes it with the episodes and the run's arguments as JSON."""
    for line in detail_lines(s):
        print(line)
    print(summary_line(s))
    if path:
        with open(path, "w", encoding="utf-8") as f:
            json.dump({"summary": s, "episodes": episodes, "args": run_args}, f, indent=1)
    return s


def summary_line(s):
    return (f"{s['env']} {s['policy']}: {s['seeds']} seeds, collisions "
            f"{100 * s['collision_rate']:.1f} %, success {100 * s['success_rate']:.1f} %, "
            f"mean speed {s['mean_speed_mps']:.1f} m/s")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--env", default="intersection-v0", choices=sorted(ENVS))
    ap.add_argument("--seeds", type=int, default=50, help="number of seeds (default 50)")
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--seed-list", default=None,
                    help="comma-separated seeds and ranges (e.g. 0-99,500-599) instead of "
                    "--first-seed/--seeds")
    ap.add_argument("--policy", default="concord", choices=POLICIES)
    ap.add_argument("--concord", default=os.path.join(ROOT, "target", "release", "concord"),
                    help="concord binary (default target/release/concord)")
    ap.add_argument("--config", default=None,
                    help="TOML for concord run --config (default deploy/highway-env.toml, "
                    "deploy/highway-env-merge.toml for the merges)")
    ap.add_argument("--rate", type=float, default=100.0, help="core loop rate, Hz")
    ap.add_argument("--policy-frequency", type=int, default=5,
                    help="environment steps per simulated second (highway-env default 1)")
    ap.add_argument("--duration", type=float, default=None,
                    help="episode duration, s: the intersection's duration configuration "
                    "(default 13) or the merge's bridge-side time limit (default 40)")
    ap.add_argument("--lookahead", type=float, default=0.6,
                    help="time ahead on the trajectory that the steering aims at, s")
    ap.add_argument("--timeout", type=float, default=2.0,
                    help="seconds to wait for a decision before the episode fails")
    ap.add_argument("--estimate-accel", action="store_true",
                    help="send other vehicles' accelerations estimated from their tracks")
    ap.add_argument("--no-turn-signals", action="store_true",
                    help="send every vehicle with its turn signal off (default: derived from "
                    "its destination, see turn_signal)")
    ap.add_argument("--keep-core", action="store_true",
                    help="one concord run for all seeds (default: a fresh core per seed)")
    ap.add_argument("--core-log", default=None, help="file for concord run's stderr")
    ap.add_argument("--trace", default=None,
                    help="write one JSON line per decision (scene, OPM conflicts, P_n) here")
    ap.add_argument("--json", default=None, help="write the results to this file")
    ap.add_argument("--ceiling", default=None,
                    help="the oracle's JSON (--oracle-ceiling --json): also report success as "
                    "a share of the seeds the oracle reaches")
    ap.add_argument("--rescore", default=None, metavar="FILE",
                    help="report a run stored with --json again (against --ceiling when given) "
                         "instead of running one; --env and --duration must match it")
    ap.add_argument("--oracle-ceiling", action="store_true",
                    help="instead of running a policy, find for each seed whether any ego "
                    "speed profile of the oracle's family arrives (highway_oracle.py)")
    ap.add_argument("--oracle-courteous", type=float, default=None, metavar="MPS2",
                    help="the oracle counts only profiles that never make another vehicle brake "
                         "harder than this because of the ego (ImposedBraking), e.g. 3")
    ap.add_argument("--oracle-min-pet", type=float, default=None, metavar="S",
                    help="the oracle counts only profiles whose post-encroachment time with "
                         "every other vehicle stays at least this (PetTracker), e.g. 1.5")
    ap.add_argument("--oracle-first", action="store_true",
                    help="the oracle stops at a seed's first arriving profile (reachability "
                    "only: the per-profile counts then cover the profiles tried)")
    ap.add_argument("--oracle-budget", type=int, default=None,
                    help="the oracle's limit of simulated steps per seed; a seed whose search "
                    "ends on it without an arrival is undecided (default: none)")
    ap.add_argument("--oracle-reuse", default=None,
                    help="an oracle JSON of the same env at a shorter or equal duration: its "
                    "reachable seeds are reachable here too and are not searched again")
    ap.add_argument("--family", default="default",
                    help="the oracle's profile family: default, limit (within the lanes' speed "
                    "limit), small, or a JSON file "
                    "(see highway_oracle.py)")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args(argv)
    spec = with_duration(ENVS[args.env], args.duration)
    if args.policy != "concord" and spec.get("own_action"):
        ap.error(f"{args.env} keeps its own continuous action: the constant DiscreteMetaAction "
                 "baselines do not apply to it")
    seeds = (parse_seeds(args.seed_list) if args.seed_list
             else list(range(args.first_seed, args.first_seed + args.seeds)))
    if args.oracle_ceiling:
        import highway_oracle

        return highway_oracle.main_oracle(args, spec, seeds)
    if args.config is None:
        default = os.path.join(ROOT, "deploy", spec["config"])
        args.config = default if os.path.exists(default) else None
    reachable, rules = (load_ceiling(args.ceiling, args.env, spec, args.policy_frequency)
                        if args.ceiling else (None, None))
    if args.rescore:
        return rescore(args, spec, reachable, rules)

    period = 1.0 / args.policy_frequency
    env = make_env(args.env, args.policy, args.policy_frequency, spec)
    policy = ConcordPolicy(args, spec, period) if args.policy == "concord" else None
    episodes = []
    started = time.monotonic()
    try:
        for seed in seeds:
            e = run_episode(env, policy, args.policy, seed, period, spec, args.verbose)
            episodes.append(e)
            outcome = {"crash": "COLLISION", "arrived": "arrived",
                       "decision_timeout": "decision timeout",
                       "time_limit": "time limit"}[e["outcome"]]
            print(f"seed {seed:3d}: {outcome:16s} {e['sim_time_s']:5.1f} s simulated, "
                  f"mean speed {e['mean_speed']:4.1f} m/s, route {e['final_progress_m']:5.1f} m, "
                  f"standing {e['standing_s']:4.1f} s, others' braking "
                  f"{e['others_max_decel_mps2']:4.1f} m/s² (imposed "
                  f"{e['imposed_decel_mps2']:3.1f}), PET "
                  + ("-" if e["min_pet_s"] is None else f"{e['min_pet_s']:.2f} s")
                  + f", minimum-risk {e['minimum_risk']}"
                  + (f", hit by a car driving backwards at {-e['crash_other_speed_mps']:.1f} m/s"
                     if e["crashed"] and (e["crash_other_speed_mps"] or 0.0) < -REVERSING_MPS
                     else "")
                  + (", hit by a car that had already crashed"
                     if e["crashed"] and e["crash_other_had_crashed"] else ""),
                  flush=True)
    finally:
        if policy is not None:
            policy.close()
        env.close()
    s = summarize(args.env, args.policy, episodes)
    s["policy_frequency_hz"] = args.policy_frequency
    s["duration_s"] = spec["duration_s"]
    s["wall_time_s"] = time.monotonic() - started
    if reachable is not None:
        s["ceiling"] = ceiling_report(episodes, reachable, rules)
    print(f"decisions {s['decisions']} for {s['steps']} steps, minimum-risk "
          f"{s['minimum_risk_decisions']}, decision timeouts {s['timeouts']}")
    return report(s, episodes, vars(args), args.json)


def parse_seeds(text):
    """"0-99,500-599,7" -> [0, ..., 99, 500, ..., 599, 7]."""
    seeds = []
    for part in text.split(","):
        part = part.strip()
        if "-" in part:
            a, b = part.split("-")
            seeds.extend(range(int(a), int(b) + 1))
        elif part:
            seeds.append(int(part))
    return seeds


if __name__ == "__main__":
    main()
