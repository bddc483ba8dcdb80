//! `concord run --geometry` overrides the configuration file's `service.geometry`, and the file
//! accepts every built-in geometry by its snake_case name.

use std::process::Command;

const CONCORD: &str = env!("CARGO_BIN_EXE_concord");

#[test]
fn the_configuration_file_names_every_built_in_geometry() {
    let dir = std::env::temp_dir();
    for name in [
        "paper_intersection",
        "merge",
        "highway_env_intersection",
        "highway_env_merge",
    ] {
        let path = dir.join(format!(
            "concord-geometry-{}-{name}.toml",
            std::process::id()
        ));
        std::fs::write(&path, format!("[service]\ngeometry = \"{name}\"\n")).unwrap();
        let out = Command::new(CONCORD)
            .args(["params", "--check"])
            .arg(&path)
            .output()
            .expect("concord params runs");
        let _ = std::fs::remove_file(&path);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn run_takes_the_geometry_from_the_command_line() {
    for (arg, shown) in [
        ("highway-env-intersection", "HighwayEnvIntersection"),
        ("highway-env-merge", "HighwayEnvMerge"),
    ] {
        let prefix = format!("geometry-{}-{arg}/", std::process::id());
        let out = Command::new(CONCORD)
            .args([
                "run",
                "--prefix",
                &prefix,
                "--rate",
                "50",
                "--duration",
                "0.5",
            ])
            .args(["--geometry", arg])
            .output()
            .expect("concord run starts");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains(&format!("geometry {shown}")), "{err}");
    }
    let bad = Command::new(CONCORD)
        .args(["run", "--geometry", "roundabout", "--duration", "0.1"])
        .output()
        .expect("concord runs");
    assert!(!bad.status.success());
}
