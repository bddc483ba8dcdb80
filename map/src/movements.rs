//! What the SUMO and OpenDRIVE loaders share: movements through junctions (incoming lane,
//! the lanes through the junction, outgoing lane), the route among them, the ones kept near it,
//! and the map built from those.

use std::collections::HashMap;

use concord_core::scene::{Lane, Turn, Vec2, MAX_LANES, MAX_LANE_POINTS};

use crate::{Map, MapError};

/// Junctions whose centre lies within this distance of the route's junction keep their
/// movements, m.
pub const RELEVANT_RADIUS_M: f64 = 60.0;

/// One movement through a junction, as a lane of the map.
pub(crate) struct Movement {
    pub id: String,
    /// The incoming and outgoing edge (SUMO) or road (OpenDRIVE): a route may name these.
    pub from: String,
    pub to: String,
    pub junction: String,
    pub turn: Turn,
    pub points: Vec<Vec2>,
    /// Arc length of the stop line (the incoming lane's end), m.
    pub stop_s: f64,
    pub width: f64,
}

/// The map of `movements` near `route` (a movement id or `"{from}>{to}"`, `forms` saying how
/// for the error), with junctions centred at `centre`. Straight movements come first, then
/// right and left turns (an agent without a turn signal matches the lowest index on a shared
/// approach); with a route, the route's movement is lane 0 and only the movements of junctions
/// within [`RELEVANT_RADIUS_M`] of its junction are kept. Returns the map, the route's lane and
/// which movement each lane is. `err` names the file.
pub(crate) fn assemble(
    movements: &[Movement],
    centre: impl Fn(&str) -> Option<Vec2>,
    route: Option<&str>,
    forms: &str,
    origin: &str,
) -> Result<(Map, Option<u8>, Vec<usize>), MapError> {
    let err = |msg: String| MapError(format!("map {origin}: {msg}"));
    let route_at = match route {
        None => None,
        Some(r) => Some(
            movements
                .iter()
                .position(|m| m.id == r)
                .or_else(|| {
                    let (from, to) = r.split_once('>')?;
                    movements.iter().position(|m| m.from == from && m.to == to)
                })
                .ok_or_else(|| {
                    err(format!(
                        "no movement {r:?}: give {forms}, e.g. {:?}",
                        movements[0].id
                    ))
                })?,
        ),
    };
    let rank = |m: &Movement| match m.turn {
        Turn::Straight => 0,
        Turn::Right => 1,
        Turn::Left => 2,
    };
    let mut order: Vec<usize> = (0..movements.len()).collect();
    order.sort_by_key(|&i| rank(&movements[i]));
    let keep: Vec<usize> = match route_at {
        None => order,
        Some(r) => {
            let here = centre(&movements[r].junction);
            let mut keep = vec![r];
            keep.extend(order.into_iter().filter(|&i| {
                i != r
                    && match (here, centre(&movements[i].junction)) {
                        (Some(a), Some(b)) => a.minus(b).norm() <= RELEVANT_RADIUS_M,
                        _ => false,
                    }
            }));
            keep
        }
    };
    if keep.len() > MAX_LANES {
        return Err(err(format!(
            "{} movements{}, more than the core's capacity MAX_LANES = {MAX_LANES}{}",
            keep.len(),
            if route.is_some() {
                format!(" within {RELEVANT_RADIUS_M} m of the route's junction")
            } else {
                String::new()
            },
            if route.is_some() {
                ""
            } else {
                " (give a route to keep only those near it)"
            }
        )));
    }
    let mut core_lanes = Vec::with_capacity(keep.len());
    for &i in &keep {
        let m = &movements[i];
        if m.points.len() > MAX_LANE_POINTS {
            return Err(err(format!(
                "movement {}: {} vertices, more than the core's capacity \
                 MAX_LANE_POINTS = {MAX_LANE_POINTS}",
                m.id,
                m.points.len()
            )));
        }
        let lane = Lane::new(&m.points, 0.5 * m.width, m.stop_s, m.turn)
            .map_err(|e| err(format!("movement {}: {e:?}", m.id)))?;
        core_lanes.push(lane);
    }
    let ids: Vec<String> = keep.iter().map(|&i| movements[i].id.clone()).collect();
    let name = origin.rsplit('/').next().unwrap_or(origin).to_string();
    let map = Map::from_lanes(
        name,
        ids,
        vec![Vec::new(); keep.len()],
        &core_lanes,
        Default::default(),
    )
    .map_err(|e| err(e.0))?;
    Ok((map, route_at.map(|_| 0), keep))
}

/// Each junction's centre as the mean of its movements' stop lines.
pub(crate) fn stop_line_centres(movements: &[Movement]) -> HashMap<String, Vec2> {
    let mut sums: HashMap<String, (Vec2, f64)> = HashMap::new();
    for m in movements {
        // A movement whose lane cannot be built is refused by `assemble`, with its reason.
        let Ok(lane) = Lane::new(&m.points, 0.5 * m.width, m.stop_s, m.turn) else {
            continue;
        };
        let e = sums
            .entry(m.junction.clone())
            .or_insert((Vec2::new(0.0, 0.0), 0.0));
        e.0 = e.0.plus(lane.pose_at(m.stop_s, 0).0);
        e.1 += 1.0;
    }
    sums.into_iter()
        .map(|(j, (p, n))| (j, p.scale(1.0 / n)))
        .collect()
}
