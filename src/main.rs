//! `concord`: the command line of the Concord decision service.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, Subcommand};
use concord_core::scene::{paper, AgentState, BuiltIn, Morphology, Scene, Vec2};
use concord_core::{DecisionCore, DecisionSource, Params};

#[derive(Parser)]
#[command(
    name = "concord",
    version,
    about = "Onboard interactive decision service for automated vehicles"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the paper's unprotected left turn in closed loop and print each decision.
    Demo {
        /// Initial speed of both vehicles, m/s (the paper uses 6, 8 and 10).
        #[arg(long, default_value_t = 8.0)]
        speed: f64,
        /// Parameter file (TOML); defaults are used for missing keys.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Simulated time limit, s.
        #[arg(long, default_value_t = 30.0)]
        duration: f64,
    },
    /// Print the default parameters as TOML, or check a parameter file.
    Params {
        /// File to check instead of printing the defaults.
        #[arg(long)]
        check: Option<PathBuf>,
    },
    /// Run the onboard core process over iceoryx2 (not yet available).
    Run,
    /// Publish synthetic scenes (not yet available).
    Feed,
    /// Show live counters of a running core (not yet available).
    Monitor,
    /// Run the LLM sidecar (not yet available).
    Sidecar,
    /// Rerun the paper's experiments (not yet available).
    Experiment,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo {
            speed,
            params,
            duration,
        } => demo(speed, params.as_deref(), duration),
        Command::Params { check: None } => toml::to_string_pretty(&Params::default())
            .map(|t| print!("{t}"))
            .map_err(|e| e.to_string()),
        Command::Params { check: Some(path) } => {
            load_params(Some(&path)).map(|_| println!("{}: ok", path.display()))
        }
        Command::Run | Command::Feed | Command::Monitor => {
            Err("not yet available: it lands with the onboard-service issue".into())
        }
        Command::Sidecar => Err("not yet available: it lands with the LLM-sidecar issue".into()),
        Command::Experiment => {
            Err("not yet available: it lands with the closed-loop evaluation issue".into())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("concord: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Parameters from `path` (or the defaults), validated.
fn load_params(path: Option<&Path>) -> Result<Params, String> {
    let params: Params = match path {
        None => Params::default(),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
            toml::from_str(&text).map_err(|e| format!("{}: {e}", p.display()))?
        }
    };
    params.validate().map_err(|e| e.to_string())?;
    Ok(params)
}

/// The paper's left turn against a constant-speed HDV, logit-only, at 20 Hz.
fn demo(speed: f64, params: Option<&Path>, duration: f64) -> Result<(), String> {
    if !(speed.is_finite() && (0.0..=30.0).contains(&speed)) {
        return Err(format!("--speed {speed}: expected 0 to 30 m/s"));
    }
    let params = load_params(params)?;
    let mut core = Box::new(
        DecisionCore::new(params, Morphology::built_in(BuiltIn::PaperIntersection))
            .map_err(|e| e.to_string())?,
    );
    let ego = AgentState::moving(0, Vec2::new(40.0, 5.0), std::f64::consts::PI, speed);
    let mut scene = Scene::new(0.0, ego, paper::CAV_LEFT);
    scene.push(AgentState::moving(1, Vec2::new(-40.0, -5.0), 0.0, speed));
    println!("Concord demo: the paper's unprotected left turn, CAV and HDV at {speed} m/s (in-process, logit-only, constant-speed HDV)");
    println!(
        "{:>6} {:>16} {:>6} {:>11} {:>7}  P_n [acc dec keep left right]",
        "t [s]", "ego (x, y) [m]", "v", "maneuver", "source"
    );
    let dt = 0.05;
    let mut latencies = Vec::new();
    let mut min_gap = f64::INFINITY;
    let mut cleared = None;
    let steps = (duration / dt).ceil() as u64;
    for k in 0..steps {
        let t = k as f64 * dt;
        scene.time_s = t;
        let started = Instant::now();
        let d = core
            .step(&scene, t, None)
            .map_err(|e| format!("scene rejected: {e:?}"))?;
        latencies.push(started.elapsed().as_secs_f64() * 1e6);
        if k % 10 == 0 || d.source == DecisionSource::MinimumRisk {
            let p = d.p_corrected.map(|v| format!("{v:.2}")).join(" ");
            println!(
                "{t:>6.2} ({:>6.1}, {:>5.1}) {:>6.2} {:>11} {:>7}  [{p}]",
                scene.ego.pos.x,
                scene.ego.pos.y,
                scene.ego.speed(),
                d.maneuver.name(),
                format!("{:?}", d.source).to_lowercase()
            );
        }
        let next = d.trajectory.sample(dt).ok_or("empty trajectory")?;
        let now = d.trajectory.points[0];
        let dir = Vec2::from_angle(next.heading);
        scene.ego = AgentState {
            pos: Vec2::new(next.x, next.y),
            vel: dir.scale(next.speed),
            acc: dir.scale((next.speed - now.speed) / dt),
            heading: next.heading,
            ..scene.ego
        };
        let hdv = &mut scene.agents[0];
        hdv.pos = hdv.pos.plus(hdv.vel.scale(dt));
        min_gap = min_gap.min(scene.ego.pos.minus(hdv.pos).norm());
        if scene.ego.pos.y < -15.0 {
            cleared = Some(t + dt);
            break;
        }
    }
    latencies.sort_by(f64::total_cmp);
    let pct = |q: f64| latencies[((latencies.len() - 1) as f64 * q).round() as usize];
    match cleared {
        Some(t) => println!("outcome: turn completed at {t:.2} s; closest approach {min_gap:.1} m"),
        None => println!(
            "outcome: turn not completed within {duration} s; closest approach {min_gap:.1} m"
        ),
    }
    println!(
        "step latency over {} steps: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
        latencies.len(),
        pct(0.5),
        pct(0.99),
        latencies[latencies.len() - 1]
    );
    Ok(())
}
