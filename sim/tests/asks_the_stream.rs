//! Negotiation through the eHMI in a stream: a left turn at 6 m/s across five cars 3–5 s
//! apart (no gap the ego's PET margins accept from its waiting point). Waiting, the ego asks a
//! car far enough to stop gently to let it go first ("I am going first"), watches it brake,
//! and goes ahead of it and of the cars queued behind it. Without asking, it waits for the
//! whole stream.

use concord_core::params::InteractionParams;
use concord_core::Params;
use concord_sim::experiment::{interaction_grid, run_episode, ControllerKind};
use concord_sim::metrics::Metrics;
use concord_sim::world::ScenarioKind;

fn stream(params: &Params) -> Metrics {
    let e = interaction_grid(30, 1)
        .into_iter()
        .find(|e| {
            e.scenario == ScenarioKind::Stream
                && e.speed == 6.0
                && e.rep == 29
                && e.controller == ControllerKind::ConcordLogit
        })
        .expect("the grid has the cell");
    assert_eq!(e.followers.len(), 4, "a stream of five cars");
    run_episode(&e, params).metrics
}

#[test]
fn the_ego_asks_the_stream_to_let_it_go_and_nobody_brakes_hard() {
    let asked = stream(&Params::default());
    assert!(asked.success && !asked.collision);
    assert!(
        asked.time_to_clear_s < 20.0,
        "{:.2} s",
        asked.time_to_clear_s
    );
    assert!(
        asked.imposed_decel_mps2 <= 3.0,
        "imposed {:.2} m/s²",
        asked.imposed_decel_mps2
    );
    assert!(asked.pet_s >= 1.5, "PET {:.2} s", asked.pet_s);
    let silent = Params {
        interaction: InteractionParams {
            request_decel_mps2: 0.0,
            ..Params::default().interaction
        },
        ..Params::default()
    };
    let waited = stream(&silent);
    assert!(waited.success && !waited.collision);
    assert!(
        waited.time_to_clear_s > asked.time_to_clear_s + 8.0,
        "without asking {:.2} s, asking {:.2} s",
        waited.time_to_clear_s,
        asked.time_to_clear_s
    );
}
