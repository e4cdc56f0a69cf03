//! Every experiment config we ship loads and validates (unknown keys stay errors).
use std::path::Path;

fn yaml_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            yaml_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "yaml") {
            out.push(p);
        }
    }
}

#[test]
fn every_shipped_config_loads() {
    let mut files = Vec::new();
    yaml_files(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs"),
        &mut files,
    );
    assert!(files.len() >= 10, "{files:?}");
    for f in &files {
        // configs/world_model/ holds the other file kind
        if f.parent().is_some_and(|d| d.ends_with("world_model")) {
            dreampolicy::world_model::config::load_world_model(f, &[])
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            continue;
        }
        // configs/collect/ holds collection runs
        if f.parent().is_some_and(|d| d.ends_with("collect")) {
            let c = dreampolicy::collect::CollectConfig::load(f, &[])
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            // every kind, in the paper's order (a kind may have more than one
            // entry, e.g. a second flat shard with other commands)
            let mut terrains: Vec<&str> =
                c.specialists.iter().map(|s| s.terrain.as_str()).collect();
            terrains.dedup();
            assert_eq!(
                terrains,
                ["flat", "uneven", "stair", "gap", "bridge"],
                "{}",
                f.display()
            );
            continue;
        }
        // configs/sim2sim/ holds sim-to-sim matrices: every cell applies to a
        // walker's eval env
        if f.parent().is_some_and(|d| d.ends_with("sim2sim")) {
            use dreampolicy::eval::sim2sim;
            let c = sim2sim::load(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            let flat = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/specialist/flat.yaml");
            let env = dreampolicy::rl::config::load(&flat, &[]).unwrap().env;
            for cell in &c.cells {
                sim2sim::cell_env(&env, cell).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            }
            continue;
        }
        // configs/benchmark/ holds benchmark files: the small one names
        // committed checkpoints, which must exist
        if f.parent().is_some_and(|d| d.ends_with("benchmark")) {
            let b = dreampolicy::benchmark::BenchmarkConfig::load(f, &[])
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            for m in &b.methods {
                for ck in m.checkpoint.iter().chain(m.checkpoints.values()) {
                    if ck.starts_with("models/") {
                        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(ck);
                        assert!(p.is_file(), "{}: {} missing", f.display(), ck.display());
                    }
                }
            }
            assert!(!b.cells().is_empty(), "{}", f.display());
            continue;
        }
        // configs/sweeps/ holds sweep files: every run's config loads
        if f.parent().is_some_and(|d| d.ends_with("sweeps")) {
            let s = dreampolicy::sweep::Sweep::load(f)
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            s.validate_runs()
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            assert!(!s.runs().is_empty(), "{}", f.display());
            // the scaling sweep's run names say its size and its kinds
            if f.ends_with("scaling_world_model.yaml") {
                let names: Vec<String> = s.runs().iter().map(|r| r.name.clone()).collect();
                assert_eq!(
                    names[0],
                    "000-size=0.25-kinds=flat+uneven+stair+gap+bridge-seed=1"
                );
                assert_eq!(names[3], "003-size=1.0-kinds=flat-seed=1");
            }
            continue;
        }
        let c = dreampolicy::rl::config::load(f, &[])
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        // a unified config's own section parses
        if c.task == dreampolicy::rl::config::TaskKind::Unified {
            let u = dreampolicy::unified::config::UnifiedConfig::of(&c)
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            // the committed one, where the config names one (paper-scale configs
            // name a run the user trains)
            let wm = Path::new(env!("CARGO_MANIFEST_DIR")).join(&u.world_model);
            if u.world_model.starts_with("models/") {
                assert!(wm.is_file(), "{}: {} missing", f.display(), u.world_model);
            }
        }
        // the baselines' own sections parse, and the committed files they
        // name exist
        let committed = |p: &str| {
            if p.starts_with("models/") {
                let full = Path::new(env!("CARGO_MANIFEST_DIR")).join(p);
                assert!(full.is_file(), "{}: {p} missing", f.display());
            }
        };
        if c.dagger.is_some() {
            let d = dreampolicy::baselines::dagger::DaggerConfig::of(&c)
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            let mut kinds: Vec<&str> = d.teachers.keys().map(|k| k.as_str()).collect();
            kinds.sort_unstable();
            if !f.to_string_lossy().contains("configs/test") {
                assert_eq!(
                    kinds,
                    ["bridge", "flat", "gap", "stair", "uneven"],
                    "{}",
                    f.display()
                );
                d.teachers.values().for_each(|p| committed(p));
            }
        }
        if c.task == dreampolicy::rl::config::TaskKind::NoGcrl {
            let n = dreampolicy::baselines::no_gcrl::NoGcrlConfig::of(&c)
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            committed(&n.world_model);
        }
    }
    // a unified section's typo is refused with the key named
    let tiny = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/test/unified_tiny.yaml");
    let c = dreampolicy::rl::config::load(&tiny, &["unified.replan_evry=3".into()]).unwrap();
    let e = dreampolicy::unified::config::UnifiedConfig::of(&c)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("replan_evry"), "{e}");
    // and a typo in a training section is refused with the key named
    let flat = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/specialist/flat.yaml");
    let e = dreampolicy::rl::config::load(&flat, &["ppo.learning_rat=1e-3".into()])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("learning_rat"), "{e}");
}

/// A trainer config written as another one changed (`base:` and `set:`) is
/// exactly its base with those `--set` overrides, through a chain of such
/// files, with the command line's `--set` last; anything else beside `base:`
/// and a loop of bases are refused with a line that says what to do.
#[test]
fn a_derived_config_is_its_base_with_its_set_list() {
    use dreampolicy::rl::config::load;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let uneven = root.join("configs/specialist/paper/uneven.yaml");
    let dir = tempfile::tempdir().unwrap();
    let yaml = |c: &dreampolicy::rl::config::ExperimentConfig| serde_yaml::to_string(c).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let one = write(
        "one.yaml",
        &format!(
            "# a comment\nbase: {}\nset:\n  - \"env.terrain.map.kinds={{stair: 1.0}}\"\n  - ppo.learning_rate=3.0e-4\n",
            uneven.display()
        ),
    );
    let sets = [
        "env.terrain.map.kinds={stair: 1.0}".to_string(),
        "ppo.learning_rate=3.0e-4".to_string(),
    ];
    let derived = load(&one, &[]).unwrap();
    assert_eq!(yaml(&derived), yaml(&load(&uneven, &sets).unwrap()));
    // the set replaces the base's mapping, it does not merge into it
    assert_eq!(derived.env.terrain.map.kinds.len(), 1);
    assert!(derived.ppo.learning_rate != load(&uneven, &[]).unwrap().ppo.learning_rate);

    // a chain of two, and the command line after both
    let two = write(
        "two.yaml",
        &format!("base: {}\nset: [train.iterations=7]\n", one.display()),
    );
    let cli = ["train.iterations=9".to_string()];
    let mut all = sets.to_vec();
    all.push("train.iterations=7".into());
    assert_eq!(
        yaml(&load(&two, &[]).unwrap()),
        yaml(&load(&uneven, &all).unwrap())
    );
    assert_eq!(load(&two, &cli).unwrap().train.iterations, 9);

    // a world-model file inherits the same way
    let wm = root.join("configs/world_model/small.yaml");
    let wm_child = write(
        "wm.yaml",
        &format!("base: {}\nset: [\"train.iterations=124\"]\n", wm.display()),
    );
    let a = dreampolicy::world_model::config::load_world_model(&wm_child, &[]).unwrap();
    let b =
        dreampolicy::world_model::config::load_world_model(&wm, &["train.iterations=124".into()])
            .unwrap();
    assert_eq!(
        serde_yaml::to_string(&a).unwrap(),
        serde_yaml::to_string(&b).unwrap()
    );

    // a mapping beside base: is refused, naming the key and the way to write it
    let mixed = write(
        "mixed.yaml",
        &format!(
            "base: {}\nppo:\n  learning_rate: 1.0e-3\n",
            uneven.display()
        ),
    );
    let e = load(&mixed, &[]).err().unwrap().to_string();
    assert!(e.contains("`ppo`") && e.contains("set:"), "{e}");
    // a set item that is not a string
    let not_str = write(
        "notstr.yaml",
        &format!("base: {}\nset:\n  - {{a: 1}}\n", uneven.display()),
    );
    let e = load(&not_str, &[]).err().unwrap().to_string();
    assert!(e.contains("key.path=value"), "{e}");
    // a loop of bases ends with a message, not a stack overflow
    let looped = dir.path().join("loop.yaml");
    std::fs::write(&looped, format!("base: {}\n", looped.display())).unwrap();
    let e = load(&looped, &[]).err().unwrap().to_string();
    assert!(e.contains("loop"), "{e}");
    // a missing base names the file
    let missing = write("missing.yaml", "base: no/such/file.yaml\n");
    let e = load(&missing, &[]).err().unwrap().to_string();
    assert!(e.contains("no/such/file.yaml"), "{e}");
}
