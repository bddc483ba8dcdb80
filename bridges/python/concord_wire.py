"""ctypes mirror of Concord's wire contract (ipc/src/wire.rs).

Every class has the Rust type's field order, sizes and offsets (checked by
test_wire_layout.py) and a ``type_name()`` equal to the Rust ``#[type_name]``, so the
``iceoryx2`` Python package (0.10) exchanges them with Concord's Rust processes, e.g.::

    import iceoryx2 as iox2
    from concord_wire import SceneFrame, service_name
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    service = (node.service_builder(iox2.ServiceName.new(service_name("scene")))
               .publish_subscribe(SceneFrame).open_or_create())

Enumerations are ``u8`` codes (see the constants below); ``UNKNOWN`` (255) marks an absent
value. Times are CLOCK_MONOTONIC nanoseconds (``time.monotonic_ns()``).
"""

import ctypes

UNKNOWN = 255
MAX_AGENTS = 32
MAX_POINTS = 65
WIRE_OBJECTS = 8
TEXT_BYTES = 256
EHMI_MAX_CHARS = 64
DEFAULT_PREFIX = "concord/"

# Maneuver codes (core/src/choice.rs), in the order of P_n.
MANEUVERS = ("accelerate", "decelerate", "keep_speed", "turn_left", "turn_right")
# DecisionSource, FallbackReason and AdviceVerdict codes.
SOURCES = ("logit", "advice", "minimum_risk")
FALLBACKS = ("none", "no_feasible_trajectory", "stale_scene", "not_finite")
FALLBACK_STALE_SCENE = FALLBACKS.index("stale_scene")
ADVICE_VERDICTS = ("no_advice", "accepted", "malformed", "unknown_request",
                   "low_confidence", "late", "navigation_inconsistent", "unsafe", "expired",
                   "implausible")
# Announcement and negotiation Phase codes of a decision.
ANNOUNCEMENTS = ("giving_way", "going_first")
NEGOTIATION_PHASES = ("idle", "waiting", "announced", "going")
# AgentKind, TurnSignal, Style, IntentAction, Task codes.
AGENT_KINDS = ("car", "truck", "bus", "motorcycle", "bicycle", "pedestrian", "unknown")
TURN_SIGNALS = ("off", "left", "right", "hazard")
STYLES = ("aggressive", "balanced", "conservative")
ACTIONS = ("yield", "proceed", "accelerate", "decelerate", "turn_left", "turn_right", "stop")
TASKS = ("commute", "emergency", "official", "leisure")
# FrameReject codes: the index into CoreStats.frames_rejected.
FRAME_REJECTS = ("bad_code", "not_finite", "out_of_range", "duplicate", "out_of_order")
# AdviceFailure codes: the index into CoreStats.advice_failures.
ADVICE_FAILURES = ("timeout", "connection", "http_status", "malformed", "schema_violation")

# Each name tuple above and the Rust enum whose codes it names (checked by test_wire_layout).
CODE_NAMES = {
    "Maneuver": MANEUVERS, "DecisionSource": SOURCES, "FallbackReason": FALLBACKS,
    "AdviceVerdict": ADVICE_VERDICTS, "AdviceFailure": ADVICE_FAILURES,
    "Announcement": ANNOUNCEMENTS, "Phase": NEGOTIATION_PHASES, "AgentKind": AGENT_KINDS,
    "TurnSignal": TURN_SIGNALS, "Style": STYLES, "IntentAction": ACTIONS, "Task": TASKS,
    "FrameReject": FRAME_REJECTS,
}


def service_name(service, prefix=DEFAULT_PREFIX):
    """Full iceoryx2 service name, e.g. ``concord/scene``."""
    return prefix + service


class _Wire(ctypes.Structure):
    _type_name = ""

    @classmethod
    def type_name(cls):
        return cls._type_name


class WireIntent(_Wire):
    _type_name = "ConcordIntent"
    _fields_ = [
        ("style_confidence", ctypes.c_float),
        ("action_confidence", ctypes.c_float),
        ("task_confidence", ctypes.c_float),
        ("style", ctypes.c_uint8),
        ("action", ctypes.c_uint8),
        ("task", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8),
    ]

    @classmethod
    def unknown(cls):
        return cls(0.0, 0.0, 0.0, UNKNOWN, UNKNOWN, UNKNOWN, 0)


class WireAgent(_Wire):
    _type_name = "ConcordAgent"
    _fields_ = [
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("vx", ctypes.c_double),
        ("vy", ctypes.c_double),
        ("ax", ctypes.c_double),
        ("ay", ctypes.c_double),
        ("heading", ctypes.c_double),
        ("intent", WireIntent),
        ("id", ctypes.c_uint32),
        ("kind", ctypes.c_uint8),
        ("turn_signal", ctypes.c_uint8),
        ("valid", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8),
    ]


class SceneFrame(_Wire):
    _type_name = "ConcordSceneFrame"
    _fields_ = [
        ("sequence", ctypes.c_uint64),
        ("stamp_ns", ctypes.c_uint64),
        ("ego", WireAgent),
        ("agents", WireAgent * MAX_AGENTS),
        ("ego_route_lane", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 7),
    ]


class WirePoint(_Wire):
    _type_name = "ConcordTrajectoryPoint"
    _fields_ = [
        ("t", ctypes.c_double),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("heading", ctypes.c_double),
        ("speed", ctypes.c_double),
        ("accel", ctypes.c_double),
    ]


class WireDecision(_Wire):
    _type_name = "ConcordDecision"
    _fields_ = [
        ("scene_sequence", ctypes.c_uint64),
        ("cycle", ctypes.c_uint64),
        ("scene_stamp_ns", ctypes.c_uint64),
        ("decided_ns", ctypes.c_uint64),
        ("compute_ns", ctypes.c_uint64),
        ("advice_request_id", ctypes.c_uint64),
        ("p_logit", ctypes.c_double * 5),
        ("p_corrected", ctypes.c_double * 5),
        ("trajectory", WirePoint * MAX_POINTS),
        ("n_points", ctypes.c_uint32),
        ("maneuver", ctypes.c_uint8),
        ("logit_maneuver", ctypes.c_uint8),
        ("source", ctypes.c_uint8),
        ("advice", ctypes.c_uint8),
        ("fallback", ctypes.c_uint8),
        ("announce", ctypes.c_uint8),
        ("negotiation", ctypes.c_uint8),
        ("courtesy_rejects", ctypes.c_uint8),
        ("ego_lane", ctypes.c_uint8),
    ]


class WireProcess(_Wire):
    _type_name = "ConcordProcess"
    _fields_ = [
        ("dist_to_stop_m", ctypes.c_double),
        ("speed_mps", ctypes.c_double),
        ("accel_mps2", ctypes.c_double),
        ("theta_v", ctypes.c_double),
        ("theta_a", ctypes.c_double),
        ("s_m", ctypes.c_double),
        ("l_m", ctypes.c_double),
        ("lane", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 7),
    ]


class WireConflict(_Wire):
    _type_name = "ConcordConflict"
    _fields_ = [
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("ego_dist_m", ctypes.c_double),
        ("agent_dist_m", ctypes.c_double),
        ("ego_ttc_s", ctypes.c_double),
        ("agent_ttc_s", ctypes.c_double),
        ("delta_ttc_s", ctypes.c_double),
        ("yielding", ctypes.c_float),
        ("proceeding", ctypes.c_float),
        ("undecided", ctypes.c_float),
        ("required_decel_mps2", ctypes.c_float),
        ("agent_id", ctypes.c_uint32),
        ("risky", ctypes.c_uint8),
        ("committed", ctypes.c_uint8),
        ("right_of_way", ctypes.c_uint8),
        ("stated", ctypes.c_uint8),
    ]


class WireObject(_Wire):
    _type_name = "ConcordObject"
    _fields_ = [
        ("state", WireAgent),
        ("process", WireProcess),
        ("longitudinal_m", ctypes.c_double),
        ("saliency", ctypes.c_double),
        ("conflict", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 7),
    ]


class AdviceRequest(_Wire):
    _type_name = "ConcordAdviceRequest"
    _fields_ = [
        ("request_id", ctypes.c_uint64),
        ("scene_sequence", ctypes.c_uint64),
        ("issued_ns", ctypes.c_uint64),
        ("deadline_ns", ctypes.c_uint64),
        ("p_logit", ctypes.c_double * 5),
        ("p_corrected", ctypes.c_double * 5),
        ("ego", WireProcess),
        ("ego_intent", WireIntent),
        ("objects", WireObject * WIRE_OBJECTS),
        ("conflicts", WireConflict * WIRE_OBJECTS),
        ("leader_gap_m", ctypes.c_double),
        ("leader_speed_mps", ctypes.c_double),
        ("route_turn", ctypes.c_uint8),
        ("n_objects", ctypes.c_uint8),
        ("n_conflicts", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 5),
    ]


class WireAgentIntent(_Wire):
    _type_name = "ConcordAgentIntent"
    _fields_ = [
        ("intent", WireIntent),
        ("agent_id", ctypes.c_uint32),
        ("reserved", ctypes.c_uint8 * 4),
    ]


class WireAdvice(_Wire):
    _type_name = "ConcordAdvice"
    _fields_ = [
        ("request_id", ctypes.c_uint64),
        ("published_ns", ctypes.c_uint64),
        ("confidence", ctypes.c_double),
        ("ego_intent", WireIntent),
        ("agent_intents", WireAgentIntent * WIRE_OBJECTS),
        ("maneuver", ctypes.c_uint8),
        ("valid", ctypes.c_uint8),
        ("n_agent_intents", ctypes.c_uint8),
        ("failure", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 4),
    ]


class IntentText(_Wire):
    _type_name = "ConcordIntentText"
    _fields_ = [
        ("stamp_ns", ctypes.c_uint64),
        ("id", ctypes.c_uint64),
        ("source_id", ctypes.c_uint32),
        ("len", ctypes.c_uint16),
        ("source", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8),
        ("text", ctypes.c_uint8 * TEXT_BYTES),
    ]


class EhmiMessage(_Wire):
    _type_name = "ConcordEhmiMessage"
    _fields_ = [
        ("decision_cycle", ctypes.c_uint64),
        ("stamp_ns", ctypes.c_uint64),
        ("len", ctypes.c_uint16),
        ("maneuver", ctypes.c_uint8),
        ("audience", ctypes.c_uint8),
        ("addressee", ctypes.c_uint32),
        ("kind", ctypes.c_uint8),
        ("reserved", ctypes.c_uint8 * 7),
        ("text", ctypes.c_uint8 * TEXT_BYTES),
    ]


class CoreStats(_Wire):
    _type_name = "ConcordCoreStats"
    _fields_ = [
        ("stamp_ns", ctypes.c_uint64),
        ("uptime_ns", ctypes.c_uint64),
        ("period_ns", ctypes.c_uint64),
        ("ticks", ctypes.c_uint64),
        ("missed_deadlines", ctypes.c_uint64),
        ("frames_received", ctypes.c_uint64),
        ("frames_superseded", ctypes.c_uint64),
        ("frames_accepted", ctypes.c_uint64),
        ("frames_rejected", ctypes.c_uint64 * len(FRAME_REJECTS)),
        ("publisher_restarts", ctypes.c_uint64),
        ("decisions", ctypes.c_uint64 * len(SOURCES)),
        ("fallbacks", ctypes.c_uint64 * len(FALLBACKS)),
        ("advice_requests", ctypes.c_uint64),
        ("advice_received", ctypes.c_uint64),
        ("advice_verdicts", ctypes.c_uint64 * len(ADVICE_VERDICTS)),
        ("advice_superseded", ctypes.c_uint64),
        ("advice_pending", ctypes.c_uint64),
        ("advice_failures", ctypes.c_uint64 * len(ADVICE_FAILURES)),
        ("courtesy_rejects", ctypes.c_uint64),
        ("deadlock_announcements", ctypes.c_uint64),
        ("cycle_ns", ctypes.c_uint64 * 5),
        ("scene_age_ns", ctypes.c_uint64 * 5),
        ("decide_ns", ctypes.c_uint64 * 5),
    ]


ALL_TYPES = (WireIntent, WireAgent, SceneFrame, WirePoint, WireDecision, WireProcess,
             WireConflict, WireObject, AdviceRequest, WireAgentIntent, WireAdvice,
             IntentText, EhmiMessage, CoreStats)


def text_of(message):
    """The UTF-8 text of an IntentText or EhmiMessage."""
    return bytes(message.text[:message.len]).decode("utf-8")


def set_text(message, text):
    """Stores ``text`` (cut at a character boundary to fit) into an IntentText or EhmiMessage."""
    data = text.encode("utf-8")[:TEXT_BYTES]
    data = data.decode("utf-8", errors="ignore").encode("utf-8")
    ctypes.memset(ctypes.addressof(message.text), 0, TEXT_BYTES)
    ctypes.memmove(ctypes.addressof(message.text), data, len(data))
    message.len = len(data)
