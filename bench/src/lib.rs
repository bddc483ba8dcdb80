//! Workloads shared by the criterion benches and the latency report.

use concord_core::scene::{AgentState, Morphology, Scene, Vec2, MAX_AGENTS};
use concord_core::{Decision, DecisionCore, Params};
use concord_map::{paper, BuiltIn};

/// A core on the paper's intersection with `samples` Monte Carlo samples.
pub fn core(samples: usize) -> DecisionCore {
    core_on(BuiltIn::PaperIntersection.morphology(), samples)
}

/// A core on `morph` with `samples` Monte Carlo samples.
pub fn core_on(morph: Morphology, samples: usize) -> DecisionCore {
    let mut params = Params::default();
    params.trajectory.samples = samples;
    DecisionCore::new(params, morph).expect("valid parameters")
}

/// Lanes of the approaches other than the ego's.
const OTHER_LANES: [u8; 5] = [
    paper::HDV_STRAIGHT,
    paper::EAST_LEFT,
    paper::NORTH_STRAIGHT,
    paper::SOUTH_STRAIGHT,
    paper::EAST_RIGHT,
];

/// Dense closed-loop traffic on the paper's intersection: the ego drives its own decisions
/// through the left turn (and starts over once through), while the HDV and up to 31 more
/// road users flow at constant speeds along the lanes of the other approaches, re-entering at
/// their lane's start. They do not react, so the ego must find its gaps.
pub struct Traffic {
    pub scene: Scene,
    lanes: [u8; MAX_AGENTS],
    s: [f64; MAX_AGENTS],
    steps: u64,
    /// The ego's route on a map ([`Traffic::on_map`]): lane, where it starts over, and where
    /// it starts.
    route: Option<(u8, f64, AgentState)>,
}

impl Traffic {
    /// `n_agents` road users besides the ego (the first is the paper's HDV).
    pub fn new(core: &DecisionCore, n_agents: usize) -> Self {
        let mut t = Traffic {
            scene: Scene::new(0.0, Self::ego_at_start(), paper::CAV_LEFT),
            lanes: [0; MAX_AGENTS],
            s: [0.0; MAX_AGENTS],
            steps: 0,
            route: None,
        };
        for i in 0..n_agents.min(MAX_AGENTS) {
            let (lane, s, speed) = if i == 0 {
                (paper::HDV_STRAIGHT, 0.0, 8.0)
            } else {
                (
                    OTHER_LANES[i % OTHER_LANES.len()],
                    11.0 * i as f64 % 70.0,
                    3.0 + (i % 5) as f64,
                )
            };
            t.lanes[i] = lane;
            t.s[i] = s;
            let (pos, tangent, _) = core.morphology().lane(lane).to_cartesian(s, 0.0, 0);
            t.scene
                .push(AgentState::moving(i as u32 + 1, pos, tangent, speed));
        }
        t
    }

    /// The same workload on any map: the ego drives its route `lane` from 40 m before its
    /// stop line to 40 m past it (and starts over); `n_agents` road users flow at 3–7 m/s
    /// along the map's other lanes in turn, from 50 m before their stop lines, re-entering
    /// there at each lane's end.
    pub fn on_map(core: &DecisionCore, lane: u8, n_agents: usize) -> Self {
        let morph = core.morphology();
        let route = morph.lane(lane);
        let at = |l: &concord_core::scene::Lane, s: f64, speed: f64, id: u32| {
            let (pos, tangent, _) = l.to_cartesian(s, 0.0, 0);
            AgentState::moving(id, pos, tangent, speed)
        };
        let start = at(route, (route.stop_s - 40.0).max(0.0), 8.0, 0);
        let mut t = Traffic {
            scene: Scene::new(0.0, start, lane),
            lanes: [0; MAX_AGENTS],
            s: [0.0; MAX_AGENTS],
            steps: 0,
            route: Some((lane, (route.stop_s + 40.0).min(route.length()), start)),
        };
        let others: Vec<u8> = (0..morph.lanes().len() as u8)
            .filter(|&l| l != lane)
            .collect();
        for i in 0..n_agents.min(MAX_AGENTS) {
            let l = others[i % others.len()];
            let own = morph.lane(l);
            let s = ((own.stop_s - 50.0).max(0.0) + 11.0 * i as f64 % 70.0).min(own.length());
            t.lanes[i] = l;
            t.s[i] = s;
            t.scene.push(at(own, s, 3.0 + (i % 5) as f64, i as u32 + 1));
        }
        t
    }

    fn ego_at_start() -> AgentState {
        AgentState::moving(0, Vec2::new(40.0, 5.0), core::f64::consts::PI, 8.0)
    }

    /// Moves everything `dt` s on: the ego along `decision`'s trajectory, the others along
    /// their lanes.
    pub fn advance(&mut self, core: &DecisionCore, decision: &Decision, dt: f64) {
        self.steps += 1;
        self.scene.time_s = self.steps as f64 * dt;
        let next = decision
            .trajectory
            .sample(dt)
            .expect("every decision has a trajectory");
        let dir = Vec2::from_angle(next.heading);
        let ego = &mut self.scene.ego;
        ego.acc = dir.scale((next.speed - ego.speed()) / dt);
        ego.pos = Vec2::new(next.x, next.y);
        ego.vel = dir.scale(next.speed);
        ego.heading = next.heading;
        match self.route {
            Some((lane, end, start)) if core.morphology().lane(lane).project(ego.pos).s > end => {
                *ego = start;
            }
            None if ego.pos.y < -30.0 => *ego = Self::ego_at_start(),
            _ => {}
        }
        for i in 0..self.scene.n_agents {
            let lane = core.morphology().lane(self.lanes[i]);
            let a = &mut self.scene.agents[i];
            self.s[i] += a.speed() * dt;
            if self.s[i] > lane.length() {
                self.s[i] = match self.route {
                    Some(_) => (lane.stop_s - 50.0).max(0.0),
                    None => 0.0,
                };
            }
            let (pos, tangent, _) = lane.to_cartesian(self.s[i], 0.0, 0);
            *a = AgentState::moving(a.id, pos, tangent, a.speed());
        }
    }
}
