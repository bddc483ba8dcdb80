"""The SUMO co-simulation bridge (sumo_bridge.py): a lock-step episode with the real core and
SUMO (libsumo), the map Concord loads against the lanes SUMO reports, and the summary."""

import json
import math
import os
import subprocess
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import sumo_bridge as sb  # noqa: E402

CONCORD = os.environ.get("CONCORD_BIN", os.path.join(sb.ROOT, "target", "release", "concord"))


def args(**kw):
    ns = sb.argparse.Namespace(net=sb.DEFAULT_NET, scenario="left_turn", step=0.05,
                               radius=100.0, duration=20.0,
                               after_clear=0.5, concord=CONCORD, config=None, rate=100.0,
                               timeout=2.0, core_log=None, trace=None)
    for k, v in kw.items():
        setattr(ns, k, v)
    return ns


def distance_to_polyline(p, pts):
    best = math.inf
    for (ax, ay), (bx, by) in zip(pts, pts[1:]):
        dx, dy = bx - ax, by - ay
        u = max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / (dx * dx + dy * dy)))
        best = min(best, math.hypot(ax + u * dx - p[0], ay + u * dy - p[1]))
    return best


class SumoBridge(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        import libsumo
        cls.ls = libsumo
        libsumo.start(["sumo", *sb.sumo_args(sb.DEFAULT_NET, 0, 0.05)])

    @classmethod
    def tearDownClass(cls):
        cls.ls.close()

    def test_a_lock_step_episode_answers_every_frame_and_commands_the_ego(self):
        a = args()
        driver = sb.ConcordDriver(a)
        commanded = []
        orig = self.ls.vehicle.setSpeed

        def set_speed(vid, v):
            commanded.append((vid, v))
            orig(vid, v)

        self.ls.vehicle.setSpeed = set_speed
        try:
            e = sb.run_episode(self.ls, a, "concord", driver, "left_turn", 8.0, 0)
        finally:
            self.ls.vehicle.setSpeed = orig
            driver.close()
        self.assertFalse(e["collision"], e)
        self.assertTrue(e["success"], e)
        self.assertEqual(e["decisions_missed"], 0, e)
        # One decision per step: every frame published was answered and turned into a command.
        self.assertEqual(driver.sequence, len(commanded))
        self.assertTrue(all(vid == "ego" for vid, _ in commanded))
        self.assertGreater(driver.sequence, 100)
        self.assertIsNotNone(e["min_pet_s"])
        self.assertLess(e["time_to_clear_s"], a.duration)
        self.assertGreater(e["max_jerk_mps3"], 0.0)
        self.assertLessEqual(e["jerk_rms_mps3"], e["max_jerk_mps3"])

    def test_a_route_across_two_junctions_hands_over_from_leg_to_leg(self):
        """The corridor (two junctions): Concord drives the route SJ1>J1J2>J2N through both,
        on its first leg's lane (lane 0) up to J1 and its second's (lane 1) from the link on."""

        class Recording(sb.ConcordDriver):
            def __init__(self, a):
                super().__init__(a)
                self.lanes = []

            def reset(self):
                super().reset()
                wait = self.core.link.wait_for_decision

                def recorded(*a, **kw):
                    d = wait(*a, **kw)
                    if d is not None:
                        self.lanes.append(d.ego_lane)
                    return d

                self.core.link.wait_for_decision = recorded

        a = args(net=sb.CORRIDOR_NET, scenario="corridor", duration=40.0)
        driver = Recording(a)
        try:
            e = sb.run_episode(self.ls, a, "concord", driver, "corridor", 8.0, 0)
        finally:
            driver.close()
        self.assertFalse(e["collision"], e)
        self.assertTrue(e["success"], e)
        self.assertEqual(e["decisions_missed"], 0, e)
        lanes = driver.lanes
        self.assertEqual(lanes[0], 0)
        self.assertEqual(lanes[-1], 1)
        self.assertEqual(lanes, sorted(lanes), "one handover, never back")
        self.assertGreater(lanes.count(1), 100)

    def test_the_map_concord_loads_is_the_network_sumo_reports(self):
        out = subprocess.run([CONCORD, "map", sb.DEFAULT_NET, "--route", "EC>CS", "--json"],
                             capture_output=True, text=True, check=True)
        m = json.loads(out.stdout)
        self.assertEqual(m["route_lane"], 0)
        lanes = {lane["id"]: lane for lane in m["lanes"]}
        ls = self.ls
        ls.load(sb.sumo_args(sb.DEFAULT_NET, 0, 0.05))  # another test may have loaded another
        expected = set()
        for incoming in ls.lane.getIDList():
            if incoming.startswith(":"):
                continue
            for link in ls.lane.getLinks(incoming):
                outgoing, via, direction = link[0], link[4], link[6]
                if direction == "t":
                    continue
                expected.add(f"{incoming}>{outgoing}")
                lane = lanes[f"{incoming}>{outgoing}"]
                shapes = [ls.lane.getShape(incoming)]
                while via:
                    shapes.append(ls.lane.getShape(via))
                    nxt = [x[4] for x in ls.lane.getLinks(via) if x[4]]
                    via = nxt[0] if nxt else ""
                shapes.append(ls.lane.getShape(outgoing))
                # Within 15 cm: vertices closer than 1 m are merged (MERGE_VERTICES_M); the
                # stop line and the ends are kept exactly.
                for shape in shapes:
                    for p in shape:
                        self.assertLess(distance_to_polyline(p, lane["points"]), 0.15,
                                        f"{incoming}>{outgoing}: {p}")
                for p in (shapes[0][0], shapes[0][-1], shapes[-1][-1]):
                    self.assertIn([round(p[0], 6), round(p[1], 6)],
                                  [[round(x, 6), round(y, 6)] for x, y in lane["points"]])
                self.assertAlmostEqual(lane["stop_s_m"], ls.lane.getLength(incoming), delta=0.01)
                self.assertAlmostEqual(2 * lane["half_width_m"], ls.lane.getWidth(incoming))
        self.assertEqual(expected, set(lanes))


def netconvert():
    import sumo
    return os.path.join(sumo.SUMO_HOME, "bin", "netconvert")


class OpenDrive(unittest.TestCase):
    def test_an_opendrive_road_loads_through_netconvert(self):
        """OpenDRIVE also reaches Concord through SUMO's netconvert (deploy/maps/README.md): the
        paper's junction written as .xodr and converted back loads with the same movements."""
        import tempfile
        with tempfile.TemporaryDirectory() as tmp:
            xodr, net = os.path.join(tmp, "paper.xodr"), os.path.join(tmp, "paper.net.xml")
            quiet = {"capture_output": True, "check": True}
            subprocess.run([netconvert(), "-s", sb.DEFAULT_NET, "--opendrive-output", xodr], **quiet)
            subprocess.run([netconvert(), "--opendrive-files", xodr, "--no-turnarounds", "true",
                            "--offset.disable-normalization", "true", "-o", net], **quiet)
            shape = []
            for path in (sb.DEFAULT_NET, net):
                out = subprocess.run([CONCORD, "map", path, "--json"], capture_output=True,
                                     text=True, check=True)
                m = json.loads(out.stdout)
                shape.append((sorted((lane["turn"], round(lane["stop_s_m"], 1),
                                      round(lane["length_m"], 1)) for lane in m["lanes"]),
                              len(m["conflicts"])))
        self.assertEqual(shape[0], shape[1])
        self.assertEqual(len(shape[0][0]), 12)


class Summary(unittest.TestCase):
    def test_counts_and_extremes_per_policy_and_speed(self):
        def ep(policy, speed, **kw):
            e = {"policy": policy, "speed_mps": speed, "collision": False, "success": True,
                 "time_to_clear_s": 10.0, "min_pet_s": 2.0, "max_decel_near_mps2": 1.0,
                 "standing_s": 0.0, "avg_speed_mps": 6.0, "decisions_missed": 0,
                 "jerk_rms_mps3": 1.0, "max_jerk_mps3": 2.0}
            e.update(kw)
            return e

        rows = sb.summarize([
            ep("concord", 8.0, min_pet_s=1.2, max_decel_near_mps2=3.5, jerk_rms_mps3=3.0,
               max_jerk_mps3=9.0),
            ep("concord", 8.0, collision=True, success=False, time_to_clear_s=None,
               min_pet_s=None),
            ep("sumo", 8.0, time_to_clear_s=12.0),
        ])
        c, s = rows
        self.assertEqual((c["policy"], c["episodes"], c["collisions"], c["success"]),
                         ("concord", 2, 1, 1))
        self.assertEqual((c["min_pet_s"], c["pet_below_1_5"], c["decel_above_3"]), (1.2, 1, 1))
        self.assertEqual(c["time_to_clear_s"], 10.0)
        self.assertEqual((c["jerk_rms_mps3"], c["max_jerk_mps3"]), (2.0, 9.0))
        self.assertEqual((s["policy"], s["time_to_clear_s"], s["min_pet_s"]), ("sumo", 12.0, 2.0))

    def test_a_missing_network_is_a_clear_error(self):
        with self.assertRaises(SystemExit), open(os.devnull, "w") as null:
            err, sys.stderr = sys.stderr, null
            try:
                sb.main(["--net", "/nonexistent.net.xml"])
            finally:
                sys.stderr = err


if __name__ == "__main__":
    unittest.main()
