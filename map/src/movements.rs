//! What the SUMO and OpenDRIVE loaders share: movements through junctions (incoming lane,
//! the lanes through the junction, outgoing lane), the route among them (one or more
//! movements, joined into one lane per junction: its legs), the ones kept near it, the loader's
//! right of way, and the map built from those.

use std::collections::HashMap;

use concord_core::scene::{
    GeometryError, Lane, RightOfWay, Route, Turn, Vec2, MAX_LANES, MAX_LANE_POINTS, MAX_ROUTE_LEGS,
};

use crate::{Map, MapError};

/// Junctions whose centre lies within this distance of a junction of the route keep their
/// movements, m.
pub const RELEVANT_RADIUS_M: f64 = 60.0;

/// One movement through a junction, as a lane of the map.
pub(crate) struct Movement {
    pub id: String,
    /// The incoming and outgoing edge (SUMO) or road (OpenDRIVE): a route may name these.
    pub from: String,
    pub to: String,
    /// The incoming and outgoing lane: a route may name these, and a route continues from a
    /// movement into one whose incoming lane is its outgoing lane.
    pub from_lane: String,
    pub to_lane: String,
    pub junction: String,
    pub turn: Turn,
    pub points: Vec<Vec2>,
    /// Arc length of the stop line (the incoming lane's end), m.
    pub stop_s: f64,
    /// Where the outgoing lane begins (the movement has left the junction).
    pub exit: Vec2,
    pub width: f64,
}

/// What each loader says about the right of way between two movements of one junction:
/// `Some(RightOfWay::A)` when the first goes first; `None` leaves the core's rule.
pub(crate) type RightOfWayRule<'a> = &'a dyn Fn(usize, usize) -> Option<RightOfWay>;

/// The chain of movements `route` names: one movement id, or waypoints joined by `>`, each an
/// incoming or outgoing edge (road) or lane; between two waypoints the route takes the fewest
/// movements, each continuing from the previous one's outgoing lane.
fn resolve(movements: &[Movement], route: &str) -> Option<Vec<usize>> {
    if let Some(i) = movements.iter().position(|m| m.id == route) {
        return Some(vec![i]);
    }
    let points: Vec<&str> = route.split('>').map(str::trim).collect();
    if points.len() < 2 || points.iter().any(|p| p.is_empty()) {
        return None;
    }
    let starts = |m: &Movement, w: &str| m.from == w || m.from_lane == w;
    let ends = |m: &Movement, w: &str| m.to == w || m.to_lane == w;
    let mut chain: Vec<usize> = Vec::new();
    for pair in points.windows(2) {
        let (from, to) = (pair[0], pair[1]);
        // Breadth first from the movements leaving `from` (after the chain so far's last
        // movement, from its outgoing lane), in index order.
        let first: Vec<usize> = (0..movements.len())
            .filter(|&i| match chain.last() {
                Some(&last) => movements[i].from_lane == movements[last].to_lane,
                None => starts(&movements[i], from),
            })
            .collect();
        let mut came_from: HashMap<usize, Option<usize>> =
            first.iter().map(|&i| (i, None)).collect();
        let mut frontier = first;
        let mut found = None;
        while found.is_none() && !frontier.is_empty() {
            found = frontier.iter().copied().find(|&i| ends(&movements[i], to));
            let mut next = Vec::new();
            for &i in &frontier {
                for j in 0..movements.len() {
                    if movements[j].from_lane == movements[i].to_lane && !came_from.contains_key(&j)
                    {
                        came_from.insert(j, Some(i));
                        next.push(j);
                    }
                }
            }
            frontier = next;
        }
        let mut piece = vec![found?];
        while let Some(&Some(prev)) = came_from.get(piece.last().unwrap()) {
            piece.push(prev);
        }
        piece.reverse();
        chain.extend(piece);
    }
    Some(chain)
}

/// The polyline of a route from `chain[0]` on: each movement up to where its outgoing lane
/// begins, then the next movement (which begins there), and the last one whole.
fn join(movements: &[Movement], chain: &[usize]) -> Result<Vec<Vec2>, GeometryError> {
    let mut points = Vec::new();
    for (k, &i) in chain.iter().enumerate() {
        let m = &movements[i];
        if k + 1 == chain.len() {
            points.extend_from_slice(&m.points);
            break;
        }
        let lane = Lane::new(&m.points, 0.5 * m.width, m.stop_s, m.turn)?;
        let exit_s = lane.project(m.exit).s;
        points.extend(
            m.points
                .iter()
                .enumerate()
                .take_while(|&(j, _)| lane.s_at_vertex(j) < exit_s - SAME_POINT_M)
                .map(|(_, p)| *p),
        );
    }
    Ok(points)
}

/// Two points closer than this are one, m.
const SAME_POINT_M: f64 = 0.05;

/// The map of `movements` near `route` (a movement id, or waypoints joined by `>`: see
/// [`resolve`]; `forms` says which for the error), with junctions centred at `centre` and
/// SUMO's or OpenDRIVE's right of way `row` between two movements of one junction.
///
/// Without a route every movement is a lane: straight movements first, then right and left
/// turns (an agent without a turn signal matches the lowest index on a shared approach). With
/// one, the route's legs come first ([`Route`]: one lane per junction of the route, the rest
/// of the route from that junction's approach on), then the other movements of every junction
/// within [`RELEVANT_RADIUS_M`] of a junction of the route, in the same order. Each leg hands
/// over to the next once the ego has cleared every conflict zone of its lane that begins
/// before the leg's junction exit. `origin` names the file in errors.
pub(crate) fn assemble(
    movements: &[Movement],
    centre: impl Fn(&str) -> Option<Vec2>,
    route: Option<&str>,
    forms: &str,
    origin: &str,
    row: RightOfWayRule<'_>,
) -> Result<(Map, Option<Route>), MapError> {
    let err = |msg: String| MapError(format!("map {origin}: {msg}"));
    let chain = match route {
        None => Vec::new(),
        Some(r) => resolve(movements, r).ok_or_else(|| {
            err(format!(
                "no route {r:?} through the map's junctions: give {forms}, or waypoints joined \
                 by '>' (e.g. {:?})",
                movements[0].id
            ))
        })?,
    };
    if chain.len() > MAX_ROUTE_LEGS {
        return Err(err(format!(
            "route {:?} passes {} junctions, more than the core's capacity \
             MAX_ROUTE_LEGS = {MAX_ROUTE_LEGS}",
            route.unwrap_or_default(),
            chain.len()
        )));
    }
    let rank = |m: &Movement| match m.turn {
        Turn::Straight => 0,
        Turn::Right => 1,
        Turn::Left => 2,
    };
    let mut order: Vec<usize> = (0..movements.len()).collect();
    order.sort_by_key(|&i| rank(&movements[i]));
    let here: Vec<Vec2> = chain
        .iter()
        .filter_map(|&i| centre(&movements[i].junction))
        .collect();
    let others: Vec<usize> = order
        .into_iter()
        .filter(|i| !chain.contains(i))
        .filter(|&i| {
            route.is_none()
                || centre(&movements[i].junction)
                    .is_some_and(|c| here.iter().any(|h| h.minus(c).norm() <= RELEVANT_RADIUS_M))
        })
        .collect();
    // Each lane: the movements it runs through.
    let lanes: Vec<Vec<usize>> = (0..chain.len())
        .map(|k| chain[k..].to_vec())
        .chain(others.iter().map(|&i| vec![i]))
        .collect();
    if lanes.len() > MAX_LANES {
        return Err(err(format!(
            "{} movements{}, more than the core's capacity MAX_LANES = {MAX_LANES}{}",
            lanes.len(),
            if route.is_some() {
                format!(" within {RELEVANT_RADIUS_M} m of the route's junctions")
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
    let mut core_lanes = Vec::with_capacity(lanes.len());
    let mut ids = Vec::with_capacity(lanes.len());
    for through in &lanes {
        let m = &movements[through[0]];
        let id = if through.len() == 1 {
            m.id.clone()
        } else {
            through.iter().fold(m.from_lane.clone(), |id, &i| {
                format!("{id}>{}", movements[i].to_lane)
            })
        };
        let points = join(movements, through).map_err(|e| err(format!("movement {id}: {e:?}")))?;
        if points.len() > MAX_LANE_POINTS {
            return Err(err(format!(
                "{} {id}: {} vertices, more than the core's capacity \
                 MAX_LANE_POINTS = {MAX_LANE_POINTS}",
                if through.len() == 1 {
                    "movement"
                } else {
                    "route"
                },
                points.len()
            )));
        }
        let lane = Lane::new(&points, 0.5 * m.width, m.stop_s, m.turn)
            .map_err(|e| err(format!("movement {id}: {e:?}")))?;
        core_lanes.push(lane);
        ids.push(id);
    }
    let name = origin.rsplit('/').next().unwrap_or(origin).to_string();
    let mut map = Map::from_lanes(
        name,
        ids,
        vec![Vec::new(); lanes.len()],
        &core_lanes,
        Default::default(),
    )
    .map_err(|e| err(e.0))?;
    // The loader's right of way, between lanes through a common junction.
    for a in 0..lanes.len() {
        for b in a + 1..lanes.len() {
            let common = lanes[a].iter().find_map(|&ma| {
                lanes[b]
                    .iter()
                    .find(|&&mb| movements[ma].junction == movements[mb].junction)
                    .map(|&mb| (ma, mb))
            });
            if let Some(r) = common.and_then(|(ma, mb)| row(ma, mb)) {
                map.morphology.set_right_of_way(a as u8, b as u8, r);
            }
        }
    }
    let route = (!chain.is_empty()).then(|| {
        let morph = map.morphology();
        let legs: Vec<(u8, f64)> = (0..chain.len())
            .map(|k| {
                let lane = k as u8;
                let exit = morph.lane(lane).project(movements[chain[k]].exit).s;
                let cleared = morph
                    .zones_on(lane)
                    .filter(|z| z[0] < exit)
                    .fold(exit, |c, z| c.max(z[1]));
                (lane, cleared)
            })
            .collect();
        Route::new(&legs).expect("legs checked against MAX_ROUTE_LEGS")
    });
    Ok((map, route))
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
