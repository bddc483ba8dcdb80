"""The highway-env bridge drives a real `concord run` in lock-step and reports well-formed results.

Needs the packages of requirements.txt (highway-env, iceoryx2) and a built `concord` binary
($CONCORD_BIN, default target/debug/concord). Runs the bridge's command line for two seeds of
intersection-v0 (about 20 s), one seed of merge-v0 (a few seconds) and one seed of a baseline,
which needs no core.
"""

import json
import math
import os
import re
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
CONCORD = os.environ.get("CONCORD_BIN", os.path.join(ROOT, "target", "debug", "concord"))
SUMMARY = re.compile(r"^(\S+) (\w+): (\d+) seeds, collisions (\d+\.\d) %, "
                     r"success (\d+\.\d) %, mean speed (\d+\.\d) m/s$")


def run_bridge(*args, env="intersection-v0"):
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "result.json")
        proc = subprocess.run(
            [sys.executable, "-W", "ignore", os.path.join(HERE, "highway_bridge.py"),
             "--env", env, "--json", out, *args],
            cwd=HERE, capture_output=True, text=True, timeout=120)
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


class HighwayBridge(unittest.TestCase):
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
        self.assertTrue(os.path.exists(CONCORD), f"build concord first: {CONCORD}")
        stdout, result = run_bridge("--policy", "concord", "--seeds", "1", "--concord", CONCORD,
                                    env="merge-v0")
        s = self.check_summary(stdout, result, "concord", 1, env="merge-v0", top=40.0)
        self.assertEqual(s["timeouts"], 0, stdout)
        self.assertEqual(s["decisions"], s["steps"])
        # The default configuration for merge-v0 is deploy/highway-env-merge.toml.
        self.assertTrue(result["args"]["config"].endswith("highway-env-merge.toml"))
        e = result["episodes"][0]
        self.assertEqual(e["decisions"], e["steps"])
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


if __name__ == "__main__":
    unittest.main()
