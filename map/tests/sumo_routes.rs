//! Routes across several junctions of a SUMO network: one leg per junction, each the rest of
//! the route from its junction's approach on, handing over once its junction is cleared; the
//! legs see the conflicts of every junction ahead with SUMO's right of way, and nothing that
//! branches off them; more junctions than the core's capacity is an error naming it.

use std::path::{Path, PathBuf};

use concord_core::scene::{ConflictKind, RightOfWay, Turn, TurnSignal, Vec2, MAX_ROUTE_LEGS};
use concord_map::Map;

fn corridor() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/maps/sumo/corridor.net.xml")
}

fn index(map: &Map, id: &str) -> u8 {
    map.ids().iter().position(|i| i == id).expect(id) as u8
}

#[test]
fn a_route_through_two_junctions_has_a_leg_for_each() {
    let (map, route) = Map::load_route(&corridor(), Some("SJ1>J2N")).unwrap();
    let route = route.unwrap();
    let by_lanes = Map::load_route(&corridor(), Some("SJ1_0>J1J2_0>J2N_0")).unwrap();
    assert_eq!(by_lanes.0.ids(), map.ids(), "waypoints by edge or by lane");
    assert_eq!(by_lanes.1, Some(route));
    assert_eq!(route.lanes(), &[0, 1]);
    assert_eq!(&map.ids()[..2], ["SJ1_0>J1J2_0>J2N_0", "J1J2_0>J2N_0"]);
    let morph = map.morphology();
    let (first, second) = (morph.lane(0), morph.lane(1));
    assert_eq!((first.turn, second.turn), (Turn::Right, Turn::Left));
    // The first leg runs on into the second, vertex for vertex.
    let tail = &first.points()[first.points().len() - second.points().len()..];
    assert_eq!(tail, second.points());
    for w in first.points().windows(2) {
        assert!(w[1].minus(w[0]).norm() > 0.05, "{w:?}");
    }
    // Each leg's stop line is its own junction's.
    assert!(
        (first
            .pose_at(first.stop_s, 0)
            .0
            .minus(Vec2::new(5.0, -11.5)))
        .norm()
            < 1e-6
    );
    assert!(
        (second
            .pose_at(second.stop_s, 0)
            .0
            .minus(Vec2::new(68.5, -5.0)))
        .norm()
            < 1e-6
    );

    // From the first leg, both junctions' conflicts are in view, with SUMO's right of way:
    // the ego merges behind the major road at J1 and turns left across it at J2.
    let seen = |a: u8, b: &str| morph.conflict(a, index(&map, b));
    let merge = seen(0, "WJ1_0>J1J2_0").expect("the merge at J1");
    assert_eq!(merge.kind, ConflictKind::Merging);
    assert_eq!(merge.right_of_way, RightOfWay::B);
    for leg in [0, 1] {
        let across = seen(leg, "EJ2_0>J2J1_0").expect("the oncoming major road at J2");
        assert_eq!(across.kind, ConflictKind::Crossing);
        assert_eq!(across.right_of_way, RightOfWay::B);
        let minor = seen(leg, "NJ2_0>J2E_0").expect("the minor road's left turn at J2");
        assert_eq!(minor.right_of_way, RightOfWay::A);
    }
    // What branches off the route is a leader while ahead on the shared lane, never a
    // conflict; nor are the legs with each other.
    assert!(seen(0, "J1J2_0>J2E_0").is_none());
    assert!(seen(0, "SJ1_0>J1W_0").is_none());
    assert!(morph.conflict(0, 1).is_none());

    // A car on the major road approaching J1 is on its own movement through J1, not on the
    // extensions of the lanes that start beyond J1 (the second leg, J2's movements).
    let eastbound_at = |x: f64| {
        let (lane, f) = morph
            .match_lane(
                Vec2::new(x, -5.0),
                Vec2::new(1.0, 0.0),
                0.5,
                TurnSignal::Off,
            )
            .unwrap();
        (map.ids()[lane as usize].as_str(), f.s)
    };
    assert_eq!(eastbound_at(-10.0).0, "WJ1_0>J1J2_0");
    // Queued further back than the map reaches, it is still matched, by extension.
    let (id, s) = eastbound_at(-120.0);
    assert!(id.starts_with("WJ1_0>") && s < 0.0, "{id} {s}");

    // The first leg hands over once it has cleared J1's merge zone, on the link to J2.
    let handover = route.handover_s(0);
    assert!(
        handover > first.stop_s + 11.0 && handover < first.stop_s + 30.0,
        "{handover}"
    );
    let at = |x: f64, y: f64| route.lane_at(&morph, Vec2::new(x, y));
    assert_eq!(at(5.0, -40.0), 0, "approaching J1");
    assert_eq!(at(14.0, -5.0), 0, "leaving J1, still in its merge zone");
    assert_eq!(at(40.0, -5.0), 1, "on the link to J2");
    assert_eq!(at(85.0, 40.0), 1, "past J2");
    assert_eq!(at(f64::NAN, 0.0), 0, "a position that is not finite");
}

/// `n` junctions in a line, 100 m apart, one lane through each: edge e{i} leads into J{i}.
fn line_of_junctions(n: usize) -> String {
    let mut xml = String::from("<net>\n");
    for i in 0..=n {
        let x = 100.0 * i as f64;
        xml += &format!(
            "<edge id=\"e{i}\" from=\"J{p}\" to=\"J{i}\"><lane id=\"e{i}_0\" index=\"0\" shape=\"{a},0 {b},0\"/></edge>\n",
            p = i as i64 - 1,
            a = x - 45.0,
            b = x + 45.0
        );
        if i < n {
            xml += &format!(
                "<edge id=\":J{i}_0\" function=\"internal\"><lane id=\":J{i}_0_0\" index=\"0\" shape=\"{a},0 {b},0\"/></edge>\n\
                 <junction id=\"J{i}\" type=\"priority\" x=\"{c}\" y=\"0\" intLanes=\":J{i}_0_0\"><request index=\"0\" response=\"0\" foes=\"0\" cont=\"0\"/></junction>\n\
                 <connection from=\"e{i}\" to=\"e{j}\" fromLane=\"0\" toLane=\"0\" via=\":J{i}_0_0\" dir=\"s\" state=\"M\"/>\n",
                a = x + 45.0,
                b = x + 55.0,
                c = x + 50.0,
                j = i + 1
            );
        }
    }
    xml + "</net>\n"
}

#[test]
fn a_route_is_found_from_start_to_exit_within_the_legs_capacity() {
    let dir = std::env::temp_dir().join(format!("concord-sumo-line-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("line.net.xml");
    std::fs::write(&path, line_of_junctions(MAX_ROUTE_LEGS + 1)).unwrap();
    let longest = Map::load_route(&path, Some(&format!("e0>e{MAX_ROUTE_LEGS}")));
    let too_long = Map::load_route(&path, Some(&format!("e0>e{}", MAX_ROUTE_LEGS + 1)));
    let via = Map::load_route(&path, Some("e0>e2>e3"));
    let backwards = Map::load_route(&path, Some("e3>e1"));
    let _ = std::fs::remove_dir_all(&dir);
    let (map, route) = longest.unwrap();
    let route = route.unwrap();
    assert_eq!(route.lanes().len(), MAX_ROUTE_LEGS);
    let morph = map.morphology();
    for (k, &lane) in route.lanes().iter().enumerate() {
        // Leg k starts on e{k} and runs to the route's end.
        let l = morph.lane(lane);
        assert_eq!(l.points()[0], Vec2::new(100.0 * k as f64 - 45.0, 0.0));
        let end = 100.0 * MAX_ROUTE_LEGS as f64 + 45.0;
        assert_eq!(*l.points().last().unwrap(), Vec2::new(end, 0.0));
        if k + 1 < route.lanes().len() {
            // No conflict zone: it hands over at its junction's exit.
            assert!(
                (route.handover_s(k) - 100.0).abs() < 1e-9,
                "{}",
                route.handover_s(k)
            );
        }
    }
    assert!(morph.conflicts().is_empty(), "{:?}", morph.conflicts());
    let e = too_long.unwrap_err();
    assert!(
        e.0.contains(&format!("MAX_ROUTE_LEGS = {MAX_ROUTE_LEGS}")),
        "{e}"
    );
    let (_, via) = via.unwrap();
    assert_eq!(via.unwrap().lanes().len(), 3);
    let e = backwards.unwrap_err();
    assert!(
        e.0.contains("no route \"e3>e1\"") && e.0.contains("line.net.xml"),
        "{e}"
    );
}
