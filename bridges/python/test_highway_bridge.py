"""The highway-env bridge drives a real `concord run` in lock-step and reports well-formed results.

Needs the packages of requirements.txt (highway-env, iceoryx2) and a built `concord` binary
($CONCORD_BIN, default target/debug/concord). Runs the bridge's command line for two seeds of
intersection-v0 (about 20 s), one seed each of merge-v0, roundabout-v0 (on the map
highway_maps.py builds, which must rebuild the shipped file exactly) and intersection-v1 (its
own dynamical action kept), and one seed of a baseline, which needs no core.

Without Concord (constant DiscreteMetaAction baselines, about a minute in all): intersection-v2
and merge-v1 in lock-step, --duration, the per-episode outcome kind, standing time and other
vehicles' braking, the ceiling report, and the oracle (highway_oracle.py): a deep copy of the
environment replays like a fresh reset, its faster stepping changes no state, and on a seed
where constant FASTER crashes a profile of the small family arrives, which a plain replay
confirms.
"""

import copy
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CONCORD = os.environ.get("CONCORD_BIN", os.path.join(ROOT, "target", "debug", "concord"))
SUMMARY = re.compile(r"^(\S+) (\w+): (\d+) seeds, collisions (\d+\.\d) %, "
                     r"success (\d+\.\d) %, mean speed (\d+\.\d) m/s$")


def run_bridge(*args, env="intersection-v0", check=True):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "result.json")
        proc = subprocess.run(
            [sys.executable, "-W", "ignore", os.path.join(HERE, "highway_bridge.py"),
             "--env", env, "--json", out, *args],
            cwd=HERE, capture_output=True, text=True, timeout=120)
        if not check:
            return proc
        if proc.returncode != 0:
            raise AssertionError(f"bridge failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
        with open(out, encoding="utf-8") as f:
            return proc.stdout, json.load(f)


class Following(unittest.TestCase):
    """The controller's geometry, without a simulator."""

    def test_pursuit_holds_the_bicycle_model_on_a_circle(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        # Steady state on a 13 m circle (the left turn): the centre of gravity moves along the
        # tangent, the body lags by the slip angle asin(L / 2R), steering atan(2 tan(slip)).
        r = 13.0
        slip = math.asin(hb.VEHICLE_LENGTH / (2 * r))
        heading = math.pi / 2 - slip  # at (r, 0), moving counter-clockwise
        for ahead in (3.0, 6.0, 10.0):
            phi = ahead / r
            dx, dy = r * math.cos(phi) - r, r * math.sin(phi)
            beta = hb.pursuit_slip(math.atan2(dy, dx) - heading, math.hypot(dx, dy))
            self.assertAlmostEqual(beta, slip, places=6)
        self.assertAlmostEqual(math.atan(2 * math.tan(slip)), 0.3738, places=3)

    def test_route_progress_of_the_left_turn(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        self.assertAlmostEqual(hb.intersection_progress(2.0, 39.0), 72.0)
        self.assertAlmostEqual(hb.intersection_progress(2.0, 11.0), 100.0)
        quarter = 13.0 * math.pi / 2
        self.assertAlmostEqual(hb.intersection_progress(-11.0 + 13 / math.sqrt(2),
                                                        11.0 - 13 / math.sqrt(2)),
                               100.0 + quarter / 2)
        # Arrival (25 m into the exit lane) is 145.4 m along the route.
        self.assertAlmostEqual(hb.intersection_progress(-36.0, -2.0), 100.0 + quarter + 25.0)


class TurnSignals(unittest.TestCase):
    """Signals derived from highway-env's destinations match the routes its vehicles follow."""

    def test_directions_in_the_y_down_frame(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        # Heading east (+x); in highway-env's y-down frame north is -y, on the driver's left.
        self.assertEqual(hb.turn_signal(0.0, 0.0, -1.0), hb.SIGNAL_LEFT)
        self.assertEqual(hb.turn_signal(0.0, 0.0, 1.0), hb.SIGNAL_RIGHT)
        self.assertEqual(hb.turn_signal(0.0, 1.0, 0.0), hb.SIGNAL_OFF)
        self.assertEqual(hb.turn_signal(0.0, 0.0, 0.0), hb.SIGNAL_OFF)  # no route

    def test_signals_match_intersection_v0_routes(self):
        sys.path.insert(0, HERE)
        import gymnasium as gym
        import highway_env  # noqa: F401
        import highway_bridge as hb

        env = gym.make("intersection-v0", config=hb.env_config("concord", 5))
        checked = 0
        try:
            for seed in range(5):
                env.reset(seed=seed)
                for v in env.unwrapped.road.vehicles[:-1]:  # the last one is the ego
                    start, end, _ = v.lane_index
                    if not (start.startswith("o") and end.startswith("ir")) or not v.route:
                        continue
                    if v.lane.local_coordinates(v.position)[0] > v.lane.length - 15.0:
                        continue  # close to the junction the destination is no longer ahead
                    k, m = int(start[1]), int(v.route[-1][1][1])
                    expected = {(k + 2) % 4: hb.SIGNAL_OFF, (k + 1) % 4: hb.SIGNAL_LEFT,
                                (k - 1) % 4: hb.SIGNAL_RIGHT}[m]
                    d = v.destination_direction
                    self.assertEqual(hb.turn_signal(v.heading, d[0], d[1]), expected,
                                     f"seed {seed}: {v.lane_index} to o{m}")
                    checked += 1
        finally:
            env.close()
        self.assertGreater(checked, 10)


class BridgeChecks:
    """What every test of a bridge run checks: a well-formed summary and episodes."""

    def check_summary(self, stdout, result, policy, seeds, env="intersection-v0", top=20.0):
        last = stdout.strip().splitlines()[-1]
        m = SUMMARY.match(last)
        self.assertIsNotNone(m, f"summary line: {last!r}")
        self.assertEqual(m.group(1), env)
        self.assertEqual(m.group(2), policy)
        self.assertEqual(int(m.group(3)), seeds)
        s = result["summary"]
        self.assertEqual(s["seeds"], seeds)
        self.assertEqual(len(result["episodes"]), seeds)
        for key in ("collision_rate", "success_rate"):
            self.assertTrue(0.0 <= s[key] <= 1.0, f"{key} = {s[key]}")
        self.assertLessEqual(s["collision_rate"] + s["success_rate"], 1.0 + 1e-9)
        self.assertTrue(math.isfinite(s["mean_speed_mps"]) and 0.0 <= s["mean_speed_mps"] <= top)
        # The printed line rounds the JSON's numbers.
        self.assertAlmostEqual(float(m.group(4)), 100 * s["collision_rate"], delta=0.051)
        self.assertAlmostEqual(float(m.group(5)), 100 * s["success_rate"], delta=0.051)
        self.assertAlmostEqual(float(m.group(6)), s["mean_speed_mps"], delta=0.051)
        for e in result["episodes"]:
            self.assertGreater(e["steps"], 0)
            self.assertFalse(e["crashed"] and e["arrived"])
        return s

    def concord_seed(self, env, top, *args):
        """One seed of Concord on ``env`` (``args`` added to the command line): the summary
        line and counts, no decision timeout, a decision every step. Returns the stdout, the
        summary and the episode."""
        self.assertTrue(os.path.exists(CONCORD), f"build concord first: {CONCORD}")
        stdout, result = run_bridge("--policy", "concord", "--seeds", "1", "--concord", CONCORD,
                                    *args, env=env)
        s = self.check_summary(stdout, result, "concord", 1, env=env, top=top)
        self.assertEqual(s["timeouts"], 0, stdout)
        self.assertEqual(s["decisions"], s["steps"])
        e = result["episodes"][0]
        self.assertEqual(e["decisions"], e["steps"])
        return stdout, result, e


class HighwayBridge(BridgeChecks, unittest.TestCase):
    def test_concord_decides_every_step_of_two_seeds(self):
        self.assertTrue(os.path.exists(CONCORD), f"build concord first: {CONCORD}")
        stdout, result = run_bridge("--policy", "concord", "--seeds", "2", "--concord", CONCORD)
        s = self.check_summary(stdout, result, "concord", 2)
        self.assertEqual(s["timeouts"], 0, stdout)
        self.assertEqual(s["decisions"], s["steps"])
        for e in result["episodes"]:
            self.assertFalse(e["timed_out"])
            self.assertEqual(e["decisions"], e["steps"], f"seed {e['seed']}")
            self.assertEqual(sum(e["maneuvers"].values()), e["decisions"])
            self.assertLessEqual(e["minimum_risk"], e["decisions"])
            # Every episode ends: a collision, an arrival or the 13 s limit.
            self.assertTrue(e["crashed"] or e["arrived"] or e["sim_time_s"] >= 13.0 - 1e-6, e)
        self.assertLessEqual(s["minimum_risk_decisions"], s["decisions"])

    def test_concord_decides_every_step_of_a_merge_v0_seed(self):
        _, result, e = self.concord_seed("merge-v0", 40.0)
        # The default configuration for merge-v0 is deploy/highway-env-merge.toml.
        self.assertTrue(result["args"]["config"].endswith("highway-env-merge.toml"))
        self.assertEqual(sum(e["maneuvers"].values()), e["decisions"])
        # The episode ends in a collision, past x = 370 (merge-v0's end) or at the bridge's 40 s.
        self.assertTrue(e["crashed"] or e["sim_time_s"] >= 40.0 - 1e-6
                        or e["final_position"][0] > 370.0, e)
        self.assertEqual(e["arrived"], e["final_position"][0] > 370.0 and not e["crashed"])
        # The ego stays in its lane (y = 4): the core plans along it.
        self.assertAlmostEqual(e["final_position"][1], 4.0, delta=0.5)

    def test_merge_progress_and_arrival(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        self.assertEqual(hb.merge_progress(120.0, 4.0), 120.0)
        self.assertEqual(hb.MERGE_END_X, 370.0)
        cfg = hb.env_config("concord", 5, hb.ENVS["merge-v0"])
        # merge-v0 spawns the ego at 30 m/s: the continuous action must reach it.
        self.assertGreaterEqual(cfg["action"]["speed_range"][1], 30.0)
        self.assertNotIn("spawn_probability", cfg)
        self.assertIn("spawn_probability", hb.env_config("concord", 5))

    def test_a_baseline_runs_without_concord(self):
        stdout, result = run_bridge("--policy", "idle", "--seeds", "1", "--concord",
                                    "/nonexistent/concord")
        s = self.check_summary(stdout, result, "idle", 1)
        self.assertEqual(s["decisions"], 0)
        # intersection-v0's ego starts at its lane's 10 m/s and IDLE holds the 9 m/s set-point.
        self.assertGreater(s["mean_speed_mps"], 8.0)

    def test_intersection_v2_in_lock_step_with_a_baseline(self):
        stdout, result = run_bridge("--policy", "faster", "--seeds", "1", "--concord",
                                    "/nonexistent/concord", env="intersection-v2")
        s = self.check_summary(stdout, result, "faster", 1, env="intersection-v2")
        self.assertEqual(s["decisions"], 0)
        e = result["episodes"][0]
        # Every episode ends: a collision, an arrival or intersection's 13 s (13.2 s at 5 Hz:
        # highway-env's clock sums 0.2 s steps, which reach 13 only after 66 of them).
        self.assertTrue(e["crashed"] or e["arrived"] or e["sim_time_s"] >= 13.0, e)
        self.assertEqual(e["arrived"], e["final_progress_m"] > 145.0 and not e["crashed"], e)

    def test_merge_v1_in_lock_step_with_a_baseline(self):
        stdout, result = run_bridge("--policy", "slower", "--seeds", "1", "--concord",
                                    "/nonexistent/concord", env="merge-v1")
        s = self.check_summary(stdout, result, "slower", 1, env="merge-v1", top=40.0)
        e = result["episodes"][0]
        self.assertTrue(e["crashed"] or e["sim_time_s"] >= 40.0 - 1e-6
                        or e["final_position"][0] > 370.0, e)
        self.assertEqual(e["arrived"], e["final_position"][0] > 370.0 and not e["crashed"])
        self.assertLess(s["mean_speed_mps"], 25.0)  # SLOWER follows the lanes' 20 m/s traffic

    def test_duration_overrides_the_episode_length(self):
        # intersection: highway-env's own "duration", which ends the episode at the first step
        # whose clock (a float sum of 0.2 s steps) reaches it: 6 s after 30 steps, but 13 s
        # only after 66 (13.2 s).
        clock, steps = 0.0, 0
        while clock < 6.0:
            clock += 1 / 5
            steps += 1
        _, result = run_bridge("--policy", "slower", "--seeds", "1", "--duration", "6",
                               "--concord", "/nonexistent/concord")
        e = result["episodes"][0]
        self.assertEqual(e["outcome"], "time_limit", e)
        self.assertEqual(e["steps"], steps)
        self.assertEqual(result["summary"]["duration_s"], 6.0)
        # merge: the bridge's own time limit.
        _, result = run_bridge("--policy", "slower", "--seeds", "1", "--duration", "3",
                               "--concord", "/nonexistent/concord", env="merge-v1")
        e = result["episodes"][0]
        self.assertEqual(e["outcome"], "time_limit", e)
        self.assertAlmostEqual(e["sim_time_s"], 3.0, delta=1e-6)


class Roundabout(BridgeChecks, unittest.TestCase):
    """roundabout-v0 on the map built from its road network, and intersection-v1 with its own
    action configuration."""

    def test_the_shipped_map_is_what_highway_maps_builds(self):
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "roundabout.toml")
            subprocess.run([sys.executable, "-W", "ignore", os.path.join(HERE, "highway_maps.py"),
                            "roundabout", "--out", out], cwd=HERE, check=True,
                           capture_output=True, timeout=120)
            with open(out, encoding="utf-8") as f:
                built = f.read()
        with open(os.path.join(ROOT, "deploy", "maps", "highway-env-roundabout.toml"),
                  encoding="utf-8") as f:
            self.assertEqual(built, f.read(), "rerun highway_maps.py roundabout")

    def test_connectors_bridge_highway_envs_gaps_smoothly(self):
        sys.path.insert(0, HERE)
        import highway_maps as hm

        lanes = {lane["id"]: lane for lane in hm.build("roundabout")}
        for lane_id, lane in lanes.items():
            d = np.diff(lane["points"], axis=0)
            steps = np.linalg.norm(d, axis=1)
            self.assertGreater(steps.min(), 0.9, lane_id)  # no vertices on top of each other
            h = np.arctan2(d[:, 1], d[:, 0])
            turns = np.abs(np.angle(np.exp(1j * np.diff(h))))
            # No corner where highway-env's lanes leave a gap (a straight connector turns by
            # 26°): the sharpest turns are the 4 m chords of the 20 m ring, 11.5°, and no
            # stretch is tighter than a radius of 12 m.
            self.assertLess(np.degrees(turns.max()), 13.0, lane_id)
            self.assertLess((turns / np.minimum(steps[1:], steps[:-1])).max(), 1 / 12.0, lane_id)
        # Movements through one ring lane share its vertices exactly: the ego's path after the
        # merge is the outer ring's.
        ego = {tuple(p) for p in lanes["ego"]["points"]}
        ring = {tuple(p) for p in lanes["ring_outer_north"]["points"]}
        self.assertGreaterEqual(len(ego & ring), 10)

    def test_concord_drives_a_roundabout_v0_seed(self):
        _, _, e = self.concord_seed("roundabout-v0", 16.0)
        # Seed 0 (tuning): the ego starts 55 m along its route, enters the ring at about 75 m
        # and drives round it without a collision.
        self.assertFalse(e["crashed"], e)
        self.assertGreater(e["final_progress_m"], 100.0, e)
        self.assertLess(math.hypot(*e["final_position"]), 26.0, e)
        self.assertEqual(e["arrived"], e["final_position"][1] < -25.5)

    def test_concord_keeps_intersection_v1s_dynamical_action(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        spec = hb.with_duration(hb.ENVS["intersection-v1"], None)
        self.assertNotIn("action", hb.env_config("concord", 5, spec))
        env = hb.make_env("intersection-v1", "concord", 5, spec)
        try:
            env.reset(seed=0)
            a = env.unwrapped.action_type
            self.assertTrue(a.dynamical)
            self.assertEqual(tuple(a.acceleration_range), (-5.0, 5.0))
            self.assertEqual(type(env.unwrapped.vehicle).__name__, "BicycleVehicle")
        finally:
            env.close()
        _, _, e = self.concord_seed("intersection-v1", 20.0, "--duration", "4")
        # The ego drives up its approach (x = 2, towards -y) along the planned path.
        self.assertAlmostEqual(e["final_position"][0], 2.0, delta=0.5)
        self.assertLess(e["final_position"][1], 30.0)

    def test_the_intersection_map_lies_on_highway_envs_lanes(self):
        """intersection-v0/v1/v2's map (``deploy/maps/highway-env-intersection.toml``) was
        written before highway_maps.py; it is held to highway-env's road network instead: the
        polyline the core loads lies on the centre lines of the lanes its comment names (every
        0.5 m, within 2 cm: 1 m chords of the 13 m arc sag by 1 cm), from the first lane's start to the last
        one's end, with the stop line where the approach lane ends."""
        import gymnasium as gym
        import highway_env  # noqa: F401

        path = os.path.join(ROOT, "deploy", "maps", "highway-env-intersection.toml")
        loaded = json.loads(subprocess.run([CONCORD, "map", path, "--json"], check=True,
                                           capture_output=True, text=True).stdout)
        with open(path, encoding="utf-8") as f:
            routes = re.findall(r'^id = "(\w+)"  # ([\w →]+?):', f.read(), re.M)
        self.assertEqual(len(routes), len(loaded["lanes"]))
        env = gym.make("intersection-v0")
        try:
            env.reset(seed=0)
            net = env.unwrapped.road.network
            for (lane_id, route), lane in zip(routes, loaded["lanes"]):
                self.assertEqual(lane["id"], lane_id)
                nodes = route.split(" → ")
                hw = [net.get_lane((a, b, 0)) for a, b in zip(nodes, nodes[1:])]
                pts = np.array(lane["points"])
                for a, b in zip(pts, pts[1:]):
                    for w in np.linspace(0.0, 1.0, int(np.linalg.norm(b - a) / 0.5) + 2):
                        p = a + w * (b - a)
                        off = min(abs(c[1]) if -0.01 <= c[0] <= l.length + 0.01 else math.inf
                                  for l in hw for c in [l.local_coordinates(p)])
                        self.assertLess(off, 0.02, f"{lane_id}: {p} between {a} and {b}")
                self.assertLess(np.linalg.norm(np.array(lane["points"][0]) - hw[0].position(0, 0)),
                                0.01, lane_id)
                self.assertLess(np.linalg.norm(np.array(lane["points"][-1])
                                               - hw[-1].position(hw[-1].length, 0)), 0.01, lane_id)
                self.assertAlmostEqual(lane["stop_s_m"], hw[0].length, delta=0.01, msg=lane_id)
        finally:
            env.close()


class Environments(unittest.TestCase):
    """The v1/v2 variants are highway-env's connected-lane classes with the v0 settings."""

    def test_variants_build_highway_envs_connected_lane_classes(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.envs.intersection_env import ConnectedLaneIntersectionEnv
        from highway_env.envs.merge_env import ConnectedLaneMergeEnv, MergeEnv

        for name, cls, connected in (("intersection-v2", ConnectedLaneIntersectionEnv, True),
                                     ("merge-v1", ConnectedLaneMergeEnv, True),
                                     ("merge-v0", MergeEnv, False)):
            spec = hb.with_duration(hb.ENVS[name], None)
            env = hb.make_env(name, "concord", 5, spec)
            try:
                u = env.unwrapped
                self.assertIsInstance(u, cls, name)
                env.reset(seed=0)
                self.assertEqual(u.road.neighbour_vehicles_connected_lanes, connected, name)
                # merge-v1 needs the reward fix for a ContinuousAction, as merge-v0 does.
                env.step(np.zeros(2, dtype=np.float32))
                self.assertEqual(type(u.action_type).__name__, "ContinuousAction")
            finally:
                env.close()
        self.assertEqual(hb.ENVS["intersection-v2"]["road"], hb.ENVS["intersection-v0"]["road"])
        self.assertEqual(hb.ENVS["merge-v1"]["time_limit_s"], 40.0)
        spec = hb.with_duration(hb.ENVS["intersection-v2"], 20)
        self.assertEqual(hb.env_config("concord", 5, spec)["duration"], 20.0)
        self.assertIsNone(spec["time_limit_s"])
        spec = hb.with_duration(hb.ENVS["merge-v1"], 25)
        self.assertEqual(spec["time_limit_s"], 25.0)
        self.assertNotIn("duration", hb.env_config("concord", 5, spec))


class EpisodeFields(unittest.TestCase):
    """Outcome kinds, standing time, other vehicles' braking and the ceiling report."""

    @classmethod
    def setUpClass(cls):
        # A synthetic ceiling: seed 0 reachable, seed 1 not.
        cls.tmp = tempfile.TemporaryDirectory()
        cls.ceiling = os.path.join(cls.tmp.name, "ceiling.json")
        with open(cls.ceiling, "w", encoding="utf-8") as f:
            json.dump({"oracle": {"env": "intersection-v0", "duration_s": 13.0,
                                  "policy_frequency_hz": 5},
                       "seeds": [{"seed": 0, "reachable": True},
                                 {"seed": 1, "reachable": False},
                                 {"seed": 2, "reachable": False, "undecided": True}]}, f)
        cls.stdout, cls.result = run_bridge("--policy", "slower", "--seeds", "3", "--concord",
                                            "/nonexistent/concord", "--ceiling", cls.ceiling)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_fields_are_present_and_consistent(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        s, episodes = self.result["summary"], self.result["episodes"]
        self.assertEqual(sum(s["outcomes"].values()), s["seeds"])
        self.assertEqual(set(s["outcomes"]), set(hb.OUTCOMES))
        for e in episodes:
            self.assertEqual(e["outcome"], hb.outcome_kind(e))
            self.assertEqual(e["outcome"] == "crash", e["crashed"])
            self.assertEqual(e["outcome"] == "arrived", e["arrived"])
            self.assertTrue(0.0 <= e["standing_s"] <= e["sim_time_s"] + 1e-9, e)
            self.assertGreaterEqual(e["others_max_decel_mps2"], 0.0)
            self.assertLessEqual(e["others_max_decel_mps2"], 8.0)  # IDM's ACC_MAX is 6
            self.assertGreater(e["min_distance_m"], 0.0)
            self.assertTrue(e["min_pet_s"] is None or e["min_pet_s"] >= 0.0, e)
        # SLOWER stops before the junction and waits out the episode (13.2 s).
        for e in episodes:
            self.assertEqual(e["outcome"], "time_limit", e)
            self.assertGreater(e["standing_s"], 5.0, e)
        standing = [e["standing_s"] for e in episodes]
        self.assertAlmostEqual(s["standing_s"]["mean"], sum(standing) / len(standing))
        self.assertAlmostEqual(s["standing_s"]["max"], max(standing))
        decel = [e["others_max_decel_mps2"] for e in episodes]
        b = s["others_braking"]
        self.assertAlmostEqual(b["max_mps2"], max(decel))
        self.assertAlmostEqual(b["mean_of_episode_max_mps2"], sum(decel) / len(decel))
        self.assertEqual(b["episodes_harder_than_threshold"], sum(d > 3.0 for d in decel))
        self.assertAlmostEqual(s["min_distance_m"]["min"],
                               min(e["min_distance_m"] for e in episodes))
        # The printed lines carry the same counts.
        o = s["outcomes"]
        self.assertIn(f"outcomes: arrived {o['arrived']}, time_limit {o['time_limit']}, crash "
                      f"{o['crash']}, decision_timeout {o['decision_timeout']}", self.stdout)
        self.assertIn(f"max {s['standing_s']['max']:.2f} s per episode", self.stdout)

    def test_ceiling_report(self):
        c = self.result["summary"]["ceiling"]
        self.assertEqual(c["seeds_in_ceiling"], 2)
        self.assertEqual(c["reachable"], 1)
        self.assertEqual(c["arrived_on_reachable"], 0)  # SLOWER never arrives
        self.assertEqual(c["success_of_reachable"], 0.0)
        self.assertEqual(c["reachable_failed"], [0])
        self.assertEqual(c["unreachable_failed"], [1])
        self.assertEqual(c["unreachable_passed"], [])
        self.assertEqual(c["undecided"], [2])  # left out of the shares
        self.assertEqual(c["missing_seeds"], [])
        self.assertIn("ceiling: 1 of 2 seeds reachable, arrived on 0 of them", self.stdout)
        self.assertIn("ceiling: unreachable seeds failed [1], passed []", self.stdout)
        # A ceiling measured at another duration is refused.
        proc = run_bridge("--policy", "slower", "--seeds", "1", "--duration", "20",
                          "--ceiling", self.ceiling, check=False)
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn("other settings", proc.stderr)

    def test_arrivals_count_within_the_ceilings_rules_only_when_they_keep_them(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        def ep(seed, arrived, imposed=0.0, pet=None):
            return {"seed": seed, "arrived": arrived, "imposed_decel_mps2": imposed,
                    "min_pet_s": pet}

        episodes = [ep(0, True), ep(1, True, imposed=3.0, pet=1.5), ep(2, True, imposed=3.1),
                    ep(3, True, pet=1.49), ep(4, False), ep(5, True, imposed=9.0)]
        reachable = {0: True, 1: True, 2: True, 3: True, 4: True, 5: False}
        rules = {"max_imposed_decel_mps2": 3.0, "min_pet_s": 1.5}
        c = hb.ceiling_report(episodes, reachable, rules)
        # Limits inclusive, no encroachment keeps the PET rule; an unreachable seed never counts.
        self.assertEqual(c["arrived_on_reachable"], 4)
        self.assertEqual(c["arrived_within_rules_on_reachable"], 2)
        self.assertAlmostEqual(c["success_within_rules_of_reachable"], 2 / 5)
        self.assertEqual(c["reachable_arrived_breaking_rules"], [2, 3])
        # Courtesy alone: the short PET no longer breaks anything.
        c = hb.ceiling_report(episodes, reachable, {"max_imposed_decel_mps2": 3.0,
                                                    "min_pet_s": None})
        self.assertEqual(c["reachable_arrived_breaking_rules"], [2])
        # Every summary counts the arrivals keeping courtesy (3 m/s²) and PET (1.5 s).
        base = self.result["episodes"][0]
        full = [{**base, **e, "crashed": False} for e in episodes]
        k = hb.summarize("intersection-v0", "concord", full)["arrived_keeping_rules"]
        self.assertEqual((k["courteous"], k["courteous_and_pet"]), (3, 2))  # seeds 0, 1, 3; 0, 1
        self.assertIn("arrivals keeping the rules: courteous (imposed braking <= 3 m/s²) 0, and "
                      "PET >= 1.5 s too 0", self.stdout)
        # A ceiling without rules: every arrival keeps them, and no rules line is printed.
        c = hb.ceiling_report(episodes, reachable)
        self.assertEqual(c["arrived_within_rules_on_reachable"], c["arrived_on_reachable"])
        self.assertFalse(any("within its rules" in line for line in hb.detail_lines(
            {**self.result["summary"], "ceiling": c})))

    def test_a_stored_run_is_rescored_against_a_ceiling_with_rules(self):
        stored = os.path.join(self.tmp.name, "run.json")
        with open(stored, "w", encoding="utf-8") as f:
            json.dump(self.result, f)
        ruled = os.path.join(self.tmp.name, "ceiling_rules.json")
        with open(ruled, "w", encoding="utf-8") as f:
            json.dump({"oracle": {"env": "intersection-v0", "duration_s": 13.0,
                                  "policy_frequency_hz": 5, "max_imposed_decel_mps2": 3.0,
                                  "min_pet_s": 1.5},
                       "seeds": [{"seed": s, "reachable": True} for s in range(3)]}, f)
        stdout, again = run_bridge("--rescore", stored, "--ceiling", ruled)
        self.assertEqual(again["episodes"], self.result["episodes"])
        for k in ("outcomes", "standing_s", "imposed_braking", "success_rate"):
            self.assertEqual(again["summary"][k], self.result["summary"][k])
        c = again["summary"]["ceiling"]
        self.assertEqual((c["reachable"], c["arrived_within_rules_on_reachable"]), (3, 0))
        self.assertIn("ceiling: within its rules (imposed braking <= 3 m/s², PET >= 1.5 s) on 0 "
                      "of them: 0.0 % of reachable; arrived breaking them []", stdout)
        # A run stored at another duration is refused.
        proc = run_bridge("--rescore", stored, "--duration", "20", check=False)
        self.assertNotEqual(proc.returncode, 0)
        self.assertIn("other settings", proc.stderr)

    def test_others_braking_counts_near_living_vehicles_only(self):
        sys.path.insert(0, HERE)
        from types import SimpleNamespace as NS

        import highway_bridge as hb

        def car(x, speed, crashed=False):
            return NS(position=np.array([x, 0.0]), speed=speed, crashed=crashed)

        ego = car(0.0, 5.0)
        near, far, wrecked, leaving = car(10.0, 8.0), car(50.0, 8.0), car(5.0, 8.0), car(20.0, 8.0)
        u = NS(vehicle=ego, road=NS(vehicles=[ego, near, far, wrecked, leaving]))
        m = hb.OthersMonitor(u, 0.2)
        self.assertAlmostEqual(m.min_distance, 5.0)
        near.speed = 7.0      # 5 m/s² at 10 m: counts
        far.speed = 2.0       # 30 m/s² at 50 m: too far
        wrecked.speed = 0.0   # 40 m/s², crashed: highway-env's crash model, not braking
        wrecked.crashed = True
        newcomer = car(15.0, 0.0)  # first seen now: no previous speed
        u.road.vehicles = [ego, near, far, wrecked, newcomer]  # leaving is gone
        m.observe(u, 0.2)
        self.assertAlmostEqual(m.max_decel, 5.0)
        self.assertAlmostEqual(m.max_decel_t, 0.2)
        # Within 30 m at either end of the step: a car braking as it comes into range counts.
        far.position = np.array([29.0, 0.0])
        far.speed = 0.0       # 10 m/s², 50 m -> 29 m
        m.observe(u, 0.4)
        self.assertAlmostEqual(m.max_decel, 10.0)
        self.assertEqual(hb.outcome_kind({"crashed": True, "arrived": False, "timed_out": False}),
                         "crash")
        self.assertEqual(hb.outcome_kind({"crashed": False, "arrived": False,
                                          "timed_out": True}), "decision_timeout")


def _standing_ego(hb, name="intersection-v0"):
    """An intersection env reset at seed 0 with the ego standing 60 m into its approach."""
    env = hb.make_env(name, "concord", 5, hb.ENVS[name])
    env.reset(seed=0)
    u = env.unwrapped
    lane = u.road.network.get_lane(("o0", "ir0", 0))
    u.vehicle.position = lane.position(60.0, 0.0)
    u.vehicle.heading = lane.heading_at(60.0)
    u.vehicle.speed = 0.0
    return env, u


def _episode(**fields):
    """An episode record for ``summarize``: one step, arrived, nothing measured, ``fields``
    overriding."""
    e = {"crashed": False, "arrived": True, "timed_out": False, "steps": 1, "speed_sum": 0.0,
         "decisions": 1, "minimum_risk": 0, "standing_s": 0.0, "others_max_decel_mps2": 0.0,
         "imposed_decel_mps2": 0.0, "imposed_whole_decel_mps2": 0.0, "min_distance_m": 2.0,
         "outcome": "arrived"}
    e.update(fields)
    return e


class Reversing(unittest.TestCase):
    """A collision with a car that drives backwards is told apart: the crashed car's speed
    along its heading is negative, and the summary counts it."""

    def test_a_car_backing_into_the_standing_ego(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.vehicle.kinematics import Vehicle

        env, u = _standing_ego(hb)
        try:
            road, ego = u.road, u.vehicle
            self.assertIsNone(hb.crash_other(u))
            # A car 3 m ahead of the ego's front, facing the same way, backing at 4 m/s.
            back = Vehicle.make_on_lane(road, ("o0", "ir0", 0), 68.0, speed=-4.0)
            back.route = [("o0", "ir0", 0)]
            road.vehicles = [ego, back]
            for _ in range(5):
                env.step(np.array([0.0, 0.0], dtype=np.float32))
                if ego.crashed:
                    break
            self.assertTrue(ego.crashed)
            speed, had_crashed = hb.crash_other(u, [])
            self.assertLess(speed, -hb.REVERSING_MPS)
            self.assertFalse(had_crashed)
            self.assertTrue(hb.crash_other(u, [back])[1])
        finally:
            env.close()
        e = _episode(crashed=True, arrived=False, outcome="crash")
        episodes = [dict(e, crash_other_speed_mps=v, crash_other_had_crashed=c)
                    for v, c in ((-3.0, False), (2.0, True), (3.0, False), (None, None))]
        s = hb.summarize("intersection-v0", "concord", episodes)
        self.assertEqual((s["collisions_reversing"], s["collisions_with_crashed"]), (1, 1))


def _imposed_over_one_step(hb, env, u, before=None):
    """One env step at t = 0.2 s with an ImposedBraking split at intersection-v0's approach
    attached (``before`` runs first, attached): the monitor."""
    imposed = hb.ImposedBraking(hb.ENVS["intersection-v0"]["approach"])
    imposed.t = 0.2
    with imposed.attached(u):
        if before:
            before()
        env.step(np.array([0.0, 0.0], dtype=np.float32))
    return imposed


class Imposed(unittest.TestCase):
    """The braking the ego imposes: a follower braking for the ego counts, beyond what it would
    brake without the ego; a car braking for another car does not, and the episode's first step
    does not."""

    def braking(self, behind_ego, car_beyond_ego=False):
        """One step with the ego standing 60 m into its approach and an IDM car 20 m behind
        it at 10 m/s (``behind_ego``), or behind a standing IDM car on another approach:
        the imposed braking and the follower's own, m/s². With ``car_beyond_ego`` a standing
        IDM car 15 m ahead of the ego makes the follower brake without the ego too."""
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.vehicle.behavior import IDMVehicle

        env, u = _standing_ego(hb)
        try:
            road, ego = u.road, u.vehicle
            approach = ("o0", "ir0", 0) if behind_ego else ("o2", "ir2", 0)
            follower = IDMVehicle.make_on_lane(road, approach, 40.0, speed=10.0)
            follower.plan_route_to("o1")
            road.vehicles = [ego, follower]
            if car_beyond_ego:
                beyond = IDMVehicle.make_on_lane(road, approach, 75.0, speed=0.0)
                beyond.plan_route_to("o1")
                road.vehicles.append(beyond)
            if not behind_ego:
                leader = IDMVehicle.make_on_lane(road, approach, 60.0, speed=0.0)
                leader.plan_route_to("o1")
                road.vehicles.append(leader)
            def regulation():
                # The regulation's turn now: the follower yields (to the ego or its leader).
                road.enforce_road_rules()
                self.assertTrue(follower.is_yielding)
                self.assertEqual(follower.yields_to_ego, behind_ego)

            imposed = _imposed_over_one_step(hb, env, u, regulation)
            first = hb.ImposedBraking()  # t = 0: the episode's first step
            with first.attached(u):
                env.step(np.array([0.0, 0.0], dtype=np.float32))
            self.assertEqual(first.max_decel, 0.0)
            self.assertGreaterEqual(imposed.max_whole, imposed.max_decel)
            # Split by who brakes: here the follower waits behind the ego on its approach.
            self.assertEqual(imposed.max_part, {"queue": imposed.max_decel if behind_ego else 0.0,
                                                "regulation": 0.0, "leader": 0.0,
                                                "off_path": 0.0})
            return imposed.max_decel, (10.0 - follower.speed) / 0.4, imposed.max_whole
        finally:
            env.close()

    def test_a_follower_braking_for_the_ego_inside_the_junction_is_not_a_queue(self):
        """The ego standing 8 m into its left turn, past its line, and an IDM car 16 m behind
        it on its approach at 10 m/s (intersection-v2, whose cars see a leader on the next
        lane): its braking counts on the other side of the split."""
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.vehicle.behavior import IDMVehicle

        env, u = _standing_ego(hb, "intersection-v2")
        try:
            road, ego = u.road, u.vehicle
            turn = road.network.get_lane(("ir0", "il1", 0))
            ego.position, ego.heading = turn.position(8.0, 0.0), turn.heading_at(8.0)
            ego.lane_index, ego.lane = ("ir0", "il1", 0), turn
            follower = IDMVehicle.make_on_lane(road, ("o0", "ir0", 0), 92.0, speed=10.0)
            follower.plan_route_to("o1")
            road.vehicles = [ego, follower]
            imposed = _imposed_over_one_step(hb, env, u)
            self.assertGreater(imposed.max_decel, 3.0)
            self.assertEqual(imposed.max_part, {"queue": 0.0, "regulation": 0.0,
                                                "leader": imposed.max_decel, "off_path": 0.0})
        finally:
            env.close()

    def _ego_ahead_of_a_car(self, name, lane_index, s, turn, car_s):
        """The ego standing ``s`` m into ``lane_index``, ``turn`` rad off its heading, and an
        IDM car ``car_s`` m into the north approach at 10 m/s going straight on (south, its
        next lane ("ir2", "il0")), after one step: the imposed braking's split."""
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.vehicle.behavior import IDMVehicle

        env, u = _standing_ego(hb, name)
        try:
            road, ego = u.road, u.vehicle
            lane = road.network.get_lane(lane_index)
            ego.position = lane.position(s, 0.0)
            ego.heading = lane.heading_at(s) + turn
            ego.lane_index, ego.lane = lane_index, lane
            car = IDMVehicle.make_on_lane(road, ("o2", "ir2", 0), car_s, speed=10.0)
            car.plan_route_to("o0")
            road.vehicles = [ego, car]
            return _imposed_over_one_step(hb, env, u).max_part
        finally:
            env.close()

    def test_a_car_braking_for_the_ego_off_its_path_counts_apart(self):
        """intersection-v2 finds a leader on every lane that leaves the end of a car's lane:
        a car going straight on brakes as hard for the ego standing 8 m into the right turn
        from its approach, which it does not take, as for the ego 8 m into its own straight
        lane; only the second is a leader on its path (the car 92 m into its approach, 16 m
        behind). On intersection-v0 the car brakes for the ego standing 14 m ahead on its own
        approach turned round (a car driving the other way) as for one facing its way or
        standing across its lane: off its path, and on it."""
        for name, lane, s, turn, car_s, part in (
                ("intersection-v2", ("ir2", "il1", 0), 8.0, 0.0, 92.0, "off_path"),
                ("intersection-v2", ("ir2", "il0", 0), 8.0, 0.0, 92.0, "leader"),
                ("intersection-v0", ("o2", "ir2", 0), 80.0, math.pi, 66.0, "off_path"),
                ("intersection-v0", ("o2", "ir2", 0), 80.0, 0.0, 66.0, "leader"),
                ("intersection-v0", ("o2", "ir2", 0), 80.0, 1.6, 66.0, "leader")):
            with self.subTest(name=name, lane=lane, turn=turn):
                split = self._ego_ahead_of_a_car(name, lane, s, turn, car_s)
                self.assertGreater(split[part], 3.0, split)
                self.assertEqual([k for k, b in split.items() if b > 0.0], [part])

    def test_a_car_the_regulation_makes_yield_to_the_ego_counts_apart(self):
        """A car on the opposite approach at 8 m/s that ``RegulatedRoad`` made yield to the
        ego (its target speed 0, as the regulation sets it; marked here, one step into its
        yield): highway-env's IDM then brakes at its 6 m/s² limit, counted as the
        regulation's."""
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        from highway_env.vehicle.behavior import IDMVehicle

        env, u = _standing_ego(hb)
        try:
            road, ego = u.road, u.vehicle
            other = IDMVehicle.make_on_lane(road, ("o2", "ir2", 0), 60.0, speed=8.0)
            other.plan_route_to("o1")
            other.target_speed, other.is_yielding, other.yield_timer = 0.0, True, 1
            other.yields_to_ego = True
            road.vehicles = [ego, other]
            imposed = _imposed_over_one_step(hb, env, u)
            self.assertGreater(imposed.max_decel, 5.0)
            self.assertEqual(imposed.max_part, {"queue": 0.0, "regulation": imposed.max_decel,
                                                "leader": 0.0, "off_path": 0.0})
            # Recorded where it braked: on the opposite approach, at its speed then.
            t, x, y, speed = imposed.max_part_at["regulation"]
            self.assertEqual(t, 0.2)
            self.assertLess(abs(x - (-2.0)), 0.5)
            self.assertLess(y, -11.0)
            self.assertLess(abs(speed - 8.0), 0.5)
            self.assertIsNone(imposed.max_part_at["leader"])
        finally:
            env.close()

    def test_a_follower_braking_for_the_ego_counts(self):
        imposed, braked, whole = self.braking(behind_ego=True)
        self.assertGreater(braked, 3.0)
        self.assertGreater(imposed, 3.0)
        self.assertEqual(imposed, whole)  # it would not brake without the ego

    def test_only_the_braking_beyond_the_one_without_the_ego_counts(self):
        imposed, braked, whole = self.braking(behind_ego=True, car_beyond_ego=True)
        self.assertGreater(braked, 3.0)
        self.assertGreater(whole, 3.0)
        # Without the ego it brakes at 3.3 m/s² for the car beyond: 2.7 of its 6 count.
        self.assertGreater(imposed, 1.0)
        self.assertLess(imposed, whole - 1.0)

    def test_braking_for_another_car_does_not(self):
        imposed, braked, _ = self.braking(behind_ego=False)
        self.assertGreater(braked, 3.0)
        self.assertEqual(imposed, 0.0)


class _Car:
    """A vehicle for PetTracker: a position, a heading and a speed of its own."""

    def __init__(self, x, y, heading, vx, vy):
        self.start, self.heading, self.vel = np.array([x, y]), heading, np.array([vx, vy])
        self.position = self.start.copy()


class _Road:
    def __init__(self, *vehicles):
        self.vehicles = list(vehicles)


class Pet(unittest.TestCase):
    """Post-encroachment time: the time between one vehicle leaving a piece of road and the
    other, crossing or merging, entering it; 0 when both are in it at once; none for a car
    following another."""

    def pet(self, ego, other, frames=120, dt=0.05):
        """Move both cars in straight lines for ``frames`` frames and return the tracker."""
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        road = _Road(other, ego)
        tracker = hb.PetTracker(ego)
        for k in range(1, frames + 1):
            for v in road.vehicles:
                v.position = v.start + v.vel * (k * dt)
            tracker.observe(road, dt)
        return tracker

    def test_the_ego_crossing_behind_a_car(self):
        # The other drives east through the origin at 10 m/s (its rear leaves x = 1, the ego's
        # side, at 2.35 s); the ego drives north 1.5 s later (its front reaches y = -1, the
        # other's side, at 3.15 s): PET 0.8 s, to within a cell and a frame.
        other = _Car(-20.0, 0.0, 0.0, 10.0, 0.0)
        ego = _Car(0.0, -35.0, math.pi / 2, 0.0, 10.0)
        t = self.pet(ego, other)
        self.assertAlmostEqual(t.min_pet, 0.8, delta=0.12)
        self.assertAlmostEqual(t.min_pet_t, 3.15, delta=0.12)

    def test_a_car_crossing_behind_the_ego(self):
        # The same crossing with the roles swapped: the other enters where the ego was.
        ego = _Car(-20.0, 0.0, 0.0, 10.0, 0.0)
        other = _Car(0.0, -35.0, math.pi / 2, 0.0, 10.0)
        self.assertAlmostEqual(self.pet(ego, other).min_pet, 0.8, delta=0.12)

    def test_both_in_the_crossing_at_once(self):
        other = _Car(-20.0, 0.0, 0.0, 10.0, 0.0)
        ego = _Car(0.0, -20.0, math.pi / 2, 0.0, 10.0)
        self.assertEqual(self.pet(ego, other).min_pet, 0.0)

    def test_following_in_a_lane_is_no_encroachment(self):
        other = _Car(-10.0, 0.0, 0.0, 10.0, 0.0)
        ego = _Car(-20.0, 0.0, 0.0, 10.0, 0.0)
        t = self.pet(ego, other)
        self.assertEqual(t.min_pet, math.inf)
        self.assertIsNone(t.min_pet_t)

    def test_a_merge_at_an_angle_counts(self):
        # The other comes into the ego's lane at 45 degrees and reaches (-10, 0) at 2 s, 1 s
        # after the ego's centre.
        ego = _Car(-20.0, 0.0, 0.0, 10.0, 0.0)
        d = 10.0 / math.sqrt(2.0)
        other = _Car(-10.0 - 2.0 * d, -2.0 * d, math.pi / 4, d, d)
        t = self.pet(ego, other, frames=60)
        self.assertGreater(t.min_pet, 0.3)
        self.assertLess(t.min_pet, 1.2)

    def test_summary_counts_episodes_below_each_threshold(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        episodes = [_episode(min_pet_s=p) for p in (0.2, 0.7, 1.2, 2.0, None)]
        p = hb.summarize("intersection-v0", "concord", episodes)["pet_s"]
        self.assertEqual(p["episodes"], 4)
        self.assertEqual(p["min"], 0.2)
        self.assertEqual(p["episodes_below"], {"0.5": 1, "1.0": 2, "1.5": 3})


def _states(u):
    sys.path.insert(0, HERE)
    import highway_oracle as ho

    return ho.vehicle_states(u)


# Actions for the determinism tests: ContinuousAction units (acceleration, steering).
ACTIONS = [np.array([0.4, 0.0], dtype=np.float32)] * 6 + \
          [np.array([-0.6, 0.1], dtype=np.float32)] * 6 + \
          [np.array([0.9, -0.05], dtype=np.float32)] * 12


class OracleReplay(unittest.TestCase):
    """The oracle's branches replay exactly what a normal run would simulate."""

    def make(self, name="intersection-v2"):
        sys.path.insert(0, HERE)
        import highway_bridge as hb

        return hb.make_env(name, "concord", 5, hb.with_duration(hb.ENVS[name], None))

    def reference(self, env, seed):
        env.reset(seed=seed)
        out = []
        for a in ACTIONS:
            env.step(a)
            out.append(_states(env.unwrapped))
        return out

    def test_a_deep_copy_replays_like_a_fresh_reset(self):
        env = self.make()
        try:
            seed = 3
            ref = self.reference(env, seed)
            self.assertGreater(len(ref[-1][0]), 5)  # there is traffic to get wrong
            # A copy made right after the reset.
            env.reset(seed=seed)
            c = copy.deepcopy(env.unwrapped)
            for k, a in enumerate(ACTIONS):
                c.step(a)
                self.assertEqual(_states(c), ref[k], f"copy at 0 s, step {k}")
            # A copy made mid-episode, and the original after it was copied.
            env.reset(seed=seed)
            for a in ACTIONS[:8]:
                env.step(a)
            c = copy.deepcopy(env.unwrapped)
            for k, a in enumerate(ACTIONS[8:], start=8):
                c.step(a)
                env.step(a)
                self.assertEqual(_states(c), ref[k], f"copy at 1.6 s, step {k}")
                self.assertEqual(_states(env.unwrapped), ref[k], f"original, step {k}")
        finally:
            env.close()

    def test_the_oracles_stepping_changes_no_state(self):
        sys.path.insert(0, HERE)
        import highway_oracle as ho

        env = self.make()
        try:
            seed = 3
            ref = self.reference(env, seed)
            env.reset(seed=seed)
            c = copy.deepcopy(env.unwrapped)
            with ho.fast_regulation():
                for k, a in enumerate(ACTIONS):
                    ho.fast_step(c, a)
                    self.assertEqual(_states(c), ref[k], f"step {k}")
        finally:
            env.close()

    def test_the_oracle_reaches_a_seed_where_faster_crashes(self):
        sys.path.insert(0, HERE)
        import highway_bridge as hb
        import highway_oracle as ho

        name, seeds = "intersection-v0", [3, 4]
        spec = hb.with_duration(hb.ENVS[name], None)
        # Constant FASTER (a normal baseline run) crashes on seed 3.
        env = hb.make_env(name, "faster", 5, spec)
        try:
            e = hb.run_episode(env, None, "faster", seeds[0], 0.2, spec)
        finally:
            env.close()
        self.assertIn(e["outcome"], ("crash", "time_limit"), e)
        family = ho.FAMILIES["small"]
        profiles = ho.profiles_of(family)
        doc = ho.run_oracle(name, spec, seeds, family)
        self.assertEqual([r["seed"] for r in doc["seeds"]], seeds)
        for r in doc["seeds"]:
            self.assertIsInstance(r["reachable"], bool)
            self.assertEqual(len(r["outcomes"]), len(profiles))
            self.assertEqual(sum(r["counts"].values()), len(profiles))
            self.assertEqual(r["reachable"], r["counts"]["arrived"] > 0)
        r = doc["seeds"][0]
        self.assertTrue(r["reachable"], r)
        self.assertEqual(doc["summary"]["reachable"], sum(x["reachable"] for x in doc["seeds"]))
        # Replay the first arriving profile with plain env.step (no oracle machinery) from a
        # fresh reset: it arrives without a collision, when the oracle said.
        i = next(k for k, o in enumerate(r["outcomes"]) if o[0] == "arrived")
        env = hb.make_env(name, "concord", 5, spec)
        try:
            env.reset(seed=seeds[0])
            u = env.unwrapped
            root, arrival = ho.plan_tree(u, profiles, 0.2)
            node, actions = root, []
            while node.children:
                a, node = next((a, n) for a, n in node.children.values() if i in n.below)
                actions.append(a)
            self.assertEqual(len(actions), arrival[i])
            for a in actions:
                _, _, terminated, truncated, _ = env.step(a)
            self.assertFalse(u.vehicle.crashed)
            self.assertTrue(u.has_arrived(u.vehicle))
            self.assertAlmostEqual(u.time, r["outcomes"][i][1], delta=1e-6)
        finally:
            env.close()
        # The first-arrival search agrees on reachability.
        doc1 = ho.run_oracle(name, spec, seeds, family, first=True)
        self.assertEqual([x["reachable"] for x in doc1["seeds"]],
                         [x["reachable"] for x in doc["seeds"]])
        # A longer episode reuses the reachable seeds and searches the others only.
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "oracle.json")
            with open(path, "w", encoding="utf-8") as f:
                json.dump(doc, f)
            spec20 = hb.with_duration(hb.ENVS[name], 20)
            reuse = ho.reusable(path, name, 20.0, 5, family)
            self.assertEqual(set(reuse[0]), {x["seed"] for x in doc["seeds"] if x["reachable"]})
            with self.assertRaises(SystemExit):
                ho.reusable(path, name, 10.0, 5, family)
            doc20 = ho.run_oracle(name, spec20, seeds, family, first=True, reuse=reuse)
        self.assertEqual(doc20["seeds"][0]["reused_from_duration_s"], 13.0)
        self.assertNotIn("reused_from_duration_s", doc20["seeds"][1])
        self.assertGreater(doc20["seeds"][1]["simulated_steps"], 0)
        self.assertEqual(doc20["oracle"]["duration_s"], 20.0)
        # Asking every encroachment to keep a PET no profile can keep: no profile arrives, and
        # the ones that came closest end as ``close``; a search without that rule is not reused.
        doc_pet = ho.run_oracle(name, spec, seeds[:1], family, min_pet=1e9)
        r = doc_pet["seeds"][0]
        self.assertEqual(doc_pet["oracle"]["min_pet_s"], 1e9)
        self.assertFalse(r["reachable"], r)
        self.assertGreater(r["counts"]["close"], 0, r)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "oracle.json")
            with open(path, "w", encoding="utf-8") as f:
                json.dump(doc, f)
            with self.assertRaises(SystemExit):
                ho.reusable(path, name, 20.0, 5, family, min_pet=1.5)


if __name__ == "__main__":
    unittest.main()
