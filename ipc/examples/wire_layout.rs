//! Prints the size, alignment, type name and field offsets and types of every wire type, and the
//! names of the codes of every enum the wire carries, as JSON, for the layout test of the Python
//! mirror (`bridges/python/test_wire_layout.py`).

use concord_core::negotiation::Phase;
use concord_core::scene::{AgentKind, IntentAction, Style, Task, TurnSignal};
use concord_core::{AdviceVerdict, Announcement, DecisionSource, FallbackReason, Maneuver};
use concord_ipc::wire::*;
use iceoryx2::prelude::ZeroCopySend;
use std::fmt::Debug;
use std::mem::{align_of, offset_of, size_of};

/// The type of the field `field` selects, e.g. `type_of(|s: &WireAgent| &s.x)` is `f64`.
fn type_of<S, T>(_field: fn(&S) -> &T) -> &'static str {
    std::any::type_name::<T>()
}

/// `name` without module paths: `[concord_ipc::wire::WireAgent; 32]` -> `[WireAgent; 32]`.
fn short(name: &str) -> String {
    let mut out = String::new();
    let mut path_start = 0; // where the path being copied starts in `out`
    let mut rest = name;
    while let Some(c) = rest.chars().next() {
        if let Some(after) = rest.strip_prefix("::") {
            out.truncate(path_start);
            rest = after;
            continue;
        }
        out.push(c);
        if !(c.is_alphanumeric() || c == '_') {
            path_start = out.len();
        }
        rest = &rest[c.len_utf8()..];
    }
    out
}

/// A JSON array of names.
fn json_list<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let quoted: Vec<String> = names.into_iter().map(|n| format!("\"{n}\"")).collect();
    format!("[{}]", quoted.join(", "))
}

/// snake_case of a variant's name: `NoFeasibleTrajectory` -> `no_feasible_trajectory`.
fn snake(camel: &str) -> String {
    let mut out = String::new();
    for (i, c) in camel.char_indices() {
        if c.is_uppercase() && i > 0 {
            out.push('_');
        }
        out.extend(c.to_lowercase());
    }
    out
}

/// The names of codes 0, 1, … of a wire enum, up to the first unknown code.
fn code_names<E: TryFrom<u8> + Debug>() -> String {
    let names: Vec<String> = (0..=u8::MAX)
        .map_while(|code| E::try_from(code).ok())
        .map(|v| snake(&format!("{v:?}")))
        .collect();
    json_list(names.iter().map(String::as_str))
}

macro_rules! layout {
    ($ty:ty { $($field:ident),+ $(,)? }) => {{
        let fields: Vec<String> = vec![$(format!(
            "\"{}\": {{\"offset\": {}, \"type\": \"{}\"}}",
            stringify!($field),
            offset_of!($ty, $field),
            short(type_of(|s: &$ty| &s.$field))
        )),+];
        // SAFETY: type_name only reads the name given to the derive.
        let name = unsafe { <$ty as ZeroCopySend>::type_name() };
        format!(
            "\"{}\": {{\"type_name\": \"{}\", \"size\": {}, \"align\": {}, \"fields\": {{{}}}}}",
            stringify!($ty), name, size_of::<$ty>(), align_of::<$ty>(), fields.join(", ")
        )
    }};
}

fn main() {
    let entries = [
        layout!(WireIntent {
            style_confidence,
            action_confidence,
            task_confidence,
            style,
            action,
            task,
            reserved
        }),
        layout!(WireAgent {
            x,
            y,
            vx,
            vy,
            ax,
            ay,
            heading,
            intent,
            id,
            kind,
            turn_signal,
            valid,
            reserved
        }),
        layout!(SceneFrame {
            sequence,
            stamp_ns,
            ego,
            agents,
            ego_route_lane,
            reserved
        }),
        layout!(WirePoint {
            t,
            x,
            y,
            heading,
            speed,
            accel
        }),
        layout!(WireDecision {
            scene_sequence,
            cycle,
            scene_stamp_ns,
            decided_ns,
            compute_ns,
            advice_request_id,
            p_logit,
            p_corrected,
            trajectory,
            n_points,
            maneuver,
            logit_maneuver,
            source,
            advice,
            fallback,
            announce,
            negotiation,
            courtesy_rejects,
            ego_lane
        }),
        layout!(WireProcess {
            dist_to_stop_m,
            speed_mps,
            accel_mps2,
            theta_v,
            theta_a,
            s_m,
            l_m,
            lane,
            reserved
        }),
        layout!(WireConflict {
            x,
            y,
            ego_dist_m,
            agent_dist_m,
            ego_ttc_s,
            agent_ttc_s,
            delta_ttc_s,
            yielding,
            proceeding,
            undecided,
            required_decel_mps2,
            agent_id,
            risky,
            committed,
            right_of_way,
            stated
        }),
        layout!(WireObject {
            state,
            process,
            longitudinal_m,
            saliency,
            conflict,
            reserved
        }),
        layout!(AdviceRequest {
            request_id,
            scene_sequence,
            issued_ns,
            deadline_ns,
            p_logit,
            p_corrected,
            ego,
            ego_intent,
            objects,
            conflicts,
            leader_gap_m,
            leader_speed_mps,
            route_turn,
            n_objects,
            n_conflicts,
            reserved
        }),
        layout!(WireAgentIntent {
            intent,
            agent_id,
            reserved
        }),
        layout!(WireAdvice {
            request_id,
            published_ns,
            confidence,
            ego_intent,
            agent_intents,
            maneuver,
            valid,
            n_agent_intents,
            failure,
            reserved
        }),
        layout!(IntentText {
            stamp_ns,
            id,
            source_id,
            len,
            source,
            reserved,
            text
        }),
        layout!(EhmiMessage {
            decision_cycle,
            stamp_ns,
            len,
            maneuver,
            audience,
            addressee,
            kind,
            reserved,
            text
        }),
        layout!(CoreStats {
            stamp_ns,
            uptime_ns,
            period_ns,
            ticks,
            missed_deadlines,
            frames_received,
            frames_superseded,
            frames_accepted,
            frames_rejected,
            publisher_restarts,
            decisions,
            fallbacks,
            advice_requests,
            advice_received,
            advice_verdicts,
            advice_superseded,
            advice_pending,
            advice_failures,
            courtesy_rejects,
            deadlock_announcements,
            cycle_ns,
            scene_age_ns,
            decide_ns
        }),
    ];
    let names = [
        ("Maneuver", json_list(Maneuver::ALL.map(Maneuver::name))),
        ("DecisionSource", code_names::<DecisionSource>()),
        ("FallbackReason", code_names::<FallbackReason>()),
        (
            "AdviceVerdict",
            json_list(AdviceVerdict::ALL.map(AdviceVerdict::name)),
        ),
        (
            "AdviceFailure",
            json_list(AdviceFailure::ALL.map(AdviceFailure::name)),
        ),
        ("Announcement", code_names::<Announcement>()),
        ("Phase", code_names::<Phase>()),
        ("AgentKind", code_names::<AgentKind>()),
        ("TurnSignal", code_names::<TurnSignal>()),
        ("Style", code_names::<Style>()),
        ("IntentAction", code_names::<IntentAction>()),
        ("Task", code_names::<Task>()),
        (
            "FrameReject",
            json_list(FrameReject::ALL.map(FrameReject::name)),
        ),
    ]
    .map(|(name, list)| format!("\"{name}\": {list}"));
    println!(
        "{{\"types\": {{{}}},\n\"names\": {{{}}}}}",
        entries.join(",\n"),
        names.join(",\n")
    );
}
