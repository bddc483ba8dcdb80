//! Service names. Every service lives under a prefix, `concord/` by default; tests and
//! parallel deployments choose their own (`--prefix`), so their services never meet.
//!
//! | service | payload | publisher | subscribers |
//! |---|---|---|---|
//! | `scene` | [`SceneFrame`](crate::wire::SceneFrame) | perception, `concord feed`, simulator bridges | core |
//! | `decision` | [`WireDecision`](crate::wire::WireDecision) | core | controller, monitor, sidecar (eHMI) |
//! | `advice_request` | [`AdviceRequest`](crate::wire::AdviceRequest) | core | sidecar |
//! | `advice` | [`WireAdvice`](crate::wire::WireAdvice) | sidecar | core |
//! | `intent_text` | [`IntentText`](crate::wire::IntentText) | eHMI input, passenger UI | sidecar |
//! | `ehmi` | [`EhmiMessage`](crate::wire::EhmiMessage) | sidecar | eHMI display, monitor |
//! | `stats` | [`CoreStats`](crate::wire::CoreStats) | core | monitor |
//!
//! Two event services wake lock-step simulators and a core that decides on arrival
//! (`service.decide_on = "arrival"`): scene publishers notify `scene_ready` after each frame,
//! and such a core notifies `decision_ready` after each decision.

/// Default prefix.
pub const DEFAULT_PREFIX: &str = "concord/";

pub const SCENE: &str = "scene";
pub const DECISION: &str = "decision";
pub const ADVICE_REQUEST: &str = "advice_request";
pub const ADVICE: &str = "advice";
pub const INTENT_TEXT: &str = "intent_text";
pub const EHMI: &str = "ehmi";
pub const STATS: &str = "stats";
pub const SCENE_READY: &str = "scene_ready";
pub const DECISION_READY: &str = "decision_ready";

/// Full service name of `service` under `prefix`.
pub fn name(prefix: &str, service: &str) -> String {
    format!("{prefix}{service}")
}
