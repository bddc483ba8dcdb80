//! Valid wire messages for the tests that break them field by field.

use concord_ipc::wire::{WireAdvice, WireAgentIntent, WireIntent, WIRE_OBJECTS};

/// An intent with every dimension known, so every confidence is read.
pub fn known_intent() -> WireIntent {
    WireIntent {
        style_confidence: 0.8,
        action_confidence: 0.8,
        task_confidence: 0.8,
        style: 1,
        action: 0,
        task: 0,
        reserved: 0,
    }
}

/// A valid, confident "decelerate" answering `request_id`, with known intents for the
/// passenger and the first `n_intents` road users (all agent 1).
pub fn advice(request_id: u64, published_ns: u64, n_intents: u8) -> WireAdvice {
    WireAdvice {
        request_id,
        published_ns,
        confidence: 0.9,
        ego_intent: known_intent(),
        agent_intents: [WireAgentIntent {
            intent: known_intent(),
            agent_id: 1,
            reserved: [0; 4],
        }; WIRE_OBJECTS],
        maneuver: 1,
        valid: 1,
        n_agent_intents: n_intents,
        failure: 0,
        reserved: [0; 4],
    }
}
