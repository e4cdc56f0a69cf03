//! The w/o-diffusion baseline (`train no-diffusion`): the discriminator's real
//! transitions are exactly the dataset's consecutive frames of one episode and
//! nothing else, it learns to tell them from the policy's, and a run resumes
//! with it and is read by `eval` as any policy.
use dreampolicy::baselines::no_diffusion::{self, NoDiffusionTask};
use dreampolicy::env::obs::OBS_DIM;
use dreampolicy::env::task::VecTask;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::terrain::TerrainKind;
use dreampolicy::unified::amp::{Discriminator, AMP_DIM, AMP_FEATURES};

mod common;
use common::Scratch;

/// The synthetic expert state of episode `ord` at `step`: far from any state
/// the env gives (tens where the robot's are ones), distinct per episode and
/// step.
fn marker(ord: u32, step: u32) -> Vec<f32> {
    (0..OBS_DIM)
        .map(|k| 20.0 + ord as f32 + 0.1 * step as f32 + 0.001 * k as f32)
        .collect()
}

/// 2 envs x 10 steps: env 0 runs 4-step episodes on stairs (3 + 3 + 1
/// transitions: its third episode is cut at 2 frames), env 1 5-step ones on
/// the flat (4 + 4).
fn write_dataset(dir: &Scratch) -> std::path::PathBuf {
    let path = dir.0.join("dataset");
    std::fs::create_dir_all(&path).unwrap();
    common::write_synthetic_shard(
        &path,
        2,
        10,
        |e| 4 + e,
        |f, ord, env, step| {
            f.state.copy_from_slice(&marker(ord, step));
            f.terrain = if env == 0 {
                TerrainKind::Stair
            } else {
                TerrainKind::Flat
            };
        },
    );
    path
}

fn cfg(dataset: &std::path::Path, sets: &[&str]) -> dreampolicy::rl::config::ExperimentConfig {
    let mut all = vec![format!("no_diffusion.dataset={}", dataset.display())];
    all.extend(sets.iter().map(|s| s.to_string()));
    let all: Vec<&str> = all.iter().map(|s| s.as_str()).collect();
    common::load_config("test/no_diffusion_tiny.yaml", &all)
}

#[test]
fn real_transitions_are_the_datasets_consecutive_frames_of_one_episode() {
    let dir = Scratch::new("nodiff-real");
    let ds = write_dataset(&dir);
    let row = 2 * AMP_DIM;
    let (all, episodes) = no_diffusion::dataset_transitions(&ds, &[], 1000, 0).unwrap();
    assert_eq!(
        all.len() / row,
        15,
        "3 + 3 + 1 on stairs, 4 + 4 on the flat"
    );
    assert_eq!(episodes, 5);
    // every row is (s_t, s_t+1) of one episode, none spans two
    let mut expected = Vec::new();
    // episode ordinals: env 0 gets 0, env 1 gets 1, then they count up in the
    // order episodes start (env 0's second at step 4: 2; env 1's at step 5: 3;
    // env 0's third at step 8: 4)
    for (ord, len) in [(0u32, 4u32), (1, 5), (2, 4), (3, 5), (4, 2)] {
        for t in 0..len - 1 {
            expected.push(Discriminator::features(
                &marker(ord, t),
                &marker(ord, t + 1),
                OBS_DIM,
            ));
        }
    }
    let mut got: Vec<Vec<f32>> = all.chunks(row).map(|r| r.to_vec()).collect();
    let mut expected: Vec<Vec<f32>> = expected;
    let key = |v: &Vec<f32>| (v[0] * 1000.0) as i64 * 100_000 + (v[AMP_DIM] * 1000.0) as i64;
    got.sort_by_key(key);
    expected.sort_by_key(key);
    assert_eq!(got, expected);
    // the kind filter and the cap
    let (stairs, _) =
        no_diffusion::dataset_transitions(&ds, &[TerrainKind::Stair], 1000, 0).unwrap();
    assert_eq!(stairs.len() / row, 7);
    // the cap draws uniformly from the whole file, not its first rows: over
    // many seeds each of the 15 transitions is kept about 4 / 15 of the time
    // (the first-in-file-order rule kept the same 4 every time, all of them
    // from the episodes written first)
    let draws = 300;
    let mut kept: std::collections::HashMap<i64, usize> = Default::default();
    for seed in 0..draws {
        let (capped, _) = no_diffusion::dataset_transitions(&ds, &[], 4, seed).unwrap();
        assert_eq!(capped.len() / row, 4);
        for r in capped.chunks(row) {
            *kept.entry(key(&r.to_vec())).or_default() += 1;
        }
    }
    assert_eq!(kept.len(), 15, "every transition is drawn by some seed");
    for (k, n) in &kept {
        let share = *n as f64 / draws as f64;
        assert!(
            (share - 4.0 / 15.0).abs() < 0.1,
            "transition {k} kept in {share:.3} of the draws, not about 4/15"
        );
    }
    // the same seed draws the same rows
    let a = no_diffusion::dataset_transitions(&ds, &[], 4, 7).unwrap();
    let b = no_diffusion::dataset_transitions(&ds, &[], 4, 7).unwrap();
    assert_eq!(a, b);
    let e = no_diffusion::dataset_transitions(&ds, &[TerrainKind::Gap], 1000, 0)
        .expect_err("no gap episodes");
    assert!(e.to_string().contains("no two consecutive frames"), "{e}");
    // Φ is the motion slice of the state
    assert_eq!(AMP_FEATURES.len(), AMP_DIM);
}

#[test]
fn the_discriminator_reads_only_dataset_transitions_and_learns_them() {
    let dir = Scratch::new("nodiff-disc");
    let ds = write_dataset(&dir);
    let c = cfg(&ds, &[]);
    tch::set_num_threads(1);
    let mut task = NoDiffusionTask::new(&c).unwrap();
    let real = task.real().to_vec();
    assert_eq!(real.len() / (2 * AMP_DIM), 15);
    let n = task.n_envs();
    let zeros = vec![0.0f32; n * dreampolicy::robot::NUM_JOINTS];
    let mut last = Vec::new();
    for it in 0..12 {
        let mut live = 0;
        for _ in 0..8 {
            task.step(&zeros);
            live += task.outcomes().iter().filter(|o| !o.episode_done).count();
        }
        // the policy's transitions are the env's, from its noise-free states
        let fake = task.fake().to_vec();
        assert_eq!(fake.len() / (2 * AMP_DIM), live);
        assert!(
            fake.iter().all(|v| v.abs() < 19.0),
            "a fake row holds a dataset value"
        );
        last = task.after_rollout().unwrap();
        assert!(
            task.fake().is_empty(),
            "the policy's transitions are used once"
        );
        assert_eq!(
            task.real(),
            real.as_slice(),
            "iteration {it}: the real pool changed"
        );
        assert_eq!(last[6], 15.0, "real_transitions");
    }
    // D tells the dataset's transitions from the policy's
    let d_real: f64 = task
        .disc
        .d(&real)
        .iter()
        .map(|&d| f64::from(d))
        .sum::<f64>()
        / 15.0;
    assert!(last[2] > last[3], "d_real {} d_fake {}", last[2], last[3]);
    assert!(last[4] > 0.9, "accuracy {last:?}");
    assert!(d_real > 0.0, "D on the dataset's transitions: {d_real}");
}

#[test]
fn a_no_diffusion_run_resumes_with_its_discriminator_and_eval_reads_it() {
    let dir = Scratch::new("nodiff-run");
    let ds = write_dataset(&dir);
    let c = cfg(&ds, &[]);
    let run = dir.0.join("run");
    let s = no_diffusion::train(&c, &run, false, true).unwrap();
    assert_eq!((s.iterations, s.env_steps), (2, 64));
    let ck = Checkpoint::read(&run.join("checkpoints/latest.pt")).unwrap();
    assert!(
        ck.task_tensor("amp.norm").is_some(),
        "the discriminator is saved"
    );
    let mut more = c.clone();
    more.train.iterations = 3;
    let s = no_diffusion::train(&more, &run, true, true).unwrap();
    assert_eq!(s.iterations, 3);
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    assert!(metrics
        .lines()
        .next()
        .unwrap()
        .ends_with("real_transitions"));
    assert_eq!(metrics.lines().count(), 4);
    let ck = Checkpoint::read(&run.join("checkpoints/latest.pt")).unwrap();
    let r = dreampolicy::eval::evaluate(&ck, &common::flat_eval(2)).unwrap();
    assert_eq!((r.episodes, r.checkpoint_iteration), (2, 3));
    let e = dreampolicy::rl::runner::train(&c, &dir.0.join("x"), false, true)
        .expect_err("train specialist refuses it");
    assert!(e.to_string().contains("train no-diffusion"), "{e}");
}
