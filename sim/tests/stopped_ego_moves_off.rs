//! A stopped Concord ego moves off once nothing holds it: the paper's left turn at 6 m/s with a
//! hesitant driver who stops before the junction and waits for a sign, which it does not get:
//! here it does not see the eHMI (with it, it answers the ego's announcement and the ego never
//! stops). Nor does the ego ask while it slows (`request_decel_mps2 = 0`): asking, it reads the
//! driver's stop as the answer and never stops either. So the ego stops too, announces that it
//! goes first and, once the driver keeps waiting, counts it as yielding: no conflict holds it
//! back any more, yet the history terms of eq. 12–14 would keep choosing "decelerate" in the
//! unchanging scene (see `idle_penalty`).

use concord_core::Params;
use concord_sim::controllers::{Advisor, ConcordController, Controller};
use concord_sim::driver::{DriverStyle, HumanDriver};
use concord_sim::world::{ScenarioKind, World};

/// (seconds the ego stood still, whether it got 15 m past the zone without a collision in
/// 40 s).
fn replay(params: Params) -> (f64, bool) {
    let dt = 0.05;
    let mut w = World::new(ScenarioKind::LeftTurn, 6.0, -5.0);
    let mut drivers = [HumanDriver::new(DriverStyle::Hesitant, 6.0, 1_047_828)];
    let mut cav = ConcordController::new(params, &w, Advisor::None);
    let mut stood = 0.0;
    while w.t < 40.0 && !w.collided() {
        if w.ego_past_zones(15.0) {
            return (stood, true);
        }
        if w.ego.v < 0.01 {
            stood += dt;
        }
        let cmd = cav.act(&w, &drivers);
        let a = drivers[0].act(&w, 0, None).accel;
        w.step(cmd.accel, &[a]);
    }
    (stood, false)
}

/// The defaults, except that the ego never asks before it stands (the deadlock is the point).
fn not_asking() -> Params {
    Params {
        interaction: concord_core::params::InteractionParams {
            request_decel_mps2: 0.0,
            ..Params::default().interaction
        },
        ..Params::default()
    }
}

#[test]
fn a_stopped_ego_moves_off_once_the_conflict_is_gone() {
    let (stood, through) = replay(not_asking());
    // It does stop (the situation this test is about), briefly, and gets through.
    assert!(stood > 0.5, "stood only {stood:.2} s");
    assert!(stood < 4.0, "stood {stood:.2} s");
    assert!(through);
    let without = Params {
        choice: concord_core::params::ChoiceParams {
            idle_penalty: 0.0,
            ..Params::default().choice
        },
        ..not_asking()
    };
    // Without the idle penalty it stands on long after the driver has stopped for it.
    let (stood, _) = replay(without);
    assert!(
        stood > 8.0,
        "stood only {stood:.2} s without the idle penalty"
    );
}
