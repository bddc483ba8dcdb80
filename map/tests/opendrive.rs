//! OpenDRIVE files: the paper's junction as OpenDRIVE (`deploy/maps/opendrive/paper.xodr`,
//! written by netconvert from the SUMO network, `deploy/maps/sumo/build.sh`) loads as the same
//! twelve movements as the SUMO network, lying on its lanes; a junction's `<priority>` sets the
//! right of way; a route across the two junctions of `corridor.xodr` has the legs the SUMO
//! network has; broken files are errors that name the file.

use std::path::{Path, PathBuf};

use concord_core::scene::{RightOfWay, Turn};
use concord_map::Map;

fn shipped(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../deploy/maps")
        .join(rel)
}

fn xodr_text() -> String {
    std::fs::read_to_string(shipped("opendrive/paper.xodr")).unwrap()
}

/// Loads OpenDRIVE `text` through a file of its own (the loader goes by the extension).
fn load_text(text: &str, name: &str, route: Option<&str>) -> Result<(Map, Option<u8>), String> {
    let path = std::env::temp_dir().join(format!("{name}-{}.xodr", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let got = Map::load_route(&path, route)
        .map(|(map, r)| (map, r.map(|r| r.first())))
        .map_err(|e| e.0);
    let _ = std::fs::remove_file(&path);
    got
}

#[test]
fn the_paper_junction_has_the_sumo_networks_movements_on_its_lanes() {
    let xodr = Map::load(&shipped("opendrive/paper.xodr")).unwrap();
    let sumo = Map::load(&shipped("sumo/paper.net.xml")).unwrap();
    let (x, s) = (xodr.morphology(), sumo.morphology());
    assert_eq!(x.lanes().len(), 12);
    for turn in [Turn::Straight, Turn::Left, Turn::Right] {
        assert_eq!(x.lanes().iter().filter(|l| l.turn == turn).count(), 4);
    }
    for (i, lane) in x.lanes().iter().enumerate() {
        let pts = lane.points();
        let (start, end) = (pts[0], pts[pts.len() - 1]);
        // The SUMO movement with the same ends.
        let twin = s
            .lanes()
            .iter()
            .find(|l| {
                let q = l.points();
                q[0].minus(start).norm() < 0.01 && q[q.len() - 1].minus(end).norm() < 0.01
            })
            .unwrap_or_else(|| {
                panic!(
                    "{}: no SUMO movement from {start:?} to {end:?}",
                    xodr.ids()[i]
                )
            });
        assert_eq!(lane.turn, twin.turn, "{}", xodr.ids()[i]);
        assert!(
            (lane.stop_s - twin.stop_s).abs() < 0.01,
            "{}",
            xodr.ids()[i]
        );
        assert!((lane.half_width - twin.half_width).abs() < 0.01);
        // Every metre of a straight movement lies on the SUMO one. A turn departs from it:
        // netconvert writes each junction-internal shape as one parametric cubic between its
        // ends, up to 1.7 m off SUMO's polyline in the middle of a left turn (checked against
        // the file's own curve below).
        if lane.turn == Turn::Straight {
            let mut at = 0.0;
            while at <= lane.length() {
                let (p, _, _) = lane.pose_at(at, 0);
                let off = twin.project(p).l.abs();
                assert!(off < 0.001, "{} at s = {at}: {off} m off", xodr.ids()[i]);
                at += 1.0;
            }
        }
    }
    // The left turn from road 54 runs through connecting road 63: a paramPoly3 from
    // (11.5, 2.5) heading west, u = 28p − 14p², v = 14p² (p in [0, 1]), whose lane −1 lies
    // 2.5 m to its right. Half way (p = 0.5) the reference line is at (1, −1) heading
    // south-west, so the lane centre is at (1 − 2.5/√2, −1 + 2.5/√2).
    let left = xodr.ids().iter().position(|i| i == "54_-1>52_-1").unwrap() as u8;
    let h = 2.5 / 2f64.sqrt();
    let mid = concord_core::scene::Vec2::new(1.0 - h, -1.0 + h);
    let f = x.lane(left).project(mid);
    assert!(f.l.abs() < 0.03, "{} m off the file's curve", f.l);
    assert!((88.5..88.5 + 22.71).contains(&f.s), "at s = {}", f.s);
    // The same crossings, plus the two pairs of opposing left turns whose curves netconvert
    // writes touching (SUMO's network warns they intersect).
    assert_eq!(s.conflicts().len(), 28);
    assert_eq!(x.conflicts().len(), 30);
}

#[test]
fn a_route_by_roads_keeps_its_junction_and_comes_first() {
    let (map, route) = Map::load_route(&shipped("opendrive/paper.xodr"), Some("54>52")).unwrap();
    assert_eq!(route.map(|r| r.lanes().to_vec()), Some(vec![0]));
    assert_eq!(map.ids()[0], "54_-1>52_-1");
    assert_eq!(map.morphology().lane(0).turn, Turn::Left);
    let err = Map::load_route(&shipped("opendrive/paper.xodr"), Some("54>54")).unwrap_err();
    assert!(err.0.contains("no route \"54>54\""), "{}", err.0);
}

#[test]
fn a_junction_priority_sets_the_right_of_way() {
    let text = xodr_text();
    // Connecting road 62 (:C_4) is the straight movement from road 54, 59 (:C_1) the one from
    // road 55; they cross.
    let with = text.replacen(
        "    </junction>",
        "        <priority high=\"59\" low=\"62\"/>\n    </junction>",
        1,
    );
    assert_ne!(with, text);
    let row = |text: &str| {
        let (map, _) = load_text(text, "priority", None).unwrap();
        let id = |s: &str| map.ids().iter().position(|i| i == s).unwrap() as u8;
        let (a, b) = (id("54_-1>53_-1"), id("55_-1>52_-1"));
        let c = map
            .morphology()
            .conflicts()
            .iter()
            .find(|c| (c.lane_a, c.lane_b) == (a.min(b), a.max(b)))
            .copied()
            .expect("the two straights cross");
        // As seen from the movement from road 54.
        match (c.right_of_way, a < b) {
            (RightOfWay::Neither, _) => "neither",
            (RightOfWay::A, true) | (RightOfWay::B, false) => "road 54",
            _ => "road 55",
        }
    };
    assert_eq!(
        row(&text),
        "neither",
        "no <priority>: first come, first served"
    );
    assert_eq!(row(&with), "road 55");
}

#[test]
fn broken_files_are_errors_naming_the_file() {
    let err = load_text("<OpenDRIVE><road", "broken", None).unwrap_err();
    assert!(
        err.contains("broken-") && err.contains("not OpenDRIVE"),
        "{err}"
    );
    let no_junction = "<?xml version=\"1.0\"?><OpenDRIVE><header revMajor=\"1\" revMinor=\"6\"/>\
        <road length=\"10\" id=\"1\" junction=\"-1\"><planView><geometry s=\"0\" x=\"0\" y=\"0\" \
        hdg=\"0\" length=\"10\"><line/></geometry></planView><lanes><laneSection s=\"0\">\
        <center><lane id=\"0\" type=\"none\"/></center><right><lane id=\"-1\" type=\"driving\">\
        <width sOffset=\"0\" a=\"3.5\" b=\"0\" c=\"0\" d=\"0\"/></lane></right></laneSection>\
        </lanes></road></OpenDRIVE>";
    let err = load_text(no_junction, "plain-road", None).unwrap_err();
    assert!(
        err.contains("plain-road-") && err.contains("no drivable lane through a junction"),
        "{err}"
    );
}

#[test]
fn a_route_across_two_junctions_has_the_legs_the_sumo_network_has() {
    // corridor.xodr is netconvert's OpenDRIVE of sumo/corridor.net.xml: road 67 is the south
    // arm, 65 the link from J1 to J2, 62 the north arm.
    let (xodr, route) =
        Map::load_route(&shipped("opendrive/corridor.xodr"), Some("67>62")).unwrap();
    let (sumo, sumo_route) =
        Map::load_route(&shipped("sumo/corridor.net.xml"), Some("SJ1>J2N")).unwrap();
    let (route, sumo_route) = (route.unwrap(), sumo_route.unwrap());
    assert_eq!(route.lanes(), &[0, 1]);
    assert_eq!(&xodr.ids()[..2], ["67_-1>65_-1>62_-1", "65_-1>62_-1"]);
    let (x, s) = (xodr.morphology(), sumo.morphology());
    for leg in [0, 1] {
        let (a, b) = (x.lane(leg), s.lane(leg));
        assert_eq!(a.turn, b.turn);
        assert!(
            (a.stop_s - b.stop_s).abs() < 0.05,
            "{} {}",
            a.stop_s,
            b.stop_s
        );
        assert!(
            (a.length() - b.length()).abs() < 0.5,
            "{} {}",
            a.length(),
            b.length()
        );
        let conflicts = |m: &concord_core::scene::Morphology| {
            m.conflicts()
                .iter()
                .filter(|c| c.lane_a == leg || c.lane_b == leg)
                .count()
        };
        assert_eq!(conflicts(&x), conflicts(&s), "leg {leg}");
    }
    assert!((route.handover_s(0) - sumo_route.handover_s(0)).abs() < 0.5);
}
