//! `concord run --geometry` overrides the configuration file's `service.geometry`, and the file
//! accepts every built-in geometry by its snake_case name; `--map` and `--route` load a map
//! file and pick the ego's lane, and a bad map or route stops the start with an error naming
//! it.

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
        (
            "highway-env-intersection",
            "highway-env-intersection (10 lanes",
        ),
        ("highway-env-merge", "highway-env-merge (3 lanes"),
    ] {
        let (ok, err) = run_briefly(&format!("geometry-{arg}"), &["--geometry", arg]);
        assert!(ok, "{err}");
        assert!(err.contains(&format!("map {shown}")), "{err}");
    }
    let bad = Command::new(CONCORD)
        .args(["run", "--geometry", "roundabout", "--duration", "0.1"])
        .output()
        .expect("concord runs");
    assert!(!bad.status.success());
}

fn maps_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/maps")
}

/// `concord run` for 0.3 s on its own prefix with `road` arguments: (success, stderr).
fn run_briefly(name: &str, road: &[&str]) -> (bool, String) {
    let prefix = format!("{name}-{}/", std::process::id());
    let out = Command::new(CONCORD)
        .args([
            "run",
            "--prefix",
            &prefix,
            "--rate",
            "50",
            "--duration",
            "0.3",
        ])
        .args(road)
        .output()
        .expect("concord run starts");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn run_loads_a_map_file_and_a_route() {
    let paper = maps_dir().join("paper.toml");
    let (ok, err) = run_briefly(
        "map",
        &["--map", paper.to_str().unwrap(), "--route", "cav_left"],
    );
    assert!(ok, "{err}");
    assert!(
        err.contains("map paper (8 lanes, 15 conflict points, route cav_left (lane 0))"),
        "{err}"
    );
    for (args, expected) in [
        (vec!["--route", "nowhere"], "no lane \"nowhere\""),
        (
            vec!["--map", "/nonexistent/map.toml"],
            "cannot read map /nonexistent/map.toml",
        ),
    ] {
        let mut cmd = Command::new(CONCORD);
        cmd.args(["run", "--duration", "0.1"]).args(&args);
        if args[0] == "--route" {
            cmd.arg("--map").arg(maps_dir().join("merge.toml"));
        }
        let out = cmd.output().expect("concord runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}

#[test]
fn a_configuration_file_names_its_map_relative_to_itself() {
    let dir = std::env::temp_dir().join(format!("concord-map-config-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("maps")).unwrap();
    std::fs::copy(maps_dir().join("merge.toml"), dir.join("maps/m.toml")).unwrap();
    let check = |route: &str| {
        let path = dir.join("concord.toml");
        std::fs::write(
            &path,
            format!("[service]\nmap = \"maps/m.toml\"\nroute = \"{route}\"\n"),
        )
        .unwrap();
        Command::new(CONCORD)
            .args(["params", "--check"])
            .arg(&path)
            .output()
            .expect("concord params runs")
    };
    let good = check("ramp");
    let bad = check("shoulder");
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        good.status.success(),
        "{}",
        String::from_utf8_lossy(&good.stderr)
    );
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("no lane \"shoulder\""));
}

/// `concord run --map` starts on every map shipped in `deploy/maps/` (and its SUMO networks
/// and OpenDRIVE files; the corridors with a route across both their junctions), deciding on
/// its tick or on each scene's arrival.
#[test]
fn every_shipped_map_runs() {
    let mut maps: Vec<_> = std::fs::read_dir(maps_dir())
        .unwrap()
        .map(|e| (e.unwrap().path(), None))
        .filter(|(p, _)| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    maps.sort();
    assert_eq!(maps.len(), 5, "{maps:?}");
    maps.push((maps_dir().join("sumo/paper.net.xml"), None));
    maps.push((maps_dir().join("opendrive/paper.xodr"), None));
    maps.push((maps_dir().join("sumo/corridor.net.xml"), Some("SJ1>J2N")));
    maps.push((maps_dir().join("opendrive/corridor.xodr"), Some("67>62")));
    for (k, (map, route)) in maps.iter().enumerate() {
        let arrival = k % 2 == 1;
        let mut road = vec!["--map", map.to_str().unwrap()];
        if let Some(r) = route {
            road.extend(["--route", r]);
        }
        if arrival {
            road.push("--on-arrival");
        }
        let (ok, err) = run_briefly(&format!("shipped{k}"), &road);
        assert!(ok, "{}: {err}", map.display());
        assert_eq!(err.contains("deciding on arrival"), arrival, "{err}");
        assert_eq!(err.contains("one per junction"), route.is_some(), "{err}");
    }
}
