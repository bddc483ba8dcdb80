//! A stopped Concord ego moves off once nothing holds it: the merge episode of the paper grid
//! (10 m/s, repetition 6) in which Concord stopped 21.5 m before the join, let the main-lane
//! car pass, and then stood still for the rest of the 40 s because the history terms of
//! eq. 12–14 kept choosing "decelerate" in an unchanging scene (see `idle_penalty`). The
//! episode is replayed as it ran then, before the logit-only controller showed its decisions
//! on the eHMI: the driver does not see them (with them, a driver told "please go ahead"
//! goes at once, and the ego no longer comes to this standstill).

use concord_core::Params;
use concord_sim::controllers::{Advisor, ConcordController, Controller};
use concord_sim::driver::{DriverStyle, HumanDriver};
use concord_sim::world::{ScenarioKind, World};

/// (the ego stopped at some point, it got 15 m past the zone without a collision in 40 s).
fn replay(params: Params) -> (bool, bool) {
    let mut w = World::new(ScenarioKind::Merge, 10.0, -3.132);
    let mut drivers = [HumanDriver::new(DriverStyle::Balanced, 10.0, 1_047_828)];
    let mut cav = ConcordController::new(params, &w, Advisor::None);
    let mut stopped = false;
    while w.t < 40.0 && !w.collided() {
        if w.ego_past_zones(15.0) {
            return (stopped, true);
        }
        stopped |= w.ego.v < 0.01;
        let cmd = cav.act(&w, &drivers);
        let a = drivers[0].act(&w, 0, None).accel;
        w.step(cmd.accel, &[a]);
    }
    (stopped, false)
}

#[test]
fn a_stopped_ego_moves_off_once_the_conflict_is_gone() {
    let (stopped, through) = replay(Params::default());
    // It does stop (the situation this test is about) and gets through.
    assert!(stopped, "never stopped");
    assert!(through);
    let without = Params {
        choice: concord_core::params::ChoiceParams {
            idle_penalty: 0.0,
            ..Params::default().choice
        },
        ..Params::default()
    };
    // Without the idle penalty it would wait out the time limit.
    assert!(!replay(without).1);
}
