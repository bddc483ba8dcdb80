//! SUMO networks (`.net.xml`, as `netconvert` writes them from OpenDRIVE, OpenStreetMap or
//! plain XML): each connection through a junction becomes one lane of the map, a *movement*:
//! the incoming lane's shape (its end is the stop line), the junction-internal lanes it runs
//! through (`via`, followed to the end of the chain) and the outgoing lane's shape. Its width
//! is the incoming lane's, its turn the connection's `dir`, and its id
//! `"{incoming lane}>{outgoing lane}"`, e.g. `"EC_0>CS_0"`. Turnarounds are left out.
//!
//! Vertices closer than [`MERGE_VERTICES_M`] are merged (SUMO's internal shapes meet in short
//! pieces whose three-vertex curvature would be far too high), keeping the stop line and the
//! ends exactly.
//!
//! Right of way is SUMO's own: at each junction, link i must yield to link j when bit j of
//! request i's `response` is set (the bit strings list link n−1 first). It is written into
//! every conflict between two movements of one junction; movements of different junctions
//! are first come, first served. Link i is the connection whose internal lanes include the
//! junction's i-th `intLanes` entry. Traffic lights are not modelled: their junctions' static
//! requests apply.
//!
//! Straight movements come first in the lane order, then right and left turns (an agent without
//! a turn signal matches the lowest index on a shared approach, and SUMO's vehicles show
//! blinkers only to turn); with a route, the route's legs come first (one lane per junction it
//! passes, see `concord_core::scene::Route`).
//!
//! Only movements near the ego's route are kept (the core holds at most
//! [`MAX_LANES`](concord_core::scene::MAX_LANES)): those of the route's junctions and of every
//! junction within [`RELEVANT_RADIUS_M`] of one. Without a route, every movement is kept.

use std::collections::HashMap;

use concord_core::scene::{RightOfWay, Route, Turn, Vec2};

pub use crate::movements::RELEVANT_RADIUS_M;
use crate::movements::{assemble, Movement};
use crate::{Map, MapError};
/// Lane width SUMO assumes when a lane has none, m.
const SUMO_DEFAULT_WIDTH_M: f64 = 3.2;
/// Consecutive vertices closer than this are merged when shapes are joined, m: SUMO's
/// junction-internal shapes are coarse and their pieces meet at vertices a few centimetres to
/// a few decimetres apart, where the curvature of three neighbouring vertices (the core's speed
/// cap in curves) would read a 16 m turn as an 8 m one.
pub const MERGE_VERTICES_M: f64 = 1.0;
/// Two anchors (the stop line, the ends) closer than this are one vertex, m.
const SAME_POINT_M: f64 = 0.05;

struct SumoLane {
    shape: Vec<Vec2>,
    width: f64,
}

struct Junction {
    centre: Vec2,
    int_lanes: Vec<String>,
    /// `response` of each request, by link index.
    responses: Vec<Vec<bool>>,
}

fn attr<'a>(node: roxmltree::Node<'a, '_>, name: &str) -> Result<&'a str, String> {
    node.attribute(name).ok_or_else(|| {
        format!(
            "<{}> on line {} has no `{name}`",
            node.tag_name().name(),
            node.document().text_pos_at(node.range().start).row
        )
    })
}

fn number(node: roxmltree::Node<'_, '_>, name: &str) -> Result<f64, String> {
    let text = attr(node, name)?;
    text.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| {
            format!(
                "<{}> {name} = {text:?}: not a finite number",
                node.tag_name().name()
            )
        })
}

fn shape(text: &str) -> Result<Vec<Vec2>, String> {
    text.split_whitespace()
        .map(|pair| {
            let mut xy = pair.split(',').map(str::parse::<f64>);
            match (xy.next(), xy.next()) {
                (Some(Ok(x)), Some(Ok(y))) if x.is_finite() && y.is_finite() => Ok(Vec2::new(x, y)),
                _ => Err(format!("shape vertex {pair:?}: not x,y")),
            }
        })
        .collect()
}

/// The polyline through `points`, each flagged as an anchor (kept exactly: the stop line and the
/// ends) or not; a vertex within [`MERGE_VERTICES_M`] of the last one kept is dropped, or, if it
/// is an anchor, replaces that one unless it is an anchor too.
fn thin(points: &[(Vec2, bool)]) -> Vec<Vec2> {
    let mut out: Vec<(Vec2, bool)> = Vec::with_capacity(points.len());
    for &(p, anchor) in points {
        match out.last_mut() {
            Some(last) if last.0.minus(p).norm() < MERGE_VERTICES_M => {
                if anchor && !last.1 {
                    *last = (p, true);
                } else if anchor && last.0.minus(p).norm() > SAME_POINT_M {
                    out.push((p, true));
                }
            }
            _ => out.push((p, anchor)),
        }
    }
    out.into_iter().map(|(p, _)| p).collect()
}

/// Parses a SUMO network and keeps the movements near `route` (a movement id, or waypoints
/// joined by `>`: edges or lanes, e.g. `"{incoming edge}>{outgoing edge}"`); `origin` names
/// the file in errors.
pub fn parse(
    text: &str,
    origin: &str,
    route: Option<&str>,
) -> Result<(Map, Option<Route>), MapError> {
    let err = |msg: String| MapError(format!("map {origin}: {msg}"));
    let doc = roxmltree::Document::parse(text).map_err(|e| err(format!("not XML: {e}")))?;
    let net = doc.root_element();
    if net.tag_name().name() != "net" {
        return Err(err("not a SUMO network (no <net>)".into()));
    }
    let mut lanes: HashMap<String, SumoLane> = HashMap::new();
    let mut edge_of: HashMap<String, String> = HashMap::new();
    let mut junctions: HashMap<String, Junction> = HashMap::new();
    let mut edge_to: HashMap<String, String> = HashMap::new();
    for node in net.children().filter(|n| n.is_element()) {
        match node.tag_name().name() {
            "edge" => {
                let edge = attr(node, "id").map_err(err)?.to_string();
                if let Some(to) = node.attribute("to") {
                    edge_to.insert(edge.clone(), to.to_string());
                }
                for lane in node.children().filter(|n| n.has_tag_name("lane")) {
                    let id = attr(lane, "id").map_err(err)?.to_string();
                    let shape = shape(attr(lane, "shape").map_err(err)?)
                        .map_err(|e| err(format!("lane {id}: {e}")))?;
                    let width = match lane.attribute("width") {
                        Some(_) => number(lane, "width").map_err(err)?,
                        None => SUMO_DEFAULT_WIDTH_M,
                    };
                    edge_of.insert(id.clone(), edge.clone());
                    lanes.insert(id, SumoLane { shape, width });
                }
            }
            "junction" => {
                let id = attr(node, "id").map_err(err)?.to_string();
                if node.attribute("type") == Some("internal") {
                    continue;
                }
                let centre = Vec2::new(
                    number(node, "x").map_err(err)?,
                    number(node, "y").map_err(err)?,
                );
                let int_lanes = node
                    .attribute("intLanes")
                    .unwrap_or("")
                    .split_whitespace()
                    .map(str::to_string)
                    .collect::<Vec<_>>();
                let mut responses = vec![Vec::new(); int_lanes.len()];
                for r in node.children().filter(|n| n.has_tag_name("request")) {
                    let index: usize = attr(r, "index").map_err(err)?.parse().map_err(|_| {
                        err(format!("junction {id}: a request index is not a number"))
                    })?;
                    let bits = attr(r, "response").map_err(err)?;
                    if index >= responses.len() || bits.len() != int_lanes.len() {
                        return Err(err(format!(
                            "junction {id}: request {index} does not match its {} internal lanes",
                            int_lanes.len()
                        )));
                    }
                    // The string lists link n − 1 first.
                    responses[index] = bits.chars().rev().map(|c| c == '1').collect();
                }
                junctions.insert(
                    id,
                    Junction {
                        centre,
                        int_lanes,
                        responses,
                    },
                );
            }
            _ => {}
        }
    }
    // Connections: from a normal lane (with its via chain) and from internal lanes.
    let mut next_via: HashMap<String, String> = HashMap::new();
    let mut starts = Vec::new();
    for c in net.children().filter(|n| n.has_tag_name("connection")) {
        let from = attr(c, "from").map_err(err)?;
        let lane_of = |edge: &str, index: &str| format!("{edge}_{index}");
        let from_lane = lane_of(from, attr(c, "fromLane").map_err(err)?);
        let to_lane = lane_of(attr(c, "to").map_err(err)?, attr(c, "toLane").map_err(err)?);
        let via = c.attribute("via").map(str::to_string);
        if from.starts_with(':') {
            if let Some(v) = via {
                next_via.insert(from_lane, v);
            }
            continue;
        }
        let dir = attr(c, "dir").map_err(err)?;
        let turn = match dir {
            "s" => Turn::Straight,
            "l" | "L" | "partially_left" => Turn::Left,
            "r" | "R" | "partially_right" => Turn::Right,
            _ => continue, // turnarounds and invalid
        };
        if let Some(v) = via {
            starts.push((
                from_lane,
                to_lane,
                v,
                turn,
                from.to_string(),
                attr(c, "to").map_err(err)?.to_string(),
            ));
        }
    }
    let mut movements = Vec::new();
    // Each movement's junction-internal lanes, in driving order.
    let mut vias = Vec::new();
    for (from_lane, to_lane, first_via, turn, from_edge, to_edge) in starts {
        let mut via = vec![first_via];
        while let Some(v) = next_via.get(via.last().unwrap()) {
            if via.contains(v) || via.len() > 8 {
                return Err(err(format!("internal lanes after {from_lane} form a loop")));
            }
            via.push(v.clone());
        }
        let shape_of = |id: &str| {
            lanes
                .get(id)
                .map(|l| l.shape.as_slice())
                .ok_or_else(|| err(format!("connection {from_lane} > {to_lane}: no lane {id}")))
        };
        let incoming = lanes
            .get(&from_lane)
            .ok_or_else(|| err(format!("connection from unknown lane {from_lane}")))?;
        // Anchors: the incoming lane's ends (its end is the stop line) and the outgoing lane's end.
        let n_in = incoming.shape.len();
        let mut flagged: Vec<(Vec2, bool)> = incoming
            .shape
            .iter()
            .enumerate()
            .map(|(k, p)| (*p, k == 0 || k + 1 == n_in))
            .collect();
        for v in &via {
            flagged.extend(shape_of(v)?.iter().map(|p| (*p, false)));
        }
        let outgoing = shape_of(&to_lane)?;
        flagged.extend(
            outgoing
                .iter()
                .enumerate()
                .map(|(k, p)| (*p, k + 1 == outgoing.len())),
        );
        let points = thin(&flagged);
        let stop_line = incoming.shape[n_in - 1];
        let stop_at = points
            .iter()
            .position(|p| p.minus(stop_line).norm() < SAME_POINT_M)
            .expect("the stop line is an anchor");
        let stop_s = points[..=stop_at]
            .windows(2)
            .map(|w| w[1].minus(w[0]).norm())
            .sum();
        let junction = edge_to.get(&from_edge).cloned().unwrap_or_default();
        movements.push(Movement {
            id: format!("{from_lane}>{to_lane}"),
            from: from_edge,
            to: to_edge,
            from_lane: from_lane.clone(),
            to_lane: to_lane.clone(),
            junction,
            turn,
            points,
            stop_s,
            exit: outgoing[0],
            width: incoming.width,
        });
        vias.push(via);
    }
    if movements.is_empty() {
        return Err(err("no connection through a junction".into()));
    }
    // SUMO's right of way between the movements of one junction.
    let link = |i: usize| -> Option<usize> {
        let j = junctions.get(&movements[i].junction)?;
        j.int_lanes.iter().position(|l| vias[i].contains(l))
    };
    let row = |a: usize, b: usize| -> Option<RightOfWay> {
        let (la, lb, j) = (link(a)?, link(b)?, junctions.get(&movements[a].junction)?);
        let yields =
            |x: usize, y: usize| j.responses.get(x).and_then(|r| r.get(y)).copied() == Some(true);
        Some(match (yields(la, lb), yields(lb, la)) {
            (true, false) => RightOfWay::B,
            (false, true) => RightOfWay::A,
            _ => RightOfWay::Neither,
        })
    };
    assemble(
        &movements,
        |j| junctions.get(j).map(|j| j.centre),
        route,
        "\"incoming lane>outgoing lane\" or \"incoming edge>outgoing edge\"",
        origin,
        &row,
    )
}
