//! `collect`: specialists rolled out into an MCAP dataset. A tiny G1 policy
//! trained for two iterations stands in for the specialists.
mod common;

use std::collections::BTreeMap;

use common::{load_config, Scratch};
use dreampolicy::collect::{collect, sha256_file, CollectConfig};
use dreampolicy::data::{Dataset, DatasetStats, Dims, Frame};
use dreampolicy::rl::runner;
use dreampolicy::terrain::TerrainKind;

fn tiny_policy(dir: &Scratch, name: &str, sets: &[&str]) -> std::path::PathBuf {
    let mut all = vec!["train.iterations=2"];
    all.extend_from_slice(sets);
    let cfg = load_config("test/g1_tiny.yaml", &all);
    runner::train(&cfg, &dir.0.join(name), false, true)
        .unwrap()
        .checkpoint
}

/// The tiny policy trained on a 3-level, 2-column map of uneven tiles.
fn tiny_uneven_policy(dir: &Scratch, extra: &[&str]) -> std::path::PathBuf {
    let mut sets = vec![
        "env.terrain.mode=map",
        "env.terrain.map.num_levels=3",
        "env.terrain.map.num_cols=2",
        "env.terrain.map.kinds={uneven: 1.0}",
    ];
    sets.extend_from_slice(extra);
    tiny_policy(dir, "uneven", &sets)
}

fn config(text: &str) -> CollectConfig {
    CollectConfig::from_str(text, "test", &[]).unwrap()
}

#[test]
fn collect_writes_whole_episodes_with_ids_flags_and_metadata() {
    let dir = Scratch::new("collect");
    let flat = tiny_policy(&dir, "flat", &[]);
    let uneven = tiny_uneven_policy(&dir, &[]);
    let text = format!(
        "specialists:\n  - {{terrain: flat, checkpoint: {}}}\n  - {{terrain: uneven, checkpoint: {}}}\n\
         n_envs: 3\nepisodes_per_env: 2\nrounds: 2\nepisode_length_s: 0.3\nthreads: 1\n",
        flat.display(),
        uneven.display()
    );
    let cfg = config(&text);
    let out = dir.0.join("dataset");
    let s = collect(&cfg, &text, &out, true).unwrap();
    assert_eq!(s.shards.len(), 4);
    // every env runs two episodes of at most 15 steps per round
    assert_eq!(s.episodes, 4 * 3 * 2);
    assert!(s.frames > 0 && s.frames <= 4 * 3 * 2 * 15, "{}", s.frames);
    assert!(s.bytes_per_frame > 0.0 && s.frames_per_s > 0.0);

    let ds = Dataset::open(&out, Default::default()).unwrap();
    let meta = ds.first_meta().unwrap();
    assert_eq!(meta.info.checkpoints["flat"], sha256_file(&flat).unwrap());
    assert_eq!(
        meta.info.checkpoints["uneven"],
        sha256_file(&uneven).unwrap()
    );
    assert!(meta.info.config.contains("episodes_per_env: 2"));
    assert!(!meta.info.mujoco_version.is_empty());

    // frames: per episode, steps 0..len, the done flag on the last one only
    let mut episodes: BTreeMap<(usize, u64), Vec<Frame>> = BTreeMap::new();
    let mut n = 0u64;
    for item in ds.frames() {
        let (shard, f) = item.unwrap();
        assert_eq!(f.state.len(), 98);
        assert!(f
            .state
            .iter()
            .chain(&f.action)
            .chain(&f.scan)
            .all(|x| x.is_finite()));
        episodes.entry((shard, f.episode)).or_default().push(f);
        n += 1;
    }
    assert_eq!(n, s.frames);
    assert_eq!(episodes.len() as u64, s.episodes);
    let mut kinds = BTreeMap::new();
    for ((shard, _), frames) in &episodes {
        let last = frames.len() - 1;
        for (k, f) in frames.iter().enumerate() {
            assert_eq!(f.step as usize, k);
            assert_eq!(f.terminated || f.truncated, k == last);
            assert_eq!(f.env, frames[0].env);
        }
        *kinds.entry((*shard, frames[0].terrain)).or_insert(0) += 1;
        // within an episode the pelvis pose moves continuously
        for w in frames.windows(2) {
            let d = (0..3)
                .map(|i| (w[1].pos[i] - w[0].pos[i]).powi(2))
                .sum::<f64>();
            assert!(d.sqrt() < 0.2, "pelvis jumped {} m", d.sqrt());
        }
    }
    let per_shard: Vec<_> = kinds.into_iter().collect();
    assert_eq!(
        per_shard,
        [
            ((0, TerrainKind::Flat), 6),
            ((1, TerrainKind::Flat), 6),
            ((2, TerrainKind::Uneven), 6),
            ((3, TerrainKind::Uneven), 6)
        ]
    );
    // the stats were written over the whole dataset
    DatasetStats::load(&out, Dims::G1).unwrap();

    // a second run keeps every finished shard and redoes an unfinished one
    let shard1 = out.join("shard-00001.mcap");
    std::fs::rename(&shard1, out.join("shard-00001.mcap.tmp")).unwrap();
    let again = collect(&cfg, &text, &out, true).unwrap();
    let skipped: Vec<bool> = again.shards.iter().map(|s| s.skipped).collect();
    assert_eq!(skipped, [true, false, true, true]);
    assert!(shard1.exists() && !out.join("shard-00001.mcap.tmp").exists());
}

#[test]
fn collect_refuses_mismatched_specialists_and_bad_configs() {
    let dir = Scratch::new("collect-bad");
    let flat = tiny_policy(&dir, "flat", &[]);
    let text = format!(
        "specialists:\n  - {{terrain: stair, checkpoint: {}}}\nn_envs: 2\nepisode_length_s: 0.2\nthreads: 1\n",
        flat.display()
    );
    let e = collect(&config(&text), &text, &dir.0.join("ds"), true)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("stair") && e.contains("plane"), "{e}");

    let e = CollectConfig::from_str("specialists: []\n", "t", &[])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("specialists is empty"), "{e}");
    let e = CollectConfig::from_str(
        "specialists: [{terrain: lava, checkpoint: x.pt}]\n",
        "t",
        &[],
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("lava"), "{e}");
    let e = CollectConfig::from_str(
        "specialists: [{terrain: flat, checkpoint: x.pt}]\nenvs: 3\n",
        "t",
        &[],
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("envs"), "{e}");
    let text = "specialists: [{terrain: flat, checkpoint: /nonexistent/x.pt}]\n";
    let e = collect(&config(text), text, &dir.0.join("ds2"), true)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("/nonexistent/x.pt"), "{e}");
}

/// A specialist's own `max_level` overrides the config's: its envs start on
/// levels `0..=max_level` of its training map only. Row `l` of the map holds
/// level `l` along x, so every episode's first pelvis x lies in one row with
/// `max_level: 0` and spreads over rows with the config's `max_level: 2`.
#[test]
fn collect_starts_each_specialist_at_its_own_levels() {
    let dir = Scratch::new("collect-levels");
    let tile = 8.0;
    let tile_set = format!("env.terrain.map.tile_length={tile}");
    let uneven = tiny_uneven_policy(&dir, &[&tile_set]);
    let spread = |own: &str, name: &str| {
        let text = format!(
            "specialists:\n  - {{terrain: uneven, checkpoint: {}{own}}}\n\
             n_envs: 8\nepisodes_per_env: 1\nrounds: 1\nepisode_length_s: 0.1\nthreads: 1\nmax_level: 2\n",
            uneven.display()
        );
        let out = dir.0.join(name);
        collect(&config(&text), &text, &out, true).unwrap();
        let xs: Vec<f64> = Dataset::open(&out, Default::default())
            .unwrap()
            .frames()
            .map(|f| f.unwrap().1)
            .filter(|f| f.step == 0)
            .map(|f| f.pos[0])
            .collect();
        assert_eq!(xs.len(), 8);
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        hi - lo
    };
    let own = spread(", max_level: 0", "own");
    let config_wide = spread("", "config");
    assert!(own < 0.5 * tile, "level 0 only: x spread {own} m");
    assert!(
        config_wide > 0.9 * tile,
        "levels 0-2: x spread {config_wide} m"
    );
}

/// A specialist that reads a finer scan grid records the paper's (default)
/// grid all the same: on the same lanes and seeds its episodes' first frames
/// hold the scandots of a default-grid specialist, not its own.
#[test]
fn collect_records_the_default_scan_grid_whatever_the_specialist_reads() {
    let dir = Scratch::new("collect-grid");
    let plain = tiny_uneven_policy(&dir, &[]);
    let fine_dir = Scratch::new("collect-grid-fine");
    let fine = tiny_uneven_policy(
        &fine_dir,
        &[
            "env.observation.scan_grid.x0=-0.25",
            "env.observation.scan_grid.y0=-0.25",
            "env.observation.scan_grid.spacing=0.05",
        ],
    );
    let first_scans = |ck: &std::path::Path, name: &str| {
        let text = format!(
            "specialists:\n  - {{terrain: uneven, checkpoint: {}}}\n\
             n_envs: 4\nepisodes_per_env: 1\nrounds: 1\nepisode_length_s: 0.1\nthreads: 1\n",
            ck.display()
        );
        let out = dir.0.join(name);
        collect(&config(&text), &text, &out, true).unwrap();
        let mut rows: Vec<(u32, Vec<f32>)> = Dataset::open(&out, Default::default())
            .unwrap()
            .frames()
            .map(|f| f.unwrap().1)
            .filter(|f| f.step == 0)
            .map(|f| (f.env, f.scan))
            .collect();
        rows.sort_by_key(|r| r.0);
        rows
    };
    let (a, b) = (first_scans(&plain, "plain"), first_scans(&fine, "fine"));
    assert_eq!(a.len(), 4);
    assert_eq!(a, b, "the same lanes give the same recorded scandots");
    let relief = a
        .iter()
        .flat_map(|r| r.1.iter())
        .fold(0f32, |m, v| m.max((v - a[0].1[0]).abs()));
    assert!(relief > 0.01, "the lanes have relief ({relief})");
}

/// `commands` replaces every specialist's training commands: a fixed yaw-rate
/// command (heading mode off) is the one every recorded state holds; a
/// specialist's own `commands` replaces the config's.
#[test]
fn collect_gives_the_config_commands_instead_of_the_training_ones() {
    use dreampolicy::env::obs::COMMAND;
    let dir = Scratch::new("collect-commands");
    let flat = tiny_policy(&dir, "flat", &[]);
    let text = format!(
        "specialists:\n  - {{terrain: flat, checkpoint: {}}}\n\
         n_envs: 2\nepisodes_per_env: 1\nrounds: 1\nepisode_length_s: 0.2\nthreads: 1\n\
         commands: {{heading_command: false, lin_vel_x: [0.6, 0.6], lin_vel_y: [0.0, 0.0], \
         ang_vel_yaw: [0.7, 0.7], min_norm: 0.0}}\n",
        flat.display()
    );
    let out = dir.0.join("dataset");
    collect(&config(&text), &text, &out, true).unwrap();
    let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&flat).unwrap();
    let scales = ck.config().unwrap().env.observation.scales.commands;
    // every recorded state holds the forward speed `vx` and yaw rate `yaw`
    let holds = |out: &std::path::Path, vx: f64, yaw: f64| {
        let mut n = 0;
        for f in Dataset::open(out, Default::default()).unwrap().frames() {
            let f = f.unwrap().1;
            let cmd = &f.state[COMMAND];
            assert!((cmd[0] as f64 - vx * scales[0]).abs() < 1e-5, "{cmd:?}");
            assert!((cmd[2] as f64 - yaw * scales[2]).abs() < 1e-5, "{cmd:?}");
            n += 1;
        }
        assert!(n > 0);
    };
    holds(&out, 0.6, 0.7);
    // a range that runs backwards is refused at load
    let bad = text.replace("[0.7, 0.7]", "[1.0, -1.0]");
    let e = CollectConfig::from_str(&bad, "test", &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("commands.ang_vel_yaw"), "{e}");

    // a specialist's own `commands` wins over the config's
    let own = text.replace(
        &format!("checkpoint: {}}}", flat.display()),
        &format!(
            "checkpoint: {}, commands: {{heading_command: false, lin_vel_x: [0.5, 0.5], \
             lin_vel_y: [0.0, 0.0], ang_vel_yaw: [-0.4, -0.4], min_norm: 0.0}}}}",
            flat.display()
        ),
    );
    assert_ne!(own, text);
    let out = dir.0.join("dataset-own");
    collect(&config(&own), &own, &out, true).unwrap();
    holds(&out, 0.5, -0.4);
    let bad = own.replace("[-0.4, -0.4]", "[1.0, -1.0]");
    let e = CollectConfig::from_str(&bad, "test", &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("specialists[flat].commands.ang_vel_yaw"), "{e}");
}
