//! SUMO networks: the paper's junction as netconvert builds it (`deploy/maps/sumo/`) loads as
//! one movement per connection, through its internal lanes, with SUMO's own right of way; a
//! route keeps the movements near it; what exceeds the core's capacity or is missing is an
//! error that names it.

use std::path::{Path, PathBuf};

use concord_core::scene::{RightOfWay, Turn, Vec2, MAX_LANES};
use concord_map::sumo::RELEVANT_RADIUS_M;
use concord_map::Map;

fn paper() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/maps/sumo/paper.net.xml")
}

fn on_lane(map: &Map, lane: u8, p: Vec2) -> bool {
    let f = map.morphology().lane(lane).project(p);
    f.l.abs() < 1e-6
}

#[test]
fn every_connection_becomes_a_movement_through_its_internal_lanes() {
    let (map, route) = Map::load_route(&paper(), Some("EC>CS")).unwrap();
    assert_eq!(route.map(|r| r.lanes().to_vec()), Some(vec![0]));
    assert_eq!(map.ids()[0], "EC_0>CS_0");
    assert_eq!(
        map.ids().len(),
        12,
        "4 approaches × 3 movements, no turnarounds"
    );
    let morph = map.morphology();
    let ego = morph.lane(0);
    assert_eq!(ego.turn, Turn::Left);
    assert_eq!(ego.half_width, 2.5);
    // The stop line is the end of the incoming lane EC_0 (100, 5) → (11.5, 5).
    assert!((ego.stop_s - 88.5).abs() < 1e-9, "{}", ego.stop_s);
    // Incoming lane, both internal lanes (:C_5_0, :C_12_0), outgoing lane CS_0.
    for (x, y) in [
        (100.0, 5.0),
        (11.5, 5.0),
        (5.98, 3.6),
        (0.33, -0.33),
        (-5.0, -11.5),
        (-5.0, -100.0),
    ] {
        assert!(on_lane(&map, 0, Vec2::new(x, y)), "({x}, {y})");
    }
    let straight = map.lane_index("WC_0>CE_0").unwrap();
    assert_eq!(map.morphology().lane(straight).turn, Turn::Straight);
    assert_eq!(
        map.lane_index("SC_0>CW_0")
            .map(|i| map.morphology().lane(i).turn),
        Ok(Turn::Left)
    );
}

#[test]
fn right_of_way_is_the_junctions_own() {
    let (map, _) = Map::load_route(&paper(), Some("EC_0>CS_0")).unwrap();
    let m = map.morphology();
    let lane = |id: &str| map.lane_index(id).unwrap();
    let row = |a: &str, b: &str| m.conflict(lane(a), lane(b)).expect(a).right_of_way;
    // The left turn from the major road gives way to the oncoming straight car ...
    assert_eq!(row("EC_0>CS_0", "WC_0>CE_0"), RightOfWay::B);
    // ... and goes before the minor road.
    assert_eq!(row("EC_0>CS_0", "SC_0>CN_0"), RightOfWay::A);
    assert_eq!(row("NC_0>CS_0", "WC_0>CE_0"), RightOfWay::B);
    assert_eq!(row("WC_0>CE_0", "NC_0>CS_0"), RightOfWay::A);
    // The minor road's two straight movements run side by side: no conflict.
    assert!(m.conflict(lane("NC_0>CS_0"), lane("SC_0>CN_0")).is_none());
}

/// A network of `n` separate junctions 100 m apart, each one movement.
fn chain_of_junctions(n: usize) -> String {
    let mut xml = String::from("<net>\n");
    for i in 0..n {
        let x = 100.0 * i as f64;
        xml += &format!(
            "<edge id=\"a{i}\" from=\"s{i}\" to=\"J{i}\"><lane id=\"a{i}_0\" index=\"0\" shape=\"{x},-50 {x},-5\"/></edge>\n\
             <edge id=\":J{i}_0\" function=\"internal\"><lane id=\":J{i}_0_0\" index=\"0\" shape=\"{x},-5 {x},5\"/></edge>\n\
             <edge id=\"b{i}\" from=\"J{i}\" to=\"e{i}\"><lane id=\"b{i}_0\" index=\"0\" shape=\"{x},5 {x},50\"/></edge>\n\
             <junction id=\"J{i}\" type=\"priority\" x=\"{x}\" y=\"0\" intLanes=\":J{i}_0_0\"><request index=\"0\" response=\"0\" foes=\"0\" cont=\"0\"/></junction>\n\
             <connection from=\"a{i}\" to=\"b{i}\" fromLane=\"0\" toLane=\"0\" via=\":J{i}_0_0\" dir=\"s\" state=\"M\"/>\n"
        );
    }
    xml + "</net>\n"
}

#[test]
fn a_route_keeps_the_junctions_near_it_and_beyond_a_capacity_is_an_error() {
    let dir = std::env::temp_dir().join(format!("concord-sumo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("chain.net.xml");
    std::fs::write(&path, chain_of_junctions(MAX_LANES + 1)).unwrap();
    let all = Map::load(&path).map(|_| ()).unwrap_err();
    let routed = Map::load_route(&path, Some("a3>b3"));
    let unknown = Map::load_route(&path, Some("a3>b4"))
        .map(|_| ())
        .unwrap_err();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(all.0.contains(&format!("MAX_LANES = {MAX_LANES}")), "{all}");
    assert!(all.0.contains("give a route"), "{all}");
    // Junctions are 100 m apart, more than the radius: only the route's own is kept.
    const { assert!(RELEVANT_RADIUS_M < 100.0) };
    let (map, lane) = routed.unwrap();
    assert_eq!(
        (map.ids(), lane.map(|r| r.lanes().to_vec())),
        (&["a3_0>b3_0".to_string()][..], Some(vec![0]))
    );
    assert!(unknown.0.contains("no route \"a3>b4\""), "{unknown}");
}

#[test]
fn a_broken_network_is_an_error_naming_what_is_wrong() {
    let dir = std::env::temp_dir().join(format!("concord-sumo-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = chain_of_junctions(1);
    let cases = [
        ("<nets/>", "no <net>"),
        ("<net", "not XML"),
        ("<net></net>", "no connection through a junction"),
        (&*good.replace("0,-50 0,-5", "0,-50 0,nan"), "not x,y"),
        (
            &*good.replace(" via=\":J0_0_0\"", " via=\":J0_9_0\""),
            "no lane :J0_9_0",
        ),
        (
            &*good.replace("response=\"0\"", "response=\"00\""),
            "does not match",
        ),
    ];
    let results: Vec<_> = cases
        .iter()
        .enumerate()
        .map(|(i, (text, _))| {
            let path = dir.join(format!("bad{i}.net.xml"));
            std::fs::write(&path, text).unwrap();
            Map::load(&path).map(|_| ()).unwrap_err()
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    for ((_, expected), e) in cases.iter().zip(results) {
        assert!(e.0.contains(expected) && e.0.contains(".net.xml"), "{e}");
    }
}

#[test]
fn internal_shapes_are_merged_into_vertices_a_metre_apart_and_the_turn_keeps_its_radius() {
    use concord_map::sumo::MERGE_VERTICES_M;
    let (map, _) = Map::load_route(&paper(), Some("EC>CS")).unwrap();
    let morph = map.morphology();
    let ego = morph.lane(0);
    for w in ego.points().windows(2) {
        assert!(w[1].minus(w[0]).norm() >= MERGE_VERTICES_M, "{w:?}");
    }
    // SUMO's left turn is a quarter circle of about 16.5 m from (11.5, 5) to (−5, −11.5); its
    // pieces meet 0.35 m apart at (5.98, 3.6), which unmerged read as an 8.8 m turn.
    let sharpest = (0..ego.segments())
        .map(|k| ego.curvature_at(ego.s_at_vertex(k), k))
        .fold(0.0, f64::max);
    assert!(1.0 / sharpest > 14.0, "radius {}", 1.0 / sharpest);
    assert!((ego.stop_s - 88.5).abs() < 1e-9);
}
