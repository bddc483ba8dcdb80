"""Talk to a running Concord core from Python over iceoryx2 (``pip install iceoryx2==0.10.0``).

    link = ConcordLink(prefix="concord/")
    link.publish_scene(frame)            # a concord_wire.SceneFrame
    decision = link.latest_decision()    # a concord_wire.WireDecision or None

Services are opened with exactly the settings the Rust processes use (ipc/src/iox.rs), so it
does not matter which side starts first.
"""

import ctypes
import math
import os
import subprocess
import time

import iceoryx2 as iox2

import concord_wire as wire
from pet import wrap

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# Service settings shared with ipc/src/iox.rs.
MAX_PUBLISHERS = 4
MAX_SUBSCRIBERS = 16
MAX_NODES = 32
MAX_BUFFER = 256


def _service(node, name, payload):
    return (node.service_builder(iox2.ServiceName.new(name))
            .publish_subscribe(payload)
            .enable_safe_overflow(True)
            .history_size(1)
            .subscriber_max_buffer_size(MAX_BUFFER)
            .subscriber_max_borrowed_samples(2)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create())


def _event(node, name):
    return node.service_builder(iox2.ServiceName.new(name)).event().open_or_create()


class ConcordLink:
    """Scene publisher and decision, eHMI and statistics subscribers under one prefix.

    Each scene also notifies ``scene_ready``, which wakes a core that decides on arrival
    (``concord run --on-arrival``); such a core notifies ``decision_ready`` after each
    decision, and ``wait_for_decision`` sleeps on that event instead of polling."""

    def __init__(self, prefix=wire.DEFAULT_PREFIX, node_name="concord-python"):
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.node = iox2.NodeBuilder.new().name(iox2.NodeName.new(node_name)).create(iox2.ServiceType.Ipc)
        self.scene_publisher = _service(self.node, wire.service_name("scene", prefix), wire.SceneFrame).publisher_builder().create()
        self.decisions = _service(self.node, wire.service_name("decision", prefix), wire.WireDecision).subscriber_builder().buffer_size(MAX_BUFFER).create()
        self.stats = _service(self.node, wire.service_name("stats", prefix), wire.CoreStats).subscriber_builder().create()
        self.ehmi = _service(self.node, wire.service_name("ehmi", prefix), wire.EhmiMessage).subscriber_builder().buffer_size(8).create()
        self.scene_ready = _event(self.node, wire.service_name("scene_ready", prefix)).notifier_builder().create()
        self.decision_ready = _event(self.node, wire.service_name("decision_ready", prefix)).listener_builder().create()

    def publish_scene(self, frame):
        self.scene_publisher.send_copy(frame)
        self.scene_ready.notify()

    @staticmethod
    def _drain(subscriber, payload_type):
        out = []
        while True:
            sample = subscriber.receive()
            if sample is None:
                return out
            copy = payload_type()
            ctypes.memmove(ctypes.byref(copy), sample.payload_ptr, ctypes.sizeof(payload_type))
            out.append(copy)
            sample.delete()

    def decisions_received(self):
        """Every decision received since the last call, oldest first."""
        return self._drain(self.decisions, wire.WireDecision)

    def latest_decision(self):
        got = self.decisions_received()
        return got[-1] if got else None

    def latest_stats(self):
        got = self._drain(self.stats, wire.CoreStats)
        return got[-1] if got else None

    def wait_for_decision(self, sequence, timeout_s=1.0):
        """The decision answering scene ``sequence``, or None after ``timeout_s``. A stale-scene
        fallback carries the last valid frame's sequence: it is skipped by its code."""
        deadline = time.monotonic() + timeout_s
        while True:
            for d in self.decisions_received():
                if d.scene_sequence == sequence and d.fallback != wire.FALLBACK_STALE_SCENE:
                    return d
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            # Woken by a core deciding on arrival; a core on its tick never notifies, so the
            # wait is capped at 1 ms.
            self.decision_ready.timed_wait(iox2.Duration.from_micros(int(min(left, 1e-3) * 1e6)))


def wire_agent(x, y, vx, vy, heading, agent_id, ax=0.0, ay=0.0, signal=0):
    """A valid wire agent of a simulator's state, with no known intent (signal: a
    ``wire.TURN_SIGNALS`` code, 0 = off)."""
    a = wire.WireAgent()
    a.x, a.y, a.vx, a.vy, a.ax, a.ay = x, y, vx, vy, ax, ay
    a.heading = wrap(heading)
    a.intent = wire.WireIntent.unknown()
    a.id, a.kind, a.turn_signal, a.valid = agent_id, 0, signal, 1
    return a


def agent_row(a):
    """A wire agent as a trace row: [id, x, y, vx, vy, ax, ay, heading, turn signal], what
    ``cargo run --example replay_trace`` reads back."""
    return [a.id, a.x, a.y, a.vx, a.vy, a.ax, a.ay, a.heading, a.turn_signal]


def agent(x, y, heading, speed, agent_id, kind=0):
    """A valid wire agent moving at ``speed`` along ``heading`` with no known intent."""
    a = wire.WireAgent()
    a.x, a.y, a.heading = x, y, heading
    a.vx, a.vy = speed * math.cos(heading), speed * math.sin(heading)
    a.intent = wire.WireIntent.unknown()
    a.id, a.kind, a.valid = agent_id, kind, 1
    return a


def sample(decision, t):
    """(x, y, heading, speed) of the decision's trajectory ``t`` s ahead (linear in between)."""
    n = decision.n_points
    pts = decision.trajectory
    if n == 0:
        return None
    if t <= pts[0].t:
        p = pts[0]
        return p.x, p.y, p.heading, p.speed
    for k in range(1, n):
        if pts[k].t >= t:
            a, b = pts[k - 1], pts[k]
            u = (t - a.t) / max(b.t - a.t, 1e-9)
            turn = wrap(b.heading - a.heading)
            return (a.x + (b.x - a.x) * u, a.y + (b.y - a.y) * u, a.heading + turn * u,
                    a.speed + (b.speed - a.speed) * u)
    p = pts[n - 1]
    return p.x, p.y, p.heading, p.speed


class ConcordProcess:
    """``concord run`` on a private prefix with ``road`` arguments (``["--geometry", name]`` or
    ``["--map", file, "--route", id]``), and the link to it. It decides on each scene's
    arrival (lock-step), unless ``on_arrival`` is false; ``rate`` is then the tick that
    decides, else the one that only watches for staleness. The process is stopped by
    ``close``."""

    started = 0

    def __init__(self, binary, road, rate, config=None, log=None, trace=False, tag="py",
                 on_arrival=True):
        ConcordProcess.started += 1
        self.prefix = f"{tag}-{os.getpid()}-{ConcordProcess.started}/"
        args = [binary, "run", "--prefix", self.prefix, *road, "--rate", str(rate)]
        if on_arrival:
            args.append("--on-arrival")
        if config:
            args += ["--config", config]
        self.log = open(log, "a", encoding="utf-8") if log else subprocess.DEVNULL
        self.proc = subprocess.Popen(args, cwd=ROOT, stderr=self.log, stdout=self.log)
        self.link = ConcordLink(prefix=self.prefix,
                                node_name=f"{tag}-bridge-{os.getpid()}-{ConcordProcess.started}")
        # The advice requests carry the OPM triplet of each decision: conflicts, selected
        # objects, P_n; a trace logs them.
        self.requests = None
        if trace:
            self.requests = (_service(self.link.node, wire.service_name("advice_request", self.prefix),
                                      wire.AdviceRequest)
                             .subscriber_builder().buffer_size(64).create())
        deadline = time.monotonic() + 30
        while self.link.latest_stats() is None:
            if self.proc.poll() is not None:
                raise RuntimeError(f"concord run exited with {self.proc.returncode}")
            if time.monotonic() > deadline:
                self.close()
                raise RuntimeError("concord run never published statistics")
            time.sleep(0.05)

    def close(self):
        self.requests = None
        self.link = None  # releases the iceoryx2 node and its ports
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.log is not subprocess.DEVNULL:
            self.log.close()
