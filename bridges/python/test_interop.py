"""Python publishes scenes to a running `concord run` and reads its decisions over iceoryx2.

Needs the iceoryx2 package and a built `concord` binary ($CONCORD_BIN, default
target/debug/concord).
"""

import math
import os
import subprocess
import time
import unittest

import concord_wire as wire
from concord_link import ConcordLink, ConcordProcess, agent

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CONCORD = os.environ.get("CONCORD_BIN", os.path.join(ROOT, "target", "debug", "concord"))


def paper_frame(seq):
    """Scene ``seq`` of the paper's left turn, 0.05 s apart: the ego and one oncoming car."""
    t = seq * 0.05
    frame = wire.SceneFrame()
    frame.sequence = seq
    frame.stamp_ns = time.monotonic_ns()
    frame.ego = agent(40.0 - 8.0 * t, 5.0, math.pi, 8.0, 0)
    frame.agents[0] = agent(-40.0 + 8.0 * t, -5.0, 0.0, 8.0, 1)
    frame.ego_route_lane = 0  # the paper's left-turn lane
    return frame


class Interop(unittest.TestCase):
    def setUp(self):
        self.prefix = f"pytest-{os.getpid()}/"
        self.core = subprocess.Popen([CONCORD, "run", "--prefix", self.prefix, "--rate", "100"],
                                     stderr=subprocess.DEVNULL)
        self.link = ConcordLink(prefix=self.prefix, node_name=f"concord-pytest-{os.getpid()}")
        deadline = time.monotonic() + 20
        while self.link.latest_stats() is None:
            self.assertIsNone(self.core.poll(), "concord run exited")
            self.assertLess(time.monotonic(), deadline, "concord run never published statistics")
            time.sleep(0.05)

    def tearDown(self):
        self.core.terminate()
        self.assertEqual(self.core.wait(timeout=10), 0, "concord run did not stop cleanly")

    def test_scenes_from_python_are_answered_with_decisions(self):
        answered = 0
        for seq in range(1, 31):
            self.link.publish_scene(paper_frame(seq))
            d = self.link.wait_for_decision(seq)
            self.assertIsNotNone(d, f"no decision for scene {seq}")
            self.assertAlmostEqual(sum(d.p_corrected), 1.0, places=9)
            self.assertIn(wire.MANEUVERS[d.maneuver], wire.MANEUVERS)
            self.assertEqual(wire.SOURCES[d.source], "logit")
            self.assertGreater(d.n_points, 1)
            answered += 1
            time.sleep(0.03)
        self.assertEqual(answered, 30)

    def test_a_nan_frame_is_rejected_and_counted(self):
        frame = wire.SceneFrame()
        frame.sequence = 1
        frame.stamp_ns = time.monotonic_ns()
        frame.ego = agent(40.0, 5.0, math.pi, 8.0, 0)
        frame.ego.vx = float("nan")
        self.link.publish_scene(frame)
        deadline = time.monotonic() + 3
        stats = None
        while time.monotonic() < deadline:
            stats = self.link.latest_stats() or stats
            if stats is not None and stats.frames_rejected[wire.FRAME_REJECTS.index("not_finite")] == 1:
                break
            time.sleep(0.05)
        self.assertEqual(stats.frames_rejected[wire.FRAME_REJECTS.index("not_finite")], 1)
        self.assertEqual(stats.frames_accepted, 0)


if __name__ == "__main__":
    unittest.main()


class DecisionsOnArrival(unittest.TestCase):
    """`concord run --on-arrival` decides on each scene as it arrives, not on its tick."""

    def test_each_scene_is_answered_before_the_next_tick(self):
        # A 1 Hz tick: a core deciding on its tick could answer at most one of these in time.
        core = ConcordProcess(CONCORD, ["--geometry", "paper-intersection"], 1.0, tag="pyarrive")
        try:
            started = time.monotonic()
            for seq in range(1, 21):
                core.link.publish_scene(paper_frame(seq))
                d = core.link.wait_for_decision(seq, timeout_s=0.3)
                self.assertIsNotNone(d, f"no decision for scene {seq} within 0.3 s")
                self.assertEqual(d.scene_sequence, seq)
            elapsed = time.monotonic() - started
            self.assertLess(elapsed, 0.3 * 20)
            stats = None
            deadline = time.monotonic() + 3
            while stats is None or stats.frames_accepted < 20:
                self.assertLess(time.monotonic(), deadline, "statistics never counted 20 frames")
                stats = core.link.latest_stats() or stats
                time.sleep(0.05)
            self.assertEqual(stats.frames_accepted, 20)
        finally:
            core.close()
