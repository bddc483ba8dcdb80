//! Object–Process–Methodology scene abstraction: object selection, conflict pairs
//! C(vᵢ, vⱼ, ΔTTC) (eq. 4), intent pairs I(vᵢ, vⱼ), relations 𝓡 (eq. 5) and the triplet
//! T = (𝓞, 𝓟, 𝓡) (eq. 6) in a fixed-size form.

use crate::intent::{self, ImplicitIntent, Motion};
use crate::params::{InteractionParams, OpmParams};
use crate::scene::{
    AgentKind, AgentState, ConflictKind, ExplicitIntent, History, Morphology, ProcessState,
    RightOfWay, Scene, Vec2, MAX_AGENTS,
};

/// Most objects the triplet keeps.
pub const MAX_SELECTED: usize = 8;

/// Time to reach a point `dist_m` ahead at `speed_mps`, guarded near standstill:
/// TTC = max(d, 0) / max(v, v_floor), capped at `ttc_max_s`. Always finite.
pub fn guarded_ttc(dist_m: f64, speed_mps: f64, p: &OpmParams) -> f64 {
    (dist_m.max(0.0) / speed_mps.max(p.ttc_speed_floor_mps)).min(p.ttc_max_s)
}

/// ΔTTC = |TTCᵢ − TTCⱼ| (eq. 4), each TTC guarded by [`guarded_ttc`].
pub fn delta_ttc(d_i: f64, v_i: f64, d_j: f64, v_j: f64, p: &OpmParams) -> f64 {
    (guarded_ttc(d_i, v_i, p) - guarded_ttc(d_j, v_j, p)).abs()
}

/// Conflict pair C(ego, vⱼ, ΔTTC) at the crossing or merge point of their lanes (eq. 4).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ConflictPair {
    /// Index of the agent in the scene.
    pub agent: u8,
    /// Conflict point.
    pub point: Vec2,
    /// Ego distance to the point along its lane, m (negative once past).
    pub ego_dist_m: f64,
    /// Agent distance to the point along its lane, m.
    pub agent_dist_m: f64,
    /// Guarded TTC of the ego, s.
    pub ego_ttc_s: f64,
    /// Guarded TTC of the agent, s.
    pub agent_ttc_s: f64,
    /// |ΔTTC|, s.
    pub delta_ttc_s: f64,
    /// Arc length of the point on the ego's lane, m.
    pub ego_point_s: f64,
    pub kind: ConflictKind,
    /// The ego's conflict zone (where its footprint is in the agent's lane) as distances from
    /// its centre along its lane, [enter, exit], m (negative once passed).
    pub ego_zone_m: [f64; 2],
    /// The agent's conflict zone, distances from its centre along its lane, m.
    pub agent_zone_m: [f64; 2],
    /// The ego's and the agent's passages, whose occupancy times give the PET, m (see
    /// `ConflictPoint::pass_a`).
    pub ego_pass_m: [f64; 2],
    pub agent_pass_m: [f64; 2],
    /// Right of way: `A` the ego, `B` the agent.
    pub right_of_way: RightOfWay,
    /// The agent's speed, m/s, and the acceleration its motion shows, m/s².
    pub agent_speed_mps: f64,
    pub agent_accel_mps2: f64,
    /// The agent's implicit intent towards the ego's path, fused with its stated one.
    pub intent: ImplicitIntent,
}

impl ConflictPair {
    /// Risky per §3.1: |ΔTTC| < ΔT_th, and at least one party is arriving (TTC below the cap);
    /// never once the agent has left its zone.
    pub fn is_risky(&self, p: &OpmParams) -> bool {
        self.agent_zone_m[1] >= 0.0
            && self.delta_ttc_s < p.delta_ttc_threshold_s
            && self.ego_ttc_s.min(self.agent_ttc_s) < p.ttc_max_s
    }
}

/// Intent pair I(ego, vⱼ): a selected agent that expressed an explicit intent.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IntentPair {
    pub agent: u8,
    pub intent: ExplicitIntent,
}

/// The nearest vehicle ahead in the ego's lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Leader {
    pub agent: u8,
    /// Bumper-free centre gap along the lane, m.
    pub gap_m: f64,
    pub speed_mps: f64,
}

/// One selected object: its state 𝓕ᵢ, process P_ti and how it was selected.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OpmObject {
    /// Index in the scene.
    pub agent: u8,
    pub id: u32,
    pub kind: AgentKind,
    pub state: AgentState,
    pub process: ProcessState,
    /// Longitudinal distance to the ego along lane centre lines, m (∞ when unrelated).
    pub longitudinal_m: f64,
    /// Index into `OpmTriplet::conflicts`, when the object conflicts with the ego.
    pub conflict: Option<u8>,
    /// Saliency score from eq. 7, in [0, 1]; scores of all objects sum to 1.
    pub saliency: f64,
}

/// The OPM triplet T = (𝓞, 𝓟, 𝓡) (eq. 6), fixed-size.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OpmTriplet {
    /// Process state of the ego.
    pub ego: ProcessState,
    /// Explicit intent of the ego (the passenger), I_explicitEgo.
    pub ego_intent: ExplicitIntent,
    /// 𝓞 with each object's 𝓟, most critical first.
    pub objects: [OpmObject; MAX_SELECTED],
    pub n_objects: usize,
    /// Conflict pairs of 𝓡.
    pub conflicts: [ConflictPair; MAX_SELECTED],
    pub n_conflicts: usize,
    /// Intent pairs of 𝓡.
    pub intents: [IntentPair; MAX_SELECTED],
    pub n_intents: usize,
    /// The car-following leader, if any (selected or not).
    pub leader: Option<Leader>,
    /// Agents that qualified for selection, including those beyond `MAX_SELECTED`.
    pub n_candidates: usize,
}

impl OpmTriplet {
    pub fn objects(&self) -> &[OpmObject] {
        &self.objects[..self.n_objects]
    }
    pub fn conflicts(&self) -> &[ConflictPair] {
        &self.conflicts[..self.n_conflicts]
    }
    pub fn intents(&self) -> &[IntentPair] {
        &self.intents[..self.n_intents]
    }
    /// Conflicts with |ΔTTC| below the threshold.
    pub fn risky_conflicts<'a>(
        &'a self,
        p: &'a OpmParams,
    ) -> impl Iterator<Item = &'a ConflictPair> + 'a {
        self.conflicts().iter().filter(move |c| c.is_risky(p))
    }
}

/// Conflict pairs of the ego with every agent, selected or not: the safety degree of the
/// choice stage weighs all of them, since a maneuver can make an unselected conflict risky.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConflictSet {
    pairs: [ConflictPair; MAX_AGENTS],
    n: usize,
}

impl Default for ConflictSet {
    fn default() -> Self {
        ConflictSet {
            pairs: [ConflictPair::default(); MAX_AGENTS],
            n: 0,
        }
    }
}

impl ConflictSet {
    /// A set of `pairs` (the first [`MAX_AGENTS`] of them).
    pub fn of(pairs: &[ConflictPair]) -> Self {
        let mut set = ConflictSet::default();
        for c in pairs {
            set.push(*c);
        }
        set
    }
    pub fn pairs(&self) -> &[ConflictPair] {
        &self.pairs[..self.n]
    }
    fn push(&mut self, c: ConflictPair) {
        if self.n < MAX_AGENTS {
            self.pairs[self.n] = c;
            self.n += 1;
        }
    }
}

/// Candidate for selection, before ranking.
#[derive(Clone, Copy)]
struct Candidate {
    /// Lower is more critical.
    rank: f64,
    agent: u8,
    process: ProcessState,
    longitudinal_m: f64,
    conflict: Option<ConflictPair>,
}

/// Builds the triplet of `scene` into `out` (object selection of §3.1 and eq. 4–6, implicit
/// intents of §4.1). `ego_stop_m` is the distance the ego needs to stop comfortably
/// ([`crate::params::Params::ego_comfort_stop_m`]), `processes` holds P_ti of every agent, in
/// scene order, and `history` their tracks; `all` receives every conflict pair.
#[allow(clippy::too_many_arguments)]
pub fn build(
    scene: &Scene,
    morph: &Morphology,
    p: &OpmParams,
    ip: &InteractionParams,
    ego_stop_m: f64,
    processes: &[ProcessState; MAX_AGENTS],
    history: &History,
    out: &mut OpmTriplet,
    all: &mut ConflictSet,
) {
    let ego_lane_id = scene.ego_lane;
    let ego_lane = morph.lane(ego_lane_id);
    let ego_f = ego_lane.project(scene.ego.pos);
    let mut ego = ProcessState::of(&scene.ego, morph, p.lane_match_heading_rad);
    // The ego is on its route lane by definition, even where lanes of one approach overlap.
    ego.lane = Some(ego_lane_id);
    ego.s_m = ego_f.s;
    ego.l_m = ego_f.l;
    ego.dist_to_stop_m = ego_lane.stop_s - ego_f.s;
    let ego_speed = scene.ego.speed();

    *out = OpmTriplet {
        ego,
        ego_intent: scene.ego.intent,
        ..OpmTriplet::default()
    };

    all.n = 0;
    let mut picked = [None::<Candidate>; MAX_SELECTED];
    let mut n_picked = 0usize;
    let mut leader: Option<Leader> = None;

    for (i, agent) in scene.agents().iter().enumerate() {
        let process = processes[i];
        // Longitudinal position along the ego's lane, when the agent is in its corridor.
        let on_ego = ego_lane.project(agent.pos);
        let in_corridor = on_ego.l.abs() <= ego_lane.half_width + 0.5;
        let mut longitudinal = f64::INFINITY;
        if in_corridor {
            let gap = on_ego.s - ego_f.s;
            longitudinal = gap.abs();
            if gap > 0.0 && leader.is_none_or(|l| gap < l.gap_m) {
                leader = Some(Leader {
                    agent: i as u8,
                    gap_m: gap,
                    speed_mps: agent.speed(),
                });
            }
        }
        let conflict = process
            .lane
            .filter(|&l| l != ego_lane_id)
            .and_then(|l| morph.conflict(ego_lane_id, l))
            .and_then(|cp| {
                let rel = |s: f64| s - ego_f.s;
                let own = |s: f64| s - process.s_m;
                let ego_zone = cp.zone_a.map(rel);
                let agent_zone = cp.zone_b.map(own);
                // A road user that has crossed the ego's lane and left its zone stays in
                // conflict until `pet_behind_s` after it left its passage (at its speed, at
                // least 0.1 m/s): the margin the ego keeps behind it (`choice::conflict_risk`,
                // the planner's margins) holds until then, while the ego can still stop
                // comfortably before its own passage (`ego_stop_m`; a committed ego planned
                // that margin before the car left, on its predicted exit). One that merged into the
                // ego's lane ahead is its leader: car following keeps that distance.
                let left_s = -own(cp.pass_b[1]) / process.speed_mps.max(0.1);
                let committed = ego_stop_m > rel(cp.pass_a[0]);
                let gone =
                    left_s >= ip.pet_behind_s || committed || cp.kind != ConflictKind::Crossing;
                if ego_zone[1] < 0.0 || (agent_zone[1] < 0.0 && gone) {
                    return None;
                }
                let (d_e, d_a) = (rel(cp.s_a), own(cp.s_b));
                let (te, ta) = (
                    guarded_ttc(d_e, ego_speed, p),
                    guarded_ttc(d_a, process.speed_mps, p),
                );
                let motion = Motion::of(agent, history.track(agent.id), scene.time_s, ip);
                Some(ConflictPair {
                    agent: i as u8,
                    point: ego_lane.pose_at(cp.s_a, 0).0,
                    ego_dist_m: d_e,
                    agent_dist_m: d_a,
                    ego_ttc_s: te,
                    agent_ttc_s: ta,
                    delta_ttc_s: delta_ttc(d_e, ego_speed, d_a, process.speed_mps, p),
                    ego_point_s: cp.s_a,
                    kind: cp.kind,
                    ego_zone_m: ego_zone,
                    agent_zone_m: agent_zone,
                    ego_pass_m: cp.pass_a.map(rel),
                    agent_pass_m: cp.pass_b.map(own),
                    right_of_way: cp.right_of_way,
                    agent_speed_mps: motion.speed,
                    agent_accel_mps2: motion.accel,
                    intent: intent::infer(
                        &motion,
                        agent_zone[0],
                        &agent.intent,
                        p.intent_confidence_min,
                        ip,
                    ),
                })
            });
        if let Some(c) = conflict {
            all.push(c);
            // Path distance through the conflict point counts as longitudinal distance.
            longitudinal = longitudinal.min(c.ego_dist_m.max(0.0) + c.agent_dist_m.max(0.0));
        }
        let risky = conflict.filter(|c| c.is_risky(p));
        let near = longitudinal < p.proximity_threshold_m;
        if risky.is_none() && !near {
            continue;
        }
        out.n_candidates += 1;
        let rank = match risky {
            Some(c) => c.delta_ttc_s,
            None => p.delta_ttc_threshold_s + longitudinal,
        };
        let cand = Candidate {
            rank,
            agent: i as u8,
            process,
            longitudinal_m: longitudinal,
            conflict,
        };
        insert_ranked(&mut picked, &mut n_picked, cand);
    }
    out.leader = leader;

    for cand in picked.iter().take(n_picked).flatten() {
        let agent = &scene.agents[cand.agent as usize];
        let conflict = cand.conflict.map(|c| {
            out.conflicts[out.n_conflicts] = c;
            out.n_conflicts += 1;
            (out.n_conflicts - 1) as u8
        });
        out.objects[out.n_objects] = OpmObject {
            agent: cand.agent,
            id: agent.id,
            kind: agent.kind,
            state: *agent,
            process: cand.process,
            longitudinal_m: cand.longitudinal_m,
            conflict,
            saliency: 0.0,
        };
        out.n_objects += 1;
        if agent.intent.any_strong(p.intent_confidence_min) {
            out.intents[out.n_intents] = IntentPair {
                agent: cand.agent,
                intent: agent.intent,
            };
            out.n_intents += 1;
        }
    }
}

/// Keeps the `MAX_SELECTED` lowest ranks, sorted; ties keep scene order.
fn insert_ranked(picked: &mut [Option<Candidate>; MAX_SELECTED], n: &mut usize, c: Candidate) {
    let mut pos = *n;
    while pos > 0 && picked[pos - 1].is_some_and(|p| p.rank > c.rank) {
        pos -= 1;
    }
    if pos >= MAX_SELECTED {
        return;
    }
    let last = (*n).min(MAX_SELECTED - 1);
    let mut k = last;
    while k > pos {
        picked[k] = picked[k - 1];
        k -= 1;
    }
    picked[pos] = Some(c);
    *n = (*n + 1).min(MAX_SELECTED);
}
