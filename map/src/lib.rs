//! Road maps for Concord: the lanes of a junction or merge in a small TOML format, loaded into
//! the core's [`Morphology`] (eq. 2: stop lines P_stop, half-widths R_lane, reference lines
//! L_ref), from which the core derives every conflict point, conflict zone and right of way.
//!
//! The format is documented with examples in `deploy/maps/README.md`. A map names a junction
//! rule and lists lanes; each lane is one movement through the junction (approach, turn,
//! exit) as a polyline, given either as `points` or as a `start` and a `path` of straight runs
//! and circular arcs, with its width, stop line, turn, right-of-way level and successors. The
//! lanes' order in the file is their index in the core (the wire's `ego_route_lane`).
//!
//! The built-in geometries are map files in `deploy/maps/`, compiled in ([`BuiltIn`]) and
//! loaded the same way as a user's file. Everything that exceeds a fixed capacity of the core
//! ([`MAX_LANES`], [`MAX_LANE_POINTS`], [`MAX_CONFLICTS`]) is an error naming the limit.
//!
//! Units: metres and degrees; coordinates are whatever frame the scene frames use.

use std::fmt;
use std::path::Path;

use concord_core::scene::{
    GeometryError, JunctionRule, Lane, Morphology, Route, Turn, Vec2, MAX_CONFLICTS, MAX_LANES,
    MAX_LANE_POINTS,
};
use serde::Deserialize;

mod movements;
pub mod opendrive;
pub mod sumo;

/// Default spacing of the vertices an arc is sampled at, m.
pub const DEFAULT_ARC_STEP_M: f64 = 1.0;
/// Widest lane a map may declare, m.
pub const MAX_LANE_WIDTH_M: f64 = 10.0;

/// Why a map could not be loaded; the message names the file, the lane and the field.
#[derive(Debug, Clone, PartialEq)]
pub struct MapError(pub String);

impl fmt::Display for MapError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for MapError {}

/// A loaded map: the core's morphology and the lanes' ids.
#[derive(Debug, Clone)]
pub struct Map {
    /// The map's `name`.
    pub name: String,
    ids: Vec<String>,
    successors: Vec<Vec<u8>>,
    morphology: Morphology,
}

impl Map {
    /// Reads and loads a map file: Concord's TOML format, a SUMO network (`*.net.xml`, see
    /// [`sumo`]) or an OpenDRIVE file (`*.xodr`, see [`opendrive`]).
    pub fn load(path: &Path) -> Result<Map, MapError> {
        Map::load_route(path, None).map(|(map, _)| map)
    }

    /// [`Map::load`], and the ego's `route`: a lane id; for a SUMO network or OpenDRIVE, a
    /// movement id or waypoints joined by `>` (edges or lanes, roads or lanes:
    /// `"{incoming edge}>{outgoing edge}"`, or through several junctions `"{a}>{b}>{c}"`),
    /// which also selects the movements that are kept.
    pub fn load_route(path: &Path, route: Option<&str>) -> Result<(Map, Option<Route>), MapError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| MapError(format!("cannot read map {}: {e}", path.display())))?;
        let origin = path.display().to_string();
        if origin.ends_with(".net.xml") {
            return sumo::parse(&text, &origin, route);
        }
        if origin.ends_with(".xodr") {
            return opendrive::parse(&text, &origin, route);
        }
        Map::parse(&text, &origin)?.with_route(route)
    }

    /// The map and the route of the one lane `route` names, if any.
    pub fn with_route(self, route: Option<&str>) -> Result<(Map, Option<Route>), MapError> {
        let lane = route.map(|id| self.lane_index(id)).transpose()?;
        Ok((self, lane.map(Route::single)))
    }

    /// A map of `lanes` with their ids and successors (indices), checked against the core's
    /// capacities.
    fn from_lanes(
        name: String,
        ids: Vec<String>,
        successors: Vec<Vec<u8>>,
        lanes: &[Lane],
        rule: JunctionRule,
    ) -> Result<Map, MapError> {
        if lanes.len() > MAX_LANES {
            return Err(MapError(format!(
                "{} lanes, more than the core's capacity MAX_LANES = {MAX_LANES}",
                lanes.len()
            )));
        }
        let morphology = Morphology::with_rule(lanes, rule).map_err(|e| {
            MapError(match e {
                GeometryError::TooManyConflicts => format!(
                    "the lanes cross or merge at more than the core's capacity \
                     MAX_CONFLICTS = {MAX_CONFLICTS} points"
                ),
                other => format!("{other:?}"),
            })
        })?;
        Ok(Map {
            name,
            ids,
            successors,
            morphology,
        })
    }

    /// Loads a map from its TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Map, MapError> {
        let file: MapFile =
            toml::from_str(text).map_err(|e| MapError(format!("map {origin}: {e}")))?;
        file.build(origin)
    }

    /// The morphology to give the core.
    pub fn morphology(&self) -> Morphology {
        self.morphology
    }

    /// Lane ids, in index order.
    pub fn ids(&self) -> &[String] {
        &self.ids
    }

    /// Index of the lane `id`.
    pub fn lane_index(&self, id: &str) -> Result<u8, MapError> {
        self.ids
            .iter()
            .position(|x| x == id)
            .map(|i| i as u8)
            .ok_or_else(|| {
                MapError(format!(
                    "map {}: no lane {id:?} (lanes: {})",
                    self.name,
                    self.ids.join(", ")
                ))
            })
    }

    /// Indices of the lanes that lane `index` leads into.
    pub fn successors(&self, index: u8) -> &[u8] {
        &self.successors[index as usize]
    }
}

/// The built-in geometries, shipped as map files in `deploy/maps/`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuiltIn {
    /// The paper's unsignalised intersection (§6.1): `deploy/maps/paper.toml`.
    PaperIntersection,
    /// A single-lane on-ramp merging into a main lane (§6, Fig. 7): `deploy/maps/merge.toml`.
    Merge,
    /// highway-env's `intersection-v0` in its own coordinates:
    /// `deploy/maps/highway-env-intersection.toml`.
    HighwayEnvIntersection,
    /// highway-env's `merge-v0` in its own coordinates: `deploy/maps/highway-env-merge.toml`.
    HighwayEnvMerge,
}

impl BuiltIn {
    /// Every built-in geometry.
    pub const ALL: [BuiltIn; 4] = [
        BuiltIn::PaperIntersection,
        BuiltIn::Merge,
        BuiltIn::HighwayEnvIntersection,
        BuiltIn::HighwayEnvMerge,
    ];

    /// The map file's path under `deploy/maps/` and its text.
    pub fn source(self) -> (&'static str, &'static str) {
        match self {
            BuiltIn::PaperIntersection => (
                "deploy/maps/paper.toml",
                include_str!("../../deploy/maps/paper.toml"),
            ),
            BuiltIn::Merge => (
                "deploy/maps/merge.toml",
                include_str!("../../deploy/maps/merge.toml"),
            ),
            BuiltIn::HighwayEnvIntersection => (
                "deploy/maps/highway-env-intersection.toml",
                include_str!("../../deploy/maps/highway-env-intersection.toml"),
            ),
            BuiltIn::HighwayEnvMerge => (
                "deploy/maps/highway-env-merge.toml",
                include_str!("../../deploy/maps/highway-env-merge.toml"),
            ),
        }
    }

    /// The loaded map (the shipped files are checked by this crate's tests).
    pub fn map(self) -> Map {
        let (origin, text) = self.source();
        Map::parse(text, origin).unwrap_or_else(|e| panic!("built-in map: {e}"))
    }

    /// The loaded map's morphology.
    pub fn morphology(self) -> Morphology {
        self.map().morphology()
    }
}

/// Lane indices of [`BuiltIn::PaperIntersection`] (`deploy/maps/paper.toml`, which describes
/// each lane and its priority level).
pub mod paper {
    /// Westbound from (40, 5), turning left to southbound: the CAV's route.
    pub const CAV_LEFT: u8 = 0;
    /// Eastbound straight from (−40, −5): the HDV's route.
    pub const HDV_STRAIGHT: u8 = 1;
    /// Westbound straight from (40, 5).
    pub const WEST_STRAIGHT: u8 = 2;
    /// Eastbound from (−40, −5), turning left to northbound.
    pub const EAST_LEFT: u8 = 3;
    /// Northbound straight from (5, −40).
    pub const NORTH_STRAIGHT: u8 = 4;
    /// Southbound straight from (−5, 40).
    pub const SOUTH_STRAIGHT: u8 = 5;
    /// Westbound from (40, 5), turning right to northbound.
    pub const WEST_RIGHT: u8 = 6;
    /// Eastbound from (−40, −5), turning right to southbound.
    pub const EAST_RIGHT: u8 = 7;
}

/// Lane indices of [`BuiltIn::Merge`] (`deploy/maps/merge.toml`).
pub mod merge {
    /// Main carriageway, eastbound along y = 0 from x = −150.
    pub const MAIN: u8 = 0;
    /// On-ramp from (−150, −12), joining the main lane at the origin: the CAV's route.
    pub const RAMP: u8 = 1;
}

/// Lane indices of [`BuiltIn::HighwayEnvIntersection`]
/// (`deploy/maps/highway-env-intersection.toml`).
pub mod highway_env_intersection {
    /// From the south, turning left to the west exit: the ego's route.
    pub const EGO_LEFT: u8 = 0;
}

/// Lane indices of [`BuiltIn::HighwayEnvMerge`] (`deploy/maps/highway-env-merge.toml`).
pub mod highway_env_merge {
    /// The right-hand lane of the main road: the ego's.
    pub const EGO_RIGHT: u8 = 0;
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    name: String,
    #[serde(default)]
    rule: RuleFile,
    #[serde(rename = "lane")]
    lanes: Vec<LaneFile>,
}

#[derive(Deserialize, Default, Clone, Copy)]
#[serde(rename_all = "snake_case")]
enum RuleFile {
    #[default]
    Levels,
    RightBeforeLeft,
}

#[derive(Deserialize, Default, Clone, Copy)]
#[serde(rename_all = "snake_case")]
enum TurnFile {
    #[default]
    Straight,
    Left,
    Right,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LaneFile {
    id: String,
    #[serde(default)]
    turn: TurnFile,
    #[serde(default)]
    priority: u8,
    width_m: f64,
    stop_s_m: Option<f64>,
    stop_at: Option<[f64; 2]>,
    points: Option<Vec<[f64; 2]>>,
    start: Option<[f64; 2]>,
    path: Option<Vec<Piece>>,
    #[serde(default)]
    successors: Vec<String>,
}

#[derive(Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
enum Piece {
    LineTo([f64; 2]),
    Arc(ArcFile),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ArcFile {
    centre: [f64; 2],
    sweep_deg: f64,
    step_m: Option<f64>,
}

fn v(p: [f64; 2]) -> Vec2 {
    Vec2::new(p[0], p[1])
}

impl MapFile {
    fn build(self, origin: &str) -> Result<Map, MapError> {
        let err = |msg: String| MapError(format!("map {origin}: {msg}"));
        if self.lanes.is_empty() {
            return Err(err("no [[lane]]".into()));
        }
        let ids: Vec<String> = self.lanes.iter().map(|l| l.id.clone()).collect();
        for (i, id) in ids.iter().enumerate() {
            if id.is_empty() || ids[..i].contains(id) {
                return Err(err(format!("lane {i}: id {id:?} is empty or repeated")));
            }
        }
        let mut lanes = Vec::with_capacity(self.lanes.len());
        let mut successors = Vec::with_capacity(self.lanes.len());
        for l in &self.lanes {
            let lane = l
                .build()
                .map_err(|msg| err(format!("lane {:?}: {msg}", l.id)))?;
            lanes.push(lane);
            let next = l
                .successors
                .iter()
                .map(|s| {
                    ids.iter()
                        .position(|x| x == s)
                        .map(|i| i as u8)
                        .ok_or_else(|| err(format!("lane {:?}: unknown successor {s:?}", l.id)))
                })
                .collect::<Result<Vec<u8>, MapError>>()?;
            successors.push(next);
        }
        let rule = match self.rule {
            RuleFile::Levels => JunctionRule::Levels,
            RuleFile::RightBeforeLeft => JunctionRule::RightBeforeLeft,
        };
        Map::from_lanes(self.name, ids, successors, &lanes, rule).map_err(|e| err(e.0))
    }
}

impl LaneFile {
    fn build(&self) -> Result<Lane, String> {
        if !(self.width_m.is_finite() && self.width_m > 0.0 && self.width_m <= MAX_LANE_WIDTH_M) {
            return Err(format!(
                "width_m = {}: expected more than 0 and at most {MAX_LANE_WIDTH_M} m",
                self.width_m
            ));
        }
        let points = match (&self.points, self.start, &self.path) {
            (Some(points), None, None) => points.iter().map(|p| v(*p)).collect(),
            (None, Some(start), Some(path)) => sample_path(start, path)?,
            _ => return Err("give either `points`, or `start` and `path`".into()),
        };
        if points.len() > MAX_LANE_POINTS {
            return Err(format!(
                "{} vertices, more than the core's capacity MAX_LANE_POINTS = {MAX_LANE_POINTS} \
                 (sample arcs with a larger step_m)",
                points.len()
            ));
        }
        let turn = match self.turn {
            TurnFile::Straight => Turn::Straight,
            TurnFile::Left => Turn::Left,
            TurnFile::Right => Turn::Right,
        };
        let why = |e: GeometryError| match e {
            GeometryError::TooFewPoints => "fewer than 2 vertices".to_string(),
            GeometryError::NotFinite => "a coordinate is not a finite number".to_string(),
            GeometryError::DuplicatePoint => "two successive vertices coincide".to_string(),
            other => format!("{other:?}"),
        };
        let lane = Lane::new(&points, 0.5 * self.width_m, 0.0, turn).map_err(why)?;
        let stop_s = match (self.stop_s_m, self.stop_at) {
            (Some(s), None) => s,
            (None, Some(p)) if p.iter().all(|x| x.is_finite()) => lane.project(v(p)).s,
            (None, None) => return Err("give its stop line as `stop_s_m` or `stop_at`".into()),
            _ => return Err("give `stop_s_m` or a finite `stop_at`, not both".into()),
        };
        if !(stop_s.is_finite() && (0.0..=lane.length()).contains(&stop_s)) {
            return Err(format!(
                "stop line at s = {stop_s} m: expected 0 to the lane's length {:.1} m",
                lane.length()
            ));
        }
        Lane::new(&points, 0.5 * self.width_m, stop_s, turn)
            .map(|l| l.with_priority(self.priority))
            .map_err(why)
    }
}

/// Vertices of a `start` and `path`: arcs go through the core's [`Lane::builder`], which
/// samples them at most `step_m` apart.
fn sample_path(start: [f64; 2], path: &[Piece]) -> Result<Vec<Vec2>, String> {
    let mut b = Lane::builder(v(start));
    for piece in path {
        b = match piece {
            Piece::LineTo(p) => b.line_to(v(*p)),
            Piece::Arc(a) => {
                let step = a.step_m.unwrap_or(DEFAULT_ARC_STEP_M);
                if !(a.sweep_deg.is_finite() && a.sweep_deg != 0.0 && a.sweep_deg.abs() <= 360.0) {
                    return Err(format!(
                        "arc sweep_deg = {}: expected a non-zero angle within ±360°",
                        a.sweep_deg
                    ));
                }
                if !(step.is_finite() && step > 0.0) {
                    return Err(format!("arc step_m = {step}: expected more than 0 m"));
                }
                b.arc(v(a.centre), a.sweep_deg.to_radians(), step)
            }
        };
    }
    if b.overflowed() {
        return Err(format!(
            "more vertices than the core's capacity MAX_LANE_POINTS = {MAX_LANE_POINTS} \
             (sample arcs with a larger step_m)"
        ));
    }
    Ok(b.points().to_vec())
}
