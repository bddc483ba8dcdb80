//! OpenDRIVE files (`.xodr`: CARLA, esmini, most HD-map tools), read with the `xodr` crate,
//! which bakes every road's reference line, lane offsets and widths into lane centre lines and
//! a lane graph. Each drivable lane of a junction's connecting road becomes one lane of the map,
//! a *movement*: the incoming lane that drives into it (its end is the stop line), the
//! connecting lane, and the outgoing lane it leads into. Its width is the incoming lane's, its
//! turn the change of heading across the junction (more than 30° to the left or right), and
//! its id `"{incoming road}_{lane}>{outgoing road}_{lane}"` (OpenDRIVE's road and lane ids),
//! e.g. `"5_-1>7_-1"`; a route may also be `"{incoming road}>{outgoing road}"`.
//!
//! Each piece is simplified to the fewest vertices within [`SIMPLIFY_M`] of the baked centre
//! line (the baking samples densely), keeping the stop line and the ends exactly.
//!
//! Right of way: a junction's `<priority high low>` elements, where the file has them (the
//! connecting road `low` yields to `high`); otherwise, as OpenDRIVE files seldom state it,
//! first come, first served. (SUMO's `netconvert --opendrive-files` derives a junction's right
//! of way from its roads; `deploy/maps/README.md` shows that path.) Straight movements come
//! first in the lane order, then right and left turns; with a route (also waypoints across
//! several junctions, `"{road}>{road}>{road}"`), the route's legs come first and only the
//! movements of junctions within [`RELEVANT_RADIUS_M`] of its junctions are kept.

use concord_core::scene::{RightOfWay, Route, Turn, Vec2};
use xodr::{Direction, LaneId};

#[cfg(doc)]
use crate::movements::RELEVANT_RADIUS_M;
use crate::movements::{assemble, stop_line_centres, Movement};
use crate::{Map, MapError};

/// Largest distance of a simplified piece from the baked centre line, m.
pub const SIMPLIFY_M: f64 = 0.02;
/// Lanes that end and start closer than this meet, m.
const SAME_POINT_M: f64 = 0.05;
/// A heading change across the junction beyond this is a turn, rad (30°).
const TURN_RAD: f64 = std::f64::consts::FRAC_PI_6;

/// The fewest of `points` whose polyline stays within [`SIMPLIFY_M`] of them all
/// (Douglas–Peucker), keeping both ends.
fn simplify(points: &[Vec2]) -> Vec<Vec2> {
    fn keep(points: &[Vec2], out: &mut Vec<Vec2>) {
        let (a, b) = (points[0], points[points.len() - 1]);
        let d = b.minus(a);
        let far = points[1..points.len() - 1]
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let r = p.minus(a);
                let off = if d.norm() > 0.0 {
                    d.cross(r).abs() / d.norm()
                } else {
                    r.norm()
                };
                (k + 1, off)
            })
            .max_by(|x, y| x.1.total_cmp(&y.1));
        match far {
            Some((k, off)) if off > SIMPLIFY_M => {
                keep(&points[..=k], out);
                keep(&points[k..], out);
            }
            _ => out.push(b),
        }
    }
    let mut out = vec![points[0]];
    if points.len() > 1 {
        keep(points, &mut out);
    }
    out
}

/// Signed change of heading from `a` to `b`, rad, in (−π, π].
fn turn_between(a: Vec2, b: Vec2) -> f64 {
    a.cross(b).atan2(a.x * b.x + a.y * b.y)
}

/// Parses an OpenDRIVE file and keeps the movements near `route` (a movement id, or waypoints
/// joined by `>`: roads or lanes, e.g. `"{incoming road}>{outgoing road}"`); `origin` names
/// the file in errors.
pub fn parse(
    text: &str,
    origin: &str,
    route: Option<&str>,
) -> Result<(Map, Option<Route>), MapError> {
    let err = |msg: String| MapError(format!("map {origin}: {msg}"));
    let net = xodr::load_str(text).map_err(|e| err(format!("not OpenDRIVE: {e}")))?;
    let lane_name = |id: LaneId| -> Option<(String, String, Option<String>)> {
        let at = net.road_lane(id)?;
        let road = net.road(at.road)?;
        Some((
            road.od_id().to_string(),
            format!("{}_{}", road.od_id(), at.od_id),
            road.junction().filter(|j| *j != "-1").map(str::to_string),
        ))
    };
    // A lane's centre line in its direction of travel.
    let travel = |lane: &xodr::Lane| -> Vec<Vec2> {
        let mut p: Vec<Vec2> = lane
            .center
            .points()
            .iter()
            .map(|p| Vec2::new(f64::from(p.x), f64::from(p.y)))
            .collect();
        if lane.direction == Direction::Backward {
            p.reverse();
        }
        p
    };
    let mut movements = Vec::new();
    // Each movement's connecting road.
    let mut connecting_roads = Vec::new();
    for lane in net.driving_lanes() {
        let Some((_, _, Some(junction))) = lane_name(lane.id) else {
            continue;
        };
        if lane.direction == Direction::Both {
            continue;
        }
        let connecting_road = net.road_lane(lane.id).expect("a named lane").road;
        let outside = |id: &&LaneId| {
            lane_name(**id).is_some_and(|(_, _, j)| j.is_none())
                && net.lane(**id).is_some_and(|l| l.kind.is_drivable())
        };
        for from in lane.predecessors.iter().filter(outside) {
            for to in lane.successors.iter().filter(outside) {
                let (Some(incoming), Some(outgoing)) = (net.lane(*from), net.lane(*to)) else {
                    continue;
                };
                let (from_road, from_name, _) = lane_name(*from).expect("named");
                let (to_road, to_name, _) = lane_name(*to).expect("named");
                let pieces = [travel(incoming), travel(lane), travel(outgoing)];
                if pieces.iter().any(|p| p.len() < 2) {
                    continue;
                }
                // Where pieces meet, the lane's own end or start stays: the incoming lane's end
                // (the stop line, shared by its approach's movements) and the outgoing lane's
                // start (shared by the movements into it, which merge there).
                let mut points = simplify(&pieces[0]);
                let stop_at = points.len() - 1;
                let mut connecting = simplify(&pieces[1]);
                if connecting[0].minus(points[stop_at]).norm() < SAME_POINT_M {
                    connecting.remove(0);
                }
                let outgoing = simplify(&pieces[2]);
                if connecting
                    .last()
                    .is_some_and(|p| p.minus(outgoing[0]).norm() < SAME_POINT_M)
                {
                    connecting.pop();
                }
                points.extend(connecting);
                points.extend(outgoing);
                let stop_s = points[..=stop_at]
                    .windows(2)
                    .map(|w| w[1].minus(w[0]).norm())
                    .sum();
                let dir = |p: &[Vec2], end: bool| {
                    let n = p.len();
                    if end {
                        p[n - 1].minus(p[n - 2])
                    } else {
                        p[1].minus(p[0])
                    }
                };
                let angle = turn_between(dir(&pieces[0], true), dir(&pieces[2], false));
                let turn = if angle > TURN_RAD {
                    Turn::Left
                } else if angle < -TURN_RAD {
                    Turn::Right
                } else {
                    Turn::Straight
                };
                movements.push(Movement {
                    id: format!("{from_name}>{to_name}"),
                    from: from_road,
                    to: to_road,
                    from_lane: from_name,
                    to_lane: to_name,
                    exit: pieces[2][0],
                    junction: junction.clone(),
                    turn,
                    points,
                    stop_s,
                    width: f64::from(incoming.width),
                });
                connecting_roads.push(connecting_road);
            }
        }
    }
    if movements.is_empty() {
        return Err(err("no drivable lane through a junction".into()));
    }
    let centres = stop_line_centres(&movements);
    // The junctions' <priority> elements, between the connecting roads of one junction.
    let row = |a: usize, b: usize| -> Option<RightOfWay> {
        let yields = |x: usize, y: usize| {
            net.yields_to(connecting_roads[x])
                .any(|r| r == connecting_roads[y])
        };
        match (yields(a, b), yields(b, a)) {
            (true, false) => Some(RightOfWay::B),
            (false, true) => Some(RightOfWay::A),
            _ => None,
        }
    };
    assemble(
        &movements,
        |j| centres.get(j).copied(),
        route,
        "\"incoming road_lane>outgoing road_lane\" or \"incoming road>outgoing road\"",
        origin,
        &row,
    )
}
