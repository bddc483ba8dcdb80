//! Episodes, the paper's experiment grid, a parallel deterministic runner, and CSV output.
//!
//! An episode runs at 20 Hz until the CAV is 15 m past the conflict zone and the HDV has left
//! it, a collision, or [`TIME_LIMIT_S`]. Every episode is seeded by its own spec, so results do
//! not depend on the number of threads or their timing.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use concord_core::scene::Style;
use concord_core::Params;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use crate::controllers::{
    AdviceSource, Advisor, ConcordController, Controller, ExternalAdvice, IdmYield, Stackelberg,
    Timing,
};
use crate::driver::HumanDriver;
use crate::metrics::{self, Metrics, Sample};
use crate::world::{ScenarioKind, World};

/// Longest episode, s.
pub const TIME_LIMIT_S: f64 = 40.0;

/// The CAV controllers compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ControllerKind {
    Idm,
    GameTheoretic,
    ConcordLogit,
    ConcordOracle,
    /// Concord advised by an LLM, simulated time waiting for each answer.
    ConcordLlmWait,
    /// Concord advised by an LLM, each answer landing after its measured latency.
    ConcordLlmLatency,
}

impl ControllerKind {
    /// Every controller, the LLM ones last.
    pub const EVERY: [ControllerKind; 6] = [
        ControllerKind::Idm,
        ControllerKind::GameTheoretic,
        ControllerKind::ConcordLogit,
        ControllerKind::ConcordOracle,
        ControllerKind::ConcordLlmWait,
        ControllerKind::ConcordLlmLatency,
    ];
    /// The controllers that need no LLM.
    pub const ALL: [ControllerKind; 4] = [
        ControllerKind::Idm,
        ControllerKind::GameTheoretic,
        ControllerKind::ConcordLogit,
        ControllerKind::ConcordOracle,
    ];
    pub fn name(self) -> &'static str {
        match self {
            ControllerKind::Idm => "idm",
            ControllerKind::GameTheoretic => "game_theoretic",
            ControllerKind::ConcordLogit => "concord_logit",
            ControllerKind::ConcordOracle => "concord_oracle",
            ControllerKind::ConcordLlmWait => "concord_llm_wait",
            ControllerKind::ConcordLlmLatency => "concord_llm_latency",
        }
    }
}

fn style_name(s: Style) -> &'static str {
    match s {
        Style::Aggressive => "aggressive",
        Style::Balanced => "balanced",
        Style::Conservative => "conservative",
    }
}

/// One episode's specification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Episode {
    pub scenario: ScenarioKind,
    pub controller: ControllerKind,
    /// Initial speed of both vehicles, m/s.
    pub speed: f64,
    pub style: Style,
    /// The HDV's start shifted along its lane, m.
    pub hdv_offset_m: f64,
    pub seed: u64,
    pub rep: u32,
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
    let mut w = World::new(e.scenario, e.speed, e.hdv_offset_m);
    let mut hdv = HumanDriver::new(e.style, e.speed, e.seed);
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
    let mut samples = Vec::with_capacity((TIME_LIMIT_S / crate::world::DT) as usize + 1);
    loop {
        let (ego_d, hdv_d) = w.to_conflict();
        let collided = w.collided();
        samples.push(Sample {
            t: w.t,
            ego_d,
            hdv_d,
            ego_v: w.ego.v,
            hdv_v: w.hdv.v,
            ego_a: w.ego.a,
            collided,
        });
        let done = ego_d < -(w.zone_half_m + 15.0) && hdv_d < -w.zone_half_m;
        if collided || done || w.t >= TIME_LIMIT_S {
            break;
        }
        let controller: &mut dyn Controller = match (e.controller, concord.as_mut()) {
            (ControllerKind::Idm, _) => &mut idm,
            (ControllerKind::GameTheoretic, _) => &mut gt,
            (ControllerKind::ConcordLogit | ControllerKind::ConcordOracle, Some(c)) => c,
            _ => match external.as_mut() {
                Some(x) => x,
                None => panic!("{} needs an advice source", e.controller.name()),
            },
        };
        let cmd = controller.act(&w, &hdv);
        let a_h = hdv.act(&w, cmd.ehmi);
        w.step(cmd.accel, a_h);
    }
    Outcome {
        episode: *e,
        metrics: metrics::compute(&samples, params.opm.delta_ttc_threshold_s, w.zone_half_m),
        samples,
        sources: concord
            .map(|c| c.sources)
            .or(external.map(|x| x.sources()))
            .unwrap_or([0; 3]),
    }
}

/// The paper's grid (Fig. 4, Fig. 7b): both scenarios × initial speeds 6, 8, 10 m/s × `reps`
/// repetitions × every controller, with a balanced human driver whose start varies by up to
/// ±5 m and whose noise is seeded per repetition (the same for every controller).
pub fn paper_grid(reps: u32, seed: u64) -> Vec<Episode> {
    let mut out = Vec::new();
    for scenario in [ScenarioKind::LeftTurn, ScenarioKind::Merge] {
        for speed in [6.0, 8.0, 10.0] {
            for rep in 0..reps {
                let s = seed
                    .wrapping_mul(1_000_003)
                    .wrapping_add(rep as u64 * 7919 + (speed as u64) * 31 + scenario as u64);
                let mut rng = SmallRng::seed_from_u64(s);
                let offset = rng.random_range(-5.0..5.0);
                for controller in ControllerKind::ALL {
                    out.push(Episode {
                        scenario,
                        controller,
                        speed,
                        style: Style::Balanced,
                        hdv_offset_m: offset,
                        seed: s,
                        rep,
                    });
                }
            }
        }
    }
    out
}

/// A sweep of `n` random left turns per controller: styles, initial speeds (5–11 m/s) and HDV
/// starts (±15 m) drawn from `seed`.
pub fn sweep_grid(n: u32, seed: u64) -> Vec<Episode> {
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut out = Vec::new();
    for rep in 0..n {
        let style =
            [Style::Aggressive, Style::Balanced, Style::Conservative][rng.random_range(0..3)];
        let speed = rng.random_range(5.0..11.0);
        let offset = rng.random_range(-15.0..15.0);
        let s = rng.random::<u64>();
        for controller in ControllerKind::ALL {
            out.push(Episode {
                scenario: ScenarioKind::LeftTurn,
                controller,
                speed,
                style,
                hdv_offset_m: offset,
                seed: s,
                rep,
            });
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

/// Metric columns: name and value.
pub fn columns(m: &Metrics) -> [(&'static str, f64); 8] {
    [
        ("avg_speed_mps", m.avg_speed_mps),
        ("avg_abs_jerk_mps3", m.avg_abs_jerk_mps3),
        ("conflict_duration_s", m.conflict_duration_s),
        ("min_ttc_s", m.min_ttc_s),
        ("pet_s", m.pet_s),
        ("collision", f64::from(m.collision as u8)),
        ("success", f64::from(m.success as u8)),
        ("time_to_clear_s", m.time_to_clear_s),
    ]
}

/// One summary row: (scenario, controller, speed) with the mean and CI of every metric.
#[derive(Clone, Debug)]
pub struct SummaryRow {
    pub scenario: ScenarioKind,
    pub controller: ControllerKind,
    pub speed: f64,
    pub n: usize,
    /// Per metric of [`columns`]: (mean, CI half-width, finite values).
    pub stats: Vec<(&'static str, f64, f64, usize)>,
}

impl SummaryRow {
    pub fn get(&self, metric: &str) -> (f64, f64) {
        self.stats
            .iter()
            .find(|s| s.0 == metric)
            .map_or((f64::NAN, f64::NAN), |s| (s.1, s.2))
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
                    let (m, ci, n) = mean_ci(&xs);
                    (*name, m, ci, n)
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

/// Writes `episodes.csv` (one row per episode), `summary.csv` (mean and 95 % CI per group) and
/// `traces/<scenario>_<controller>_<speed>_<rep>.csv` (each episode's states) under `dir`.
pub fn write_csv(dir: &Path, outcomes: &[Outcome], rows: &[SummaryRow]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir.join("traces"))?;
    let mut ep = String::from(
        "scenario,controller,speed_mps,style,hdv_offset_m,seed,rep,avg_speed_mps,avg_abs_jerk_mps3,conflict_duration_s,min_ttc_s,pet_s,collision,success,time_to_clear_s,decisions_logit,decisions_advice,decisions_minimum_risk\n",
    );
    for o in outcomes {
        let e = &o.episode;
        let _ = write!(
            ep,
            "{},{},{:.3},{},{:.3},{},{}",
            e.scenario.name(),
            e.controller.name(),
            e.speed,
            style_name(e.style),
            e.hdv_offset_m,
            e.seed,
            e.rep
        );
        for (_, v) in columns(&o.metrics) {
            let _ = write!(ep, ",{v:.4}");
        }
        let _ = writeln!(ep, ",{},{},{}", o.sources[0], o.sources[1], o.sources[2]);
        let mut trace = String::from("t_s,ego_to_conflict_m,hdv_to_conflict_m,ego_speed_mps,hdv_speed_mps,ego_accel_mps2,collided\n");
        for s in &o.samples {
            let _ = writeln!(
                trace,
                "{:.2},{:.3},{:.3},{:.3},{:.3},{:.3},{}",
                s.t, s.ego_d, s.hdv_d, s.ego_v, s.hdv_v, s.ego_a, s.collided as u8
            );
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
    for (name, ..) in &rows[0].stats {
        let _ = write!(head, ",{name}_mean,{name}_ci95,{name}_n");
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
        for (_, m, ci, n) in &r.stats {
            let _ = write!(line, ",{m:.4},{ci:.4},{n}");
        }
        writeln!(f, "{line}")?;
    }
    Ok(())
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
}
