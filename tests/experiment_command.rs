//! `concord experiment paper` end to end at one repetition: the CSVs, the traces and the
//! figures are written, and the summary covers every controller in both scenarios; with
//! `--llm`, Concord advised by the real local LLM runs in both timing modes.
//! `concord experiment interaction` at one repetition: its CSVs, traces and table.

#[path = "support/local_llm.rs"]
mod local_llm;

/// Runs `concord experiment paper ARGS --out DIR` in a fresh directory; returns it and stdout.
fn paper(tag: &str, args: &[&str]) -> (std::path::PathBuf, String) {
    experiment("paper", tag, args)
}

/// Runs `concord experiment WHICH ARGS --out DIR` in a fresh directory; returns it and stdout.
fn experiment(which: &str, tag: &str, args: &[&str]) -> (std::path::PathBuf, String) {
    let out = std::env::temp_dir().join(format!("concord-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_concord"))
        .args(["experiment", which])
        .args(args)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("concord runs");
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    (out, stdout)
}

#[test]
fn experiment_paper_writes_csvs_traces_and_figures() {
    let (out, stdout) = paper("experiment", &["--reps", "1", "--threads", "2"]);
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    // 2 scenarios × 3 speeds × 1 repetition × 4 controllers, and the header.
    assert_eq!(episodes.lines().count(), 1 + 24);
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 1 + 24);
    for c in ["idm", "game_theoretic", "concord_logit", "concord_oracle"] {
        assert!(stdout.contains(&format!("| left_turn | {c} | 8 |")), "{c}");
        assert!(stdout.contains(&format!("| merge | {c} | 8 |")), "{c}");
    }
    assert_eq!(std::fs::read_dir(out.join("traces")).unwrap().count(), 24);
    for fig in ["fig4_left_turn.svg", "fig7b_merge.svg"] {
        let svg = std::fs::read_to_string(out.join(fig)).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("concord_logit"),
            "{fig}"
        );
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn experiment_interaction_writes_csvs_traces_and_its_table() {
    let (out, stdout) = experiment(
        "interaction",
        "interaction",
        &["--reps", "1", "--threads", "2", "--seed", "500"],
    );
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    // 3 scenarios × 3 speeds × 1 repetition × 5 controllers, and the header.
    assert_eq!(episodes.lines().count(), 1 + 45);
    let header = episodes.lines().next().unwrap();
    for column in [
        "imposed_decel_mps2",
        "standing_s",
        "stood_in_crossing",
        "wait_while_other_stands_s",
        "wait_while_other_stands_total_s",
        "time_to_clear_s",
    ] {
        assert!(header.split(',').any(|c| c == column), "{column}");
    }
    // Every stream has 2 to 6 cars; the hesitant and minor-road left turns one.
    for line in episodes.lines().skip(1) {
        let cells: Vec<&str> = line.split(',').collect();
        let hdvs: usize = cells[4].parse().unwrap();
        match cells[0] {
            "stream" => assert!((2..=6).contains(&hdvs), "{line}"),
            "left_turn" => assert!(hdvs == 1 && cells[3] == "hesitant", "{line}"),
            "left_turn_priority" => assert!(hdvs == 1 && cells[3] == "balanced", "{line}"),
            other => panic!("unexpected scenario {other}"),
        }
    }
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 1 + 45);
    assert!(summary.lines().next().unwrap().contains("pet_s_min"));
    for scenario in ["left_turn", "left_turn_priority", "stream"] {
        for c in [
            "idm",
            "game_theoretic",
            "gap_acceptance",
            "concord_logit",
            "concord_oracle",
        ] {
            assert!(
                stdout.contains(&format!("| {scenario} | {c} | 8 | 1 |")),
                "{scenario} {c}"
            );
        }
    }
    assert!(stdout.contains("| imposed decel max m/s² |"));
    assert_eq!(std::fs::read_dir(out.join("traces")).unwrap().count(), 45);
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn experiment_paper_with_the_local_llm_runs_both_timing_modes() {
    let llm = local_llm::LocalLlm::start("experiment");
    let (out, stdout) = paper(
        "experiment-llm",
        &["--reps", "1", "--llm", &llm.url, "--llm-reps", "1"],
    );
    for scenario in ["left_turn", "merge"] {
        for c in ["concord_llm_wait", "concord_llm_latency"] {
            for speed in [6, 8, 10] {
                assert!(
                    stdout.contains(&format!("| {scenario} | {c} | {speed} | 1 | 0 |")),
                    "{scenario} {c} {speed}"
                );
            }
        }
    }
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert_eq!(episodes.lines().count(), 1 + 24 + 12);
    std::fs::remove_dir_all(&out).unwrap();
}
