//! The onboard core process: a fixed-rate loop (iceoryx2 WaitSet interval) that takes the
//! newest scene, runs the decision core on it, and publishes the decision and an advice request.
//! With `decide_on = "arrival"` it also wakes on the `scene_ready` event and decides at once,
//! for lock-step simulators; the interval then only watches for staleness.
//!
//! Each tick: drain `scene` (newest wins) and `advice`; check the frame's sequence and codes;
//! step the core (which checks every number); publish `decision` and, for every
//! `request_every`-th request the core issues (`advice.request_period_s`),
//! `advice_request`. With no valid scene for `staleness_s`, every tick publishes the
//! minimum-risk fallback: it carries the last valid frame's `scene_sequence` and
//! `fallback = stale_scene`, so a client matching decisions to frames skips it by that code.
//!
//! Concord's code on this path does not allocate: ports, buffers and histograms are set up
//! before the loop (iceoryx2 0.10 itself allocates a 48-byte state per loaned sample, and two
//! small `Vec`s when a notification wakes the WaitSet; `ipc/tests/loop_allocations.rs`).
//! Counters and latency percentiles go out on `stats` every `stats_period_s` and to stderr
//! every `print_period_s` and on exit.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;
use std::time::Duration;

use concord_core::negotiation::Phase;
use concord_core::scene::{Route, Scene, SceneErrorKind};
use concord_core::{Advice, AdviceVerdict, DecisionCore, FallbackReason, Params};
use concord_map::{BuiltIn, Map, MapError};
use hdrhistogram::Histogram;
use iceoryx2::config::Config;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::clock::{now_ns, secs};
use crate::iox::{self, IpcError};
use crate::services;
use crate::system::{apply_realtime, Notifier, RealtimeConfig};
use crate::wire::{
    AdviceFailure, AdviceRequest, CheckedAdvice, CoreStats, FrameReject, Percentiles, SceneFrame,
    WireAdvice, WireDecision,
};

/// Which built-in geometry the core uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    #[default]
    PaperIntersection,
    Merge,
    /// highway-env's `intersection-v0`, in its coordinates (`bridges/python/highway_bridge.py`).
    HighwayEnvIntersection,
    /// highway-env's `merge-v0`, in its coordinates (`bridges/python/highway_bridge.py`).
    HighwayEnvMerge,
}

impl Geometry {
    /// The built-in map (`deploy/maps/`).
    pub fn built_in(self) -> BuiltIn {
        match self {
            Geometry::PaperIntersection => BuiltIn::PaperIntersection,
            Geometry::Merge => BuiltIn::Merge,
            Geometry::HighwayEnvIntersection => BuiltIn::HighwayEnvIntersection,
            Geometry::HighwayEnvMerge => BuiltIn::HighwayEnvMerge,
        }
    }

    pub fn morphology(self) -> concord_core::Morphology {
        self.built_in().morphology()
    }
}

/// What wakes the core to decide.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DecideOn {
    /// Every period of `rate_hz` (a live perception feed).
    #[default]
    Tick,
    /// As soon as a scene publisher notifies `scene_ready` (lock-step simulators); the core
    /// then notifies `decision_ready` after each decision. The `rate_hz` tick still checks
    /// staleness and statistics.
    Arrival,
}

/// The road the core drives on: a map, and the ego's route when one is configured.
#[derive(Debug, Clone)]
pub struct Road {
    pub map: Map,
    /// Replaces every scene frame's `ego_route_lane` with the lane of the route's leg the ego
    /// is on (`service.route`).
    pub route: Option<Route>,
}

/// Loop settings of the core process.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Prefix of every service name.
    pub prefix: String,
    /// Loop rate, Hz.
    pub rate_hz: f64,
    /// What wakes the core to decide: its tick, or each scene's arrival.
    pub decide_on: DecideOn,
    /// After this long without a valid scene the minimum-risk fallback applies, s.
    pub staleness_s: f64,
    /// Publish every n-th advice request the core issues (0: never); see
    /// `core.advice.request_period_s`.
    pub request_every: u32,
    /// Period of `stats` messages, s.
    pub stats_period_s: f64,
    /// Period of the statistics line on stderr, s (0: only on exit).
    pub print_period_s: f64,
    /// Geometry of the road: a built-in map.
    pub geometry: Geometry,
    /// A map file, replacing `geometry`: Concord's TOML format (`deploy/maps/README.md`), a
    /// SUMO network (`*.net.xml`) or an OpenDRIVE file (`*.xodr`).
    pub map: Option<PathBuf>,
    /// The ego's route: the id of a lane of the map (of a SUMO network or OpenDRIVE, a
    /// movement "incoming lane>outgoing lane", "incoming edge>outgoing edge", or waypoints
    /// through several junctions, "a>b>c"). Scene frames then need not name it: their
    /// `ego_route_lane` is replaced by the lane of the route's leg the ego is on.
    pub route: Option<String>,
    /// Intents parsed by the sidecar from language apply for this long after the advice that
    /// carried them, s.
    pub intent_hold_s: f64,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            prefix: services::DEFAULT_PREFIX.into(),
            rate_hz: 20.0,
            decide_on: DecideOn::Tick,
            staleness_s: 0.3,
            request_every: 1,
            stats_period_s: 1.0,
            print_period_s: 10.0,
            geometry: Geometry::PaperIntersection,
            map: None,
            route: None,
            intent_hold_s: 10.0,
        }
    }
}

impl ServiceConfig {
    /// Loads the configured map (`map`, else the built-in `geometry`) and resolves `route`.
    pub fn road(&self) -> Result<Road, String> {
        let route = |e: MapError| format!("service.route: {e}");
        let (map, route) = match &self.map {
            Some(path) => {
                Map::load_route(path, self.route.as_deref()).map_err(|e| e.to_string())?
            }
            None => self
                .geometry
                .built_in()
                .map()
                .with_route(self.route.as_deref())
                .map_err(route)?,
        };
        Ok(Road { map, route })
    }
}

/// The whole configuration file of `concord run` (`deploy/concord.toml`).
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    pub service: ServiceConfig,
    pub realtime: RealtimeConfig,
    /// Parameters of the decision core.
    pub core: Params,
}

impl RunConfig {
    /// Checks what the loop and the core rely on.
    pub fn validate(&self) -> Result<(), String> {
        let s = &self.service;
        if !(s.rate_hz.is_finite() && (0.5..=1000.0).contains(&s.rate_hz)) {
            return Err(format!(
                "service.rate_hz = {}: expected 0.5 to 1000 Hz",
                s.rate_hz
            ));
        }
        // Each period becomes nanoseconds added to the clock: bounded so none can overflow.
        let periods = [
            ("service.staleness_s", s.staleness_s, 1e-3, 60.0),
            ("service.intent_hold_s", s.intent_hold_s, 0.0, 3600.0),
            ("service.stats_period_s", s.stats_period_s, 1e-3, 3600.0),
            ("service.print_period_s", s.print_period_s, 0.0, 3600.0),
        ];
        for (key, v, min, max) in periods {
            if !(min..=max).contains(&v) {
                return Err(format!("{key} = {v}: expected {min} to {max} s"));
            }
        }
        if let Some(cpu) = self
            .realtime
            .cpu
            .filter(|&c| c >= libc::CPU_SETSIZE as usize)
        {
            return Err(format!(
                "realtime.cpu = {cpu}: expected a CPU below {}",
                libc::CPU_SETSIZE
            ));
        }
        if let Some(p) = self
            .realtime
            .fifo_priority
            .filter(|p| !(1..=99).contains(p))
        {
            return Err(format!("realtime.fifo_priority = {p}: expected 1 to 99"));
        }
        self.core.validate().map_err(|e| format!("core: {e}"))
    }
}

/// When the loop ends, besides SIGINT and SIGTERM.
#[derive(Debug, Clone, Copy, Default)]
pub struct StopAfter {
    pub ticks: Option<u64>,
    pub duration_s: Option<f64>,
}

/// The intents of the last valid advice (eq. 8), held until `expires_ns`.
#[derive(Clone, Copy, Default)]
struct LanguageIntents {
    from: Option<CheckedAdvice>,
    expires_ns: u64,
}

impl LanguageIntents {
    /// Merges the held intents into `scene` until they expire.
    fn apply(&self, scene: &mut Scene, now_ns: u64) {
        if let Some(c) = self.from.filter(|_| now_ns < self.expires_ns) {
            c.merge_intents_into(scene);
        }
    }
}

/// Latency histogram in ns (1 µs to 10 s, 3 significant digits); allocated once.
struct Latency(Histogram<u64>);

impl Latency {
    fn new() -> Self {
        Latency(
            Histogram::new_with_bounds(1_000, 10_000_000_000, 3).expect("valid histogram bounds"),
        )
    }
    fn record(&mut self, ns: u64) {
        self.0.saturating_record(ns.max(1_000));
    }
    fn percentiles(&self) -> Percentiles {
        if self.0.is_empty() {
            return [0; 5];
        }
        let q = |q: f64| self.0.value_at_quantile(q);
        [q(0.5), q(0.9), q(0.99), q(0.999), self.0.max()]
    }
}

struct Ports {
    scene: Subscriber<ipc::Service, SceneFrame, ()>,
    advice: Subscriber<ipc::Service, WireAdvice, ()>,
    decision: Publisher<ipc::Service, WireDecision, ()>,
    request: Publisher<ipc::Service, AdviceRequest, ()>,
    stats: Publisher<ipc::Service, CoreStats, ()>,
    /// With `DecideOn::Arrival`: wakes the clients after each decision.
    decision_ready: Option<iceoryx2::port::notifier::Notifier<ipc::Service>>,
}

struct Loop<'a> {
    core: &'a mut DecisionCore,
    cfg: &'a ServiceConfig,
    route: Option<Route>,
    ports: Ports,
    notifier: Notifier,
    stats: CoreStats,
    cycle: Latency,
    scene_age: Latency,
    decide: Latency,
    started_ns: u64,
    period_ns: u64,
    prev_tick_ns: u64,
    last_stats_ns: u64,
    last_print_ns: u64,
    last_watchdog_ns: u64,
    /// (sequence, stamp) of the last frame that passed the sequence checks.
    last_frame: Option<(u64, u64)>,
    last_valid_rx_ns: Option<u64>,
    last_sequence: u64,
    last_stamp_ns: u64,
    advice: Option<Advice>,
    intents: LanguageIntents,
    /// Negotiation phase of the last decision published.
    last_phase: Phase,
    requests_since_publish: u32,
    publish_failures: u64,
}

/// Runs the core loop until SIGINT, SIGTERM or `stop`; returns the final statistics.
///
/// `route`, when given, replaces every frame's `ego_route_lane` ([`Road::route`]).
pub fn run(
    core: &mut DecisionCore,
    cfg: &ServiceConfig,
    route: Option<Route>,
    rt: &RealtimeConfig,
    iox_config: &Config,
    stop: StopAfter,
) -> Result<CoreStats, IpcError> {
    run_observed(core, cfg, route, rt, iox_config, stop, |_| {})
}

/// [`run`], calling `observe` with the counters after every tick (on the loop thread).
pub fn run_observed(
    core: &mut DecisionCore,
    cfg: &ServiceConfig,
    route: Option<Route>,
    rt: &RealtimeConfig,
    iox_config: &Config,
    stop: StopAfter,
    mut observe: impl FnMut(&CoreStats),
) -> Result<CoreStats, IpcError> {
    let cleaned = iox::remove_dead_nodes(iox_config)?;
    if cleaned > 0 {
        eprintln!("concord run: removed the resources of {cleaned} dead node(s)");
    }
    let node = iox::node("concord-core", iox_config)?;
    let name = |s| services::name(&cfg.prefix, s);
    let ports = Ports {
        scene: iox::subscriber(&node, &name(services::SCENE), 1)?,
        advice: iox::subscriber(&node, &name(services::ADVICE), 1)?,
        decision: iox::publisher(&node, &name(services::DECISION))?,
        request: iox::publisher(&node, &name(services::ADVICE_REQUEST))?,
        stats: iox::publisher(&node, &name(services::STATS))?,
        decision_ready: match cfg.decide_on {
            DecideOn::Arrival => Some(iox::notifier(&node, &name(services::DECISION_READY))?),
            DecideOn::Tick => None,
        },
    };
    // With `DecideOn::Arrival`: woken by scene publishers.
    let scene_ready: Option<Listener<ipc::Service>> = match cfg.decide_on {
        DecideOn::Arrival => Some(iox::listener(&node, &name(services::SCENE_READY))?),
        DecideOn::Tick => None,
    };
    for refusal in apply_realtime(rt) {
        eprintln!("concord run: WARNING: {refusal}; the loop runs without it");
    }
    let period_ns = (1e9 / cfg.rate_hz) as u64;
    let now = now_ns();
    let mut state = Loop {
        core,
        cfg,
        route,
        ports,
        notifier: Notifier::from_env(),
        stats: CoreStats {
            period_ns,
            ..CoreStats::default()
        },
        cycle: Latency::new(),
        scene_age: Latency::new(),
        decide: Latency::new(),
        started_ns: now,
        period_ns,
        prev_tick_ns: now,
        last_stats_ns: now,
        last_print_ns: now,
        last_watchdog_ns: now,
        last_frame: None,
        last_valid_rx_ns: None,
        last_sequence: 0,
        last_stamp_ns: 0,
        advice: None,
        intents: LanguageIntents::default(),
        last_phase: Phase::Idle,
        requests_since_publish: 0,
        publish_failures: 0,
    };
    let waitset = WaitSetBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| IpcError(format!("creating the WaitSet: {e:?}")))?;
    let tick = waitset
        .attach_interval(Duration::from_nanos(period_ns))
        .map_err(|e| IpcError(format!("attaching the {period_ns} ns interval: {e:?}")))?;
    let arrival = match &scene_ready {
        Some(l) => Some(
            waitset
                .attach_notification(l)
                .map_err(|e| IpcError(format!("attaching scene_ready: {e:?}")))?,
        ),
        None => None,
    };
    state.notifier.ready();
    let until_ns = stop
        .duration_s
        .map(|d| now.saturating_add((d * 1e9) as u64));
    let mut failure = None;
    let result = waitset.wait_and_process(|id| {
        let arrived = arrival.as_ref().is_some_and(|a| id.has_event_from(a));
        if arrived {
            if let Some(l) = &scene_ready {
                if let Err(e) = l.try_wait(|_| {}) {
                    failure = Some(IpcError(format!("scene_ready: {e:?}")));
                    return CallbackProgression::Stop;
                }
            }
        }
        if arrived || id.has_event_from(&tick) {
            if let Err(e) = state.tick(!arrived) {
                failure = Some(e);
                return CallbackProgression::Stop;
            }
            observe(&state.stats);
        }
        let done = stop.ticks.is_some_and(|t| state.stats.ticks >= t)
            || until_ns.is_some_and(|u| now_ns() >= u);
        if done {
            CallbackProgression::Stop
        } else {
            CallbackProgression::Continue
        }
    });
    state.notifier.stopping();
    state.publish_stats(now_ns());
    let mut line = String::new();
    render_stats(&state.stats, &mut line);
    eprintln!("concord run: final: {line}");
    if state.publish_failures > 0 {
        eprintln!("concord run: {} publish failures", state.publish_failures);
    }
    if let Some(e) = failure {
        return Err(e);
    }
    result.map_err(|e| IpcError(format!("WaitSet: {e:?}")))?;
    Ok(state.stats)
}

impl Loop<'_> {
    /// One pass: `interval` when the rate's tick woke it, else a scene's arrival.
    fn tick(&mut self, interval: bool) -> Result<(), IpcError> {
        let t0 = now_ns();
        self.stats.ticks += 1;
        let late = interval
            && t0.saturating_sub(self.prev_tick_ns) > self.period_ns + self.period_ns / 2
            && self.stats.ticks > 1;
        if interval {
            self.prev_tick_ns = t0;
        }

        let (advice, n) = iox::newest(&self.ports.advice)?;
        self.stats.advice_received += n;
        self.stats.advice_superseded += n.saturating_sub(1);
        if let Some(a) = advice {
            self.take_advice(&a, t0);
        }
        let (frame, n) = iox::newest(&self.ports.scene)?;
        self.stats.frames_received += n;
        self.stats.frames_superseded += n.saturating_sub(1);
        match frame {
            Some(f) => self.decide_on(&f, t0),
            None => self.check_staleness(t0),
        }

        let t1 = now_ns();
        let work = t1 - t0;
        self.cycle.record(work);
        if late || work > self.period_ns {
            self.stats.missed_deadlines += 1;
        }
        if t1 - self.last_stats_ns >= (self.cfg.stats_period_s * 1e9) as u64 {
            self.publish_stats(t1);
        }
        if self.cfg.print_period_s > 0.0
            && t1 - self.last_print_ns >= (self.cfg.print_period_s * 1e9) as u64
        {
            self.last_print_ns = t1;
            print_stats(&self.stats);
        }
        if let Some(interval) = self.notifier.watchdog_interval_ns {
            if t1 - self.last_watchdog_ns >= interval {
                self.last_watchdog_ns = t1;
                self.notifier.watchdog();
            }
        }
        Ok(())
    }

    /// Installs a valid advice and the intents it carries ([`WireAdvice::check`]). A failure
    /// report installs nothing; nor does a malformed advice, which is counted.
    fn take_advice(&mut self, a: &WireAdvice, now: u64) {
        match a.check(now) {
            Ok(Some(c)) => {
                self.intents = LanguageIntents {
                    from: Some(c),
                    expires_ns: now.saturating_add((self.cfg.intent_hold_s * 1e9) as u64),
                };
                self.advice = Some(c.advice);
                self.stats.advice_superseded += self.stats.advice_pending;
                self.stats.advice_pending = 1;
            }
            Ok(None) => {
                self.stats.advice_verdicts[AdviceVerdict::NoAdvice as usize] += 1;
                if let Some(f) = AdviceFailure::from_code(a.failure) {
                    self.stats.advice_failures[f as usize] += 1;
                }
            }
            Err(_) => self.stats.advice_verdicts[AdviceVerdict::Malformed as usize] += 1,
        }
    }

    /// The counted reason for a scene the core refuses.
    fn why(kind: SceneErrorKind) -> FrameReject {
        match kind {
            SceneErrorKind::NotFinite => FrameReject::NotFinite,
            SceneErrorKind::OutOfRange => FrameReject::OutOfRange,
        }
    }

    fn reject(&mut self, why: FrameReject) {
        self.stats.frames_rejected[why as usize] += 1;
    }

    /// Decides on one frame. Its content is checked first, so a corrupt frame is refused for
    /// what is wrong with it and never moves the ordering state: only a valid frame's sequence
    /// and stamp can make later frames out of order.
    fn decide_on(&mut self, f: &SceneFrame, rx: u64) {
        self.scene_age.record(rx.saturating_sub(f.stamp_ns));
        let mut scene = match f.to_scene() {
            Ok(s) => s,
            Err(_) => return self.reject(FrameReject::BadCode),
        };
        let n_lanes = self.core.morphology().lanes().len();
        if let Err(e) = scene.validate(&self.core.params().limits, n_lanes) {
            return self.reject(Self::why(e.kind));
        }
        if let Some((seq, stamp)) = self.last_frame {
            if f.sequence == seq {
                return self.reject(FrameReject::Duplicate);
            }
            if f.sequence < seq {
                // Once the scene is stale, an older frame starts the source over: a bogus
                // frame with a far sequence and stamp cannot lock out a live source.
                let stale = self
                    .last_valid_rx_ns
                    .is_none_or(|t| rx.saturating_sub(t) >= (self.cfg.staleness_s * 1e9) as u64);
                if f.stamp_ns <= stamp && !stale {
                    return self.reject(FrameReject::OutOfOrder);
                }
                self.stats.publisher_restarts += 1;
            }
        }
        self.last_frame = Some((f.sequence, f.stamp_ns));
        if let Some(route) = &self.route {
            scene.ego_lane = route.lane_at(self.core.morphology(), scene.ego.pos);
        }
        self.intents.apply(&mut scene, rx);
        let started = now_ns();
        let decision = match self.core.step(&scene, secs(started), self.advice.as_ref()) {
            Ok(d) => d,
            Err(e) => return self.reject(Self::why(e.kind)),
        };
        let compute = now_ns() - started;
        self.stats.frames_accepted += 1;
        self.last_valid_rx_ns = Some(rx);
        self.last_sequence = f.sequence;
        self.last_stamp_ns = f.stamp_ns;
        if self.stats.advice_pending == 1 {
            self.stats.advice_verdicts[decision.advice as usize] += 1;
            self.stats.advice_pending = 0;
        }
        self.publish_decision(&decision, compute);
        self.decide.record(now_ns() - rx);
        if decision.request_id != decision.cycle {
            return;
        }
        self.requests_since_publish += 1;
        if self.cfg.request_every > 0 && self.requests_since_publish >= self.cfg.request_every {
            self.requests_since_publish = 0;
            let issued = secs(started);
            let deadline = issued + self.core.params().advice.deadline_s;
            let request = AdviceRequest::from_core(
                decision.cycle,
                f.sequence,
                started,
                (deadline * 1e9) as u64,
                &decision,
                self.core,
                scene.ego_lane,
            );
            if iox::send(&self.ports.request, &request).is_err() {
                self.publish_failures += 1;
            }
            self.stats.advice_requests += 1;
        }
    }

    fn check_staleness(&mut self, now: u64) {
        let Some(rx) = self.last_valid_rx_ns else {
            return;
        };
        if now - rx < (self.cfg.staleness_s * 1e9) as u64 {
            return;
        }
        let started = now_ns();
        if let Some(d) = self.core.stale_fallback(secs(started)) {
            let compute = now_ns() - started;
            self.publish_decision(&d, compute);
        }
    }

    fn publish_decision(&mut self, d: &concord_core::Decision, compute_ns: u64) {
        self.stats.decisions[d.source as usize] += 1;
        self.stats.fallbacks[d.fallback as usize] += 1;
        self.stats.courtesy_rejects += u64::from(d.courtesy_rejects);
        if d.negotiation == Phase::Announced && self.last_phase != Phase::Announced {
            self.stats.deadlock_announcements += 1;
        }
        self.last_phase = d.negotiation;
        let mut wire = WireDecision::from_decision(
            d,
            self.last_sequence,
            self.last_stamp_ns,
            now_ns(),
            compute_ns,
        );
        if d.advice != AdviceVerdict::NoAdvice {
            wire.advice_request_id = self.advice.map_or(0, |a| a.request_id);
        }
        if iox::send(&self.ports.decision, &wire).is_err() {
            self.publish_failures += 1;
        }
        if let Some(n) = &self.ports.decision_ready {
            if n.notify().is_err() {
                self.publish_failures += 1;
            }
        }
    }

    fn publish_stats(&mut self, now: u64) {
        self.last_stats_ns = now;
        self.stats.stamp_ns = now;
        self.stats.uptime_ns = now - self.started_ns;
        self.stats.cycle_ns = self.cycle.percentiles();
        self.stats.scene_age_ns = self.scene_age.percentiles();
        self.stats.decide_ns = self.decide.percentiles();
        if iox::send(&self.ports.stats, &self.stats).is_err() {
            self.publish_failures += 1;
        }
    }
}

/// A fixed buffer that `write!` fills without allocating; text past its end is dropped.
struct LineBuf {
    buf: [u8; 1024],
    len: usize,
}

impl std::fmt::Write for LineBuf {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let n = s.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

/// Prints one statistics line to stderr without allocating.
fn print_stats(stats: &CoreStats) {
    let mut line = LineBuf {
        buf: [0; 1024],
        len: 0,
    };
    let _ = line.write_str("concord run: ");
    render_stats(stats, &mut line);
    let _ = line.write_str("\n");
    let _ = std::io::stderr().write_all(&line.buf[..line.len]);
}

/// One-line summary of `stats`: counters and latency percentiles.
pub fn render_stats(s: &CoreStats, out: &mut impl std::fmt::Write) {
    let us = |p: &Percentiles| [p[0] / 1000, p[2] / 1000, p[3] / 1000, p[4] / 1000];
    let c = us(&s.cycle_ns);
    let a = us(&s.scene_age_ns);
    let _ = write!(
        out,
        "{:.0} s, {} ticks, {} missed | frames {} in, {} superseded, {} decided, rejected",
        secs(s.uptime_ns),
        s.ticks,
        s.missed_deadlines,
        s.frames_received,
        s.frames_superseded,
        s.frames_accepted
    );
    for r in FrameReject::ALL {
        let _ = write!(out, " {}={}", r.name(), s.frames_rejected[r as usize]);
    }
    let _ = write!(
        out,
        ", restarts {} | decisions logit={} advice={} minimum_risk={} (stale {}, not finite {}) \
         | advice {} in:",
        s.publisher_restarts,
        s.decisions[0],
        s.decisions[1],
        s.decisions[2],
        s.fallbacks[FallbackReason::StaleScene as usize],
        s.fallbacks[FallbackReason::NotFinite as usize],
        s.advice_received
    );
    for v in AdviceVerdict::ALL {
        if s.advice_verdicts[v as usize] > 0 {
            let _ = write!(out, " {}={}", v.name(), s.advice_verdicts[v as usize]);
        }
    }
    let _ = write!(
        out,
        " superseded={} pending={}",
        s.advice_superseded, s.advice_pending
    );
    if s.advice_failures.iter().any(|&n| n > 0) {
        let _ = write!(out, " | sidecar failures:");
        for f in AdviceFailure::ALL {
            if s.advice_failures[f as usize] > 0 {
                let _ = write!(out, " {}={}", f.name(), s.advice_failures[f as usize]);
            }
        }
    }
    let _ = write!(
        out,
        " | courtesy rejects {} | deadlock announcements {}",
        s.courtesy_rejects, s.deadlock_announcements
    );
    let _ = write!(
        out,
        " | cycle µs p50 {} p99 {} p99.9 {} max {} | scene age µs p50 {} p99 {} max {}",
        c[0], c[1], c[2], c[3], a[0], a[1], a[3]
    );
}
