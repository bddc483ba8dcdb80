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

/// A core on the paper's junction, boxed as a deployment holds it (it is a few hundred KB).
pub fn paper_core(params: Params) -> Box<DecisionCore> {
    Box::new(
        DecisionCore::new(params, BuiltIn::PaperIntersection.morphology()).expect("valid params"),
    )
}
