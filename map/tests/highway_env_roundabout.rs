//! The map of highway-env's roundabout-v0 (`deploy/maps/highway-env-roundabout.toml`, built by
//! `bridges/python/highway_maps.py`, whose test checks that it rebuilds the file exactly):
//! what the core derives from it against the roundabout's known shape.

use std::path::Path;

use concord_core::scene::{ConflictKind, RightOfWay};
use concord_map::Map;

fn roundabout() -> (Map, u8) {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/maps/highway-env-roundabout.toml");
    let (map, route) = Map::load_route(&path, Some("ego")).expect("the shipped roundabout loads");
    (map, route.expect("the ego's route").first())
}

fn lane(map: &Map, id: &str) -> u8 {
    map.ids().iter().position(|i| i == id).expect(id) as u8
}

#[test]
fn the_ego_merges_onto_the_outer_ring_where_the_ring_traffic_passes() {
    let (map, ego) = roundabout();
    let morph = map.morphology();
    let find = |other: &str| {
        let o = lane(&map, other);
        morph
            .conflicts()
            .iter()
            .find(|c| (c.lane_a, c.lane_b) == (ego.min(o), ego.max(o)))
            .copied()
            .unwrap_or_else(|| panic!("no conflict between ego and {other}"))
    };
    // The entry joins the outer ring (radius 24 m) in the south-east quadrant, 4 m past
    // highway-env's node "se" (66° in its y-down frame); the outer ring's cars going on to
    // the north exit merge there, those leaving east cross the ego's path there too.
    let merge = find("ring_outer_north");
    assert_eq!(merge.kind, ConflictKind::Merging);
    let r = merge.pos.norm();
    assert!(
        (r - 24.0).abs() < 0.05,
        "merge point {:?} at radius {r}",
        merge.pos
    );
    let angle = merge.pos.y.atan2(merge.pos.x).to_degrees();
    assert!((50.0..66.0).contains(&angle), "merge point at {angle}°");
    assert_eq!(find("ring_outer_east").pos, merge.pos);
    // An inner-ring car leaving east cuts across the outer lane, after the merge.
    let cut = find("ring_inner_east");
    assert_eq!(cut.kind, ConflictKind::Crossing);
    assert!(
        cut.pos.y < merge.pos.y && cut.pos.x > merge.pos.x,
        "{:?}",
        cut.pos
    );
    // The east entry joins the ego's path on the ring.
    assert_eq!(find("east_north").kind, ConflictKind::Merging);
    // highway-env's roundabout has no right of way: every conflict is first come first served.
    assert!(morph
        .conflicts()
        .iter()
        .all(|c| c.right_of_way == RightOfWay::Neither));
}

#[test]
fn the_ego_lane_runs_from_the_south_approach_to_the_north_exit() {
    let (map, ego) = roundabout();
    let morph = map.morphology();
    let l = morph.lane(ego);
    let pts = l.points();
    let (start, end) = (pts[0], pts[pts.len() - 1]);
    assert_eq!((start.x, start.y), (2.0, 100.0));
    assert_eq!((end.x, end.y), (2.0, -170.0));
    // Its stop line lies where it leaves the entry's S-bend, outside the ring (radius > 26 m).
    let (p, _, _) = l.pose_at(l.stop_s, 0);
    assert!(p.norm() > 26.0 && p.y > 0.0, "stop line at {p:?}");
}
