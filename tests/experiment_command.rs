//! `concord experiment paper` end to end at one repetition: the CSVs, the traces and the
//! figures are written, and the summary covers every controller in both scenarios; with
//! `--llm`, Concord advised by the real local LLM runs in both timing modes.

#[path = "support/local_llm.rs"]
mod local_llm;

/// Runs `concord experiment paper ARGS --out DIR` in a fresh directory; returns it and stdout.
fn paper(tag: &str, args: &[&str]) -> (std::path::PathBuf, String) {
    let out = std::env::temp_dir().join(format!("concord-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_concord"))
        .args(["experiment", "paper"])
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
fn experiment_paper_with_the_local_llm_runs_both_timing_modes() {
    let llm = local_llm::LocalLlm::start("experiment");
    let (out, stdout) = paper(
        "experiment-llm",
        &["--reps", "1", "--llm", &llm.url, "--llm-reps", "1"],
    );
    for c in ["concord_llm_wait", "concord_llm_latency"] {
        for speed in [6, 8, 10] {
            assert!(
                stdout.contains(&format!("| left_turn | {c} | {speed} | 1 | 0 |")),
                "{c} {speed}"
            );
        }
    }
    let episodes = std::fs::read_to_string(out.join("episodes.csv")).unwrap();
    assert_eq!(episodes.lines().count(), 1 + 24 + 6);
    std::fs::remove_dir_all(&out).unwrap();
}
