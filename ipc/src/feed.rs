//! `concord feed`: synthetic scenes for the core, at a fixed rate, with optional faults.
//!
//! The ego drives the newest decision's trajectory (closed loop, as a perfect controller would)
//! or, before the first decision or with `closed_loop` off, its route at constant speed. Other
//! road users follow their lanes: the paper's HDV (a stochastic human), a main-lane platoon
//! for the merge, or random dense traffic. Faults replace the frame of their period, so every
//! frame the core could see is accounted for in the [`FeedSummary`].

use std::time::Duration;

use concord_core::scene::{AgentState, Morphology, Scene, Vec2, MAX_AGENTS};
use concord_core::trajectory::{Trajectory, TrajectoryPoint};
use concord_map::{merge, paper};
use iceoryx2::config::Config;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use crate::clock::now_ns;
use crate::core_service::Geometry;
use crate::iox::{self, IpcError};
use crate::services;
use crate::wire::{SceneFrame, WireDecision};

/// What the feed simulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    /// The paper's left turn against one stochastic human driver.
    Paper,
    /// The ego merges from the ramp into a main-lane platoon.
    Merge,
    /// The ego turns left through random dense traffic on every other approach.
    Dense,
}

impl Scenario {
    pub fn geometry(self) -> Geometry {
        match self {
            Scenario::Merge => Geometry::Merge,
            _ => Geometry::PaperIntersection,
        }
    }
}

/// An injected fault; it replaces one period's frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// A NaN in the ego's velocity.
    Nan,
    /// An agent 100 km away: out of range.
    Jump,
    /// Nothing published for `stall_s`.
    Stall,
    /// The previous frame again (same sequence number).
    Duplicate,
    /// An older sequence number with an older stamp.
    Reorder,
    /// The publisher (and its node) is dropped and recreated; sequence numbers restart at 0.
    Restart,
}

impl Fault {
    pub const ALL: [Fault; 6] = [
        Fault::Nan,
        Fault::Jump,
        Fault::Stall,
        Fault::Duplicate,
        Fault::Reorder,
        Fault::Restart,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Fault::Nan => "nan",
            Fault::Jump => "jump",
            Fault::Stall => "stall",
            Fault::Duplicate => "duplicate",
            Fault::Reorder => "reorder",
            Fault::Restart => "restart",
        }
    }
    pub fn parse(s: &str) -> Option<Fault> {
        Fault::ALL.into_iter().find(|f| f.name() == s)
    }
}

/// Settings of a feed run.
#[derive(Debug, Clone)]
pub struct FeedConfig {
    pub prefix: String,
    pub rate_hz: f64,
    pub scenario: Scenario,
    /// Initial speed of the ego and the HDV, m/s.
    pub speed_mps: f64,
    /// Road users besides the ego in the dense scenario.
    pub agents: usize,
    pub seed: u64,
    /// Stop after this long; `None` runs until the scenario ends (paper, merge) or forever.
    pub duration_s: Option<f64>,
    /// Repeat the scenario when it ends (for soaks).
    pub repeat: bool,
    pub closed_loop: bool,
    /// Faults to inject, in turn, one every `fault_every` frames (0: none).
    pub faults: Vec<Fault>,
    pub fault_every: u64,
    /// Length of a stall, s.
    pub stall_s: f64,
}

impl Default for FeedConfig {
    fn default() -> Self {
        FeedConfig {
            prefix: services::DEFAULT_PREFIX.into(),
            rate_hz: 20.0,
            scenario: Scenario::Paper,
            speed_mps: 8.0,
            agents: 16,
            seed: 1,
            duration_s: None,
            repeat: false,
            closed_loop: true,
            faults: Vec::new(),
            fault_every: 0,
            stall_s: 0.5,
        }
    }
}

/// What a feed run published.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FeedSummary {
    /// Frames with new sequence numbers and valid contents.
    pub valid_frames: u64,
    /// Faults injected, in `Fault::ALL` order.
    pub faults: [u64; 6],
    /// Episodes that ended with the ego through (paper, dense) or merged.
    pub completed: u64,
    /// Episodes that ended with the ego within 1 m (centre to centre: 2 m) of another car.
    pub collisions: u64,
}

impl std::fmt::Display for FeedSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "feed summary: valid={} completed={} collisions={}",
            self.valid_frames, self.completed, self.collisions
        )?;
        for (fault, n) in Fault::ALL.iter().zip(self.faults) {
            write!(f, " {}={n}", fault.name())?;
        }
        Ok(())
    }
}

/// A road user that follows a lane at a speed set each step.
#[derive(Debug, Clone, Copy)]
struct LaneAgent {
    lane: u8,
    s: f64,
    speed: f64,
    accel: f64,
    desired: f64,
    id: u32,
}

/// The simulated world of one episode.
struct World {
    morph: Morphology,
    scenario: Scenario,
    ego: AgentState,
    ego_lane: u8,
    /// The ego's arc length along its lane in open loop, m.
    ego_s: f64,
    others: Vec<LaneAgent>,
    rng: StdRng,
    noise: Normal<f64>,
}

impl World {
    fn new(cfg: &FeedConfig, episode: u64) -> Self {
        let morph = cfg.scenario.geometry().morphology();
        let mut rng = StdRng::seed_from_u64(cfg.seed.wrapping_mul(7919).wrapping_add(episode));
        let v = cfg.speed_mps;
        let (ego_lane, ego_s) = match cfg.scenario {
            Scenario::Merge => (merge::RAMP, 40.0),
            _ => (paper::CAV_LEFT, 0.0),
        };
        let mut others = Vec::new();
        match cfg.scenario {
            Scenario::Paper => others.push(LaneAgent {
                lane: paper::HDV_STRAIGHT,
                s: 0.0,
                speed: v,
                accel: 0.0,
                desired: v * (1.0 + 0.1 * rng.random_range(-1.0..1.0)),
                id: 1,
            }),
            Scenario::Merge => {
                for i in 0..4 {
                    others.push(LaneAgent {
                        lane: merge::MAIN,
                        s: 60.0 - 30.0 * i as f64 + rng.random_range(-3.0..3.0),
                        speed: v,
                        accel: 0.0,
                        desired: v,
                        id: i + 1,
                    });
                }
            }
            Scenario::Dense => {
                const LANES: [u8; 5] = [
                    paper::HDV_STRAIGHT,
                    paper::EAST_LEFT,
                    paper::NORTH_STRAIGHT,
                    paper::SOUTH_STRAIGHT,
                    paper::EAST_RIGHT,
                ];
                for i in 0..cfg.agents.min(MAX_AGENTS) {
                    let speed = rng.random_range(3.0..9.0);
                    others.push(LaneAgent {
                        lane: LANES[i % LANES.len()],
                        s: rng.random_range(0.0..70.0),
                        speed,
                        accel: 0.0,
                        desired: speed,
                        id: i as u32 + 1,
                    });
                }
            }
        }
        let lane = morph.lane(ego_lane);
        let (pos, tangent, _) = lane.to_cartesian(ego_s, 0.0, 0);
        World {
            morph,
            scenario: cfg.scenario,
            ego: AgentState::moving(0, pos, tangent, v),
            ego_lane,
            ego_s,
            others,
            rng,
            noise: Normal::new(0.0, 0.3).expect("valid deviation"),
        }
    }

    fn scene(&self, time_s: f64) -> Scene {
        let mut scene = Scene::new(time_s, self.ego, self.ego_lane);
        for a in &self.others {
            let lane = self.morph.lane(a.lane);
            let (pos, tangent, _) = lane.to_cartesian(a.s, 0.0, 0);
            let mut agent = AgentState::moving(a.id, pos, tangent, a.speed);
            agent.acc = Vec2::from_angle(tangent).scale(a.accel);
            scene.push(agent);
        }
        scene
    }

    /// Advances everyone by `dt`; the ego follows `plan` (sampled `since_plan_s` after its
    /// start) when there is one.
    fn advance(&mut self, dt: f64, plan: Option<(&Trajectory, f64)>) {
        match plan.and_then(|(traj, since)| traj.sample(since)) {
            Some(p) => {
                let dir = Vec2::from_angle(p.heading);
                self.ego.acc = dir.scale(p.accel);
                self.ego.pos = Vec2::new(p.x, p.y);
                self.ego.vel = dir.scale(p.speed.max(0.0));
                self.ego.heading = p.heading;
            }
            None => {
                self.ego_s += self.ego.speed() * dt;
                let (pos, tangent, _) = self
                    .morph
                    .lane(self.ego_lane)
                    .to_cartesian(self.ego_s, 0.0, 0);
                self.ego = AgentState::moving(0, pos, tangent, self.ego.speed());
            }
        }
        let ego_pos = self.ego.pos;
        for i in 0..self.others.len() {
            let a = self.others[i];
            let lane = *self.morph.lane(a.lane);
            // A stochastic human: noisy pursuit of the desired speed, and braking for a car
            // ahead within two seconds of travel.
            let ahead = (0..self.others.len())
                .filter(|&j| j != i && self.others[j].lane == a.lane && self.others[j].s > a.s)
                .map(|j| self.others[j].s - a.s)
                .fold(f64::INFINITY, f64::min);
            let (pos, tangent, _) = lane.to_cartesian(a.s, 0.0, 0);
            let to_ego = ego_pos.minus(pos);
            let ego_ahead = Vec2::from_angle(tangent).dot(to_ego) > 0.0
                && to_ego.norm() < (2.0 * a.speed).max(8.0);
            let mut accel = 0.5 * (a.desired - a.speed) + self.noise.sample(&mut self.rng);
            if ahead < (2.0 * a.speed).max(8.0) || ego_ahead {
                accel = -3.0;
            }
            let a = &mut self.others[i];
            a.accel = accel.clamp(-4.0, 2.0);
            a.speed = (a.speed + a.accel * dt).max(0.0);
            a.s += a.speed * dt;
            if self.scenario == Scenario::Dense && a.s > lane.length() {
                a.s = 0.0;
            }
        }
    }

    /// The episode's end: `Some(true)` through, `Some(false)` collision.
    fn outcome(&self) -> Option<bool> {
        let scene = self.scene(0.0);
        if scene
            .agents()
            .iter()
            .any(|a| a.pos.minus(self.ego.pos).norm() < 2.0)
        {
            return Some(false);
        }
        let through = match self.scenario {
            Scenario::Merge => self.ego.pos.x > 60.0,
            _ => self.ego.pos.y < -25.0,
        };
        through.then_some(true)
    }
}

/// Publishes scenes until the scenario or `duration_s` ends, or SIGINT/SIGTERM.
pub fn run(cfg: &FeedConfig, iox_config: &Config) -> Result<FeedSummary, IpcError> {
    let scene_name = services::name(&cfg.prefix, services::SCENE);
    let mut node = iox::node("concord-feed", iox_config)?;
    let ready_name = services::name(&cfg.prefix, services::SCENE_READY);
    let mut publisher: Publisher<ipc::Service, SceneFrame, ()> =
        iox::publisher(&node, &scene_name)?;
    let mut ready = iox::notifier(&node, &ready_name)?;
    let decisions = iox::subscriber::<WireDecision>(
        &node,
        &services::name(&cfg.prefix, services::DECISION),
        1,
    )?;
    let period = Duration::from_secs_f64(1.0 / cfg.rate_hz);
    let dt = period.as_secs_f64();
    let started = now_ns();
    let mut summary = FeedSummary::default();
    let mut episode = 0;
    let mut world = World::new(cfg, episode);
    let mut sequence = 0u64;
    let mut previous: Option<SceneFrame> = None;
    let mut plan: Option<(Trajectory, u64)> = None;
    let mut frame_no = 0u64;
    let mut fault_no = 0usize;
    loop {
        if node.wait(period).is_err() {
            break; // SIGINT or SIGTERM
        }
        let now = now_ns();
        if cfg
            .duration_s
            .is_some_and(|d| (now - started) as f64 * 1e-9 >= d)
        {
            break;
        }
        if cfg.closed_loop {
            if let (Some(d), _) = iox::newest(&decisions)? {
                plan = Some((decision_trajectory(&d), d.scene_stamp_ns));
            }
        }
        let follow = plan
            .as_ref()
            .map(|(t, stamp)| (t, (now.saturating_sub(*stamp)) as f64 * 1e-9));
        world.advance(dt, follow);
        if let Some(ok) = world.outcome() {
            if ok {
                summary.completed += 1;
            } else {
                summary.collisions += 1;
            }
            if !cfg.repeat {
                break;
            }
            episode += 1;
            world = World::new(cfg, episode);
            plan = None;
        }
        frame_no += 1;
        let fault =
            (cfg.fault_every > 0 && !cfg.faults.is_empty() && frame_no % cfg.fault_every == 0)
                .then(|| {
                    let f = cfg.faults[fault_no % cfg.faults.len()];
                    fault_no += 1;
                    f
                });
        let mut frame = SceneFrame::from_scene(sequence, now, &world.scene(now as f64 * 1e-9));
        match fault {
            None => {}
            Some(f) => {
                summary.faults[f as usize] += 1;
                match f {
                    Fault::Nan => frame.ego.vx = f64::NAN,
                    Fault::Jump => frame.agents[0].x += 1e5,
                    Fault::Stall => {
                        std::thread::sleep(Duration::from_secs_f64(cfg.stall_s));
                        continue;
                    }
                    Fault::Duplicate => {
                        if let Some(p) = previous {
                            publish(&publisher, &ready, &p)?;
                        }
                        continue;
                    }
                    Fault::Reorder => {
                        if let Some(p) = previous {
                            let mut older = p;
                            older.sequence = p.sequence.saturating_sub(1);
                            older.stamp_ns = p.stamp_ns - 1;
                            publish(&publisher, &ready, &older)?;
                        }
                        continue;
                    }
                    Fault::Restart => {
                        drop((publisher, ready));
                        drop(node);
                        node = iox::node("concord-feed", iox_config)?;
                        publisher = iox::publisher(&node, &scene_name)?;
                        ready = iox::notifier(&node, &ready_name)?;
                        sequence = 0;
                        frame.sequence = 0;
                    }
                }
            }
        }
        publish(&publisher, &ready, &frame)?;
        sequence += 1;
        if !matches!(fault, Some(Fault::Nan | Fault::Jump)) {
            summary.valid_frames += 1;
            previous = Some(frame);
        }
    }
    Ok(summary)
}

/// Publishes `frame` and wakes a core that decides on arrival (`scene_ready`).
fn publish(
    publisher: &Publisher<ipc::Service, SceneFrame, ()>,
    ready: &Notifier<ipc::Service>,
    frame: &SceneFrame,
) -> Result<(), IpcError> {
    iox::send(publisher, frame)?;
    ready
        .notify()
        .map_err(|e| IpcError(format!("notifying scene_ready: {e:?}")))?;
    Ok(())
}

/// The trajectory of a published decision, as the core's type (Frenet fields left at 0).
pub fn decision_trajectory(d: &WireDecision) -> Trajectory {
    let mut t = Trajectory {
        n: (d.n_points as usize).min(d.trajectory.len()),
        ..Trajectory::default()
    };
    for (out, p) in t.points.iter_mut().zip(&d.trajectory[..t.n]) {
        *out = TrajectoryPoint {
            t: p.t,
            s: 0.0,
            l: 0.0,
            x: p.x,
            y: p.y,
            heading: p.heading,
            speed: p.speed,
            accel: p.accel,
        };
    }
    t
}
