//! The built-in map files load, and their conflict points, zones and right of way equal
//! those of the geometries the core was built with before they became map files (values
//! recorded then; tolerance 1 µm). A map that breaks a rule or exceeds a capacity of the core
//! is an error that names the lane, the field or the limit.

use concord_core::scene::{ConflictKind, RightOfWay, MAX_CONFLICTS, MAX_LANES, MAX_LANE_POINTS};
use concord_map::{highway_env_intersection, highway_env_merge, merge, paper, BuiltIn, Map};

/// (lane a, lane b, s on a, s on b, point, kind, right of way, zone on a, zone on b,
/// passage on a).
type Expected = (
    u8,
    u8,
    f64,
    f64,
    [f64; 2],
    ConflictKind,
    RightOfWay,
    [f64; 2],
    [f64; 2],
    [f64; 2],
);

#[rustfmt::skip]
const PAPER_INTERSECTION: &[Expected] = &[
        (0, 1, 50.70165578477376, 34.99999999999999, [-5.0, -5.0], ConflictKind::Crossing, RightOfWay::B, [45.37450734727376, 55.60204640977376], [30.100585937499993, 39.97753906249999], [45.37450734727376, 55.60204640977376]),
        (0, 3, 35.0, 50.70165578477376, [5.0, 5.0], ConflictKind::Crossing, RightOfWay::Neither, [30.099609375, 40.42578125], [45.27587453477376, 55.60204640977376], [30.099609375, 40.42578125]),
        (0, 4, 35.0, 45.0, [5.0, 5.0], ConflictKind::Crossing, RightOfWay::A, [30.099609375, 40.3271484375], [40.0224609375, 49.8994140625], [30.099609375, 40.3271484375]),
        (0, 5, 50.70165578477376, 45.0, [-5.0, -4.999999999999999], ConflictKind::Merging, RightOfWay::A, [40.14599172227376, 55.50165578477376], [33.9345703125, 49.8], [48.301655784773764, 53.10165578477376]),
        (0, 7, 55.70165578477376, 37.841371226364856, [-5.0, -10.0], ConflictKind::Merging, RightOfWay::B, [47.28466359727376, 60.50165578477376], [30.101136851364856, 42.64137122636485], [53.301655784773764, 58.10165578477376]),
        (1, 4, 45.0, 35.0, [5.0, -5.0], ConflictKind::Crossing, RightOfWay::A, [40.1005859375, 49.8994140625], [30.1005859375, 39.8994140625], [40.1005859375, 49.8994140625]),
        (1, 5, 35.0, 45.0, [-5.0, -5.0], ConflictKind::Crossing, RightOfWay::A, [30.1005859375, 39.8994140625], [40.1005859375, 49.8994140625], [30.1005859375, 39.8994140625]),
        (2, 3, 35.0, 50.70165578477376, [5.0, 5.0], ConflictKind::Crossing, RightOfWay::A, [30.1005859375, 39.9775390625], [45.37450734727376, 55.60204640977376], [30.1005859375, 39.9775390625]),
        (2, 4, 35.0, 45.0, [5.0, 5.0], ConflictKind::Crossing, RightOfWay::A, [30.1005859375, 39.8994140625], [40.1005859375, 49.8994140625], [30.1005859375, 39.8994140625]),
        (2, 5, 45.0, 35.0, [-5.0, 5.0], ConflictKind::Crossing, RightOfWay::A, [40.1005859375, 49.8994140625], [30.1005859375, 39.8994140625], [40.1005859375, 49.8994140625]),
        (3, 4, 50.70165578477376, 45.0, [5.0, 5.0], ConflictKind::Merging, RightOfWay::A, [40.14599172227376, 55.50165578477376], [33.9345703125, 49.8], [48.301655784773764, 53.10165578477376]),
        (3, 5, 35.0, 45.0, [-5.0, -5.0], ConflictKind::Crossing, RightOfWay::A, [30.099609375, 40.3271484375], [40.0224609375, 49.8994140625], [30.099609375, 40.3271484375]),
        (3, 6, 55.70165578477376, 37.84137122636485, [5.0, 10.0], ConflictKind::Merging, RightOfWay::B, [47.28466359727376, 60.50165578477376], [30.10113685136485, 42.641371226364846], [53.301655784773764, 58.10165578477376]),
        (4, 6, 50.0, 37.84137122636485, [5.0, 10.0], ConflictKind::Merging, RightOfWay::B, [41.2626953125, 54.8], [30.08258216386485, 42.641371226364846], [47.6, 52.4]),
        (5, 7, 50.0, 37.841371226364856, [-5.0, -10.0], ConflictKind::Merging, RightOfWay::B, [41.2626953125, 54.8], [30.082582163864856, 42.64137122636485], [47.6, 52.4]),
];

#[rustfmt::skip]
const MERGE: &[Expected] = &[
        (0, 1, 150.0, 151.1882341631134, [0.0, 0.0], ConflictKind::Merging, RightOfWay::A, [133.421875, 154.8], [136.1550310381134, 155.98823416311342], [147.6, 152.4]),
];

#[rustfmt::skip]
const HIGHWAY_ENV_INTERSECTION: &[Expected] = &[
        (0, 1, 110.47078313832816, 112.6280800751903, [-2.0, 1.6280800751903062], ConflictKind::Crossing, RightOfWay::B, [103.30965032582816, 115.92097845082816], [106.9230019501903, 119.8351113251903], [103.30965032582816, 115.92097845082816]),
        (0, 2, 120.41559207487369, 114.13070818559476, [-10.999999999999998, -2.0], ConflictKind::Merging, RightOfWay::B, [112.47125613737369, 125.21559207487368], [106.32699724809476, 118.93070818559475], [118.01559207487368, 122.81559207487369]),
        (0, 4, 109.94480893654551, 109.37191992480969, [-1.6280800751903062, 2.0], ConflictKind::Crossing, RightOfWay::B, [104.49461362404551, 117.10594174904551], [102.16488867480969, 115.07699804980969], [104.49461362404551, 117.10594174904551]),
        (0, 5, 113.12484081748356, 107.29075125739016, [-4.088869763603319, -4.440892098500626e-16], ConflictKind::Crossing, RightOfWay::B, [108.57405956748356, 118.97835644248356], [101.43723563239016, 111.84153250739016], [108.57405956748356, 118.97835644248356]),
        (0, 6, 120.41559207487369, 122.00000000000001, [-11.0, -2.0], ConflictKind::Merging, RightOfWay::B, [109.31500613737369, 125.21559207487368], [110.61523437500001, 126.80000000000001], [118.01559207487368, 122.81559207487369]),
        (0, 7, 107.29075125739011, 113.12484081748362, [0.0, 4.088869763603318], ConflictKind::Crossing, RightOfWay::B, [101.43723563239011, 111.84153250739011], [108.57405956748362, 118.97835644248362], [101.43723563239011, 111.84153250739011]),
        (1, 4, 113.0, 109.0, [-2.0, 2.0], ConflictKind::Crossing, RightOfWay::B, [108.6005859375, 117.3994140625], [104.6005859375, 113.3994140625], [108.6005859375, 117.3994140625]),
        (1, 5, 109.37191992480969, 109.94480893654556, [-2.0, -1.6280800751903115], ConflictKind::Crossing, RightOfWay::B, [102.16488867480969, 115.07699804980969], [104.49461362404556, 117.10594174904556], [102.16488867480969, 115.07699804980969]),
        (1, 6, 109.0, 113.0, [-2.0, -2.0], ConflictKind::Crossing, RightOfWay::B, [104.6005859375, 113.3994140625], [108.6005859375, 117.3994140625], [104.6005859375, 113.3994140625]),
        (1, 7, 122.00000000000001, 120.41559207487377, [-2.0, 11.000000000000014], ConflictKind::Merging, RightOfWay::B, [110.61523437500001, 126.80000000000001], [109.31500613737377, 125.21559207487377], [119.60000000000001, 124.40000000000002]),
        (1, 8, 122.00000000000001, 114.13070818559476, [-2.0, 11.000000000000014], ConflictKind::Merging, RightOfWay::B, [112.06152343750001, 126.80000000000001], [104.61898943559476, 118.93070818559475], [119.60000000000001, 124.40000000000002]),
        (2, 6, 114.13070818559476, 122.00000000000001, [-10.999999999999998, -2.0], ConflictKind::Merging, RightOfWay::B, [104.61898943559476, 118.93070818559475], [112.06152343750001, 126.80000000000001], [111.73070818559475, 116.53070818559476]),
        (3, 4, 120.41559207487377, 122.00000000000001, [11.0, 2.0], ConflictKind::Merging, RightOfWay::B, [109.31500613737377, 125.21559207487377], [110.61523437500001, 126.80000000000001], [118.01559207487377, 122.81559207487378]),
        (3, 5, 107.29075125739016, 113.1248408174836, [-2.7755575615628914e-16, -4.088869763603319], ConflictKind::Crossing, RightOfWay::B, [101.43723563239016, 111.84153250739016], [108.5740595674836, 118.9783564424836], [101.43723563239016, 111.84153250739016]),
        (3, 6, 109.94480893654556, 109.37191992480969, [1.6280800751903062, -2.0], ConflictKind::Crossing, RightOfWay::B, [104.49461362404556, 117.10594174904556], [102.16488867480969, 115.07699804980969], [104.49461362404556, 117.10594174904556]),
        (3, 7, 113.12484081748363, 107.29075125739014, [4.088869763603318, 9.992007221626409e-16], ConflictKind::Crossing, RightOfWay::B, [108.57405956748363, 118.97835644248363], [101.43723563239014, 111.84153250739014], [108.57405956748363, 118.97835644248363]),
        (4, 7, 112.6280800751903, 110.4707831383282, [1.6280800751902973, 2.0], ConflictKind::Crossing, RightOfWay::A, [106.9230019501903, 119.8351113251903], [103.3096503258282, 115.9209784508282], [106.9230019501903, 119.8351113251903]),
        (5, 6, 110.4707831383282, 112.6280800751903, [-1.6280800751903048, -2.0], ConflictKind::Crossing, RightOfWay::B, [103.3096503258282, 115.9209784508282], [106.9230019501903, 119.8351113251903], [103.3096503258282, 115.9209784508282]),
        (5, 9, 120.41559207487374, 114.13070818559477, [2.0, -10.999999999999998], ConflictKind::Merging, RightOfWay::B, [112.47125613737374, 125.21559207487374], [106.32699724809477, 118.93070818559477], [118.01559207487374, 122.81559207487375]),
        (7, 8, 120.41559207487377, 114.13070818559476, [-2.0, 10.999999999999998], ConflictKind::Merging, RightOfWay::B, [112.47125613737377, 125.21559207487377], [106.32699724809476, 118.93070818559475], [118.01559207487377, 122.81559207487378]),
];

#[rustfmt::skip]
const HIGHWAY_ENV_MERGE: &[Expected] = &[
        (0, 2, 250.0, 250.719824862509, [250.0, 4.0], ConflictKind::Merging, RightOfWay::A, [232.40234375, 254.8], [233.804785800009, 255.519824862509], [247.6, 252.4]),
];

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

#[test]
fn each_built_in_map_has_the_conflicts_of_the_geometry_it_replaced() {
    for (which, expected) in [
        (BuiltIn::PaperIntersection, PAPER_INTERSECTION),
        (BuiltIn::Merge, MERGE),
        (BuiltIn::HighwayEnvIntersection, HIGHWAY_ENV_INTERSECTION),
        (BuiltIn::HighwayEnvMerge, HIGHWAY_ENV_MERGE),
    ] {
        let morph = which.morphology();
        let got = morph.conflicts();
        assert_eq!(got.len(), expected.len(), "{which:?}");
        for (c, e) in got.iter().zip(expected) {
            let what = format!("{which:?} lanes {} x {}", e.0, e.1);
            assert_eq!((c.lane_a, c.lane_b), (e.0, e.1), "{what}");
            assert!(close(c.s_a, e.2) && close(c.s_b, e.3), "{what}: s");
            assert!(
                close(c.pos.x, e.4[0]) && close(c.pos.y, e.4[1]),
                "{what}: point"
            );
            assert_eq!((c.kind, c.right_of_way), (e.5, e.6), "{what}");
            for (got, want) in [(c.zone_a, e.7), (c.zone_b, e.8), (c.pass_a, e.9)] {
                assert!(
                    close(got[0], want[0]) && close(got[1], want[1]),
                    "{what}: zone"
                );
            }
        }
    }
}

#[test]
fn the_lane_constants_name_the_lanes_of_the_map_files() {
    let at = |which: BuiltIn, id: &str| which.map().lane_index(id).unwrap();
    let p = BuiltIn::PaperIntersection;
    for (id, index) in [
        ("cav_left", paper::CAV_LEFT),
        ("hdv_straight", paper::HDV_STRAIGHT),
        ("west_straight", paper::WEST_STRAIGHT),
        ("east_left", paper::EAST_LEFT),
        ("north_straight", paper::NORTH_STRAIGHT),
        ("south_straight", paper::SOUTH_STRAIGHT),
        ("west_right", paper::WEST_RIGHT),
        ("east_right", paper::EAST_RIGHT),
    ] {
        assert_eq!(at(p, id), index, "{id}");
    }
    assert_eq!(at(BuiltIn::Merge, "main"), merge::MAIN);
    assert_eq!(at(BuiltIn::Merge, "ramp"), merge::RAMP);
    assert_eq!(
        at(BuiltIn::HighwayEnvIntersection, "ego_left"),
        highway_env_intersection::EGO_LEFT
    );
    assert_eq!(
        at(BuiltIn::HighwayEnvMerge, "ego_right"),
        highway_env_merge::EGO_RIGHT
    );
    let err = BuiltIn::Merge.map().lane_index("shoulder").unwrap_err();
    assert!(
        err.0.contains("no lane \"shoulder\"") && err.0.contains("main, ramp"),
        "{err}"
    );
}

#[test]
fn the_shipped_files_on_disk_are_the_compiled_in_ones() {
    for which in BuiltIn::ALL {
        let (path, text) = which.source();
        let on_disk = format!("{}/../{path}", env!("CARGO_MANIFEST_DIR"));
        let loaded = Map::load(std::path::Path::new(&on_disk)).unwrap();
        assert_eq!(std::fs::read_to_string(&on_disk).unwrap(), text);
        assert_eq!(loaded.ids(), which.map().ids());
    }
}

/// A map of one lane, with `extra` TOML lines added to it.
fn one_lane(extra: &str) -> String {
    format!("name = \"t\"\n[[lane]]\nid = \"a\"\n{extra}\n")
}

fn error_of(text: &str) -> String {
    Map::parse(text, "test.toml").unwrap_err().0
}

#[test]
fn a_lane_that_breaks_a_rule_is_an_error_naming_the_lane_and_the_field() {
    let line = "points = [[0.0, 0.0], [50.0, 0.0]]";
    let cases = [
        (
            one_lane(&format!("width_m = 0.0\nstop_s_m = 10.0\n{line}")),
            "width_m = 0",
        ),
        (
            one_lane(&format!("width_m = nan\nstop_s_m = 10.0\n{line}")),
            "width_m = NaN",
        ),
        (
            one_lane(&format!("width_m = 3.0\nstop_s_m = 60.0\n{line}")),
            "stop line at s = 60",
        ),
        (one_lane(&format!("width_m = 3.0\n{line}")), "stop_s_m"),
        (
            one_lane("width_m = 3.0\nstop_s_m = 1.0\npoints = [[0.0, 0.0], [0.0, inf]]"),
            "not a finite number",
        ),
        (
            one_lane("width_m = 3.0\nstop_s_m = 1.0\npoints = [[0.0, 0.0], [0.0, 0.0]]"),
            "coincide",
        ),
        (
            one_lane(&format!(
                "width_m = 3.0\nstop_s_m = 1.0\n{line}\nstart = [0.0, 0.0]"
            )),
            "either `points`, or `start` and `path`",
        ),
        (
            one_lane(&format!(
                "width_m = 3.0\nstop_s_m = 1.0\n{line}\nsuccessors = [\"b\"]"
            )),
            "unknown successor \"b\"",
        ),
        (
            one_lane(&format!("width_m = 3.0\nstop_s_m = 1.0\n{line}\nspeed = 3")),
            "unknown field `speed`",
        ),
        (
            one_lane(
                "width_m = 3.0\nstop_s_m = 1.0\nstart = [0.0, 0.0]\n\
                 path = [{ arc = { centre = [0.0, 10.0], sweep_deg = 0.0 } }]",
            ),
            "sweep_deg = 0",
        ),
    ];
    for (text, expected) in cases {
        let e = error_of(&text);
        assert!(
            e.contains("test.toml") && e.contains(expected),
            "{e}\nfor\n{text}"
        );
    }
    let twice = format!(
        "name = \"t\"\n[[lane]]\nid = \"a\"\nwidth_m = 3.0\nstop_s_m = 1.0\n{line}\n\
         [[lane]]\nid = \"a\"\nwidth_m = 3.0\nstop_s_m = 1.0\n{line}\n"
    );
    assert!(error_of(&twice).contains("\"a\" is empty or repeated"));
}

#[test]
fn a_map_beyond_a_capacity_of_the_core_is_an_error_naming_the_limit() {
    // A long arc sampled every 0.1 m has more vertices than a lane may hold.
    let arc = one_lane(
        "width_m = 3.0\nstop_s_m = 1.0\nstart = [0.0, 0.0]\n\
         path = [{ arc = { centre = [0.0, 10.0], sweep_deg = 90.0, step_m = 0.1 } }]",
    );
    assert!(error_of(&arc).contains(&format!("MAX_LANE_POINTS = {MAX_LANE_POINTS}")));
    // The same arc at the default step fits.
    Map::parse(&arc.replace(", step_m = 0.1", ""), "test.toml").unwrap();
    let lane = |i: usize, from: [f64; 2], to: [f64; 2]| {
        format!(
            "[[lane]]\nid = \"l{i}\"\nwidth_m = 3.0\nstop_s_m = 1.0\npoints = [[{:?}, {:?}], [{:?}, {:?}]]\n",
            from[0], from[1], to[0], to[1]
        )
    };
    let too_many: String = (0..=MAX_LANES)
        .map(|i| lane(i, [0.0, 10.0 * i as f64], [100.0, 10.0 * i as f64]))
        .collect();
    let e = error_of(&format!("name = \"t\"\n{too_many}"));
    assert!(e.contains(&format!("MAX_LANES = {MAX_LANES}")), "{e}");
    // Lanes through the centre at 16 angles cross each other pairwise: 120 crossings.
    let star: String = (0..MAX_LANES)
        .map(|i| {
            let a = std::f64::consts::PI * i as f64 / MAX_LANES as f64;
            let (c, s) = (100.0 * a.cos(), 100.0 * a.sin());
            lane(i, [c + 0.1 * i as f64, s], [-c, -s])
        })
        .collect();
    const { assert!(MAX_LANES * (MAX_LANES - 1) / 2 > MAX_CONFLICTS) };
    let e = error_of(&format!("name = \"t\"\n{star}"));
    assert!(
        e.contains(&format!("MAX_CONFLICTS = {MAX_CONFLICTS}")),
        "{e}"
    );
}

#[test]
fn a_stop_line_given_as_a_point_is_projected_onto_the_lane() {
    let map = Map::parse(
        &one_lane("width_m = 3.0\nstop_at = [30.0, 1.0]\npoints = [[0.0, 0.0], [50.0, 0.0]]"),
        "test.toml",
    )
    .unwrap();
    assert!(close(map.morphology().lane(0).stop_s, 30.0));
}

#[test]
fn successors_and_the_junction_rule_come_from_the_file() {
    let text = "name = \"t\"\nrule = \"right_before_left\"\n\
        [[lane]]\nid = \"east\"\nwidth_m = 3.0\nstop_s_m = 40.0\npoints = [[-50.0, -2.0], [50.0, -2.0]]\nsuccessors = [\"north\"]\n\
        [[lane]]\nid = \"north\"\nwidth_m = 3.0\nstop_s_m = 40.0\npoints = [[2.0, -50.0], [2.0, 50.0]]\n";
    let map = Map::parse(text, "test.toml").unwrap();
    assert_eq!(map.successors(0), &[1]);
    assert!(map.successors(1).is_empty());
    let c = map.morphology().conflict(0, 1).unwrap();
    // Equal levels: the northbound lane comes from the eastbound one's right.
    assert_eq!(c.right_of_way, RightOfWay::B);
    let levels = Map::parse(&text.replace("right_before_left", "levels"), "t").unwrap();
    assert_eq!(
        levels.morphology().conflict(0, 1).unwrap().right_of_way,
        RightOfWay::Neither
    );
}

#[test]
fn the_example_of_the_format_documentation_loads() {
    let doc = include_str!("../../deploy/maps/README.md");
    let start = doc.find("```toml\n").expect("a TOML example") + "```toml\n".len();
    let text = &doc[start..start + doc[start..].find("```").unwrap()];
    let map = Map::parse(text, "deploy/maps/README.md").unwrap();
    assert_eq!(map.ids(), ["main_east", "minor_left"]);
    let c = map
        .morphology()
        .conflict(1, 0)
        .expect("the left turn crosses the main road");
    assert_eq!(c.right_of_way, RightOfWay::B);
    let e = error_of(&text.replace("stop_s_m = 40.0", "stop_s_m = 130.0"));
    assert!(
        e.contains("lane \"main_east\": stop line at s = 130 m"),
        "{e}"
    );
}

#[test]
fn queued_traffic_behind_an_approachs_first_vertex_is_matched_to_it() {
    use concord_core::scene::{TurnSignal, Vec2, LANE_EXTENSION_M};
    let m = BuiltIn::PaperIntersection.morphology();
    let east = Vec2::new(1.0, 0.0);
    let at = |x: f64| m.match_lane(Vec2::new(x, -5.0), east, 0.5, TurnSignal::Off);
    // The approach starts at x = −40: 30 m behind it is queued traffic, 60 m behind is not.
    let (lane, f) = at(-70.0).expect("matched by extension");
    assert_eq!(lane, paper::HDV_STRAIGHT);
    assert!((f.s + 30.0).abs() < 1e-9, "{}", f.s);
    assert!(at(-40.0 - LANE_EXTENSION_M - 10.0).is_none());
}
