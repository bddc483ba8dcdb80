//! Episodes, the experiment grids (the paper's, the sweep, the interaction scenarios), a
//! parallel deterministic runner, CSV output and the summary tables.
//!
//! An episode runs at 20 Hz until the CAV is 15 m past the conflict zone and every HDV has
//! left its zone, a collision, or [`TIME_LIMIT_S`]. Every episode is seeded by its own spec
//! (the first HDV's driver by the episode's seed, each follower's by the seed and its place),
//! so results do not depend on the number of threads or their timing; every random draw of a
//! grid (offsets, counts, headways, styles) and of a driver (noise, compliance, patience)
//! follows from the grid's `seed`.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use concord_core::Params;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::controllers::{
    AdviceSource, Advisor, ConcordController, Controller, ExternalAdvice, GapAcceptance, IdmYield,
    Stackelberg, Timing,
};
use crate::driver::{DriverParams, DriverStyle, HumanDriver};
use crate::metrics::{self, HdvSample, Layout, Metrics, Sample};
use crate::world::{ScenarioKind, World, CAR_LENGTH_M};

/// Longest episode, s.
pub const TIME_LIMIT_S: f64 = 40.0;

/// The CAV controllers compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ControllerKind {
    Idm,
    GameTheoretic,
    GapAcceptance,
    ConcordLogit,
    ConcordOracle,
    /// Concord advised by an LLM, simulated time waiting for each answer.
    ConcordLlmWait,
    /// Concord advised by an LLM, each answer landing after its measured latency.
    ConcordLlmLatency,
}

impl ControllerKind {
    /// Every controller, the LLM ones last.
    pub const EVERY: [ControllerKind; 7] = [
        ControllerKind::Idm,
        ControllerKind::GameTheoretic,
        ControllerKind::GapAcceptance,
        ControllerKind::ConcordLogit,
        ControllerKind::ConcordOracle,
        ControllerKind::ConcordLlmWait,
        ControllerKind::ConcordLlmLatency,
    ];
    /// The paper's controllers (and the sweep's).
    pub const PAPER: [ControllerKind; 4] = [
        ControllerKind::Idm,
        ControllerKind::GameTheoretic,
        ControllerKind::ConcordLogit,
        ControllerKind::ConcordOracle,
    ];
    /// The interaction experiment's controllers.
    pub const INTERACTION: [ControllerKind; 5] = [
        ControllerKind::Idm,
        ControllerKind::GameTheoretic,
        ControllerKind::GapAcceptance,
        ControllerKind::ConcordLogit,
        ControllerKind::ConcordOracle,
    ];
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Idm => "idm",
            ControllerKind::GameTheoretic => "game_theoretic",
            ControllerKind::GapAcceptance => "gap_acceptance",
            ControllerKind::ConcordLogit => "concord_logit",
            ControllerKind::ConcordOracle => "concord_oracle",
            ControllerKind::ConcordLlmWait => "concord_llm_wait",
            ControllerKind::ConcordLlmLatency => "concord_llm_latency",
        }
    }
}

/// An HDV behind the first one on its lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Follower {
    pub style: DriverStyle,
    /// Time headway behind the car ahead at the initial speed, front to front, s.
    pub headway_s: f64,
}

/// One episode's specification.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    pub scenario: ScenarioKind,
    pub controller: ControllerKind,
    /// Initial speed of every vehicle, m/s.
    pub speed: f64,
    /// The first HDV's driver style.
    pub style: DriverStyle,
    /// The first HDV's start shifted along its lane, m.
    pub hdv_offset_m: f64,
    /// The HDVs behind the first (the stream's), in order.
    pub followers: Vec<Follower>,
    pub seed: u64,
    pub rep: u32,
}

impl Episode {
    /// Every HDV's driver style, the first one first.
    pub fn styles(&self) -> impl Iterator<Item = DriverStyle> + '_ {
        std::iter::once(self.style).chain(self.followers.iter().map(|f| f.style))
    }

    /// The seed of HDV `i`'s driver: the episode's for the first.
    pub fn driver_seed(&self, i: usize) -> u64 {
        self.seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }
}

/// What an episode produced.
#[derive(Clone, Debug)]
pub struct Outcome {
    pub episode: Episode,
    pub metrics: Metrics,
    pub samples: Vec<Sample>,
    /// Concord's decisions by source (logit, advice, minimum risk).
    pub sources: [u64; 3],
}

/// Runs one episode with the core's `params` (the LLM kinds need [`run_episode_with`]).
pub fn run_episode(e: &Episode, params: &Params) -> Outcome {
    run_episode_with(e, params, None)
}

/// How often an external advisor is asked, s of simulated time.
pub const ADVICE_PERIOD_S: f64 = 1.0;

/// Runs one episode; the LLM kinds take their advice from `source`.
pub fn run_episode_with(
    e: &Episode,
    params: &Params,
    source: Option<&mut dyn AdviceSource>,
) -> Outcome {
    let headways: Vec<f64> = e.followers.iter().map(|f| f.headway_s).collect();
    let mut w = World::with_followers(e.scenario, e.speed, e.hdv_offset_m, &headways);
    let mut drivers: Vec<HumanDriver> = e
        .styles()
        .enumerate()
        .map(|(i, style)| HumanDriver::new(style, e.speed, e.driver_seed(i)))
        .collect();
    let mut concord = match e.controller {
        ControllerKind::ConcordLogit => Some(ConcordController::new(*params, &w, Advisor::None)),
        ControllerKind::ConcordOracle => Some(ConcordController::new(*params, &w, Advisor::Oracle)),
        _ => None,
    };
    let timing = match e.controller {
        ControllerKind::ConcordLlmLatency => Timing::Latency,
        _ => Timing::Wait,
    };
    let mut external = source.map(|s| ExternalAdvice::new(*params, &w, s, timing, ADVICE_PERIOD_S));
    let mut idm = IdmYield::new(e.speed);
    let mut gt = Stackelberg::default();
    let mut gap = GapAcceptance::new(e.speed);
    let mut samples = Vec::with_capacity((TIME_LIMIT_S / crate::world::DT) as usize + 1);
    let mut accels = vec![0.0; drivers.len()];
    loop {
        let collided = w.collided();
        let done = w.ego_past_zones(15.0)
            && (0..w.hdvs.len()).all(|i| w.to_conflict(i).1 < -w.hdvs[i].zone_half_m);
        let stop = collided || done || w.t >= TIME_LIMIT_S;
        let (pos, heading) = w.pose(&w.ego);
        let mut sample = Sample {
            t: w.t,
            ego_v: w.ego.v,
            ego_a: w.ego.a,
            ego_pos: pos,
            ego_heading: heading,
            collided,
            ehmi: None,
            hdvs: (0..w.hdvs.len())
                .map(|i| {
                    let (ego_d, d) = w.to_conflict(i);
                    HdvSample {
                        ego_d,
                        d,
                        v: w.hdvs[i].car.v,
                        imposed_mps2: 0.0,
                    }
                })
                .collect(),
        };
        if stop {
            samples.push(sample);
            break;
        }
        let controller: &mut dyn Controller = match (e.controller, concord.as_mut()) {
            (ControllerKind::Idm, _) => &mut idm,
            (ControllerKind::GameTheoretic, _) => &mut gt,
            (ControllerKind::GapAcceptance, _) => &mut gap,
            (ControllerKind::ConcordLogit | ControllerKind::ConcordOracle, Some(c)) => c,
            _ => match external.as_mut() {
                Some(x) => x,
                None => panic!("{} needs an advice source", e.controller.name()),
            },
        };
        let cmd = controller.act(&w, &drivers);
        sample.ehmi = cmd.ehmi;
        for (i, d) in drivers.iter_mut().enumerate() {
            let r = d.act(&w, i, cmd.ehmi);
            accels[i] = r.accel;
            sample.hdvs[i].imposed_mps2 = r.imposed_mps2;
        }
        samples.push(sample);
        w.step(cmd.accel, &accels);
    }
    Outcome {
        metrics: metrics::compute(&samples, &layout(&w, params)),
        episode: e.clone(),
        samples,
        sources: concord
            .map(|c| c.sources)
            .or(external.map(|x| x.sources()))
            .unwrap_or([0; 3]),
    }
}

/// What the metrics need of `w`.
fn layout(w: &World, params: &Params) -> Layout {
    let mut lanes: Vec<u8> = w.hdvs.iter().map(|h| h.car.lane).collect();
    lanes.sort_unstable();
    lanes.dedup();
    Layout {
        delta_ttc_s: params.opm.delta_ttc_threshold_s,
        zone_half_m: w.hdvs.iter().map(|h| h.zone_half_m).collect(),
        pass_half_m: w
            .hdvs
            .iter()
            .map(|h| {
                if w.kind == ScenarioKind::Merge {
                    0.5 * crate::world::CAR_LENGTH_M
                } else {
                    h.zone_half_m
                }
            })
            .collect(),
        crossing_lanes: lanes.into_iter().map(|l| *w.morph.lane(l)).collect(),
        junction: w.junction(),
    }
}

/// The seed of one repetition of a grid cell.
fn cell_seed(seed: u64, rep: u32, speed: f64, scenario: ScenarioKind) -> u64 {
    seed.wrapping_mul(1_000_003)
        .wrapping_add(rep as u64 * 7919 + (speed as u64) * 31 + scenario as u64)
}

/// The paper's grid (Fig. 4, Fig. 7b): both scenarios × initial speeds 6, 8, 10 m/s × `reps`
/// repetitions × every controller, with a balanced human driver whose start varies by up to
/// ±5 m and whose noise is seeded per repetition (the same for every controller).
pub fn paper_grid(reps: u32, seed: u64) -> Vec<Episode> {
    let mut out = Vec::new();
    for scenario in [ScenarioKind::LeftTurn, ScenarioKind::Merge] {
        for speed in [6.0, 8.0, 10.0] {
            for rep in 0..reps {
                let s = cell_seed(seed, rep, speed, scenario);
                let mut rng = SmallRng::seed_from_u64(s);
                let offset = rng.random_range(-5.0..5.0);
                for controller in ControllerKind::PAPER {
                    out.push(Episode {
                        scenario,
                        controller,
                        speed,
                        style: DriverStyle::Balanced,
                        hdv_offset_m: offset,
                        followers: Vec::new(),
                        seed: s,
                        rep,
                    });
                }
            }
        }
    }
    out
}

/// A sweep of `n` random left turns per controller: styles (all four), initial speeds
/// (5–11 m/s) and HDV starts (±15 m) drawn from `seed`.
pub fn sweep_grid(n: u32, seed: u64) -> Vec<Episode> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut out = Vec::new();
    for rep in 0..n {
        let style = DriverStyle::ALL[rng.random_range(0..DriverStyle::ALL.len())];
        let speed = rng.random_range(5.0..11.0);
        let offset = rng.random_range(-15.0..15.0);
        let s = rng.random::<u64>();
        for controller in ControllerKind::PAPER {
            out.push(Episode {
                scenario: ScenarioKind::LeftTurn,
                controller,
                speed,
                style,
                hdv_offset_m: offset,
                followers: Vec::new(),
                seed: s,
                rep,
            });
        }
    }
    out
}

/// Cars in a stream, fewest and most.
pub const STREAM_CARS: (usize, usize) = (2, 6);
/// Time headways drawn between the cars of a stream, s (front to front, at the initial
/// speed): from a dense 1.5 s to 5 s, around the HCM's 4.1 s critical gap, so some gaps
/// suffice for a left turn and others do not.
pub const STREAM_HEADWAY_S: (f64, f64) = (1.5, 5.0);

/// The cars behind the first of a stream at `speed`: 1 to 5 followers (2–6 cars), each of a
/// style drawn among aggressive, balanced and conservative, at a headway drawn from
/// [`STREAM_HEADWAY_S`] but never closer than the follower's desired IDM gap at `speed`
/// (s0 + vT, plus a car length), so that no one brakes at the start.
pub fn stream_followers(rng: &mut SmallRng, speed: f64) -> Vec<Follower> {
    let cars = rng.random_range(STREAM_CARS.0..=STREAM_CARS.1);
    (1..cars)
        .map(|_| {
            let style = DriverStyle::DECISIVE[rng.random_range(0..DriverStyle::DECISIVE.len())];
            let drawn = rng.random_range(STREAM_HEADWAY_S.0..STREAM_HEADWAY_S.1);
            let p = DriverParams::of(style);
            let desired = (p.s0_m + speed * p.headway_s + CAR_LENGTH_M) / speed.max(0.1);
            Follower {
                style,
                headway_s: drawn.max(desired),
            }
        })
        .collect()
}

/// The interaction grid: the left turn with a hesitant driver, the left turn with the right
/// of way (a balanced driver on the minor road) and the left turn across a stream (2–6 cars of
/// random styles, [`stream_followers`]), each at 6, 8 and 10 m/s × `reps` repetitions × the
/// [`ControllerKind::INTERACTION`] controllers; the first HDV's start varies by ±5 m. A
/// repetition's draws are the same for every controller.
pub fn interaction_grid(reps: u32, seed: u64) -> Vec<Episode> {
    let mut out = Vec::new();
    for scenario in [
        ScenarioKind::LeftTurn,
        ScenarioKind::LeftTurnPriority,
        ScenarioKind::Stream,
    ] {
        for speed in [6.0, 8.0, 10.0] {
            for rep in 0..reps {
                let s = cell_seed(seed, rep, speed, scenario);
                let mut rng = SmallRng::seed_from_u64(s);
                let offset = rng.random_range(-5.0..5.0);
                let (style, followers) = match scenario {
                    ScenarioKind::LeftTurn => (DriverStyle::Hesitant, Vec::new()),
                    ScenarioKind::LeftTurnPriority => (DriverStyle::Balanced, Vec::new()),
                    _ => (
                        DriverStyle::DECISIVE[rng.random_range(0..DriverStyle::DECISIVE.len())],
                        stream_followers(&mut rng, speed),
                    ),
                };
                for controller in ControllerKind::INTERACTION {
                    out.push(Episode {
                        scenario,
                        controller,
                        speed,
                        style,
                        hdv_offset_m: offset,
                        followers: followers.clone(),
                        seed: s,
                        rep,
                    });
                }
            }
        }
    }
    out
}

/// Runs `episodes` on `threads` threads, calling `progress(done, total)` after each; the
/// outcomes come back in the order of `episodes`.
pub fn run_all(
    episodes: &[Episode],
    params: &Params,
    threads: usize,
    progress: impl Fn(usize, usize) + Sync,
) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; episodes.len()]);
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(e) = episodes.get(i) else { break };
                let o = run_episode(e, params);
                results.lock().expect("results lock")[i] = Some(o);
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, episodes.len());
            });
        }
    });
    results
        .into_inner()
        .expect("results lock")
        .into_iter()
        .map(|o| o.expect("every episode ran"))
        .collect()
}

/// Mean and half-width of the 95 % confidence interval (Student's t) of `xs`; infinite values
/// are left out.
pub fn mean_ci(xs: &[f64]) -> (f64, f64, usize) {
    let v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    let n = v.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, 0);
    }
    let mean = v.iter().sum::<f64>() / n as f64;
    if n < 2 {
        return (mean, f64::NAN, n);
    }
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let t = t975(n - 1);
    (mean, t * (var / n as f64).sqrt(), n)
}

/// Student's t quantile 0.975 for `df` degrees of freedom: tabulated to 30, then the
/// Cornish–Fisher expansion around z = 1.96 (error below 0.001 there).
fn t975(df: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    if (1..=30).contains(&df) {
        return TABLE[df - 1];
    }
    let (z, d) = (1.959_964_f64, df as f64);
    z + (z.powi(3) + z) / (4.0 * d)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * d * d)
}

/// Metric columns: name and value (booleans as 0 or 1).
pub fn columns(m: &Metrics) -> [(&'static str, f64); 15] {
    [
        ("avg_speed_mps", m.avg_speed_mps),
        ("avg_abs_jerk_mps3", m.avg_abs_jerk_mps3),
        ("conflict_duration_s", m.conflict_duration_s),
        ("min_ttc_s", m.min_ttc_s),
        ("pet_s", m.pet_s),
        ("collision", f64::from(m.collision as u8)),
        ("success", f64::from(m.success as u8)),
        ("time_to_clear_s", m.time_to_clear_s),
        ("imposed_decel_mps2", m.imposed_decel_mps2),
        ("standing_s", m.standing_s),
        ("stood_in_crossing", f64::from(m.stood_in_crossing as u8)),
        ("wait_while_other_stands_s", m.wait_while_other_stands_s),
        (
            "wait_while_other_stands_total_s",
            m.wait_while_other_stands_total_s,
        ),
        ("ehmi_changes", f64::from(m.ehmi_changes)),
        ("imposed_at_start_mps2", m.imposed_at_start_mps2),
    ]
}

/// One metric over a group of episodes; infinite values are left out (NaN when none is
/// finite).
#[derive(Clone, Debug, PartialEq)]
pub struct Stat {
    pub name: &'static str,
    pub mean: f64,
    /// Half-width of the 95 % confidence interval of the mean.
    pub ci95: f64,
    /// Finite values.
    pub n: usize,
    pub min: f64,
    pub median: f64,
    pub max: f64,
}

impl Stat {
    fn of(name: &'static str, xs: &[f64]) -> Stat {
        let (mean, ci95, n) = mean_ci(xs);
        let mut v: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(f64::total_cmp);
        let median = match v.len() {
            0 => f64::NAN,
            k if k % 2 == 1 => v[k / 2],
            k => 0.5 * (v[k / 2 - 1] + v[k / 2]),
        };
        Stat {
            name,
            mean,
            ci95,
            n,
            min: v.first().copied().unwrap_or(f64::NAN),
            median,
            max: v.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// One summary row: (scenario, controller, speed) with the statistics of every metric.
#[derive(Clone, Debug)]
pub struct SummaryRow {
    pub scenario: ScenarioKind,
    pub controller: ControllerKind,
    pub speed: f64,
    pub n: usize,
    /// Per metric of [`columns`].
    pub stats: Vec<Stat>,
}

impl SummaryRow {
    /// Mean and CI half-width of `metric` (NaN when unknown).
    pub fn get(&self, metric: &str) -> (f64, f64) {
        self.stat(metric)
            .map_or((f64::NAN, f64::NAN), |s| (s.mean, s.ci95))
    }

    pub fn stat(&self, metric: &str) -> Option<&Stat> {
        self.stats.iter().find(|s| s.name == metric)
    }
}

/// Groups outcomes by scenario, controller and speed (speeds rounded to 1 m/s).
pub fn summarize(outcomes: &[Outcome]) -> Vec<SummaryRow> {
    let mut keys: Vec<(ScenarioKind, ControllerKind, i64)> = outcomes
        .iter()
        .map(|o| {
            (
                o.episode.scenario,
                o.episode.controller,
                o.episode.speed.round() as i64,
            )
        })
        .collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .map(|(scenario, controller, speed)| {
            let group: Vec<&Outcome> = outcomes
                .iter()
                .filter(|o| {
                    o.episode.scenario == scenario
                        && o.episode.controller == controller
                        && o.episode.speed.round() as i64 == speed
                })
                .collect();
            let names = columns(&group[0].metrics).map(|c| c.0);
            let stats = names
                .iter()
                .enumerate()
                .map(|(i, name)| {
                    let xs: Vec<f64> = group.iter().map(|o| columns(&o.metrics)[i].1).collect();
                    Stat::of(name, &xs)
                })
                .collect();
            SummaryRow {
                scenario,
                controller,
                speed: speed as f64,
                n: group.len(),
                stats,
            }
        })
        .collect()
}

/// Writes `episodes.csv` (one row per episode), `summary.csv` (mean, 95 % CI, count, min,
/// median and max per group and metric) and `traces/<scenario>_<controller>_<speed>_<rep>.csv`
/// (each episode's states, per HDV) under `dir`.
pub fn write_csv(dir: &Path, outcomes: &[Outcome], rows: &[SummaryRow]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir.join("traces"))?;
    let mut ep =
        String::from("scenario,controller,speed_mps,style,hdvs,headways_s,hdv_offset_m,seed,rep");
    for (name, _) in columns(&outcomes[0].metrics) {
        let _ = write!(ep, ",{name}");
    }
    ep.push_str(",decisions_logit,decisions_advice,decisions_minimum_risk\n");
    for o in outcomes {
        let e = &o.episode;
        let styles: Vec<&str> = e.styles().map(DriverStyle::name).collect();
        let headways: Vec<String> = e
            .followers
            .iter()
            .map(|f| format!("{:.2}", f.headway_s))
            .collect();
        let _ = write!(
            ep,
            "{},{},{:.3},{},{},{},{:.3},{},{}",
            e.scenario.name(),
            e.controller.name(),
            e.speed,
            styles.join("+"),
            styles.len(),
            headways.join("+"),
            e.hdv_offset_m,
            e.seed,
            e.rep
        );
        for (_, v) in columns(&o.metrics) {
            let _ = write!(ep, ",{v:.4}");
        }
        let _ = writeln!(ep, ",{},{},{}", o.sources[0], o.sources[1], o.sources[2]);
        let mut trace = String::from("t_s,ego_x_m,ego_y_m,ego_speed_mps,ego_accel_mps2,collided");
        for k in 1..=styles.len() {
            let _ = write!(
                trace,
                ",ego_to_conflict{k}_m,hdv{k}_to_conflict_m,hdv{k}_speed_mps,hdv{k}_imposed_decel_mps2"
            );
        }
        trace.push('\n');
        for s in &o.samples {
            let _ = write!(
                trace,
                "{:.2},{:.3},{:.3},{:.3},{:.3},{}",
                s.t, s.ego_pos.x, s.ego_pos.y, s.ego_v, s.ego_a, s.collided as u8
            );
            for h in &s.hdvs {
                let _ = write!(
                    trace,
                    ",{:.3},{:.3},{:.3},{:.3}",
                    h.ego_d, h.d, h.v, h.imposed_mps2
                );
            }
            trace.push('\n');
        }
        let name = format!(
            "{}_{}_{:.0}_{}.csv",
            e.scenario.name(),
            e.controller.name(),
            e.speed,
            e.rep
        );
        std::fs::write(dir.join("traces").join(name), trace)?;
    }
    std::fs::write(dir.join("episodes.csv"), ep)?;
    let mut f = std::fs::File::create(dir.join("summary.csv"))?;
    let mut head = String::from("scenario,controller,speed_mps,n");
    for s in &rows[0].stats {
        let name = s.name;
        let _ = write!(
            head,
            ",{name}_mean,{name}_ci95,{name}_n,{name}_min,{name}_median,{name}_max"
        );
    }
    writeln!(f, "{head}")?;
    for r in rows {
        let mut line = format!(
            "{},{},{:.0},{}",
            r.scenario.name(),
            r.controller.name(),
            r.speed,
            r.n
        );
        for s in &r.stats {
            let _ = write!(
                line,
                ",{:.4},{:.4},{},{:.4},{:.4},{:.4}",
                s.mean, s.ci95, s.n, s.min, s.median, s.max
            );
        }
        writeln!(f, "{line}")?;
    }
    Ok(())
}

/// A mean with its CI half-width ("∞" when every value was infinite).
fn mean_cell((m, ci): (f64, f64)) -> String {
    if m.is_nan() {
        "∞".to_string()
    } else if ci.is_finite() {
        format!("{m:.2} ± {ci:.2}")
    } else {
        format!("{m:.2}")
    }
}

/// A single value ("∞" when every value was infinite).
fn value_cell(x: f64) -> String {
    if x.is_nan() {
        "∞".to_string()
    } else {
        format!("{x:.2}")
    }
}

/// How many episodes of the row had `metric` (0 or 1) set.
fn count(r: &SummaryRow, metric: &str) -> f64 {
    (r.get(metric).0 * r.n as f64).round()
}

/// The paper's summary table (Markdown): means ± 95 % CI.
pub fn paper_table(rows: &[SummaryRow]) -> String {
    let mut out = String::from("| scenario | controller | speed | n | collisions | success | avg speed m/s | avg \\|jerk\\| m/s³ | conflict duration s | min TTC s | PET s |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let _ = writeln!(
            out,
            "| {} | {} | {:.0} | {} | {} | {:.0} % | {} | {} | {} | {} | {} |",
            r.scenario.name(),
            r.controller.name(),
            r.speed,
            r.n,
            count(r, "collision"),
            r.get("success").0 * 100.0,
            mean_cell(r.get("avg_speed_mps")),
            mean_cell(r.get("avg_abs_jerk_mps3")),
            mean_cell(r.get("conflict_duration_s")),
            mean_cell(r.get("min_ttc_s")),
            mean_cell(r.get("pet_s")),
        );
    }
    out
}

/// The interaction experiment's summary table (Markdown): means ± 95 % CI, and the smallest
/// PET, the largest imposed deceleration, the median and largest deadlock over the episodes.
pub fn interaction_table(rows: &[SummaryRow]) -> String {
    let mut out = String::from("| scenario | controller | speed | n | collisions | success | avg speed m/s | avg \\|jerk\\| m/s³ | conflict duration s | PET min s | PET mean s | imposed decel max m/s² | imposed decel mean m/s² | standing s | stood in crossing | wait while other stands median s | wait max s | time to clear s | eHMI changes |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let stat = |r: &SummaryRow, metric: &str, f: fn(&Stat) -> f64| {
        value_cell(r.stat(metric).map_or(f64::NAN, f))
    };
    for r in rows {
        let _ = writeln!(
            out,
            "| {} | {} | {:.0} | {} | {} | {:.0} % | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.scenario.name(),
            r.controller.name(),
            r.speed,
            r.n,
            count(r, "collision"),
            r.get("success").0 * 100.0,
            mean_cell(r.get("avg_speed_mps")),
            mean_cell(r.get("avg_abs_jerk_mps3")),
            mean_cell(r.get("conflict_duration_s")),
            stat(r, "pet_s", |s| s.min),
            mean_cell(r.get("pet_s")),
            stat(r, "imposed_decel_mps2", |s| s.max),
            mean_cell(r.get("imposed_decel_mps2")),
            mean_cell(r.get("standing_s")),
            count(r, "stood_in_crossing"),
            stat(r, "wait_while_other_stands_s", |s| s.median),
            stat(r, "wait_while_other_stands_s", |s| s.max),
            mean_cell(r.get("time_to_clear_s")),
            mean_cell(r.get("ehmi_changes")),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ci_of_a_known_sample() {
        let (m, ci, n) = mean_ci(&[1.0, 2.0, 3.0, 4.0, 5.0, f64::INFINITY]);
        assert_eq!((m, n), (3.0, 5));
        // s = 1.5811, t(0.975, 4) = 2.776: half-width 1.963.
        assert!((ci - 1.963).abs() < 0.001, "{ci}");
        assert!((t975(60) - 2.000).abs() < 0.001);
        let s = Stat::of("x", &[4.0, 1.0, f64::INFINITY, 3.0, 2.0]);
        assert_eq!((s.min, s.median, s.max, s.n), (1.0, 2.5, 4.0, 4));
        assert!(Stat::of("x", &[f64::INFINITY]).min.is_nan());
    }

    #[test]
    fn episodes_are_deterministic_and_independent_of_threads() {
        let grid: Vec<Episode> = paper_grid(1, 7).into_iter().take(8).collect();
        let p = Params::default();
        let one = run_all(&grid, &p, 1, |_, _| {});
        let two = run_all(&grid, &p, 2, |_, _| {});
        for (a, b) in one.iter().zip(&two) {
            assert_eq!(a.metrics, b.metrics);
            assert_eq!(a.samples.len(), b.samples.len());
        }
    }

    #[test]
    fn streams_of_several_hdvs_are_deterministic_and_independent_of_threads() {
        // One stream repetition per speed, every interaction controller but the oracle.
        let grid: Vec<Episode> = interaction_grid(1, 3)
            .into_iter()
            .filter(|e| e.scenario == ScenarioKind::Stream)
            .filter(|e| e.controller != ControllerKind::ConcordOracle)
            .collect();
        assert!(grid.iter().all(|e| !e.followers.is_empty()));
        let p = Params::default();
        let one = run_all(&grid, &p, 1, |_, _| {});
        let two = run_all(&grid, &p, 2, |_, _| {});
        let again = run_all(&grid, &p, 2, |_, _| {});
        for ((a, b), c) in one.iter().zip(&two).zip(&again) {
            assert_eq!(a.metrics, b.metrics);
            assert_eq!(a.samples, b.samples);
            assert_eq!(b.samples, c.samples);
            assert_eq!(a.samples[0].hdvs.len(), 1 + a.episode.followers.len());
        }
    }

    #[test]
    fn stream_counts_and_headways_stay_in_their_ranges_and_follow_the_seed() {
        let (mut counts, mut shortest, mut longest) = ([0usize; 7], f64::INFINITY, 0.0_f64);
        for seed in 0..300 {
            let mut rng = SmallRng::seed_from_u64(seed);
            let speed = [6.0, 8.0, 10.0][seed as usize % 3];
            let f = stream_followers(&mut rng, speed);
            counts[f.len() + 1] += 1;
            for x in &f {
                assert!(DriverStyle::DECISIVE.contains(&x.style));
                let p = DriverParams::of(x.style);
                let desired = (p.s0_m + speed * p.headway_s + CAR_LENGTH_M) / speed;
                assert!(x.headway_s >= desired - 1e-12 && x.headway_s < STREAM_HEADWAY_S.1);
                assert!(x.headway_s >= STREAM_HEADWAY_S.0);
                shortest = shortest.min(x.headway_s);
                longest = longest.max(x.headway_s);
            }
            assert_eq!(
                f,
                stream_followers(&mut SmallRng::seed_from_u64(seed), speed)
            );
        }
        // Every count from 2 to 6 occurs, and nothing else.
        assert_eq!(counts[..2], [0, 0]);
        assert!(counts[2..].iter().all(|&c| c > 30), "{counts:?}");
        assert!(shortest < 2.0 && longest > 4.8, "{shortest} {longest}");
        // In the grid: the same stream for every controller of a repetition, and the world
        // places each follower its headway behind the car ahead.
        let grid = interaction_grid(2, 9);
        let streams: Vec<&Episode> = grid
            .iter()
            .filter(|e| e.scenario == ScenarioKind::Stream && e.rep == 1 && e.speed == 8.0)
            .collect();
        assert_eq!(streams.len(), ControllerKind::INTERACTION.len());
        assert!(streams.iter().all(|e| e.followers == streams[0].followers));
        let e = streams[0];
        let headways: Vec<f64> = e.followers.iter().map(|f| f.headway_s).collect();
        let w = World::with_followers(e.scenario, e.speed, e.hdv_offset_m, &headways);
        for (k, h) in headways.iter().enumerate() {
            let gap = w.hdvs[k].car.s - w.hdvs[k + 1].car.s;
            assert!((gap - h * 8.0).abs() < 1e-9);
        }
        assert_ne!(interaction_grid(2, 10), grid, "another seed, other draws");
    }

    #[test]
    fn a_hesitant_driver_deadlocks_the_idm_baseline_for_about_its_patience() {
        for speed in [6.0, 8.0, 10.0] {
            let e = Episode {
                scenario: ScenarioKind::LeftTurn,
                controller: ControllerKind::Idm,
                speed,
                style: DriverStyle::Hesitant,
                hdv_offset_m: 0.0,
                followers: Vec::new(),
                seed: 5,
                rep: 0,
            };
            let driver = HumanDriver::new(DriverStyle::Hesitant, speed, e.driver_seed(0));
            let patience = driver.patience_s().expect("a hesitant driver has patience");
            let m = run_episode(&e, &Params::default()).metrics;
            assert!(m.success && !m.collision, "{speed}: {m:?}");
            // The patience, plus the reaction time (the driver sees the CAV stand late) and
            // less than a second to reach 0.5 m/s again.
            let wait = m.wait_while_other_stands_s;
            assert!(
                wait > patience && wait < patience + driver.p.reaction_s + 1.0,
                "{speed} m/s: deadlock {wait:.2} s, patience {patience:.2} s"
            );
        }
    }
}
