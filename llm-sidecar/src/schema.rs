//! The two answers the sidecar asks for, as JSON schemas sent in `response_format` and as the
//! types they decode into. The schema fixes the shape of every answer: no text in a prompt, a
//! road user's included, can add a field or an enum value.

use concord_core::scene::{IntentAction, Style, Task};
use concord_core::Maneuver;
use concord_ipc::wire::{WireIntent, EHMI_MAX_CHARS};
use serde::Deserialize;
use serde_json::{json, Value};

use crate::reply::{Answer, ReplyError};

/// Longest reasoning step, characters.
const STEP_CHARS: usize = 80;
/// Most tokens generated for an intent answer (three enum values need about 25).
pub const INTENT_MAX_TOKENS: u32 = 64;
/// Most tokens generated for an eHMI phrasing or a reply (64 characters need about 20).
pub const PHRASE_MAX_TOKENS: u32 = 48;

/// Maneuver names as the model writes them (the core's names, in `Maneuver` order).
pub fn maneuver_names() -> Vec<&'static str> {
    Maneuver::ALL.iter().map(|m| m.name()).collect()
}

/// How every advice answer without reasoning steps begins (`{"maneuver": "turn_left"}`), as the
/// fine-tuned adapter was trained to write it.
pub const ADVICE_ANSWER_START: &str = "{\"maneuver\": \"";

/// The advice answer without reasoning steps for `m`.
pub fn advice_answer(m: Maneuver) -> String {
    format!("{ADVICE_ANSWER_START}{}\"}}", m.name())
}

/// GBNF grammar of the rest of an advice answer begun with [`ADVICE_ANSWER_START`]: one
/// maneuver name and the closing `"}`.
pub fn advice_rest_grammar() -> String {
    let names: Vec<String> = maneuver_names()
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect();
    format!("root ::= ({}) \"\\\"}}\"", names.join(" | "))
}

/// Schema of the advice answer: A_final (its tokens carry the confidence), then up to `steps`
/// short reasoning steps (0: none, the fastest). The eHMI text is asked for separately, for the
/// decision the core executes.
pub fn advice_schema(steps: usize) -> Value {
    let mut properties = json!({
        "maneuver": {"type": "string", "enum": maneuver_names()},
    });
    let mut required = vec!["maneuver"];
    if steps > 0 {
        properties["steps"] = json!({
            "type": "array", "minItems": 1, "maxItems": steps,
            "items": {"type": "string", "maxLength": STEP_CHARS}
        });
        required.push("steps");
    }
    json!({"type": "object", "properties": properties, "required": required,
           "additionalProperties": false})
}

/// Schema of an eHMI phrasing or a reply to a road user: one text of at most
/// [`EHMI_MAX_CHARS`] characters.
pub fn phrase_schema() -> Value {
    json!({"type": "object",
           "properties": {"text": {"type": "string", "minLength": 1, "maxLength": EHMI_MAX_CHARS}},
           "required": ["text"], "additionalProperties": false})
}

/// A decoded eHMI phrasing or reply (checked by [`crate::ehmi::check`] before use).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Phrase {
    pub text: String,
}

/// Values of the intent fields as the schema spells them, "unknown" last.
pub const STYLE_VALUES: [&str; 4] = ["aggressive", "balanced", "conservative", "unknown"];
pub const ACTION_VALUES: [&str; 8] = [
    "yield",
    "proceed",
    "accelerate",
    "decelerate",
    "turn_left",
    "turn_right",
    "stop",
    "unknown",
];
pub const TASK_VALUES: [&str; 5] = ["commute", "emergency", "official", "leisure", "unknown"];

/// Schema of the intent parser's answer for one message: style, action and task (eq. 8), each
/// possibly "unknown". Enums only: nothing the parser writes is free text.
pub fn intent_schema() -> Value {
    json!({
        "type": "object",
        "properties": {
            "style": {"type": "string", "enum": STYLE_VALUES},
            "action": {"type": "string", "enum": ACTION_VALUES},
            "task": {"type": "string", "enum": TASK_VALUES}
        },
        "required": ["style", "action", "task"],
        "additionalProperties": false
    })
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAdvice {
    maneuver: String,
    #[serde(default)]
    steps: Vec<String>,
}

/// A decoded advice answer.
#[derive(Debug, Clone, PartialEq)]
pub struct AdviceAnswer {
    /// A_final.
    pub maneuver: Maneuver,
    /// Its confidence (see [`crate::reply`]), or `None` without log-probabilities.
    pub confidence: Option<f64>,
    pub steps: Vec<String>,
}

impl AdviceAnswer {
    pub fn decode(a: &Answer) -> Result<Self, ReplyError> {
        let raw: RawAdvice = a.decode()?;
        let maneuver = Maneuver::ALL
            .into_iter()
            .find(|m| m.name() == raw.maneuver)
            .ok_or_else(|| {
                ReplyError::SchemaViolation(format!("unknown maneuver {:?}", raw.maneuver))
            })?;
        Ok(AdviceAnswer {
            maneuver,
            confidence: a.confidence("maneuver", &maneuver_names()),
            steps: raw.steps,
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawIntent {
    style: String,
    action: String,
    task: String,
}

/// A decoded intent answer: each dimension with its confidence in [0, 1] (`None` when
/// unknown).
#[derive(Debug, Clone, PartialEq)]
pub struct IntentAnswer {
    pub style: Option<(Style, f64)>,
    pub action: Option<(IntentAction, f64)>,
    pub task: Option<(Task, f64)>,
}

fn lookup<T: Copy>(name: &str, table: &[(&str, T)], what: &str) -> Result<Option<T>, ReplyError> {
    if name == "unknown" {
        return Ok(None);
    }
    table
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, v)| Some(*v))
        .ok_or_else(|| ReplyError::SchemaViolation(format!("unknown {what} {name:?}")))
}

const STYLES: [(&str, Style); 3] = [
    ("aggressive", Style::Aggressive),
    ("balanced", Style::Balanced),
    ("conservative", Style::Conservative),
];
const ACTIONS: [(&str, IntentAction); 7] = [
    ("yield", IntentAction::Yield),
    ("proceed", IntentAction::Proceed),
    ("accelerate", IntentAction::Accelerate),
    ("decelerate", IntentAction::Decelerate),
    ("turn_left", IntentAction::TurnLeft),
    ("turn_right", IntentAction::TurnRight),
    ("stop", IntentAction::Stop),
];
const TASKS: [(&str, Task); 4] = [
    ("commute", Task::Commute),
    ("emergency", Task::Emergency),
    ("official", Task::Official),
    ("leisure", Task::Leisure),
];

/// Name of an action as the schema spells it.
pub fn action_name(a: IntentAction) -> &'static str {
    ACTIONS
        .iter()
        .find(|(_, v)| *v == a)
        .map_or("unknown", |(n, _)| n)
}

/// Name of a style as the schema spells it.
pub fn style_name(s: Style) -> &'static str {
    STYLES
        .iter()
        .find(|(_, v)| *v == s)
        .map_or("unknown", |(n, _)| n)
}

/// Name of a task as the schema spells it.
pub fn task_name(t: Task) -> &'static str {
    TASKS
        .iter()
        .find(|(_, v)| *v == t)
        .map_or("unknown", |(n, _)| n)
}

impl IntentAnswer {
    /// Decodes and validates `a`: each value one of the schema's, each confidence finite and
    /// in [0, 1] (a dimension without log-probabilities gets `default_confidence`); anything
    /// else is a schema violation.
    pub fn decode(a: &Answer, default_confidence: f64) -> Result<Self, ReplyError> {
        let raw: RawIntent = a.decode()?;
        let conf = |key, values: &[&str]| {
            let c = a.confidence(key, values).unwrap_or(default_confidence);
            if c.is_finite() && (0.0..=1.0).contains(&c) {
                Ok(c)
            } else {
                Err(ReplyError::SchemaViolation(format!(
                    "{key}: confidence {c} outside [0, 1]"
                )))
            }
        };
        Ok(IntentAnswer {
            style: lookup(&raw.style, &STYLES, "style")?
                .map(|v| conf("style", &STYLE_VALUES).map(|c| (v, c)))
                .transpose()?,
            action: lookup(&raw.action, &ACTIONS, "action")?
                .map(|v| conf("action", &ACTION_VALUES).map(|c| (v, c)))
                .transpose()?,
            task: lookup(&raw.task, &TASKS, "task")?
                .map(|v| conf("task", &TASK_VALUES).map(|c| (v, c)))
                .transpose()?,
        })
    }

    /// The dimensions known but below `threshold`: weak intents (§4.3), flagged, never used.
    pub fn weak(&self, threshold: f64) -> bool {
        [
            self.style.map(|s| s.1),
            self.action.map(|a| a.1),
            self.task.map(|t| t.1),
        ]
        .into_iter()
        .flatten()
        .any(|c| c < threshold)
    }

    /// As a wire intent (every dimension, weak ones with their low confidence: the core's
    /// threshold keeps them out of the decision).
    pub fn to_wire(&self) -> WireIntent {
        let mut w = WireIntent::default();
        if let Some((s, c)) = self.style {
            w.style = s as u8;
            w.style_confidence = c as f32;
        }
        if let Some((a, c)) = self.action {
            w.action = a as u8;
            w.action_confidence = c as f32;
        }
        if let Some((t, c)) = self.task {
            w.task = t as u8;
            w.task_confidence = c as f32;
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use concord_ipc::wire::UNKNOWN;

    fn answer(content: &str) -> Answer {
        let body = json!({"choices": [{"message": {"content": content}, "finish_reason": "stop"}]});
        Answer::parse(&serde_json::to_vec(&body).unwrap()).unwrap()
    }

    #[test]
    fn advice_decodes_and_rejects_unknown_maneuvers_and_fields() {
        let a = AdviceAnswer::decode(&answer(r#"{"maneuver":"keep_speed"}"#)).unwrap();
        assert_eq!(a.maneuver, Maneuver::KeepSpeed);
        assert_eq!(a.confidence, None);
        for bad in [
            r#"{"maneuver":"fly"}"#,
            r#"{"steps":[]}"#,
            r#"{"maneuver":"accelerate","confidence":1.0}"#,
        ] {
            assert!(matches!(
                AdviceAnswer::decode(&answer(bad)),
                Err(ReplyError::SchemaViolation(_))
            ));
        }
    }

    #[test]
    fn intents_decode_with_unknowns_and_weak_flags() {
        let i = IntentAnswer::decode(
            &answer(r#"{"style":"aggressive","action":"unknown","task":"emergency"}"#),
            0.5,
        )
        .unwrap();
        assert_eq!(i.style, Some((Style::Aggressive, 0.5)));
        assert_eq!(i.action, None);
        assert!(i.weak(0.7));
        let w = i.to_wire();
        assert_eq!(w.action, UNKNOWN);
        assert_eq!(w.task, Task::Emergency as u8);
        for bad in [
            r#"{"style":"calm","action":"yield","task":"commute"}"#,
            r#"{"style":"balanced","action":"yield","task":"commute","reply":"go"}"#,
            r#"{"style":"balanced","action":"yield","task":"commute","confidence":1.0}"#,
        ] {
            assert!(IntentAnswer::decode(&answer(bad), 0.9).is_err(), "{bad}");
        }
        let ok = answer(r#"{"style":"balanced","action":"yield","task":"commute"}"#);
        assert!(IntentAnswer::decode(&ok, f64::NAN).is_err());
        assert!(IntentAnswer::decode(&ok, 1.5).is_err());
    }

    #[test]
    fn schemas_list_every_core_maneuver() {
        let s = advice_schema(2);
        assert_eq!(
            s["properties"]["maneuver"]["enum"]
                .as_array()
                .unwrap()
                .len(),
            5
        );
        assert_eq!(s["properties"]["steps"]["maxItems"], 2);
        assert!(advice_schema(0)["properties"].get("steps").is_none());
    }
}
