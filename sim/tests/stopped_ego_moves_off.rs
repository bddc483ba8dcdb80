//! A stopped Concord ego moves off once nothing holds it: the merge episode of the paper grid
//! (10 m/s, repetition 6) in which Concord stopped 21.5 m before the join, let the main-lane
//! car pass, and then stood still for the rest of the 40 s because the history terms of
//! eq. 12–14 kept choosing "decelerate" in an unchanging scene (see `idle_penalty`).

use concord_core::scene::Style;
use concord_core::Params;
use concord_sim::experiment::{run_episode, ControllerKind, Episode};
use concord_sim::world::ScenarioKind;

#[test]
fn a_stopped_ego_moves_off_once_the_conflict_is_gone() {
    let episode = Episode {
        scenario: ScenarioKind::Merge,
        controller: ControllerKind::ConcordLogit,
        speed: 10.0,
        style: Style::Balanced,
        hdv_offset_m: -3.132,
        seed: 1_047_828,
        rep: 6,
    };
    let out = run_episode(&episode, &Params::default());
    // It does stop (the situation this test is about) ...
    assert!(out.samples.iter().any(|s| s.ego_v < 0.01), "never stopped");
    // ... and gets through without a collision.
    assert!(!out.metrics.collision);
    assert!(out.metrics.success, "{:?}", out.metrics);
    let without = Params {
        choice: concord_core::params::ChoiceParams {
            idle_penalty: 0.0,
            ..Params::default().choice
        },
        ..Params::default()
    };
    // Without the idle penalty it would wait out the time limit.
    assert!(!run_episode(&episode, &without).metrics.success);
}
