//! Scene builders shared by the core's integration tests.
#![allow(dead_code)]

use concord_core::scene::{AgentState, Scene, Vec2};
use concord_core::{DecisionCore, Params};
use concord_map::{paper, BuiltIn};

/// The paper's initial scene: CAV at (40, 5) heading west, HDV at (−40, −5) heading east.
pub fn paper_scene(t: f64, cav_speed: f64, hdv_speed: f64) -> Scene {
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), core::f64::consts::PI, cav_speed);
    let mut scene = Scene::new(t, ego, paper::CAV_LEFT);
    scene.push(AgentState::moving(
        1,
        Vec2::new(-40.0, -5.0),
        0.0,
        hdv_speed,
    ));
    scene
}

/// A road user `id` moving at `speed` m/s on the paper's `lane` (`paper::CAV_LEFT` or
/// `paper::HDV_STRAIGHT`), `before` m along it before the point where the two cross (negative:
/// past it).
pub fn before_the_paper_crossing(id: u32, lane: u8, before: f64, speed: f64) -> AgentState {
    let m = BuiltIn::PaperIntersection.morphology();
    let (s_cav, s_hdv) = m
        .conflict_between(paper::CAV_LEFT, paper::HDV_STRAIGHT)
        .expect("the paper's routes cross");
    let s = match lane {
        paper::CAV_LEFT => s_cav,
        paper::HDV_STRAIGHT => s_hdv,
        _ => panic!("lane {lane} is not one of the paper's crossing routes"),
    };
    let (pos, heading, _) = m.lane(lane).pose_at(s - before, 0);
    AgentState::moving(id, pos, heading, speed)
}

/// A core on the paper's junction, boxed as a deployment holds it (it is a few hundred KB).
pub fn paper_core(params: Params) -> Box<DecisionCore> {
    Box::new(
        DecisionCore::new(params, BuiltIn::PaperIntersection.morphology()).expect("valid params"),
    )
}
