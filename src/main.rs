//! `concord`: the command line of the Concord decision service.

mod advisor_eval;
mod learn;
mod llm_experiments;

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, ExitCode, Stdio};
use std::time::Duration;

use clap::{Parser, Subcommand, ValueEnum};
use concord_core::AdviceVerdict;
use concord_core::DecisionCore;
use concord_ipc::core_service::{self, DecideOn, Geometry, RunConfig, StopAfter};
use concord_ipc::feed::{self, Fault, FeedConfig, Scenario};
use concord_ipc::wire::{
    AdviceFailure, Audience, CoreStats, EhmiMessage, IntentText, TextSource, WireDecision,
};
use concord_ipc::{clock, iox, monitor, services};

#[derive(Parser)]
#[command(
    name = "concord",
    version,
    about = "Onboard interactive decision service for automated vehicles"
)]
struct Cli {
    /// iceoryx2 configuration file [default: $CONCORD_IOX_CONFIG, else deploy/iceoryx2.toml
    /// when present, else iceoryx2's defaults].
    #[arg(long, global = true)]
    iox_config: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum ScenarioArg {
    Paper,
    Merge,
    Dense,
}

/// Built-in road geometries of `concord run --geometry`.
#[derive(Clone, Copy, ValueEnum)]
enum GeometryArg {
    /// The paper's intersection (lanes at ±5 m around the origin).
    PaperIntersection,
    /// The on-ramp merge.
    Merge,
    /// highway-env's intersection-v0, in its coordinates (bridges/python/highway_bridge.py).
    HighwayEnvIntersection,
    /// highway-env's merge-v0, in its coordinates (bridges/python/highway_bridge.py).
    HighwayEnvMerge,
}

impl GeometryArg {
    fn geometry(self) -> Geometry {
        match self {
            GeometryArg::PaperIntersection => Geometry::PaperIntersection,
            GeometryArg::Merge => Geometry::Merge,
            GeometryArg::HighwayEnvIntersection => Geometry::HighwayEnvIntersection,
            GeometryArg::HighwayEnvMerge => Geometry::HighwayEnvMerge,
        }
    }
}

/// The experiments of `concord experiment`.
#[derive(Subcommand)]
enum ExperimentArg {
    /// Fig. 4 and Fig. 7b: the left turn and the merge at 6, 8 and 10 m/s, `--reps` times, for
    /// every controller; CSVs, SVG figures and a summary table.
    Paper {
        #[arg(long, default_value_t = 30)]
        reps: u32,
        /// Output directory.
        #[arg(long, default_value = "results/paper")]
        out: PathBuf,
        /// Seed of every random draw. Tuning uses the default seeds; held-out results use
        /// another (e.g. `--seed 500`).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads [default: every core].
        #[arg(long)]
        threads: Option<usize>,
        /// Also run Concord advised by the LLM server at this URL, in both timing modes (one
        /// episode at a time: the server has one slot).
        #[arg(long)]
        llm: Option<String>,
        /// Repetitions per speed of the LLM runs (the left turn and the merge).
        #[arg(long, default_value_t = 3)]
        llm_reps: u32,
    },
    /// Fig. 5: OPM vs Raw vs Simple prompts on labelled simulator scenes (oracle labels):
    /// accuracy, latency and reasoning steps, on any OpenAI-compatible server.
    Prompts {
        /// Base URL of the LLM server.
        #[arg(long, default_value = "http://127.0.0.1:8181/v1")]
        url: String,
        #[arg(long, default_value_t = 30)]
        scenes: usize,
        #[arg(long, default_value = "results/prompts")]
        out: PathBuf,
        /// Seed of the scenes. Tuning uses the default seeds; held-out results use another
        /// (e.g. `--seed 500`).
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// The advisor on held-out scenes and messages: the base model against the fine-tuned one
    /// (the server's LoRA adapter at scale 0 and 1): accuracy, confusion, calibration (ECE,
    /// reliability diagrams), the gate's pass shares, intent parsing.
    Advisor {
        /// Base URL of the LLM server (llama.cpp's, for the adapter's scale).
        #[arg(long, default_value = "http://127.0.0.1:8181/v1")]
        url: String,
        /// Held-out advice scenes.
        #[arg(long, default_value_t = 150)]
        scenes: usize,
        /// Held-out intent messages.
        #[arg(long, default_value_t = 150)]
        messages: usize,
        #[arg(long, default_value = "results/advisor")]
        out: PathBuf,
    },
    /// Fits the saliency key (eq. 7) on simulated interactions; `--write` stores it as the
    /// core's shipped key.
    Saliency {
        #[arg(long, default_value_t = 2000)]
        scenes: usize,
        /// Seed of the scenes. The shipped key is fitted with the default; held-out checks use
        /// another (e.g. `--seed 500`).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Write the fitted key to this file (the core's is core/src/saliency_key.rs).
        #[arg(long)]
        write: Option<PathBuf>,
    },
    /// Random left turns over driver styles (aggressive, balanced, conservative, hesitant),
    /// initial speeds (5–11 m/s) and HDV starts (±15 m), `--episodes` per controller.
    Sweep {
        #[arg(long, default_value_t = 1000)]
        episodes: u32,
        #[arg(long, default_value = "results/sweep")]
        out: PathBuf,
        /// Seed of every random draw. Tuning uses the default seeds; held-out results use
        /// another (e.g. `--seed 500`).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads [default: every core].
        #[arg(long)]
        threads: Option<usize>,
    },
    /// The interaction scenarios: the left turn with a hesitant driver (the paper's Fig. 6a
    /// deadlock), the left turn with the right of way (a balanced driver on the minor road)
    /// and the left turn across a stream of 2–6 cars of random styles, at 6, 8 and 10 m/s,
    /// `--reps` times, for IDM, game-theoretic, gap acceptance and Concord (logit-only and
    /// oracle); CSVs and a summary table.
    Interaction {
        #[arg(long, default_value_t = 30)]
        reps: u32,
        /// Output directory.
        #[arg(long, default_value = "results/interaction")]
        out: PathBuf,
        /// Seed of every random draw. Tuning uses the default seeds; held-out results use
        /// another (e.g. `--seed 500`).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads [default: every core].
        #[arg(long)]
        threads: Option<usize>,
    },
}

/// Prompt renderings of `concord sidecar --format`.
#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Opm,
    Raw,
    Simple,
}

#[derive(Subcommand)]
enum Command {
    /// Run the paper's left turn across processes: feed, core and a console; ends with a summary.
    Demo {
        /// Initial speed of both vehicles, m/s (the paper uses 6, 8 and 10).
        #[arg(long, default_value_t = 8.0)]
        speed: f64,
        /// Time limit, s.
        #[arg(long, default_value_t = 30.0, value_parser = seconds)]
        duration: f64,
    },
    /// Run the onboard core process.
    Run {
        /// Configuration file (TOML; see deploy/concord.toml). Missing keys take defaults.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Service-name prefix, overriding the file's.
        #[arg(long)]
        prefix: Option<String>,
        /// Loop rate, Hz, overriding the file's.
        #[arg(long, value_parser = hertz)]
        rate: Option<f64>,
        /// Road geometry, a built-in map, overriding the file's `service.geometry`.
        #[arg(long, value_enum, conflicts_with = "map")]
        geometry: Option<GeometryArg>,
        /// Map file: TOML, a SUMO network (.net.xml) or OpenDRIVE (.xodr); see
        /// deploy/maps/README.md. Overrides the file's `service.map`.
        #[arg(long)]
        map: Option<PathBuf>,
        /// The ego's route: a lane id of the map; for SUMO or OpenDRIVE, a movement or
        /// waypoints joined by '>' (edges, roads or lanes; "A>B" or, across several
        /// junctions, "A>B>C"). Overrides the file's `service.route`.
        #[arg(long)]
        route: Option<String>,
        /// Decide as soon as a scene arrives (its publisher notifies `scene_ready`), not on the
        /// tick: for lock-step simulators. Overrides the file's `service.decide_on`.
        #[arg(long)]
        on_arrival: bool,
        /// Stop after this many seconds (default: run until SIGINT/SIGTERM).
        #[arg(long, value_parser = seconds)]
        duration: Option<f64>,
    },
    /// Publish synthetic scenes.
    Feed {
        #[arg(long, value_enum, default_value_t = ScenarioArg::Paper)]
        scenario: ScenarioArg,
        /// Frame rate, Hz.
        #[arg(long, default_value_t = 20.0, value_parser = hertz)]
        rate: f64,
        /// Initial speed of the ego and the HDV, m/s.
        #[arg(long, default_value_t = 8.0)]
        speed: f64,
        /// Road users besides the ego in the dense scenario.
        #[arg(long, default_value_t = 16)]
        agents: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Stop after this many seconds (default: when the scenario ends).
        #[arg(long, value_parser = seconds)]
        duration: Option<f64>,
        /// Start the scenario over when it ends.
        #[arg(long)]
        repeat: bool,
        /// Ignore decisions: the ego keeps its speed along its route.
        #[arg(long)]
        open_loop: bool,
        /// Faults to inject in turn: nan, jump, stall, duplicate, reorder, restart.
        #[arg(long, value_delimiter = ',')]
        faults: Vec<String>,
        /// Inject one fault every this many frames.
        #[arg(long, default_value_t = 50)]
        fault_every: u64,
        #[arg(long, default_value = services::DEFAULT_PREFIX)]
        prefix: String,
    },
    /// Show a running core's counters, latencies, last decision and eHMI text.
    Monitor {
        #[arg(long, default_value = services::DEFAULT_PREFIX)]
        prefix: String,
        /// Refresh period, s.
        #[arg(long, default_value_t = 1.0, value_parser = seconds)]
        period: f64,
        /// Stop after this many seconds.
        #[arg(long, value_parser = seconds)]
        duration: Option<f64>,
    },
    /// Load a map and print its lanes and the conflicts the core derives from them (what
    /// `concord run --map FILE --route ID` would drive on).
    Map {
        /// Map file: Concord's TOML format (deploy/maps/README.md), a SUMO network (*.net.xml)
        /// or an OpenDRIVE file (*.xodr).
        file: PathBuf,
        /// The ego's route, as for `run` (for a SUMO network or OpenDRIVE it also selects the
        /// movements kept; across several junctions, one lane per junction).
        #[arg(long)]
        route: Option<String>,
        /// Print JSON (lanes with their vertices, conflicts) instead of tables.
        #[arg(long)]
        json: bool,
    },
    /// Print the default configuration as TOML, or check a configuration file.
    Params {
        /// File to check instead of printing the defaults.
        #[arg(long)]
        check: Option<PathBuf>,
    },
    /// Run the LLM sidecar: advice, intents and eHMI text from an OpenAI-compatible server.
    Sidecar {
        /// Configuration file (TOML; see deploy/sidecar.toml). Missing keys take defaults.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Service-name prefix, overriding the file's.
        #[arg(long)]
        prefix: Option<String>,
        /// Base URL of the LLM server (…/v1), overriding the file's.
        #[arg(long)]
        llm_url: Option<String>,
        /// Prompt rendering of the scene, overriding the file's.
        #[arg(long, value_enum)]
        format: Option<FormatArg>,
        /// Interaction log file, overriding the file's ("" disables it).
        #[arg(long)]
        log: Option<PathBuf>,
    },
    /// Rerun the paper's closed-loop experiments against IDM and game-theoretic baselines.
    Experiment {
        #[command(subcommand)]
        which: ExperimentArg,
    },
    /// The advisor's fine-tuning data (§5 step 5; deploy/llm/README.md has the recipe).
    Learn {
        #[command(subcommand)]
        which: LearnArg,
    },
}

/// The steps of `concord learn`.
#[derive(Subcommand)]
enum LearnArg {
    /// Writes the advice and intent sets (training and held out) and the interaction log's
    /// examples as JSONL, each prompt rendered as the sidecar renders it.
    Dataset {
        /// Output directory.
        #[arg(long, default_value = "results/learn")]
        out: PathBuf,
        /// Sidecar configuration whose prompts to render [default: the built-in one, the prompts
        /// the shipped adapter is trained on].
        #[arg(long)]
        config: Option<PathBuf>,
        /// Advice scenes for training (seeds from 0).
        #[arg(long, default_value_t = 1200)]
        advice_train: usize,
        /// Held-out advice scenes (seeds from 500 000).
        #[arg(long, default_value_t = 150)]
        advice_heldout: usize,
        /// Intent messages for training.
        #[arg(long, default_value_t = 500)]
        intents_train: usize,
        /// Held-out intent messages (from the held-out phrase file).
        #[arg(long, default_value_t = 150)]
        intents_heldout: usize,
        /// Phrase file of the training messages.
        #[arg(long, default_value = "deploy/llm/intents/train.txt")]
        phrases: PathBuf,
        /// Phrase file of the held-out messages (other templates and words).
        #[arg(long, default_value = learn::HELD_OUT_PHRASES)]
        heldout_phrases: PathBuf,
        /// Interaction logs of the sidecar to add (`log.jsonl`), repeatable.
        #[arg(long)]
        log: Vec<PathBuf>,
    },
}

/// Longest duration or period accepted on the command line, s (30 days).
const MAX_SECONDS: f64 = 30.0 * 86_400.0;

/// A duration or period on the command line, s: a number in (0, 30 days].
fn seconds(arg: &str) -> Result<f64, String> {
    let v: f64 = arg.parse().map_err(|e| format!("{e}"))?;
    if v > 0.0 && v <= MAX_SECONDS {
        Ok(v)
    } else {
        Err(format!("expected seconds in (0, {MAX_SECONDS}]"))
    }
}

/// A rate on the command line, Hz: a number in [0.5, 1000].
fn hertz(arg: &str) -> Result<f64, String> {
    let v: f64 = arg.parse().map_err(|e| format!("{e}"))?;
    if (0.5..=1000.0).contains(&v) {
        Ok(v)
    } else {
        Err("expected 0.5 to 1000 Hz".into())
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let iox_path = cli.iox_config.or_else(default_iox_config);
    let result = match cli.command {
        Command::Demo { speed, duration } => demo(speed, duration, iox_path.as_deref()),
        Command::Run {
            config,
            prefix,
            rate,
            geometry,
            map,
            route,
            on_arrival,
            duration,
        } => run(
            config.as_deref(),
            prefix,
            rate,
            on_arrival,
            RoadArgs {
                geometry: geometry.map(GeometryArg::geometry),
                map,
                route,
            },
            duration,
            iox_path.as_deref(),
        ),
        Command::Feed {
            scenario,
            rate,
            speed,
            agents,
            seed,
            duration,
            repeat,
            open_loop,
            faults,
            fault_every,
            prefix,
        } => (|| {
            let faults = faults
                .iter()
                .map(|f| Fault::parse(f).ok_or_else(|| format!("--faults: unknown fault {f:?} (nan, jump, stall, duplicate, reorder, restart)")))
                .collect::<Result<Vec<_>, _>>()?;
            let cfg = FeedConfig {
                prefix,
                rate_hz: rate,
                scenario: match scenario {
                    ScenarioArg::Paper => Scenario::Paper,
                    ScenarioArg::Merge => Scenario::Merge,
                    ScenarioArg::Dense => Scenario::Dense,
                },
                speed_mps: speed,
                agents,
                seed,
                duration_s: duration,
                repeat,
                closed_loop: !open_loop,
                faults,
                fault_every,
                ..FeedConfig::default()
            };
            let iox_config = iox::init(iox_path.as_deref()).map_err(|e| e.to_string())?;
            let summary = feed::run(&cfg, &iox_config).map_err(|e| e.to_string())?;
            println!("{summary}");
            Ok(())
        })(),
        Command::Monitor {
            prefix,
            period,
            duration,
        } => iox::init(iox_path.as_deref())
            .and_then(|c| {
                monitor::run(
                    &prefix,
                    Duration::from_secs_f64(period.max(0.05)),
                    duration,
                    &c,
                )
            })
            .map(|_| ())
            .map_err(|e| e.to_string()),
        Command::Map { file, route, json } => show_map(&file, route.as_deref(), json),
        Command::Params { check: None } => toml::to_string_pretty(&RunConfig::default())
            .map(|t| print!("{t}"))
            .map_err(|e| e.to_string()),
        Command::Params { check: Some(path) } => load_config(Some(&path))
            .and_then(|cfg| cfg.service.road())
            .map(|_| println!("{}: ok", path.display())),
        Command::Sidecar {
            config,
            prefix,
            llm_url,
            format,
            log,
        } => (|| {
            use concord_sidecar::config::PromptFormat;
            let mut cfg = match config {
                Some(path) => concord_sidecar::SidecarConfig::load(&path)?,
                None => concord_sidecar::SidecarConfig::default(),
            };
            if let Some(p) = prefix {
                cfg.prefix = p;
            }
            if let Some(u) = llm_url {
                cfg.llm.base_url = u;
            }
            if let Some(f) = format {
                cfg.advice.prompt_format = match f {
                    FormatArg::Opm => PromptFormat::Opm,
                    FormatArg::Raw => PromptFormat::Raw,
                    FormatArg::Simple => PromptFormat::Simple,
                };
            }
            if let Some(l) = log {
                cfg.log.path = l;
            }
            cfg.validate()?;
            let iox_config = iox::init(iox_path.as_deref()).map_err(|e| e.to_string())?;
            concord_sidecar::run(cfg, &iox_config)
        })(),
        Command::Learn {
            which:
                LearnArg::Dataset {
                    out,
                    config,
                    advice_train,
                    advice_heldout,
                    intents_train,
                    intents_heldout,
                    phrases,
                    heldout_phrases,
                    log,
                },
        } => (|| {
            let cfg = match config {
                Some(path) => concord_sidecar::SidecarConfig::load(&path)?,
                None => concord_sidecar::SidecarConfig::default(),
            };
            learn::dataset(
                &cfg,
                &out,
                (advice_train, advice_heldout),
                (intents_train, intents_heldout),
                (&phrases, &heldout_phrases),
                &log,
            )
        })(),
        Command::Experiment { which } => match which {
            ExperimentArg::Paper {
                reps,
                out,
                seed,
                threads,
                llm,
                llm_reps,
            } => llm
                .map(|url| llm_experiments::LlmAdvisor::new(&url).map(|a| (a, url, llm_reps)))
                .transpose()
                .and_then(|llm| {
                    experiment(
                        "paper",
                        Report::Paper,
                        concord_sim::experiment::paper_grid(reps, seed),
                        &out,
                        threads,
                        llm,
                    )
                }),
            ExperimentArg::Interaction {
                reps,
                out,
                seed,
                threads,
            } => experiment(
                "interaction",
                Report::Interaction,
                concord_sim::experiment::interaction_grid(reps, seed),
                &out,
                threads,
                None,
            ),
            ExperimentArg::Prompts {
                url,
                scenes,
                out,
                seed,
            } => llm_experiments::run(&url, scenes, seed, &out),
            ExperimentArg::Advisor {
                url,
                scenes,
                messages,
                out,
            } => advisor_eval::run(&url, scenes, messages, &out),
            ExperimentArg::Saliency {
                scenes,
                seed,
                write,
            } => (|| {
                use concord_sim::saliency_fit;
                let fit = saliency_fit::fit(&saliency_fit::dataset(scenes, seed));
                println!(
                    "fitted key {:?} on {} scenes: top-1 {:.1} % (prior {:.1} %), log-likelihood {:.3} (prior {:.3})",
                    fit.key,
                    fit.examples,
                    100.0 * fit.top1_fitted,
                    100.0 * fit.top1_prior,
                    fit.loglik_fitted,
                    fit.loglik_prior
                );
                if let Some(path) = write {
                    let command =
                        format!("concord experiment saliency --scenes {scenes} --seed {seed}");
                    std::fs::write(&path, saliency_fit::key_file(&fit, &command))
                        .map_err(|e| format!("{}: {e}", path.display()))?;
                    println!("wrote {}", path.display());
                }
                Ok(())
            })(),
            ExperimentArg::Sweep {
                episodes,
                out,
                seed,
                threads,
            } => experiment(
                "sweep",
                Report::Paper,
                concord_sim::experiment::sweep_grid(episodes, seed),
                &out,
                threads,
                None,
            ),
        },
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("concord: {e}");
            ExitCode::FAILURE
        }
    }
}

fn default_iox_config() -> Option<PathBuf> {
    std::env::var_os("CONCORD_IOX_CONFIG")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from("deploy/iceoryx2.toml")).filter(|p| p.exists()))
}

/// The configuration from `path` (or the defaults), validated. A relative `service.map` is
/// taken relative to the file's directory.
fn load_config(path: Option<&Path>) -> Result<RunConfig, String> {
    let cfg: RunConfig = match path {
        None => RunConfig::default(),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
            let mut cfg: RunConfig =
                toml::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?;
            if let (Some(map), Some(dir)) = (&cfg.service.map, p.parent()) {
                cfg.service.map = Some(dir.join(map));
            }
            cfg
        }
    };
    cfg.validate()?;
    Ok(cfg)
}

/// `concord map`: the lanes of a map and the conflicts derived from them.
fn show_map(file: &Path, route: Option<&str>, json: bool) -> Result<(), String> {
    let (map, legs) = concord_map::Map::load_route(file, route).map_err(|e| e.to_string())?;
    let morph = map.morphology();
    let on_route = |i: usize| legs.is_some_and(|r| r.lanes().contains(&(i as u8)));
    let turn = |t: concord_core::scene::Turn| format!("{t:?}").to_lowercase();
    // Written as a whole at the end; a closed pipe (`| head`) is not an error.
    let mut out = String::new();
    if json {
        let lanes: Vec<_> = morph
            .lanes()
            .iter()
            .zip(map.ids())
            .map(|(l, id)| {
                serde_json::json!({
                    "id": id, "turn": turn(l.turn), "priority": l.priority,
                    "half_width_m": l.half_width, "stop_s_m": l.stop_s, "length_m": l.length(),
                    "points": l.points().iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
                })
            })
            .collect();
        let conflicts: Vec<_> = morph
            .conflicts()
            .iter()
            .map(|c| {
                serde_json::json!({
                    "lane_a": c.lane_a, "lane_b": c.lane_b, "kind": format!("{:?}", c.kind),
                    "right_of_way": format!("{:?}", c.right_of_way), "point": [c.pos.x, c.pos.y],
                    "s_a_m": c.s_a, "s_b_m": c.s_b, "zone_a_m": c.zone_a, "zone_b_m": c.zone_b,
                })
            })
            .collect();
        // The route's legs: each leg's lane and the arc length on it where the next takes over.
        let route_legs: Vec<_> = legs
            .iter()
            .flat_map(|r| {
                r.lanes().iter().enumerate().map(|(k, &lane)| {
                    let handover = r.handover_s(k);
                    serde_json::json!({
                        "lane": lane,
                        "handover_s_m": if k + 1 < r.lanes().len() { Some(handover) } else { None },
                    })
                })
            })
            .collect();
        let json = serde_json::json!({
            "name": map.name, "route_lane": legs.map(|r| r.first()), "route_legs": route_legs,
            "lanes": lanes, "conflicts": conflicts,
        });
        let _ = writeln!(out, "{json}");
        let _ = std::io::stdout().write_all(out.as_bytes());
        return Ok(());
    }
    let _ = writeln!(
        out,
        "map {}: {} lanes, {} conflict points",
        map.name,
        map.ids().len(),
        morph.conflicts().len()
    );
    let _ = writeln!(
        out,
        "lane  id                      turn      level  width m  stop s m  length m"
    );
    for (i, (l, id)) in morph.lanes().iter().zip(map.ids()).enumerate() {
        let mark = if on_route(i) { "*" } else { " " };
        let _ = writeln!(
            out,
            "{mark}{i:<4} {id:<23} {:<9} {:>5}  {:>7.2}  {:>8.2}  {:>8.2}",
            turn(l.turn),
            l.priority,
            2.0 * l.half_width,
            l.stop_s,
            l.length()
        );
    }
    let _ = writeln!(
        out,
        "lanes    kind      right of way  point (x, y) m     zone on a m       zone on b m"
    );
    for c in morph.conflicts() {
        let who = match c.right_of_way {
            concord_core::scene::RightOfWay::A => format!("lane {}", c.lane_a),
            concord_core::scene::RightOfWay::B => format!("lane {}", c.lane_b),
            concord_core::scene::RightOfWay::Neither => "neither".into(),
        };
        let _ =
            writeln!(out,
            "{:>2} x {:<3} {:<9} {:<13} ({:>6.1}, {:>6.1})  [{:>6.1}, {:>6.1}]  [{:>6.1}, {:>6.1}]",
            c.lane_a,
            c.lane_b,
            format!("{:?}", c.kind).to_lowercase(),
            who,
            c.pos.x,
            c.pos.y,
            c.zone_a[0],
            c.zone_a[1],
            c.zone_b[0],
            c.zone_b[1]
        );
    }
    match legs {
        Some(r) if r.lanes().len() > 1 => {
            let handovers: Vec<String> = (0..r.lanes().len() - 1)
                .map(|k| format!("lane {} at s = {:.1} m", r.lanes()[k], r.handover_s(k)))
                .collect();
            let _ = writeln!(
                out,
                "* the route's legs, one per junction, each handing over to the next: {}",
                handovers.join(", ")
            );
        }
        Some(_) => {
            let _ = writeln!(out, "* the route's lane");
        }
        None => {}
    }
    let _ = std::io::stdout().write_all(out.as_bytes());
    Ok(())
}

/// The road options of `concord run`.
struct RoadArgs {
    geometry: Option<Geometry>,
    map: Option<PathBuf>,
    route: Option<String>,
}

fn run(
    config: Option<&Path>,
    prefix: Option<String>,
    rate: Option<f64>,
    on_arrival: bool,
    road: RoadArgs,
    duration: Option<f64>,
    iox_path: Option<&Path>,
) -> Result<(), String> {
    let mut cfg = load_config(config)?;
    if let Some(p) = prefix {
        cfg.service.prefix = p;
    }
    if let Some(r) = rate {
        cfg.service.rate_hz = r;
    }
    if let Some(g) = road.geometry {
        cfg.service.geometry = g;
        cfg.service.map = None;
    }
    if road.map.is_some() {
        cfg.service.map = road.map;
    }
    if road.route.is_some() {
        cfg.service.route = road.route;
    }
    if on_arrival {
        cfg.service.decide_on = DecideOn::Arrival;
    }
    cfg.validate()?;
    let loaded = cfg.service.road()?;
    let iox_config = iox::init(iox_path).map_err(|e| e.to_string())?;
    let mut core =
        Box::new(DecisionCore::new(cfg.core, loaded.map.morphology()).map_err(|e| e.to_string())?);
    let route = match (&cfg.service.route, loaded.route) {
        (Some(id), Some(r)) if r.lanes().len() == 1 => format!(", route {id} (lane {})", r.first()),
        (Some(id), Some(r)) => format!(", route {id} (lanes {:?}, one per junction)", r.lanes()),
        _ => String::new(),
    };
    eprintln!(
        "concord run: {} Hz{} on {}*, map {} ({} lanes, {} conflict points{route}), {} samples, staleness {} s",
        cfg.service.rate_hz,
        match cfg.service.decide_on {
            DecideOn::Arrival => ", deciding on arrival,",
            DecideOn::Tick => "",
        },
        cfg.service.prefix,
        loaded.map.name,
        loaded.map.ids().len(),
        loaded.map.morphology().conflicts().len(),
        cfg.core.trajectory.samples,
        cfg.service.staleness_s
    );
    core_service::run(
        &mut core,
        &cfg.service,
        loaded.route,
        &cfg.realtime,
        &iox_config,
        StopAfter {
            ticks: None,
            duration_s: duration,
        },
    )
    .map(|_| ())
    .map_err(|e| e.to_string())
}

/// A child `concord` process that is terminated (SIGTERM, then SIGKILL) when dropped.
struct ChildProcess(Child);

impl ChildProcess {
    fn spawn(args: &[&str], stdout: Stdio) -> Result<Self, String> {
        Self::spawn_with(args, stdout, Stdio::inherit())
    }
    fn spawn_with(args: &[&str], stdout: Stdio, stderr: Stdio) -> Result<Self, String> {
        let exe = std::env::current_exe().map_err(|e| format!("locating concord: {e}"))?;
        Process::new(exe)
            .args(args)
            .stdout(stdout)
            .stderr(stderr)
            .spawn()
            .map(ChildProcess)
            .map_err(|e| format!("starting concord {}: {e}", args.join(" ")))
    }
    fn terminate(&mut self) {
        // SAFETY: kill with a valid pid and signal.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        for _ in 0..50 {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            self.terminate();
        }
    }
}

/// The paper's left turn across processes: `concord run` and `concord feed` as children, this
/// process as the console.
fn demo(speed: f64, duration: f64, iox_path: Option<&Path>) -> Result<(), String> {
    if !(speed.is_finite() && (0.0..=30.0).contains(&speed)) {
        return Err(format!("--speed {speed}: expected 0 to 30 m/s"));
    }
    let prefix = format!("concord-demo-{}/", std::process::id());
    let iox_config = iox::init(iox_path).map_err(|e| e.to_string())?;
    let iox_args: Vec<String> = iox_path
        .map(|p| vec!["--iox-config".into(), p.display().to_string()])
        .unwrap_or_default();
    let with_iox = |mut v: Vec<String>| {
        v.extend(iox_args.iter().cloned());
        v
    };
    println!("Concord demo: the paper's unprotected left turn, CAV and HDV at {speed} m/s");
    let llm = DemoLlm::find();
    let mut sidecar = match llm.url() {
        Some(url) => {
            let mut args = with_iox(vec![
                "sidecar".into(),
                "--prefix".into(),
                prefix.clone(),
                "--llm-url".into(),
                url.to_string(),
                "--log".into(),
                DEMO_LOG.into(),
            ]);
            if Path::new(SIDECAR_CONFIG).exists() {
                args.extend(["--config".into(), SIDECAR_CONFIG.into()]);
            }
            Some(ChildProcess::spawn_with(
                &args.iter().map(String::as_str).collect::<Vec<_>>(),
                Stdio::null(),
                Stdio::piped(),
            )?)
        }
        None => None,
    };
    let core_args = with_iox(vec![
        "run".into(),
        "--prefix".into(),
        prefix.clone(),
        "--rate".into(),
        "50".into(),
    ]);
    let mut core = ChildProcess::spawn(
        &core_args.iter().map(String::as_str).collect::<Vec<_>>(),
        Stdio::null(),
    )?;
    let node = iox::node("concord-demo-console", &iox_config).map_err(|e| e.to_string())?;
    let decisions =
        iox::subscriber::<WireDecision>(&node, &services::name(&prefix, services::DECISION), 64)
            .map_err(|e| e.to_string())?;
    let stats = iox::subscriber::<CoreStats>(&node, &services::name(&prefix, services::STATS), 1)
        .map_err(|e| e.to_string())?;
    let ehmi = iox::subscriber::<EhmiMessage>(&node, &services::name(&prefix, services::EHMI), 32)
        .map_err(|e| e.to_string())?;
    let texts =
        iox::publisher::<IntentText>(&node, &services::name(&prefix, services::INTENT_TEXT))
            .map_err(|e| e.to_string())?;
    // What the passenger and the HDV's driver say, and when (s after the start).
    let mut script = vec![
        (
            1.0,
            TextSource::Passenger,
            0,
            "I am in a bit of a hurry, can we go?",
        ),
        (
            2.5,
            TextSource::RoadUser,
            1,
            "Go ahead, I will wait for you.",
        ),
    ]
    .into_iter()
    .peekable();
    // Message numbers per party (passenger, road user 1): each party numbers its own.
    let mut sent = std::collections::BTreeMap::new();
    let feed_args = with_iox(vec![
        "feed".into(),
        "--scenario".into(),
        "paper".into(),
        "--speed".into(),
        speed.to_string(),
        "--duration".into(),
        duration.to_string(),
        "--prefix".into(),
        prefix.clone(),
    ]);
    let mut feed = ChildProcess::spawn(
        &feed_args.iter().map(String::as_str).collect::<Vec<_>>(),
        Stdio::piped(),
    )?;
    let started = clock::now_ns();
    let mut last_print = 0u64;
    let mut last_stats = None;
    // Maneuver, source and advice verdict of the last decision printed.
    let mut last_shown = None;
    let feed_status = loop {
        if node.wait(Duration::from_millis(20)).is_err() {
            break None;
        }
        while let Ok(Some(d)) = decisions.receive() {
            let shown = Some((d.maneuver, d.source, d.advice));
            let now = clock::now_ns();
            if shown != last_shown || now - last_print > 1_000_000_000 {
                println!(
                    "{:6.2} s  {}",
                    (now - started) as f64 * 1e-9,
                    monitor::describe(&d)
                );
                last_shown = shown;
                last_print = now;
            }
        }
        let elapsed = (clock::now_ns() - started) as f64 * 1e-9;
        while let Some((_, source, id, text)) = script.next_if(|(t, ..)| elapsed >= *t) {
            let who = match source {
                TextSource::Passenger => "passenger".to_string(),
                TextSource::RoadUser => format!("road user {id}"),
            };
            println!("{elapsed:6.2} s  {who} says: {text:?}");
            let n = sent.entry((source as u8, id)).or_insert(0u64);
            *n += 1;
            let _ = iox::send(
                &texts,
                &IntentText::new(clock::now_ns(), *n, source, id, text),
            );
        }
        while let Ok(Some(m)) = ehmi.receive() {
            let to = match (m.audience, m.addressee) {
                (a, _) if a == Audience::Passenger as u8 => "HMI to the passenger".to_string(),
                (a, id) if a == Audience::RoadUser as u8 => format!("eHMI to road user {id}"),
                _ => "eHMI".to_string(),
            };
            println!("         {to}: {}", m.text().unwrap_or("(invalid UTF-8)"));
        }
        if let Ok((Some(s), _)) = iox::newest(&stats) {
            last_stats = Some(s);
        }
        if let Ok(Some(status)) = feed.0.try_wait() {
            break Some(status);
        }
    };
    let feed_output = feed.0.stdout.take().map(|mut out| {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut out, &mut s);
        s
    });
    std::thread::sleep(Duration::from_millis(300));
    if let Ok((Some(s), _)) = iox::newest(&stats) {
        last_stats = Some(s);
    }
    let sidecar_final = sidecar.as_mut().map(|sc| {
        sc.terminate();
        let mut err = String::new();
        if let Some(mut e) = sc.0.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut err);
        }
        err.lines()
            .find_map(|l| l.strip_prefix("concord sidecar: final: "))
            .map(str::to_string)
    });
    core.terminate();
    llm.stop();
    println!();
    match (
        feed_status,
        feed_output
            .as_deref()
            .and_then(|o| o.lines().find(|l| l.starts_with("feed summary"))),
    ) {
        (Some(st), Some(summary)) if st.success() => {
            let outcome = if summary.contains("completed=1") {
                "turn completed without collision"
            } else if summary.contains("collisions=1") {
                "COLLISION"
            } else {
                "turn not completed within the time limit"
            };
            println!("outcome: {outcome} ({summary})");
        }
        (status, _) => println!("outcome: the feed did not finish cleanly ({status:?})"),
    }
    match last_stats {
        Some(s) => {
            let us = |ns: u64| ns as f64 / 1000.0;
            println!(
                "core: {} frames decided, {} rejected, {} missed deadlines; cycle p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs; scene age p50 {:.0} µs",
                s.frames_accepted,
                s.frames_rejected.iter().sum::<u64>(),
                s.missed_deadlines,
                us(s.cycle_ns[0]),
                us(s.cycle_ns[2]),
                us(s.cycle_ns[4]),
                us(s.scene_age_ns[0])
            );
            let mut rejected = String::new();
            for v in AdviceVerdict::ALL.iter().skip(2) {
                if s.advice_verdicts[*v as usize] > 0 {
                    rejected += &format!(" {}={}", v.name(), s.advice_verdicts[*v as usize]);
                }
            }
            let mut failed = String::new();
            for f in AdviceFailure::ALL {
                if s.advice_failures[f as usize] > 0 {
                    failed += &format!(" {}={}", f.name(), s.advice_failures[f as usize]);
                }
            }
            println!(
                "advice: {} requests, {} answers in ({} superseded before a decision); accepted {}, rejected:{}; sidecar failures:{}",
                s.advice_requests,
                s.advice_received,
                s.advice_superseded,
                s.advice_verdicts[AdviceVerdict::Accepted as usize],
                if rejected.is_empty() {
                    " none"
                } else {
                    &rejected
                },
                if failed.is_empty() { " none" } else { &failed },
            );
            println!(
                "decisions: logit {}, advice {}, minimum-risk {}",
                s.decisions[0], s.decisions[1], s.decisions[2]
            );
        }
        None => println!("core: no statistics received"),
    }
    match (llm.url(), sidecar_final) {
        (Some(_), Some(Some(line))) => {
            println!("sidecar: {line}");
            println!("interaction log: {DEMO_LOG}");
        }
        (Some(_), _) => println!("sidecar: no final statistics (it did not exit cleanly)"),
        (None, _) => {}
    }
    Ok(())
}

/// The sidecar's configuration used by the demo when present.
const SIDECAR_CONFIG: &str = "deploy/sidecar.toml";
/// The demo's interaction log.
const DEMO_LOG: &str = "concord-demo-interactions.jsonl";
/// The local LLM server's script.
const LLM_SCRIPT: &str = "deploy/llm/llm.sh";

/// The LLM the demo's sidecar uses.
enum DemoLlm {
    /// A server already answers at the configured URL.
    Running(String),
    /// The demo started the local server and stops it at the end.
    Started(String),
    /// No LLM: the demo runs logit-only.
    Missing,
}

impl DemoLlm {
    /// Uses the configured server if it answers, else starts the local one if it is set up;
    /// says which, or why the demo runs without one.
    fn find() -> DemoLlm {
        let cfg = if Path::new(SIDECAR_CONFIG).exists() {
            concord_sidecar::SidecarConfig::load(Path::new(SIDECAR_CONFIG)).unwrap_or_default()
        } else {
            concord_sidecar::SidecarConfig::default()
        };
        let url = cfg.llm.base_url.clone();
        let probe = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| e.to_string())
            .and_then(|rt| rt.block_on(concord_sidecar::probe(&cfg.llm)));
        if let Ok(model) = probe {
            println!("LLM sidecar: using {model:?} at {url}");
            return DemoLlm::Running(url);
        }
        let local = url.starts_with("http://127.0.0.1:8181/");
        if !(local && Path::new(LLM_SCRIPT).exists()) {
            println!(
                "LLM sidecar: no LLM server answers at {url}; deciding logit-only (start one, or run `{LLM_SCRIPT} setup` from the repository root for the local default)."
            );
            return DemoLlm::Missing;
        }
        println!("LLM sidecar: starting the local LLM server ({LLM_SCRIPT} start)");
        match Process::new(LLM_SCRIPT)
            .arg("start")
            .stderr(Stdio::piped())
            .output()
        {
            Ok(out) if out.status.success() => {
                println!("LLM sidecar: local SmolLM2-135M at {url}");
                DemoLlm::Started(url)
            }
            Ok(out) => {
                let why = String::from_utf8_lossy(&out.stderr);
                println!(
                    "LLM sidecar: the local LLM is not set up ({}); deciding logit-only. Set it up with `{LLM_SCRIPT} setup`.",
                    why.lines().next().unwrap_or("no reason given").trim()
                );
                DemoLlm::Missing
            }
            Err(e) => {
                println!("LLM sidecar: cannot run {LLM_SCRIPT} ({e}); deciding logit-only.");
                DemoLlm::Missing
            }
        }
    }

    fn url(&self) -> Option<&str> {
        match self {
            DemoLlm::Running(u) | DemoLlm::Started(u) => Some(u),
            DemoLlm::Missing => None,
        }
    }

    /// Stops the server if the demo started it.
    fn stop(&self) {
        if let DemoLlm::Started(_) = self {
            let _ = Process::new(LLM_SCRIPT).arg("stop").output();
        }
    }
}

/// What an experiment reports.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Report {
    /// The paper's table and figures (Fig. 4, Fig. 7b).
    Paper,
    /// The interaction table.
    Interaction,
}

/// Runs `grid` in parallel with a progress line, writes the CSVs (and for `Report::Paper` the
/// figures) under `out`, and prints the summary table.
fn experiment(
    name: &str,
    report: Report,
    grid: Vec<concord_sim::experiment::Episode>,
    out: &Path,
    threads: Option<usize>,
    llm: Option<(llm_experiments::LlmAdvisor, String, u32)>,
) -> Result<(), String> {
    use concord_sim::experiment::{self as exp, ControllerKind};
    use concord_sim::world::ScenarioKind;
    use std::io::Write as _;
    let threads = threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let params = concord_core::Params::default();
    eprintln!(
        "concord experiment {name}: {} episodes on {threads} thread(s), output in {}",
        grid.len(),
        out.display()
    );
    let started = std::time::Instant::now();
    let outcomes = exp::run_all(&grid, &params, threads, |done, total| {
        if done % 10 == 0 || done == total {
            let width = 40;
            let filled = done * width / total.max(1);
            let elapsed = started.elapsed().as_secs_f64();
            let eta = elapsed / done.max(1) as f64 * (total - done) as f64;
            eprint!(
                "\r[{}{}] {done}/{total} episodes, {elapsed:.0} s, about {eta:.0} s left ",
                "=".repeat(filled),
                " ".repeat(width - filled)
            );
            let _ = std::io::stderr().flush();
        }
    });
    eprintln!();
    let mut outcomes = outcomes;
    if let Some((mut advisor, url, reps)) = llm {
        // The LLM runs: the paper's left turns and merges, one at a time, the same starts as
        // the grid's first reps.
        let episodes: Vec<_> = grid
            .iter()
            .filter(|e| {
                matches!(e.scenario, ScenarioKind::LeftTurn | ScenarioKind::Merge)
                    && e.controller == ControllerKind::ConcordLogit
                    && e.rep < reps
            })
            .flat_map(|e| {
                [
                    ControllerKind::ConcordLlmWait,
                    ControllerKind::ConcordLlmLatency,
                ]
                .map(|c| concord_sim::experiment::Episode {
                    controller: c,
                    ..e.clone()
                })
            })
            .collect();
        for (i, e) in episodes.iter().enumerate() {
            eprint!(
                "\rLLM runs: {}/{} episodes ({} at {url}) ",
                i + 1,
                episodes.len(),
                e.controller.name()
            );
            let _ = std::io::stderr().flush();
            outcomes.push(exp::run_episode_with(e, &params, Some(&mut advisor)));
        }
        eprintln!();
    }
    let rows = exp::summarize(&outcomes);
    exp::write_csv(out, &outcomes, &rows).map_err(|e| format!("writing {}: {e}", out.display()))?;
    let metrics = [
        ("avg_speed_mps", "average speed, m/s"),
        ("avg_abs_jerk_mps3", "average |jerk|, m/s³"),
        ("conflict_duration_s", "conflict duration, s"),
    ];
    let mut figures = Vec::new();
    if report == Report::Interaction {
        println!(
            "left_turn: a hesitant driver; left_turn_priority: a balanced driver on the minor road; stream: 2-6 cars of random styles"
        );
        print!("{}", exp::interaction_table(&rows));
    } else {
        for (scenario, file, title, which) in [
            (
                ScenarioKind::LeftTurn,
                "fig4_left_turn.svg",
                "Unprotected left turn (Fig. 4)",
                &metrics[..],
            ),
            (
                ScenarioKind::Merge,
                "fig7b_merge.svg",
                "Merge (Fig. 7b)",
                &metrics[..1],
            ),
        ] {
            if rows.iter().any(|r| r.scenario == scenario) {
                let path = out.join(file);
                concord_sim::plot::bars(&path, title, &rows, scenario, which)?;
                figures.push(path);
            }
        }
        print!("{}", exp::paper_table(&rows));
    }
    let total_collisions = |c: ControllerKind| {
        outcomes
            .iter()
            .filter(|o| o.episode.controller == c && o.metrics.collision)
            .count()
    };
    println!();
    for c in ControllerKind::EVERY {
        if !outcomes.iter().any(|o| o.episode.controller == c) {
            continue;
        }
        let mine = || outcomes.iter().filter(|o| o.episode.controller == c);
        println!(
            "{}: {} collisions in {} episodes; decisions logit {}, advice {}, minimum-risk {}",
            c.name(),
            total_collisions(c),
            mine().count(),
            mine().map(|o| o.sources[0]).sum::<u64>(),
            mine().map(|o| o.sources[1]).sum::<u64>(),
            mine().map(|o| o.sources[2]).sum::<u64>()
        );
    }
    let figures: Vec<String> = figures
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    println!(
        "wrote {}/episodes.csv, summary.csv, traces/{} in {:.0} s",
        out.display(),
        if figures.is_empty() {
            String::new()
        } else {
            format!(" and {}", figures.join(", "))
        },
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
