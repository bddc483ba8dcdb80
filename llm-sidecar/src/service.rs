//! The sidecar's async side: answers advice requests (eq. 16), parses intents from what people
//! say (eq. 8, §4.3), and turns decisions into eHMI language (§5).
//!
//! * **Advice.** One request at a time: while a request is in flight, the newest one waits and
//!   is asked as soon as it is answered. With `advice.cancel_superseded`, a newer one that
//!   describes a different situation (another logit favourite, another set of risky conflicts,
//!   another passenger intent) cancels the call instead, unless the one in flight itself
//!   replaced a cancelled request (so a slow server still answers every other request). A
//!   request is not sent at all when the corrected P_n is settled (its favourite leads by
//!   `advice.settled_margin`) and the situation is the one last asked about: the answer could
//!   not matter (counted as settled).
//!   Every answer, or failure with its reason, is published with the request id and the
//!   intents known so far, which is how intents reach the core.
//! * **Intents.** Each message is parsed once (see [`crate::ledger`]) by the quarantined intent
//!   parser, the only prompt that sees the words, into enums with confidences; the intent is set
//!   for the party the message came from only. A weak intent (< 0.7) is flagged and sent with
//!   its low confidence, which the core ignores; a weak passenger intent brings a confirmatory
//!   question. Road users get a reply written from what their message meant, checked by
//!   [`ehmi::check`] like every eHMI text.
//! * **eHMI.** Each change of decision (and every `repeat_s`) is announced; the model's text is
//!   used only for the maneuver it was written for and only if it passes [`ehmi::check`].
//!   Road users in a risky conflict whose intent is unknown are asked "Do you intend to pass
//!   first?", at most once per `inquiry_interval_s`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::future::Future;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{mpsc as std_mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use concord_core::scene::{IntentAction, Style};
use concord_core::{Announcement, DecisionSource, Maneuver};
use concord_ipc::clock::now_ns;
use concord_ipc::wire::{
    AdviceFailure, AdviceRequest, Audience, EhmiKind, EhmiMessage, IntentText, TextSource,
    WireAdvice, WireAgentIntent, WireDecision, WireIntent, UNKNOWN, WIRE_OBJECTS,
};
use hdrhistogram::Histogram;
use serde_json::json;
use tokio::sync::{mpsc, watch};

use crate::bus::{History, Outbound};
use crate::config::SidecarConfig;
use crate::ehmi::{self, Dialogue, Executed, Heard};
use crate::interaction_log::InteractionLog;
use crate::ledger::Ledger;
use crate::llm::{LlmClient, LlmError, Reply};
use crate::prompt::{self, Stated};
use crate::reply::{Answer, ReplyError};
use crate::schema::{self, AdviceAnswer, IntentAnswer};
use crate::slots::Slots;

/// The bus publishes (and stamps) an answer up to one period after it is ready: leave that
/// much before the deadline.
const PUBLISH_MARGIN: Duration = Duration::from_millis(20);
/// A road user whose implicit yield and proceed probabilities both stay below this leaves its
/// intent open (a proactive inquiry may settle it).
const OPEN_INTENT_BELOW: f32 = 0.6;

/// Counters, printed periodically and on exit.
#[derive(Debug, Default, Clone)]
pub struct Counters {
    pub requests_taken: u64,
    pub requests_too_late: u64,
    /// Requests not sent: P_n settled and the situation unchanged since the last one asked.
    pub requests_settled: u64,
    pub cancelled: u64,
    pub answered: u64,
    pub failures: [u64; 5],
    pub texts: u64,
    pub texts_unreadable: u64,
    /// Messages parsed before (the sample iceoryx2 replays to a restarted sidecar).
    pub texts_repeated: u64,
    pub intents_parsed: u64,
    pub intents_weak: u64,
    pub intent_failures: u64,
    pub ehmi_sent: u64,
    /// Announcements in the model's words, and the model's texts refused by the check.
    pub ehmi_phrased: u64,
    pub ehmi_replaced: u64,
    pub phrase_failures: u64,
    pub inquiries: u64,
    pub confirmations: u64,
    pub replies: u64,
    pub verdicts: [u64; concord_ipc::wire::VERDICTS],
}

struct Party {
    intent: WireIntent,
    heard: Instant,
}

/// State shared by the workers (never held across an await).
struct State {
    dialogue: Dialogue,
    /// Intents parsed from road users' words, by track id.
    road_users: BTreeMap<u32, Party>,
    /// The passenger's parsed intent.
    passenger: WireIntent,
    /// Words people said, which no eHMI text may repeat.
    heard: Heard,
    ledger: Ledger,
    /// The newest request seen by any worker.
    request: Option<AdviceRequest>,
    /// The situation of the last request sent to the model.
    last_asked: Option<Situation>,
    decision: Option<WireDecision>,
    /// Request id of the newest published advice, for matching the core's verdict.
    published: Option<u64>,
    log: InteractionLog,
    counters: Counters,
    latency_ms: Histogram<u64>,
    prompt_tokens: Histogram<u64>,
}

/// The async side.
pub struct Sidecar {
    cfg: SidecarConfig,
    client: LlmClient,
    slots: Slots,
    state: Mutex<State>,
    out: std_mpsc::Sender<Outbound>,
    history: History,
    texts_dropped: Arc<AtomicU64>,
}

/// When a call must be answered.
#[derive(Clone, Copy, Debug)]
enum Deadline {
    /// By this instant, waiting for a request slot included (advice: the core's deadline).
    At(Instant),
    /// Within `call` once a slot is free, waiting at most `queue` for it (messages, eHMI
    /// phrasing: they are not tied to a core cycle, and a message is not dropped because
    /// advice requests held the server).
    AfterQueue { queue: Duration, call: Duration },
}

/// An eHMI phrasing in flight.
type Phrasing<'a> = Pin<Box<dyn Future<Output = Result<String, String>> + 'a>>;

/// What makes two requests the same situation for the model.
/// The corrected P_n's favourite leads the runner-up by at least `margin`.
fn settled(p_corrected: &[f64; 5], margin: f64) -> bool {
    let mut p = *p_corrected;
    p.sort_by(|a, b| b.total_cmp(a));
    p[0] - p[1] >= margin
}

/// What makes a request new: P_n's favourite, the risky road users, the passenger's intent.
type Situation = (usize, Vec<u32>, u8, u8);

fn situation(r: &AdviceRequest) -> Situation {
    let favourite = r
        .p_corrected
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i);
    let mut risky: Vec<u32> = r.conflicts[..(r.n_conflicts as usize).min(WIRE_OBJECTS)]
        .iter()
        .filter(|c| c.risky != 0)
        .map(|c| c.agent_id)
        .collect();
    risky.sort_unstable();
    (favourite, risky, r.ego_intent.action, r.ego_intent.task)
}

/// The decision `d` executes (a minimum-risk decision stops) and what it announces.
fn executed_of(d: &WireDecision) -> Option<Executed> {
    let (maneuver, source, _, _) = d.decode()?;
    Some(Executed {
        maneuver,
        stopping: source == DecisionSource::MinimumRisk,
        gives_way: Announcement::try_from(d.announce).ok()? == Announcement::GivingWay,
    })
}

impl Sidecar {
    pub fn new(
        cfg: SidecarConfig,
        client: LlmClient,
        log: InteractionLog,
        ledger: Ledger,
        out: std_mpsc::Sender<Outbound>,
        history: History,
        texts_dropped: Arc<AtomicU64>,
    ) -> Self {
        let hist = |hi| Histogram::new_with_bounds(1, hi, 2).expect("histogram bounds");
        Sidecar {
            slots: Slots::new(cfg.llm.max_in_flight),
            state: Mutex::new(State {
                dialogue: Dialogue::new(cfg.intent.dialogue_turns, cfg.intent.max_parties),
                road_users: BTreeMap::new(),
                passenger: WireIntent::default(),
                heard: Heard::new(cfg.intent.dialogue_turns, cfg.intent.max_parties + 1),
                ledger,
                request: None,
                last_asked: None,
                decision: None,
                published: None,
                log,
                counters: Counters::default(),
                latency_ms: hist(600_000),
                prompt_tokens: hist(1_000_000),
            }),
            cfg,
            client,
            out,
            history,
            texts_dropped,
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, State> {
        self.state.lock().expect("sidecar state lock")
    }

    /// A copy of the counters.
    pub fn counters(&self) -> Counters {
        self.state().counters.clone()
    }

    /// Advice latency percentiles (p50, p95, max, ms) and mean prompt tokens.
    pub fn latency(&self) -> ([u64; 3], f64) {
        let s = self.state();
        let h = &s.latency_ms;
        if h.is_empty() {
            return ([0; 3], 0.0);
        }
        (
            [h.value_at_quantile(0.5), h.value_at_quantile(0.95), h.max()],
            s.prompt_tokens.mean(),
        )
    }

    fn publish(&self, o: Outbound) {
        let _ = self.out.send(o);
    }

    /// Intents known now, as carried by every advice.
    fn intents(&self, s: &State) -> (WireIntent, [WireAgentIntent; WIRE_OBJECTS], u8) {
        let mut agents = [WireAgentIntent::default(); WIRE_OBJECTS];
        let mut newest: Vec<_> = s.road_users.iter().collect();
        newest.sort_by_key(|(_, p)| std::cmp::Reverse(p.heard));
        let n = newest.len().min(WIRE_OBJECTS);
        for (w, (id, p)) in agents.iter_mut().zip(newest) {
            *w = WireAgentIntent {
                intent: p.intent,
                agent_id: *id,
                reserved: [0; 4],
            };
        }
        (s.passenger, agents, n as u8)
    }

    // ---- advice -------------------------------------------------------------------------

    /// Serves advice requests until the bus closes.
    pub async fn advice_worker(&self, mut rx: watch::Receiver<Option<AdviceRequest>>) {
        // A request that replaced a cancelled one runs to its end: when situations change
        // faster than the server answers, every other request still gets its answer.
        let mut after_cancel = false;
        'next: loop {
            if rx.changed().await.is_err() {
                return;
            }
            let Some(req) = *rx.borrow_and_update() else {
                continue;
            };
            self.state().request = Some(req);
            let left = Duration::from_nanos(req.deadline_ns.saturating_sub(now_ns()));
            let Some(left) = left.checked_sub(PUBLISH_MARGIN) else {
                self.state().counters.requests_too_late += 1;
                continue;
            };
            if left < Duration::from_secs_f64(self.cfg.llm.min_attempt_s) {
                self.state().counters.requests_too_late += 1;
                continue;
            }
            let here = situation(&req);
            {
                let mut s = self.state();
                if settled(&req.p_corrected, self.cfg.advice.settled_margin)
                    && s.last_asked.as_ref() == Some(&here)
                {
                    s.counters.requests_settled += 1;
                    continue;
                }
                s.last_asked = Some(here.clone());
                s.counters.requests_taken += 1;
            }
            let work = self.advise(req, Instant::now() + left);
            tokio::pin!(work);
            // A newer request seen while this one is in flight, taken once it is answered.
            let mut waiting = false;
            loop {
                tokio::select! {
                    () = &mut work => {
                        after_cancel = false;
                        if waiting {
                            rx.mark_changed();
                        }
                        continue 'next;
                    }
                    changed = rx.changed() => {
                        if changed.is_err() {
                            return;
                        }
                        let newer = *rx.borrow();
                        if let Some(n) = newer {
                            self.state().request = Some(n);
                            if self.cfg.advice.cancel_superseded
                                && situation(&n) != here
                                && !after_cancel
                            {
                                after_cancel = true;
                                self.state().counters.cancelled += 1;
                                // Unseen: the outer loop takes it at once.
                                rx.mark_changed();
                                continue 'next;
                            }
                        }
                        rx.borrow_and_update();
                        waiting = true;
                    }
                }
            }
        }
    }

    async fn advise(&self, req: AdviceRequest, deadline: Instant) {
        let format = self.cfg.advice.prompt_format;
        let messages = {
            let stated = {
                let s = self.state();
                let (passenger, agents, n) = self.intents(&s);
                Stated {
                    passenger,
                    road_users: agents[..n as usize]
                        .iter()
                        .map(|a| (a.agent_id, a.intent))
                        .collect(),
                }
            };
            let history: Vec<_> = self
                .history
                .lock()
                .expect("history lock")
                .iter()
                .copied()
                .collect();
            prompt::advice_messages(
                format,
                self.cfg.advice.reasoning_steps,
                self.cfg.advice.max_objects,
                &req,
                &history,
                &stated,
                self.cfg.intent.weak_below,
                self.cfg.llm.fine_tuned,
            )
        };
        let body = self.client.advice_body(&messages, &self.cfg.advice);
        let decoded = self
            .ask(&body, Deadline::At(deadline), AdviceAnswer::decode)
            .await;
        let mut s = self.state();
        let (ego_intent, agent_intents, n_agent_intents) = self.intents(&s);
        let mut advice = WireAdvice {
            request_id: req.request_id,
            published_ns: 0, // stamped by the bus as it publishes
            confidence: 0.0,
            ego_intent,
            agent_intents,
            maneuver: UNKNOWN,
            valid: 0,
            n_agent_intents,
            failure: 0,
            reserved: [0; 4],
        };
        let record = match &decoded {
            Ok((a, r)) => {
                let confidence = a
                    .confidence
                    .unwrap_or(self.cfg.llm.confidence_without_logprobs);
                advice.confidence = confidence;
                advice.maneuver = a.maneuver as u8;
                advice.valid = 1;
                s.counters.answered += 1;
                s.latency_ms
                    .saturating_record(r.latency.as_millis().max(1) as u64);
                s.prompt_tokens
                    .saturating_record(u64::from(r.answer.usage.prompt_tokens).max(1));
                json!({"outcome": "answered", "maneuver": a.maneuver.name(),
                       "confidence": confidence, "confidence_from_logprobs": a.confidence.is_some(),
                       "steps": a.steps, "latency_ms": r.latency.as_secs_f64() * 1e3,
                       "attempts": r.attempts, "usage": r.answer.usage, "response": r.answer.content})
            }
            Err(e) => {
                let f = e.failure();
                advice.failure = f as u8;
                s.counters.failures[f as usize] += 1;
                json!({"outcome": "failed", "failure": f.name(), "error": e.to_string()})
            }
        };
        s.published = Some(req.request_id);
        let mut line = json!({"kind": "advice", "request_id": req.request_id,
                              "format": format.name(), "messages": messages,
                              "p_corrected": req.p_corrected});
        merge(&mut line, record);
        s.log.write(&line);
        drop(s);
        self.publish(Outbound::Advice(advice));
    }

    /// Sends `body` when a request slot frees up and decodes the answer, all before
    /// `deadline`.
    async fn ask<T>(
        &self,
        body: &serde_json::Value,
        deadline: Deadline,
        decode: impl FnOnce(&Answer) -> Result<T, ReplyError>,
    ) -> Result<(T, Reply), LlmError> {
        let permit = match deadline {
            Deadline::At(t) => self.slots.urgent(t.into()).await.map(|p| (p, t)),
            Deadline::AfterQueue { queue, call } => {
                let queue_until = Instant::now() + queue;
                let p = self.slots.routine(queue_until.into()).await;
                p.map(|p| (p, Instant::now() + call))
            }
        };
        let Some((_permit, until)) = permit else {
            return Err(LlmError::Timeout);
        };
        let reply = self.client.call(body, until).await?;
        let value = decode(&reply.answer).map_err(LlmError::Reply)?;
        Ok((value, reply))
    }

    /// The deadline of a message's parse or an eHMI phrasing.
    fn text_deadline(&self) -> Deadline {
        Deadline::AfterQueue {
            queue: Duration::from_secs_f64(self.cfg.intent.queue_s),
            call: Duration::from_secs_f64(self.cfg.intent.deadline_s),
        }
    }

    // ---- intents ------------------------------------------------------------------------

    /// Parses texts until the bus closes.
    pub async fn text_worker(&self, mut rx: mpsc::Receiver<IntentText>) {
        while let Some(t) = rx.recv().await {
            self.on_text(&t).await;
        }
    }

    async fn on_text(&self, t: &IntentText) {
        let now = Instant::now();
        let (Some(text), Some(source)) = (
            t.text(),
            [TextSource::Passenger, TextSource::RoadUser]
                .into_iter()
                .find(|s| *s as u8 == t.source),
        ) else {
            let mut s = self.state();
            s.counters.texts += 1;
            s.counters.texts_unreadable += 1;
            return;
        };
        // The party is the message's source, never anything its text says.
        let (from, speaker) = match source {
            TextSource::Passenger => (None, "the passenger".to_string()),
            TextSource::RoadUser => (Some(t.source_id), format!("road user {}", t.source_id)),
        };
        let messages = {
            let mut s = self.state();
            s.counters.texts += 1;
            if !s.ledger.take(t) {
                s.counters.texts_repeated += 1;
                return;
            }
            s.heard.hear(from, text);
            let last = s
                .dialogue
                .party(from)
                .and_then(|p| p.car_said_last())
                .map(str::to_string);
            prompt::intent_messages(
                &speaker,
                last.as_deref(),
                text,
                self.cfg.intent.max_text_chars,
                self.cfg.llm.fine_tuned,
            )
        };
        let body = self.client.body(
            &messages,
            "intent",
            &schema::intent_schema(),
            schema::INTENT_MAX_TOKENS,
        );
        let default = self.cfg.llm.confidence_without_logprobs;
        let decoded = self
            .ask(&body, self.text_deadline(), |a| {
                IntentAnswer::decode(a, default)
            })
            .await;
        // The guard is released before the reply's await.
        let (confirm, answer) = {
            let mut s = self.state();
            let mut line = json!({"kind": "intent", "source": speaker, "message_id": t.id,
                                  "messages": messages});
            let (a, r) = match decoded {
                Err(e) => {
                    s.counters.intent_failures += 1;
                    merge(
                        &mut line,
                        json!({"outcome": "failed", "error": e.to_string()}),
                    );
                    s.log.write(&line);
                    return;
                }
                Ok(ok) => ok,
            };
            let weak_below = self.cfg.intent.weak_below;
            let weak = a.weak(weak_below);
            s.counters.intents_parsed += 1;
            s.counters.intents_weak += u64::from(weak);
            let strong_style = a.style.filter(|(_, c)| *c >= weak_below).map(|(v, _)| v);
            s.dialogue.set_style(from, strong_style, now);
            let wire = a.to_wire();
            s.dialogue.heard(from, wire, now);
            merge(
                &mut line,
                json!({"outcome": "parsed", "weak": weak, "response": r.answer.content,
                       "latency_ms": r.latency.as_secs_f64() * 1e3, "usage": r.answer.usage,
                       "intent": {"style": a.style.map(|(v, c)| (schema::style_name(v), c)),
                                  "action": a.action.map(|(v, c)| (schema::action_name(v), c)),
                                  "task": a.task.map(|(v, c)| (schema::task_name(v), c))}}),
            );
            s.log.write(&line);
            // The passenger is asked to confirm a weak intent; a road user is answered.
            match from {
                None => {
                    s.passenger = wire;
                    let weak_action = a.action.is_none_or(|(_, c)| c < weak_below);
                    let confirm = weak_action.then(|| {
                        let q = ehmi::confirmation(a.action.map(|(v, _)| v));
                        s.counters.confirmations += 1;
                        s.dialogue.car_said(None, q, now);
                        self.message(&s, EhmiKind::Confirmation, Audience::Passenger, 0, q)
                    });
                    (confirm, None)
                }
                Some(id) => {
                    s.road_users.insert(
                        id,
                        Party {
                            intent: wire,
                            heard: now,
                        },
                    );
                    while s.road_users.len() > self.cfg.intent.max_parties {
                        let oldest = s
                            .road_users
                            .iter()
                            .min_by_key(|(_, p)| p.heard)
                            .map(|(k, _)| *k);
                        if let Some(k) = oldest {
                            s.road_users.remove(&k);
                        }
                    }
                    (None, Some(id))
                }
            }
        };
        if let Some(m) = confirm {
            self.publish(Outbound::Ehmi(m));
        }
        if let Some(id) = answer {
            self.reply_to(id).await;
        }
    }

    /// Answers road user `id` after its message was parsed: in the model's words when they pass
    /// the check (the reply prompt knows what the message meant, never its words), else with
    /// the template; nothing without a decision to describe.
    async fn reply_to(&self, id: u32) {
        let Some((executed, turns, style)) = ({
            let s = self.state();
            s.decision.as_ref().and_then(executed_of).map(|e| {
                let party = s.dialogue.party(Some(id));
                (
                    e,
                    party.map(|p| p.turns.iter().cloned().collect::<Vec<_>>()),
                    party.and_then(|p| p.style),
                )
            })
        }) else {
            return;
        };
        let proposed = if self.cfg.ehmi.llm_phrasing && !executed.stopping {
            let messages = prompt::reply_messages(
                &turns.unwrap_or_default(),
                ehmi::describe(executed),
                ehmi::tone(style),
                self.cfg.intent.weak_below,
            );
            self.phrase("reply", messages).await.ok()
        } else {
            None
        };
        let mut s = self.state();
        // The decision may have changed meanwhile: the text must state the one executed now.
        let executed = s
            .decision
            .as_ref()
            .and_then(executed_of)
            .unwrap_or(executed);
        let (text, refusal) = ehmi::compose(
            proposed.as_deref(),
            executed,
            style,
            self.cfg.ehmi.language,
            &s.heard,
        );
        s.counters.replies += 1;
        if let Some(r) = refusal {
            s.counters.ehmi_replaced += 1;
            let line = json!({"kind": "ehmi_refused", "audience": "road_user", "addressee": id,
                              "maneuver": executed.maneuver.name(), "proposed": proposed,
                              "reason": format!("{r:?}"), "sent": text});
            s.log.write(&line);
        }
        s.dialogue.car_said(Some(id), &text, Instant::now());
        let m = self.message(&s, EhmiKind::Reply, Audience::RoadUser, id, &text);
        drop(s);
        self.publish(Outbound::Ehmi(m));
    }

    fn message(
        &self,
        s: &State,
        kind: EhmiKind,
        audience: Audience,
        addressee: u32,
        text: &str,
    ) -> EhmiMessage {
        let (cycle, maneuver) = s
            .decision
            .as_ref()
            .and_then(|d| Some((d.cycle, Maneuver::try_from(d.maneuver).ok()?)))
            .unwrap_or((0, Maneuver::KeepSpeed));
        EhmiMessage::new(cycle, now_ns(), maneuver, kind, audience, addressee, text)
    }

    // ---- eHMI ---------------------------------------------------------------------------

    /// Announces decisions and asks road users of unknown intent, until the bus closes. A
    /// change of decision is announced at once with the template; the model's phrasing of it,
    /// when it arrives and passes the check while the decision still holds, follows.
    pub async fn ehmi_worker(&self, mut rx: watch::Receiver<Option<WireDecision>>) {
        let repeat = Duration::from_secs_f64(self.cfg.ehmi.repeat_s);
        // The decision announced last, when, and the model's text for it.
        let mut last: Option<(Executed, Instant)> = None;
        let mut phrased: Option<String> = None;
        // Phrasings by (maneuver, giving way, stopping, tone): each is asked for once; accepted
        // ones kept.
        type Key = (u8, bool, bool, &'static str);
        let mut known: BTreeMap<Key, String> = BTreeMap::new();
        let mut tried = std::collections::BTreeSet::new();
        let mut asked: Option<Key> = None;
        let mut phrasing: Option<Phrasing<'_>> = None;
        loop {
            let pending = async {
                match phrasing.as_mut() {
                    Some(f) => f.await,
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                changed = rx.changed() => {
                    if changed.is_err() {
                        return;
                    }
                    let Some(d) = *rx.borrow_and_update() else { continue };
                    let Some(executed) = executed_of(&d) else { continue };
                    let now = Instant::now();
                    let changed = last.is_none_or(|(e, _)| e != executed);
                    let due = changed || last.is_some_and(|(_, t)| now.duration_since(t) >= repeat);
                    let style = {
                        let mut s = self.state();
                        s.decision = Some(d);
                        self.note_verdict(&mut s, &d);
                        self.addressed_style(&s)
                    };
                    let key = (executed.maneuver as u8, executed.stance() == ehmi::Stance::Yielding, executed.stopping, ehmi::tone(style));
                    if changed {
                        phrased = known.get(&key).cloned();
                        phrasing = None;
                    }
                    if due {
                        last = Some((executed, now));
                        let text = {
                            let s = self.state();
                            let lang = self.cfg.ehmi.language;
                            ehmi::compose(phrased.as_deref(), executed, style, lang, &s.heard).0
                        };
                        self.announce(&text);
                    }
                    if changed && self.cfg.ehmi.llm_phrasing && !executed.stopping && tried.insert(key) {
                        let messages = prompt::phrase_messages(ehmi::describe(executed), key.3);
                        asked = Some(key);
                        phrasing = Some(Box::pin(self.phrase("ehmi", messages)));
                    }
                    self.inquire(now);
                }
                result = pending => {
                    phrasing = None;
                    let Some((executed, _)) = last else { continue };
                    let stopping = executed.stopping;
                    // A failed phrasing was counted and logged: the template stays.
                    let Ok(text) = result else { continue };
                    let text = text.trim().to_string();
                    let mut s = self.state();
                    match ehmi::check(&text, executed, self.cfg.ehmi.language, &s.heard) {
                        Ok(()) if !stopping => {
                            s.counters.ehmi_phrased += 1;
                            phrased = Some(text.clone());
                            if let Some(k) = asked.take() {
                                known.insert(k, text.clone());
                            }
                            drop(s);
                            self.announce(&text);
                        }
                        verdict => {
                            s.counters.ehmi_replaced += 1;
                            let reason = verdict.err().map_or("stopping".into(), |r| format!("{r:?}"));
                            let line = json!({"kind": "ehmi_refused", "audience": "broadcast",
                                              "maneuver": executed.maneuver.name(), "proposed": text,
                                              "reason": reason});
                            s.log.write(&line);
                        }
                    }
                }
            }
        }
    }

    /// Publishes `text` as the announcement of the newest decision.
    fn announce(&self, text: &str) {
        let mut s = self.state();
        s.counters.ehmi_sent += 1;
        let m = self.message(&s, EhmiKind::Decision, Audience::Broadcast, 0, text);
        drop(s);
        self.publish(Outbound::Ehmi(m));
    }

    /// Asks road users in a risky conflict whose intent is unknown, in words and in motion,
    /// whether they go first.
    fn inquire(&self, now: Instant) {
        let interval = Duration::from_secs_f64(self.cfg.ehmi.inquiry_interval_s);
        let mut out = Vec::new();
        {
            let mut s = self.state();
            for id in self.unknown_parties(&s) {
                if s.dialogue.should_inquire(id, now, interval) {
                    s.counters.inquiries += 1;
                    out.push(self.message(
                        &s,
                        EhmiKind::Inquiry,
                        Audience::RoadUser,
                        id,
                        ehmi::INQUIRY,
                    ));
                }
            }
        }
        for m in out {
            self.publish(Outbound::Ehmi(m));
        }
    }

    /// The model's text for an eHMI message (`kind` "ehmi": a decision, §5 step 2; "reply": an
    /// answer to a road user), logged; `Err` carries the failure.
    async fn phrase(
        &self,
        kind: &'static str,
        messages: Vec<prompt::ChatMessage>,
    ) -> Result<String, String> {
        let deadline = self.text_deadline();
        let body = phrase_body(&self.client, kind, &messages);
        let decoded = self
            .ask(&body, deadline, |a| {
                a.decode::<schema::Phrase>().map(|p| p.text)
            })
            .await;
        let mut line = json!({"kind": kind, "messages": messages});
        let out = match decoded {
            Ok((text, r)) => {
                merge(
                    &mut line,
                    json!({"outcome": "answered", "response": r.answer.content,
                           "latency_ms": r.latency.as_secs_f64() * 1e3, "usage": r.answer.usage}),
                );
                Ok(text)
            }
            Err(e) => {
                let mut s = self.state();
                s.counters.phrase_failures += 1;
                drop(s);
                merge(
                    &mut line,
                    json!({"outcome": "failed", "error": e.to_string()}),
                );
                Err(e.to_string())
            }
        };
        self.state().log.write(&line);
        out
    }

    /// Records the core's verdict on the newest published advice, once.
    fn note_verdict(&self, s: &mut State, d: &WireDecision) {
        if d.advice == 0 || s.published != Some(d.advice_request_id) {
            return;
        }
        let id = s.published.take();
        if let Some(v) = s.counters.verdicts.get_mut(d.advice as usize) {
            *v += 1;
        }
        let verdict = concord_core::AdviceVerdict::try_from(d.advice)
            .map(|v| v.name())
            .unwrap_or("unknown");
        s.log.write(&json!({"kind": "verdict", "request_id": id, "cycle": d.cycle,
                            "verdict": verdict, "executed": Maneuver::try_from(d.maneuver).map(|m| m.name()).unwrap_or("?")}));
    }

    /// Style of the most salient road user in a conflict: from their words, else their signals.
    fn addressed_style(&self, s: &State) -> Option<Style> {
        let r = s.request.as_ref()?;
        let n = (r.n_objects as usize).min(WIRE_OBJECTS);
        let o = r.objects[..n]
            .iter()
            .filter(|o| o.conflict != UNKNOWN)
            .max_by(|a, b| a.saliency.total_cmp(&b.saliency))?;
        let id = o.state.id;
        s.dialogue
            .party(Some(id))
            .and_then(|p| p.style)
            .or_else(|| {
                (o.state.intent.style_confidence as f64 >= self.cfg.intent.weak_below)
                    .then(|| Style::try_from(o.state.intent.style).ok())
                    .flatten()
            })
    }

    /// Road users in a risky conflict whose intent neither their words (a strong parsed
    /// action) nor their motion (an implicit yield or proceed of at least
    /// [`OPEN_INTENT_BELOW`], or being committed) makes known.
    fn unknown_parties(&self, s: &State) -> Vec<u32> {
        let Some(r) = s.request.as_ref() else {
            return Vec::new();
        };
        let strong = |i: &WireIntent| {
            IntentAction::try_from(i.action).is_ok()
                && i.action_confidence as f64 >= self.cfg.intent.weak_below
        };
        // Risky, and its motion leaves it open (neither its implicit yield nor its proceeding
        // is likely, and it is not committed): a question can settle it.
        r.conflicts[..(r.n_conflicts as usize).min(WIRE_OBJECTS)]
            .iter()
            .filter(|c| {
                c.risky != 0 && c.committed == 0 && c.yielding.max(c.proceeding) < OPEN_INTENT_BELOW
            })
            .map(|c| c.agent_id)
            .filter(|id| {
                let from_frame = r.objects[..(r.n_objects as usize).min(WIRE_OBJECTS)]
                    .iter()
                    .any(|o| o.state.id == *id && strong(&o.state.intent));
                let from_words = s.road_users.get(id).is_some_and(|p| strong(&p.intent));
                !from_frame && !from_words
            })
            .collect()
    }

    /// One line of counters.
    pub fn render(&self) -> String {
        let c = self.counters();
        let ([p50, p95, max], tokens) = self.latency();
        let mut out = format!(
            "requests {} taken, {} settled, {} too late, {} cancelled | answered {} (latency ms p50 {p50} p95 {p95} max {max}, prompt {tokens:.0} tokens) | failures",
            c.requests_taken, c.requests_settled, c.requests_too_late, c.cancelled, c.answered
        );
        for f in AdviceFailure::ALL {
            let _ = write!(out, " {}={}", f.name(), c.failures[f as usize]);
        }
        let _ = write!(out, " | core verdicts:");
        for v in concord_core::AdviceVerdict::ALL.iter().skip(1) {
            if c.verdicts[*v as usize] > 0 {
                let _ = write!(out, " {}={}", v.name(), c.verdicts[*v as usize]);
            }
        }
        let _ = write!(
            out,
            " | texts {} (unreadable {}, parsed before {}, dropped {}), intents {} (weak {}, failed {}) | eHMI {} ({} in the model's words, {} refused, {} phrasing failures), inquiries {}, replies {}, confirmations {}",
            c.texts,
            c.texts_unreadable,
            c.texts_repeated,
            self.texts_dropped.load(Ordering::Relaxed),
            c.intents_parsed,
            c.intents_weak,
            c.intent_failures,
            c.ehmi_sent,
            c.ehmi_phrased,
            c.ehmi_replaced,
            c.phrase_failures,
            c.inquiries,
            c.replies,
            c.confirmations
        );
        let (log_failures, ledger_failures) = {
            let s = self.state();
            (s.log.failures, s.ledger.write_failures)
        };
        if log_failures > 0 {
            let _ = write!(out, " | log write failures {log_failures}");
        }
        if ledger_failures > 0 {
            let _ = write!(out, " | parsed-file write failures {ledger_failures}");
        }
        out
    }
}

/// Adds the fields of `extra` (an object) to `base` (an object).
fn merge(base: &mut serde_json::Value, extra: serde_json::Value) {
    if let (Some(b), serde_json::Value::Object(e)) = (base.as_object_mut(), extra) {
        b.extend(e);
    }
}

/// The request for an eHMI text or reply: the base model's when the server's adapter is the
/// fine-tuned advisor (`LlmConfig::phrase_with_base_model`).
fn phrase_body(
    client: &LlmClient,
    kind: &str,
    messages: &[prompt::ChatMessage],
) -> serde_json::Value {
    let body = client.body(
        messages,
        kind,
        &schema::phrase_schema(),
        schema::PHRASE_MAX_TOKENS,
    );
    let cfg = client.config();
    if cfg.fine_tuned && cfg.phrase_with_base_model {
        LlmClient::with_adapter_scale(body, 0.0)
    } else {
        body
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::LlmConfig;

    #[test]
    fn phrasings_ask_for_the_base_model_only_beside_the_fine_tuned_adapter() {
        let messages = prompt::phrase_messages("turns left", "polite");
        let body = |fine_tuned, phrase_with_base_model| {
            let cfg = LlmConfig {
                fine_tuned,
                phrase_with_base_model,
                ..LlmConfig::default()
            };
            phrase_body(&LlmClient::new(&cfg).unwrap(), "ehmi", &messages)
        };
        assert_eq!(body(true, true)["lora"], json!([{"id": 0, "scale": 0.0}]));
        assert!(body(true, false).get("lora").is_none());
        assert!(body(false, true).get("lora").is_none());
    }

    #[test]
    fn a_request_is_settled_only_when_its_favourite_leads_by_the_margin() {
        let p = [0.1, 0.84, 0.03, 0.03, 0.0];
        assert!(settled(&p, 0.6));
        assert!(!settled(&p, 0.8));
        assert!(!settled(&[0.41, 0.05, 0.03, 0.51, 0.0], 0.6));
        // Above 1 nothing is settled: every request is asked.
        assert!(!settled(&[1.0, 0.0, 0.0, 0.0, 0.0], 1.01));
    }
}
