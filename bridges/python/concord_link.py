"""Talk to a running Concord core from Python over iceoryx2 (``pip install iceoryx2==0.10.0``).

    link = ConcordLink(prefix="concord/")
    link.publish_scene(frame)            # a concord_wire.SceneFrame
    decision = link.latest_decision()    # a concord_wire.WireDecision or None

Services are opened with exactly the settings the Rust processes use (ipc/src/iox.rs), so it
does not matter which side starts first.
"""

import ctypes
import time

import iceoryx2 as iox2

import concord_wire as wire

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


class ConcordLink:
    """Scene publisher and decision, eHMI and statistics subscribers under one prefix."""

    def __init__(self, prefix=wire.DEFAULT_PREFIX, node_name="concord-python"):
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.node = iox2.NodeBuilder.new().name(iox2.NodeName.new(node_name)).create(iox2.ServiceType.Ipc)
        self.scene_publisher = _service(self.node, wire.service_name("scene", prefix), wire.SceneFrame).publisher_builder().create()
        self.decisions = _service(self.node, wire.service_name("decision", prefix), wire.WireDecision).subscriber_builder().buffer_size(MAX_BUFFER).create()
        self.stats = _service(self.node, wire.service_name("stats", prefix), wire.CoreStats).subscriber_builder().create()
        self.ehmi = _service(self.node, wire.service_name("ehmi", prefix), wire.EhmiMessage).subscriber_builder().buffer_size(8).create()

    def publish_scene(self, frame):
        self.scene_publisher.send_copy(frame)

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
        """The decision answering scene ``sequence``, or None after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for d in self.decisions_received():
                if d.scene_sequence == sequence and d.fallback != 2:
                    return d
            time.sleep(0.001)
        return None


def agent(x, y, heading, speed, agent_id, kind=0):
    """A valid wire agent moving at ``speed`` along ``heading`` with no known intent."""
    import math
    a = wire.WireAgent()
    a.x, a.y, a.heading = x, y, heading
    a.vx, a.vy = speed * math.cos(heading), speed * math.sin(heading)
    a.intent = wire.WireIntent.unknown()
    a.id, a.kind, a.valid = agent_id, kind, 1
    return a
