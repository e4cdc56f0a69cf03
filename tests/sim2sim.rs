//! The sim-to-sim matrix: cells change only what they name, a setting a build
//! cannot run is a note in its cell, other builds and the stock deployer become
//! columns, and the committed walker walks in the reference cell of every
//! build. Also run against MuJoCo 2.2.2 in CI (the build axis).
mod common;

use std::path::Path;
use std::process::Command;

use common::{walker_path, Scratch};
use dreampolicy::eval::sim2sim::{self, Cell, Sim2SimConfig};
use dreampolicy::rl::checkpoint::Checkpoint;

/// `dreampolicy sim2sim` on the committed walker with the matrix file `matrix`;
/// the caller adds the other flags.
fn sim2sim_walker(matrix: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_dreampolicy"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["sim2sim", "--checkpoint"])
        .arg(walker_path())
        .arg("--config")
        .arg(matrix);
    c
}

fn config(cells: &[(&str, &[&str])]) -> Sim2SimConfig {
    Sim2SimConfig {
        terrain: "flat".into(),
        level: None,
        episodes: 1,
        seed: 0,
        full_collision: true,
        cells: cells
            .iter()
            .map(|(n, s)| Cell {
                name: n.to_string(),
                set: s.iter().map(|x| x.to_string()).collect(),
            })
            .collect(),
        builds: Vec::new(),
        stock_deployer: None,
    }
}

#[test]
fn the_walker_loads_and_walks_the_reference_cell_on_this_build() {
    // a 3.x checkpoint's stored implicitfast reads as implicit on MuJoCo 2.x,
    // so that the build axis can load it
    let ck = Checkpoint::read(&walker_path()).unwrap();
    let cfg = ck.config().unwrap();
    let v3 = dreampolicy::sim::mujoco_version().starts_with('3');
    assert_eq!(
        cfg.env.sim.integrator == dreampolicy::env::config::Integrator::Implicitfast,
        v3
    );

    let c = config(&[
        ("reference", &[]),
        ("implicitfast", &["sim.integrator=implicitfast"]),
        (
            "solver 10 / 5",
            &["sim.iterations=10", "sim.ls_iterations=5"],
        ),
    ]);
    let mut seen = Vec::new();
    let rs = sim2sim::run_cells(&ck, &cfg, &c, 1, |i, n, name| {
        seen.push((i, n, name.to_string()))
    })
    .unwrap();
    assert_eq!(seen.len(), 3);
    assert_eq!(rs.len(), 3);
    assert_eq!(rs[0].success_rate, Some(1.0), "{:?}", rs[0]);
    assert_eq!(rs[0].episodes, 1);
    if v3 {
        assert!(rs[1].success_rate.is_some(), "{:?}", rs[1]);
    } else {
        // MuJoCo 2.x has no implicitfast: a note, not the end of the matrix
        let note = rs[1].note.as_deref().unwrap();
        assert!(note.contains("implicitfast"), "{note}");
        assert_eq!(rs[1].success_rate, None);
    }
    // too few line-search iterations: the walker falls at once (measured; the
    // README's sim-to-sim section)
    if v3 {
        assert!(rs[2].completion_rate.unwrap() < 0.5, "{:?}", rs[2]);
    }
}

#[test]
fn the_cli_writes_json_markdown_and_heatmap_with_the_build_and_deployer_columns() {
    let dir = Scratch::new("sim2sim-cli");
    let cfg_path = dir.0.join("matrix.yaml");
    std::fs::write(
        &cfg_path,
        "terrain: flat\nepisodes: 1\ncells:\n  - name: reference\n  - name: noise off\n    \
         set: [observation.add_noise=false]\nbuilds:\n  - name: MuJoCo 0.0\n    \
         binary: target/no-such-build/dreampolicy\n    build_command: make it\n\
         stock_deployer:\n  python: third_party/pyenv/bin/python\n  episodes: 1\n",
    )
    .unwrap();
    let out = dir.0.join("out");
    let o = sim2sim_walker(&cfg_path)
        .args(["--threads", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    for f in ["sim2sim.json", "sim2sim.md", "sim2sim.png"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let r: sim2sim::Sim2SimReport =
        serde_json::from_str(&std::fs::read_to_string(out.join("sim2sim.json")).unwrap()).unwrap();
    assert_eq!(r.builds.len(), 3, "{:?}", r.builds);
    assert_eq!(r.builds[0], sim2sim::this_build());
    assert_eq!(r.builds[1], "MuJoCo 0.0");
    // the missing build is a note with the command that builds it
    let missing = r.get("noise off", "MuJoCo 0.0").unwrap();
    assert!(missing.note.as_deref().unwrap().contains("make it"));
    // the stock deployer fills the reference row of its column
    let stock = r.get("reference", &r.builds[2]).unwrap();
    assert!(
        r.builds[2].starts_with("stock Python MuJoCo"),
        "{}",
        r.builds[2]
    );
    assert_eq!(stock.success_rate, Some(1.0), "{stock:?}");
    let md = std::fs::read_to_string(out.join("sim2sim.md")).unwrap();
    assert!(
        md.contains("| noise off |") && md.contains("make it"),
        "{md}"
    );
}

#[test]
fn a_bad_matrix_file_is_one_line_naming_the_cell() {
    let dir = Scratch::new("sim2sim-bad");
    let p = dir.0.join("bad.yaml");
    std::fs::write(
        &p,
        "cells:\n  - name: typo\n    set: [sim.timestpe=0.002]\n",
    )
    .unwrap();
    let o = sim2sim_walker(&p)
        .args(["--no-external", "--out"])
        .arg(dir.0.join("out"))
        .output()
        .unwrap();
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    // an unknown key is a note in its cell (the matrix goes on)
    assert!(out.contains("typo") && out.contains("timestpe"), "{out}");
    std::fs::write(&p, "cells: []\n").unwrap();
    let o = sim2sim_walker(&p).output().unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("reference cell"), "{err}");
    assert!(err.lines().count() <= 2, "{err}");
}

/// `--terrain`, `--level` and `--episodes` replace the matrix file's values, in
/// this build and in the other builds' binaries (here this same binary as the
/// other build: its cells must equal ours, which they only do when the
/// overrides reach it too).
#[test]
fn command_line_overrides_reach_every_build() {
    let dir = Scratch::new("sim2sim-override");
    let cfg_path = dir.0.join("matrix.yaml");
    std::fs::write(
        &cfg_path,
        format!(
            "terrain: flat\nepisodes: 5\ncells:\n  - name: reference\nbuilds:\n  - name: again\n    \
             binary: {}\n",
            env!("CARGO_BIN_EXE_dreampolicy")
        ),
    )
    .unwrap();
    let out = dir.0.join("out");
    let o = sim2sim_walker(&cfg_path)
        .args([
            "--threads",
            "1",
            "--terrain",
            "stair",
            "--level",
            "0",
            "--episodes",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let r: sim2sim::Sim2SimReport =
        serde_json::from_str(&std::fs::read_to_string(out.join("sim2sim.json")).unwrap()).unwrap();
    assert_eq!(
        (r.terrain.as_str(), r.level, r.episodes),
        ("stair", Some(0), 2)
    );
    assert_eq!(r.builds.len(), 2, "{:?}", r.builds);
    let ours = r.get("reference", &r.builds[0]).unwrap();
    let theirs = r.get("reference", &r.builds[1]).unwrap();
    assert_eq!(ours.episodes, 2);
    assert!(theirs.note.is_none(), "{theirs:?}");
    // the flat walker does not climb the paper's 15 cm stairs
    assert!(ours.success_rate.unwrap() < 1.0, "{ours:?}");
    assert_eq!(
        (ours.success_rate, ours.completion_rate, ours.falls),
        (theirs.success_rate, theirs.completion_rate, theirs.falls)
    );
    // an unknown terrain on the command line is one line naming it
    let o = sim2sim_walker(&cfg_path)
        .args(["--no-external", "--terrain", "moon"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("moon") && err.lines().count() <= 2, "{err}");
}
