//! Replays a bridge trace (`highway_bridge.py --trace FILE`, or `sumo_bridge.py --trace FILE`
//! with `CONCORD_REPLAY_MAP=NET CONCORD_REPLAY_ROUTE=ID`) through the decision core, printing
//! per frame the agents' matched lanes, the conflicts, the choice and, for every
//! maneuver, the Monte Carlo planning statistics.
//!
//! `cargo run --release --example replay_trace -- CONFIG TRACE [FROM_S [TO_S]]`, e.g.
//! `deploy/highway-env.toml trace.jsonl 2.0 3.0` for the frames between 2 and 3 s of an
//! intersection-v0 episode. The whole trace is replayed (the core keeps histories); only the
//! frames in [FROM_S, TO_S] are printed. Each maneuver's statistics come from a fresh Monte
//! Carlo run, so they can differ from the decision's in which candidates were drawn.

use concord_core::choice::{self, Maneuver, MANEUVERS};
use concord_core::scene::{AgentState, Scene, TurnSignal, Vec2};
use concord_core::trajectory::PlanStats;
use concord_core::DecisionCore;
use concord_ipc::core_service::RunConfig;
use concord_map::BuiltIn;

fn agent(v: &serde_json::Value) -> AgentState {
    let f = |k: usize| v[k].as_f64().unwrap();
    AgentState {
        id: f(0) as u32,
        pos: Vec2::new(f(1), f(2)),
        vel: Vec2::new(f(3), f(4)),
        acc: Vec2::new(f(5), f(6)),
        heading: f(7),
        turn_signal: v
            .get(8)
            .and_then(|s| s.as_u64())
            .and_then(|s| TurnSignal::try_from(s as u8).ok())
            .unwrap_or_default(),
        ..AgentState::default()
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: replay_trace CONFIG TRACE [FROM_S [TO_S]]");
        std::process::exit(2);
    }
    let read = |path: &str| {
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {path}: {e}"))
    };
    let cfg: RunConfig =
        toml::from_str(&read(&args[0])).unwrap_or_else(|e| panic!("{}: {e}", args[0]));
    let time = |i: usize, default: f64| {
        args.get(i).map_or(default, |a| {
            a.parse()
                .unwrap_or_else(|_| panic!("a time in seconds: {a}"))
        })
    };
    let (from, to) = (time(2, 0.0), time(3, f64::INFINITY));
    // CONCORD_REPLAY_MAP=FILE (and CONCORD_REPLAY_ROUTE=ID) replays on a map file, e.g. a
    // trace of bridges/python/sumo_bridge.py; the lane of the route's leg replaces the frames'.
    let (morph, route) = match std::env::var("CONCORD_REPLAY_MAP") {
        Ok(path) => {
            let route = std::env::var("CONCORD_REPLAY_ROUTE").ok();
            let (map, legs) = concord_map::Map::load_route(path.as_ref(), route.as_deref())
                .unwrap_or_else(|e| panic!("{e}"));
            (map.morphology(), legs)
        }
        Err(_) => (BuiltIn::HighwayEnvIntersection.morphology(), None),
    };
    if std::env::var_os("CONCORD_REPLAY_ZONES").is_some() {
        for c in morph.conflicts() {
            println!(
                "conflict lanes {} x {} {:?} at ({:.1}, {:.1}): zone on {} [{:.1}, {:.1}], on {} [{:.1}, {:.1}]",
                c.lane_a, c.lane_b, c.kind, c.pos.x, c.pos.y, c.lane_a, c.zone_a[0], c.zone_a[1],
                c.lane_b, c.zone_b[0], c.zone_b[1]
            );
        }
    }
    let mut core = Box::new(DecisionCore::new(cfg.core, morph).expect("valid parameters"));
    let p = cfg.core;
    for line in read(&args[1]).lines() {
        let r: serde_json::Value = serde_json::from_str(line).expect("a JSON line of a trace");
        let sc = &r["scene"];
        let t = sc["time"].as_f64().unwrap() * 1e-9;
        let ego = agent(&sc["ego"]);
        let lane = route.map_or(sc["lane"].as_u64().unwrap() as u8, |r| {
            r.lane_at(&morph, ego.pos)
        });
        let mut scene = Scene::new(t, ego, lane);
        for a in sc["agents"].as_array().unwrap() {
            scene.push(agent(a));
        }
        let d = match core.step(&scene, t, None) {
            Ok(d) => d,
            Err(e) => {
                println!("t={t:.1} rejected: {e:?}");
                continue;
            }
        };
        if t < from - 1e-6 || t > to + 1e-6 {
            continue;
        }
        let ch = core.choice();
        println!(
            "t={t:.1} ego s={:.1} v={:.1} -> {:?} {:?} p={:.2?} safety={:.2?}",
            core.triplet().ego.s_m,
            scene.ego.speed(),
            d.maneuver,
            d.source,
            d.p_corrected,
            ch.safety
        );
        println!(
            "   attributes [match, safety, efficiency] {:.2?} utility {:.2?} D_prev {:.2?} corrected {:.2?}",
            ch.attributes, ch.utility, ch.d_prev, ch.utility_corrected
        );
        let pts = d.trajectory.points();
        println!(
            "   plan l at 0/0.5/1/2 s: {:.2?}",
            [0, 5, 10, 20].map(|k| pts.get(k).map_or(f64::NAN, |q| q.l))
        );
        for (i, a) in scene.agents().iter().enumerate() {
            let pr = core.processes()[i];
            println!(
                "   agent {} at ({:.1},{:.1}) v={:.1} {:?} lane={:?} s={:.1}",
                a.id,
                a.pos.x,
                a.pos.y,
                a.speed(),
                a.turn_signal,
                pr.lane,
                pr.s_m
            );
        }
        let turn = ch.profiles[Maneuver::TurnLeft.index()];
        for (c, y) in core.conflicts().pairs().iter().zip(core.yields()) {
            let ego = choice::ego_interval(&turn, scene.ego.speed(), c);
            let other = choice::proceeding_interval(c, &p.interaction);
            println!(
                "   conflict agent {} de={:.1} da={:.1} te={:.2} ta={:.2} {:?} yields {:.2} (Y {:.2} P {:.2}{}) turn-left risk {:.2}: ego [{:.1}, {:.1}] s, other [{:.1}, {:.1}] s",
                scene.agents[c.agent as usize].id,
                c.ego_dist_m,
                c.agent_dist_m,
                c.ego_ttc_s,
                c.agent_ttc_s,
                c.right_of_way,
                y,
                c.intent.yielding,
                c.intent.proceeding,
                if c.intent.committed { ", committed" } else { "" },
                choice::conflict_risk(&turn, scene.ego.speed(), c, *y, &p.interaction),
                ego.0,
                ego.1,
                other.0,
                other.1
            );
        }
        if std::env::var_os("CONCORD_REPLAY_BOXES").is_some() {
            let occ = &core.planner().occupancy;
            for step in [0, 5, 10, 20, 30] {
                let boxes: Vec<String> = occ
                    .boxes(step)
                    .map(|(s0, s1, l0, l1)| format!("s[{s0:.1},{s1:.1}] l[{l0:.1},{l1:.1}]"))
                    .collect();
                println!("   boxes at step {step}: {}", boxes.join("  "));
            }
            for m in core.planner().margins() {
                println!(
                    "   margin: s[{:.1},{:.1}] during ({:.2}, {:.2}) s",
                    m.s[0], m.s[1], m.t[0], m.t[1]
                );
            }
            println!(
                "   yields {:.2?} forecasts {:?}",
                core.yields(),
                &core.forecasts()[..scene.n_agents]
            );
        }
        for m in 0..MANEUVERS {
            let mut planner = *core.planner();
            let prof = ch.profiles[m];
            planner.sample(&prof, p.trajectory.samples, 1, &p.trajectory);
            let mut st = PlanStats::default();
            let best = planner.run(p.trajectory.samples, &p.trajectory, &mut st);
            println!(
                "   {:?}: profile T={:.1} v={:.1} feasible {}/{} limits {} collisions {} best {:?}",
                Maneuver::try_from(m as u8).unwrap(),
                prof.duration,
                prof.target_speed,
                st.feasible,
                st.evaluated,
                st.limit_rejects,
                st.collision_rejects,
                best.map(|b| (b.duration, b.s.vel(b.duration)))
            );
        }
    }
}
