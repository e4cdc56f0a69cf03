//! The unified policy's parts (issue 19): heading-frame kinematics from a state
//! against the simulator's own bodies, the tracking terms by hand, the
//! diffusion-AMP discriminator on a toy problem, and the history and plan
//! buffers across resets.
mod common;

use dreampolicy::env::obs::{COMMAND, CRITIC_DIM, GRAVITY, OBS_DIM};
use dreampolicy::env::VecEnv;
use dreampolicy::robot::NUM_JOINTS;
use dreampolicy::terrain::TerrainKind;
use dreampolicy::unified::amp::{AmpConfig, Discriminator, AMP_DIM, AMP_FEATURES};
use dreampolicy::unified::fk::{
    quat_from_gravity, quat_mul, quat_yaw, BodyFk, BodyFrames, N_TRACKED,
};
use dreampolicy::unified::plan::{History, Plan};
use dreampolicy::unified::track::{TrackingErrors, TrackingSigmas};
use rand::{Rng, SeedableRng};

/// libtorch's random generator is one per process: tests that seed it and
/// draw from it (network initialization, sampling) take turns, or a
/// bit-identical comparison sees another test's draws.
static TORCH: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn torch_lock() -> std::sync::MutexGuard<'static, ()> {
    TORCH.lock().unwrap_or_else(|e| e.into_inner())
}

fn max_diff(a: &BodyFrames, b: &BodyFrames) -> f64 {
    let mut m = 0.0f64;
    for k in 0..N_TRACKED {
        for i in 0..3 {
            m = m
                .max((a.pos[k][i] - b.pos[k][i]).abs())
                .max((a.lin_vel[k][i] - b.lin_vel[k][i]).abs())
                .max((a.ang_vel[k][i] - b.ang_vel[k][i]).abs());
        }
        // q and -q are the same rotation
        let dot: f64 = (0..4).map(|i| a.quat[k][i] * b.quat[k][i]).sum();
        m = m.max(1.0 - dot.abs());
    }
    m
}

/// The G1 under random actions (it stumbles and falls, so poses, tilts and
/// velocities vary, and some envs reset): the bodies a noise-free state fixes
/// are the simulator's bodies, and tracking that state scores 1 on all four terms.
#[test]
fn targets_from_a_state_reproduce_the_simulated_bodies() {
    let c = common::load_config(
        "flat_small.yaml",
        &[
            "env.n_envs=6",
            "env.observation.add_noise=false",
            "env.domain_rand.enabled=false",
        ],
    );
    let mut v = VecEnv::new(&c.env).unwrap();
    let model = v.envs()[0].data().model().clone();
    let mut fk = BodyFk::new(model, &c.env.observation.scales).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let n = v.n_envs();
    let (mut checked, mut moving, mut tilted) = (0, 0, 0);
    for t in 0..60 {
        let a: Vec<f32> = (0..n * NUM_JOINTS)
            .map(|_| rng.random_range(-1.5..1.5))
            .collect();
        v.step(&a);
        if t % 5 != 4 {
            continue;
        }
        for e in 0..n {
            let d = v.envs()[e].data();
            let sim = fk.from_qpos(d.qpos(), d.qvel());
            let state = &v.critic[e * CRITIC_DIM..e * CRITIC_DIM + OBS_DIM];
            let planned = fk.from_state(state);
            let diff = max_diff(&sim, &planned);
            assert!(diff < 2e-4, "env {e} step {t}: {diff}");
            let scores = TrackingErrors::between(&planned, &sim).scores(&TrackingSigmas::default());
            assert!(scores.iter().all(|&s| s > 0.9999), "{scores:?}");
            checked += 1;
            moving += usize::from(sim.lin_vel.iter().any(|v| v.iter().any(|x| x.abs() > 0.2)));
            tilted += usize::from(state[GRAVITY.start + 2] > -0.99);
        }
    }
    assert_eq!(checked, 72);
    assert!(
        moving > 30 && tilted > 10,
        "moving {moving}, tilted {tilted}"
    );
}

/// `unified.tracking.base_velocity: command`: a state's pelvis moves at the
/// command it holds, the robot's at its measured velocity. A state whose
/// command is the robot's own heading-frame velocity gives the simulator's
/// bodies (but for the pelvis's vertical speed, which a state does not hold),
/// and a command 0.3 m/s faster than the robot costs the linear-velocity score
/// exactly that error on every body, where the relative frame sees nothing.
#[test]
fn with_the_base_velocity_a_robot_slower_than_its_command_is_off_the_plan() {
    let c = common::load_config(
        "flat_small.yaml",
        &[
            "env.n_envs=4",
            "env.observation.add_noise=false",
            "env.domain_rand.enabled=false",
        ],
    );
    let mut v = VecEnv::new(&c.env).unwrap();
    let model = v.envs()[0].data().model().clone();
    let mut rel = BodyFk::new(model.clone(), &c.env.observation.scales).unwrap();
    let mut abs = BodyFk::new(model, &c.env.observation.scales)
        .unwrap()
        .with_base_velocity(true);
    let sc = c.env.observation.scales.commands;
    let sig = TrackingSigmas::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let (n, mut checked, mut fast) = (v.n_envs(), 0, 0);
    for t in 0..40 {
        let a: Vec<f32> = (0..n * NUM_JOINTS)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        v.step(&a);
        if t % 4 != 3 {
            continue;
        }
        for e in 0..n {
            let d = v.envs()[e].data();
            let (qpos, qvel) = (d.qpos().to_vec(), d.qvel().to_vec());
            // the pelvis's velocity in its heading frame, from the free joint
            let yaw = quat_yaw([qpos[3], qpos[4], qpos[5], qpos[6]]);
            let (sy, cy) = yaw.sin_cos();
            let vp = [
                cy * qvel[0] + sy * qvel[1],
                -sy * qvel[0] + cy * qvel[1],
                qvel[2],
            ];
            fast += usize::from(vp[0].hypot(vp[1]) > 0.2);
            let sim = abs.from_qpos(&qpos, &qvel);
            let sim_rel = rel.from_qpos(&qpos, &qvel);
            for k in 0..N_TRACKED {
                for i in 0..3 {
                    let dv = sim.lin_vel[k][i] - sim_rel.lin_vel[k][i];
                    assert!(
                        (dv - vp[i]).abs() < 1e-6,
                        "env {e} body {k}: {dv} vs {}",
                        vp[i]
                    );
                }
            }
            let mut state = v.critic[e * CRITIC_DIM..e * CRITIC_DIM + OBS_DIM].to_vec();
            state[COMMAND.start] = (vp[0] * sc[0]) as f32;
            state[COMMAND.start + 1] = (vp[1] * sc[1]) as f32;
            let planned = abs.from_state(&state);
            for k in 0..N_TRACKED {
                for i in 0..3 {
                    let want = sim.lin_vel[k][i] - if i == 2 { vp[2] } else { 0.0 };
                    let got = planned.lin_vel[k][i];
                    assert!(
                        (got - want).abs() < 2e-4,
                        "env {e} body {k} axis {i}: {got} vs {want}"
                    );
                }
            }
            let on = TrackingErrors::between(&planned, &sim);
            assert!(
                (on.lin_vel - vp[2] * vp[2]).abs() < 1e-3,
                "{} vs {}",
                on.lin_vel,
                vp[2] * vp[2]
            );
            // commanded 0.3 m/s faster forward than the robot goes
            state[COMMAND.start] = ((vp[0] + 0.3) * sc[0]) as f32;
            let ahead = TrackingErrors::between(&abs.from_state(&state), &sim);
            assert!(
                (ahead.lin_vel - on.lin_vel - 0.09).abs() < 1e-3,
                "{} vs {}",
                ahead.lin_vel,
                on.lin_vel
            );
            assert!(ahead.scores(&sig)[2] < on.scores(&sig)[2]);
            // the relative frame does not see the command
            let r_on = TrackingErrors::between(&rel.from_state(&state), &sim_rel);
            assert!(r_on.lin_vel < 1e-6, "{}", r_on.lin_vel);
            checked += 1;
        }
    }
    assert_eq!(checked, 40);
    assert!(fast > 5, "only {fast} states moved faster than 0.2 m/s");
}

#[test]
fn the_pelvis_orientation_from_gravity_gives_that_gravity_back() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    for _ in 0..200 {
        let (roll, pitch) = (rng.random_range(-1.4..1.4), rng.random_range(-1.4..1.4));
        let (sr, cr) = f64::sin_cos(roll);
        let (sp, cp) = f64::sin_cos(pitch);
        let g = [sp, -cp * sr, -cp * cr];
        let q = quat_from_gravity(g);
        // R^T (0, 0, -1) = conj(q) (0,0,-1) q
        let v = quat_mul(
            quat_mul([q[0], -q[1], -q[2], -q[3]], [0.0, 0.0, 0.0, -1.0]),
            q,
        );
        for i in 0..3 {
            assert!((v[i + 1] - g[i]).abs() < 1e-12, "{g:?} -> {v:?}");
        }
    }
}

/// Each term by hand: every body shifted 0.1 m (ē_p = 0.01), one body turned
/// 0.5 rad about z (ē_R = 0.25 / 14), every body 0.3 m/s faster in x
/// (ē_v = 0.09), one body spinning 2 rad/s more (ē_ω = 4 / 14).
#[test]
fn each_tracking_term_by_hand() {
    let desired = BodyFrames::default();
    let mut actual = BodyFrames::default();
    for k in 0..N_TRACKED {
        actual.pos[k][1] = 0.1;
        actual.lin_vel[k][0] = -0.3;
    }
    actual.quat[3] = [0.25f64.cos(), 0.0, 0.0, 0.25f64.sin()];
    actual.ang_vel[7] = [0.0, 2.0, 0.0];
    let e = TrackingErrors::between(&desired, &actual);
    let n = N_TRACKED as f64;
    assert!((e.pos - 0.01).abs() < 1e-12, "{e:?}");
    assert!((e.ori - 0.25 / n).abs() < 1e-12, "{e:?}");
    assert!((e.lin_vel - 0.09).abs() < 1e-12, "{e:?}");
    assert!((e.ang_vel - 4.0 / n).abs() < 1e-12, "{e:?}");
    let s = TrackingSigmas::default();
    let scores = e.scores(&s);
    let want = [
        (-0.01f64 / 0.09).exp(),
        (-0.25 / n / 0.16).exp(),
        (-0.09f64).exp(),
        (-4.0 / n / (std::f64::consts::PI * std::f64::consts::PI)).exp(),
    ];
    for i in 0..4 {
        assert!((scores[i] - want[i]).abs() < 1e-12, "{scores:?} {want:?}");
    }
    // the same rotation written as -q is no error
    let mut neg = BodyFrames::default();
    neg.quat[0] = [-1.0, 0.0, 0.0, 0.0];
    assert_eq!(TrackingErrors::between(&desired, &neg).ori, 0.0);
}

/// Two Gaussian clouds of transitions: D learns to tell them apart within a
/// few hundred updates, and the style reward favours the real one.
#[test]
fn the_discriminator_separates_two_distributions() {
    let _t = torch_lock();
    tch::manual_seed(0);
    let cfg = AmpConfig {
        hidden: vec![64, 64],
        learning_rate: 1e-3,
        batch: 128,
        ..AmpConfig::default()
    };
    let mut d = Discriminator::new(&cfg, tch::Device::Cpu);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    // states of OBS_DIM floats; the real transitions move every feature up, the fake ones down
    let batch = |up: bool, rng: &mut rand_chacha::ChaCha8Rng| {
        let n = cfg.batch;
        let mut s = vec![0.0f32; n * OBS_DIM];
        let mut s2 = vec![0.0f32; n * OBS_DIM];
        for i in 0..n {
            for j in AMP_FEATURES {
                let x = rng.random_range(-1.0f32..1.0);
                s[i * OBS_DIM + j] = x;
                let drift = if up { 0.3 } else { -0.3 };
                s2[i * OBS_DIM + j] = x + drift + rng.random_range(-0.1f32..0.1);
            }
        }
        Discriminator::features(&s, &s2, OBS_DIM)
    };
    let first = d.update(&batch(true, &mut rng), &batch(false, &mut rng));
    let mut last = first;
    for _ in 0..300 {
        last = d.update(&batch(true, &mut rng), &batch(false, &mut rng));
    }
    assert!(last.loss < 0.5 * first.loss, "{first:?} -> {last:?}");
    assert!(last.accuracy > 0.95, "{last:?}");
    let real = batch(true, &mut rng);
    let fake = batch(false, &mut rng);
    assert_eq!(real.len(), cfg.batch * 2 * AMP_DIM);
    let mean = |v: Vec<f32>| v.iter().sum::<f32>() / v.len() as f32;
    let (rr, rf) = (mean(d.style_reward(&real)), mean(d.style_reward(&fake)));
    assert!(rr > 0.7 && rf < 0.3, "style reward real {rr}, fake {rf}");
    assert!(d
        .style_reward(&fake)
        .iter()
        .all(|r| (0.0..=1.0).contains(r)));
}

/// The paper's padding: after a reset every history entry is `s_0`, and the
/// states then fill in from the right; plans shift by one each step (the last
/// state held), are due every `m` steps and right after a reset.
#[test]
fn history_padding_and_plan_shifting_across_resets() {
    let mut h = History::new(2, 3, 2);
    h.reset(0, &[1.0, 1.5]);
    h.reset(1, &[9.0, 9.5]);
    h.push(0, &[1.0, 1.5]); // t = 0: s_0 itself
    assert_eq!(h.row(0), [1.0, 1.5, 1.0, 1.5, 1.0, 1.5]);
    h.push(0, &[2.0, 2.5]);
    assert_eq!(h.row(0), [1.0, 1.5, 1.0, 1.5, 2.0, 2.5]);
    h.push(0, &[3.0, 3.5]);
    h.push(0, &[4.0, 4.5]);
    assert_eq!(h.row(0), [2.0, 2.5, 3.0, 3.5, 4.0, 4.5]);
    assert_eq!(h.row(1), [9.0, 9.5, 9.0, 9.5, 9.0, 9.5], "env 1 untouched");
    h.reset(0, &[7.0, 7.5]);
    assert_eq!(h.row(0), [7.0, 7.5, 7.0, 7.5, 7.0, 7.5]);

    // plans of 3 states of 1 float, re-planned every 2 steps
    let mut p = Plan::new(2, 3, 1, 2);
    assert_eq!(p.due().collect::<Vec<_>>(), [0, 1], "no plan yet");
    p.set(0, &[1.0, 2.0, 3.0]);
    p.set(1, &[10.0, 20.0, 30.0]);
    assert_eq!(p.due().count(), 0);
    assert_eq!(p.next(0), [1.0]);
    p.advance();
    assert_eq!(p.future(0), (&[2.0, 3.0, 3.0][..], true));
    assert_eq!(p.next(1), [20.0]);
    assert_eq!(p.due().count(), 0);
    p.invalidate(1); // env 1 resets
    assert_eq!(p.due().collect::<Vec<_>>(), [1]);
    assert!(!p.future(1).1);
    p.advance();
    assert_eq!(p.future(0).0, [3.0, 3.0, 3.0]);
    assert_eq!(p.due().collect::<Vec<_>>(), [0, 1], "env 0 is 2 steps old");
}

/// `unified.plan=hold`, the inference ablation: every plan is the env's
/// current state over the whole horizon, before and after steps; `eval` takes
/// the key, training refuses it.
#[test]
fn the_hold_ablation_plans_the_current_state() {
    let _t = torch_lock();
    use dreampolicy::env::task::VecTask;
    let cfg = common::load_config("test/unified_tiny.yaml", &["unified.plan=hold"]);
    let mut task = dreampolicy::unified::task::UnifiedTask::new(&cfg).unwrap();
    let (n, h) = (task.env().n_envs(), task.horizon());
    let held = |task: &dreampolicy::unified::task::UnifiedTask| {
        for i in 0..n {
            let row = &task.plans()[i * h * OBS_DIM..(i + 1) * h * OBS_DIM];
            for k in 1..h {
                assert_eq!(
                    row[k * OBS_DIM..(k + 1) * OBS_DIM],
                    row[..OBS_DIM],
                    "env {i}"
                );
            }
        }
    };
    held(&task);
    for i in 0..n {
        assert_eq!(
            task.plans()[i * h * OBS_DIM..i * h * OBS_DIM + OBS_DIM],
            task.env().obs[i * OBS_DIM..(i + 1) * OBS_DIM],
            "env {i}: s_0 itself"
        );
    }
    let acts = vec![0.0f32; n * NUM_JOINTS];
    for _ in 0..4 {
        task.step(&acts);
        held(&task);
    }
    let dir = common::Scratch::new("uni-hold");
    let e = dreampolicy::unified::train(&cfg, &dir.0, false, true)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unified.plan=hold") && e.contains("inference"),
        "{e}"
    );
    // another source is a config error naming the key's values
    let e = unified_config_error("plan", "hover");
    assert!(e.contains("hover") && e.contains("hold"), "{e}");
}

/// `unified.history: clean` plans from the env's noise-free states (the
/// critic's copy, what the expert dataset holds), `observed` from the
/// policy's noisy observations: read through the hold ablation, whose plan is
/// the history's newest state.
#[test]
fn a_clean_history_holds_the_noise_free_states() {
    let _t = torch_lock();
    use dreampolicy::env::obs::CRITIC_DIM;
    use dreampolicy::env::task::VecTask;
    let noisy = [
        "env.observation.add_noise=true",
        "unified.plan=hold",
        "unified.replan_every=1",
    ];
    for clean in [true, false] {
        let mut sets = noisy.to_vec();
        if clean {
            sets.push("unified.history=clean");
        }
        let cfg = common::load_config("test/unified_tiny.yaml", &sets);
        let mut task = dreampolicy::unified::task::UnifiedTask::new(&cfg).unwrap();
        let (n, h) = (task.env().n_envs(), task.horizon());
        let acts = vec![0.0f32; n * NUM_JOINTS];
        for step in 0..3 {
            if step > 0 {
                task.step(&acts);
            }
            for i in 0..n {
                let planned = &task.plans()[i * h * OBS_DIM..i * h * OBS_DIM + OBS_DIM];
                let critic = &task.env().critic()[i * CRITIC_DIM..i * CRITIC_DIM + OBS_DIM];
                let obs = &task.env().obs[i * OBS_DIM..(i + 1) * OBS_DIM];
                assert_ne!(critic, obs, "env {i}: the observation noise is on");
                let want = if clean { critic } else { obs };
                assert_eq!(planned, want, "env {i} step {step} clean {clean}");
            }
        }
    }
    // another source is a config error naming the key's values
    let e = unified_config_error("history", "privileged");
    assert!(e.contains("privileged") && e.contains("clean"), "{e}");
}

/// The error of the tiny unified config with `unified.<key>: <value>`.
fn unified_config_error(key: &str, value: &str) -> String {
    let mut bad = common::load_config("test/unified_tiny.yaml", &[]);
    if let Some(serde_yaml::Value::Mapping(m)) = bad.unified.as_mut() {
        m.insert(key.into(), value.into());
    }
    dreampolicy::unified::config::UnifiedConfig::of(&bad)
        .unwrap_err()
        .to_string()
}

/// A tiny unified run (the world model in the loop, the discriminator learning)
/// stopped at its first checkpoint and resumed ends where the uninterrupted run
/// ends: the same metrics rows (tracking scores, style reward and the
/// discriminator's loss included), the same discriminator weights and moments.
#[test]
fn a_resumed_tiny_unified_run_is_bit_identical() {
    let _t = torch_lock();
    use dreampolicy::rl::checkpoint::Checkpoint;
    use dreampolicy::run::latest_checkpoint;
    let cfg = common::load_config("test/unified_tiny.yaml", &[]);
    let (a, b) = (
        common::Scratch::new("uni-full"),
        common::Scratch::new("uni-resumed"),
    );
    dreampolicy::unified::train(&cfg, &a.0, false, true).unwrap();
    let mut half = cfg.clone();
    half.train.iterations = cfg.train.save_interval;
    dreampolicy::unified::train(&half, &b.0, false, true).unwrap();
    dreampolicy::unified::train(&cfg, &b.0, true, true).unwrap();
    // the resumed run's TensorBoard file: one, each step once, the unified
    // columns tagged, the values of metrics.csv's last row
    let files = dreampolicy::run::tensorboard::event_files(&b.0).unwrap();
    assert_eq!(files.len(), 1, "{files:?}");
    let events = dreampolicy::run::tensorboard::read_events(&files[0]).unwrap();
    let steps: Vec<i64> = events[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [1, 2, 3, 4]);
    let text = std::fs::read_to_string(b.0.join("metrics.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let row: Vec<&str> = text.lines().last().unwrap().split(',').collect();
    for (column, tag) in [
        ("amp_loss", "Loss/amp_loss"),
        ("track_pos", "Episode/track_pos"),
    ] {
        let cell: f64 = row[header.iter().position(|h| *h == column).unwrap()]
            .parse()
            .unwrap();
        let e = events.last().unwrap();
        let v = e.scalars.iter().find(|(t, _)| t == tag).map(|(_, v)| *v);
        assert_eq!(v, Some(cell as f32), "{tag}");
    }
    let rows = |dir: &std::path::Path| -> (Vec<String>, Vec<Vec<String>>) {
        let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
        let mut lines = text.lines();
        let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
        let keep: Vec<usize> = (0..header.len())
            .filter(|&i| !header[i].contains("time") && !header[i].contains("per_s"))
            .collect();
        let rows = lines
            .map(|l| {
                let v: Vec<&str> = l.split(',').collect();
                keep.iter().map(|&i| v[i].to_string()).collect()
            })
            .collect();
        (header, rows)
    };
    let ((header, ra), (_, rb)) = (rows(&a.0), rows(&b.0));
    assert_eq!(ra.len(), 4);
    assert_eq!(ra, rb, "the resumed run's metrics differ");
    // the mixed map's curriculum per kind (`level_<kind>`) beside the mean
    for name in [
        "amp_loss",
        "track_pos",
        "style_reward",
        "wm_plans",
        "level_flat",
        "level_bridge",
    ] {
        assert!(header.iter().any(|h| h == name), "no {name} column");
    }
    let at = |name: &str| header.iter().position(|h| h == name).unwrap();
    let last = |dir: &std::path::Path, name: &str| -> f64 {
        let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
        let row: Vec<String> = text
            .lines()
            .last()
            .unwrap()
            .split(',')
            .map(String::from)
            .collect();
        row[at(name)].parse().unwrap()
    };
    let track = last(&a.0, "track_pos");
    assert!((0.0..=1.0).contains(&track), "track_pos {track}");
    assert!(last(&a.0, "wm_plans") > 0.0);
    assert!(last(&a.0, "amp_loss").is_finite());
    let (ca, cb) = (
        Checkpoint::read(&latest_checkpoint(&a.0)).unwrap(),
        Checkpoint::read(&latest_checkpoint(&b.0)).unwrap(),
    );
    for name in [
        "amp.disc.out.weight",
        "amp.adam_m.disc.0.weight",
        "amp.norm",
        "amp.adam_step",
    ] {
        let (ta, tb) = (ca.task_tensor(name), cb.task_tensor(name));
        let (ta, tb) = (ta.unwrap_or_else(|| panic!("no {name}")), tb.unwrap());
        assert!(ta.equal(&tb), "{name} differs");
    }
    assert_eq!(
        ca.task_tensor("amp.adam_step").unwrap().int64_value(&[0]),
        8
    );

    // `eval` runs a unified checkpoint through the paper's inference loop (the
    // world model planning from the robot's history on the lane)
    for terrain in [TerrainKind::Flat, TerrainKind::Gap] {
        let o = dreampolicy::eval::EvalOptions {
            terrain,
            then: None,
            episodes: 2,
            full_collision: true,
            seed: 0,
            threads: 1,
            level: Some(0),
            table: dreampolicy::eval::EvalTable::Eval,
            lane_lookahead: None,
        };
        let r = dreampolicy::eval::evaluate(&ca, &o).unwrap();
        assert_eq!(r.episodes, 2);
        assert!((0.0..=1.0).contains(&r.completion_rate), "{r:?}");
    }
    // the inference keys change the plans, not the policy: eval takes them
    // (and records them), a training key is refused
    let mut cg = Checkpoint::read(&latest_checkpoint(&a.0)).unwrap();
    cg.set_eval(&[
        "unified.sampling.guidance=5".into(),
        "unified.replan_every=1".into(),
    ])
    .unwrap();
    let u = cg.config().unwrap();
    let u: dreampolicy::unified::config::UnifiedConfig =
        serde_yaml::from_value(u.unified.unwrap()).unwrap();
    assert_eq!((u.sampling.guidance, u.replan_every), (5.0, 1));
    let o = dreampolicy::eval::EvalOptions {
        full_collision: true,
        ..common::flat_eval(1)
    };
    let r = dreampolicy::eval::evaluate(&cg, &o).unwrap();
    assert_eq!(
        r.eval_sets,
        ["unified.sampling.guidance=5", "unified.replan_every=1"]
    );
    let e = cg
        .set_eval(&["unified.style_weight=0".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("inference keys"), "{e}");
    exported_bundle_runs_the_inference_loop(&ca, &a.0.join("bundle"));
    // and `play` draws the plan beside the robot
    let mcap = a.0.join("play.mcap");
    let mut o = dreampolicy::play::PlayOptions::new(TerrainKind::Stair, &mcap);
    o.seconds = 0.5;
    o.level = Some(0);
    let s = dreampolicy::play::play(&ca, &o).unwrap();
    let bytes = std::fs::read(&mcap).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let plan_channel = summary
        .channels
        .values()
        .find(|c| c.topic == "/plan")
        .expect("a /plan channel")
        .id;
    let stats = summary.stats.unwrap();
    assert_eq!(stats.channel_message_counts[&plan_channel], s.frames);
    let first = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .find(|m| m.channel.topic == "/plan")
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&first.data).unwrap();
    let spheres = v["entities"][0]["spheres"].as_array().unwrap();
    // a pelvis and two feet for each of the world model's H predicted states
    assert_eq!(spheres.len(), 3 * 8);
    let z = |i: usize| spheres[i]["pose"]["position"]["z"].as_f64().unwrap();
    assert!(
        z(0) > 0.5 && z(1) < 0.3 && z(2) < 0.3,
        "pelvis {} feet {} {}",
        z(0),
        z(1),
        z(2)
    );
}

/// The unified bundle of `ck` in `dir`: `policy.pt` acts as the checkpoint's
/// agent on the unified task's inputs, and the sampling loop `unified.json`
/// describes, run with `denoiser.pt`, gives the world model's own plan for the
/// same noise.
fn exported_bundle_runs_the_inference_loop(
    ck: &dreampolicy::rl::checkpoint::Checkpoint,
    dir: &std::path::Path,
) {
    use dreampolicy::rl::{Agent, VecTask};
    use dreampolicy::world_model::sampler::Noise;
    use tch::Tensor;
    let info = dreampolicy::unified::export::write_bundle(ck, dir).unwrap();
    assert_eq!(
        (info.history_len, info.plan_states, info.replan_every),
        (3, 4, 3)
    );
    let text = std::fs::read_to_string(dir.join("unified.json")).unwrap();
    dreampolicy::seal::check_json(&text).unwrap();
    let spec: serde_json::Value = serde_json::from_str(&text).unwrap();
    for f in ["policy", "world_model"] {
        let file = dir.join(spec[f]["file"].as_str().unwrap());
        assert_eq!(
            spec[f]["sha256"].as_str().unwrap(),
            dreampolicy::seal::file_sha256(&file).unwrap()
        );
    }

    // the policy: the agent's mean actions on the task's obs, history and plan
    let cfg = ck.config().unwrap();
    let mut task = dreampolicy::unified::task::UnifiedTask::new(&cfg).unwrap();
    let n = task.n_envs();
    let d = task.dims();
    let mut agent = Agent::new(&cfg.policy, d, n, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent).unwrap();
    agent.set_frozen(true);
    agent.reset_history(&task);
    let policy = tch::CModule::load(dir.join("policy.pt")).unwrap();
    for _ in 0..4 {
        agent.prepare(&task);
        let ours = agent.act_mean();
        let obs = Tensor::from_slice(task.obs()).view([n as i64, d.obs as i64]);
        let hist = Tensor::from_slice(agent.history()).view([n as i64, 3, d.obs as i64]);
        let plan = Tensor::from_slice(VecTask::scan(&task)).view([n as i64, d.scan as i64]);
        let theirs = policy.forward_ts(&[obs, hist, plan]).unwrap();
        let theirs = Vec::<f32>::try_from(theirs.contiguous().view([-1])).unwrap();
        let worst = common::max_abs_diff(&ours, &theirs);
        assert!(worst < 1e-4, "policy.pt differs from the agent by {worst}");
        let actions = ours.clone();
        task.step(&actions);
        agent.after_step(&task);
    }

    // the world model: unified.json's loop with denoiser.pt = WorldModel::predict
    let u = dreampolicy::unified::config::UnifiedConfig::of(&cfg).unwrap();
    let mut wm = dreampolicy::world_model::WorldModel::load(
        std::path::Path::new(&u.world_model),
        tch::Device::Cpu,
    )
    .unwrap();
    let (k, h) = (wm.history() as i64, wm.horizon() as i64);
    let (b, sd) = (3i64, OBS_DIM as i64);
    let hist = Tensor::from_slice(&task.env().obs[..OBS_DIM])
        .view([1, 1, sd])
        .repeat([b, k, 1])
        + Tensor::randn([b, k, sd], tch::kind::FLOAT_CPU) * 0.05;
    let scan = Tensor::from_slice(&task.env().scan[..3 * dreampolicy::env::obs::SCAN_DIM])
        .view([b, dreampolicy::env::obs::SCAN_DIM as i64]);
    let want = wm
        .predict(&hist, &scan, &u.sampling, &mut Noise::new(11))
        .unwrap();
    let denoiser = tch::CModule::load(dir.join("denoiser.pt")).unwrap();
    let ab: Vec<f64> = spec["sampler"]["alpha_bar"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let steps: Vec<usize> = spec["sampler"]["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(spec["sampler"]["kind"], "ddim");
    let stat = |key: &str| {
        let v: Vec<f32> = spec["world_model"][key]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        Tensor::from_slice(&v)
    };
    let mut x = Noise::new(11).randn(&[b, h, sd], tch::Device::Cpu);
    for (i, &s) in steps.iter().enumerate() {
        let nt = Tensor::from_slice(&vec![s as f32; b as usize]);
        let x0 = denoiser.forward_ts(&[&x, &hist, &nt, &scan]).unwrap();
        match steps.get(i + 1) {
            None => x = x0,
            Some(&m) => {
                let eps = (&x - &x0 * ab[s].sqrt()) / (1.0 - ab[s]).sqrt();
                x = x0 * ab[m].sqrt() + eps * (1.0 - ab[m]).sqrt();
            }
        }
    }
    let got = x * stat("state_std") + stat("state_mean");
    let worst = (got - &want).abs().max().double_value(&[]);
    assert!(
        worst < 1e-3,
        "the bundle's loop differs from the world model by {worst}"
    );

    // guidance other than 1 (both passes inside the traced graph), any batch
    for omega in [0.0, 5.0] {
        let f = dir.join(format!("denoiser_{omega}.pt"));
        dreampolicy::unified::export::trace_denoiser(&mut wm, omega, &f).unwrap();
        let m = tch::CModule::load(&f).unwrap();
        for rows in [1i64, 3] {
            let (hi, sc) = (hist.narrow(0, 0, rows), scan.narrow(0, 0, rows));
            let xn = Tensor::randn([rows, h, sd], tch::kind::FLOAT_CPU);
            let theirs = m
                .forward_ts(&[
                    &xn,
                    &hi,
                    &Tensor::from_slice(&vec![7.0f32; rows as usize]),
                    &sc,
                ])
                .unwrap();
            let ours = tch::no_grad(|| {
                let y = wm.net.terrain_embedding(&wm.norm.scans(&sc));
                dreampolicy::world_model::sampler::guided_x0(
                    &wm.net,
                    &xn,
                    &wm.norm.states(&hi),
                    7,
                    &y,
                    omega,
                )
            });
            let worst = (theirs - ours).abs().max().double_value(&[]);
            assert!(worst < 1e-4, "omega {omega}, batch {rows}: {worst}");
        }
    }
}

/// The small config's start: its foundation transferred into the unified
/// policy (zero columns for the future encoder, whose input is the plan, 8
/// states of 98) acts exactly as the foundation on the unified task's states,
/// so iteration 0 walks as the foundation does.
#[test]
fn the_foundation_transfers_into_the_unified_policy_acting_the_same() {
    let _t = torch_lock();
    use dreampolicy::rl::VecTask;
    let cfg = common::load_config("unified/small.yaml", &["env.n_envs=3"]);
    let (mut task, mut old, mut new, t) = common::foundation_into_unified(&cfg);
    assert_eq!(task.dims().scan, 8 * OBS_DIM);
    assert_eq!(t.widened, ["actor.0.weight", "critic.0.weight"]);
    common::assert_acts_alike(&mut old, &mut new, &mut task, 6);
    // the plans are fed: finite, and not all the same
    let s = task.scan();
    assert!(s.iter().all(|v| v.is_finite()));
    assert!(s.iter().any(|&v| v != s[0]));
}

/// The world model is conditioned on the dataset's scandots, which `collect`
/// records on the default grid: a unified env on another grid is refused.
#[test]
fn a_unified_env_on_another_scan_grid_is_refused() {
    let cfg = common::load_config(
        "unified/small.yaml",
        &["env.n_envs=2", "env.observation.scan_grid.spacing=0.05"],
    );
    let e = dreampolicy::unified::task::UnifiedTask::new(&cfg)
        .err()
        .expect("another grid than the world model's");
    assert!(e.to_string().contains("scan_grid"), "{e}");
}

/// `unified.scandots`: the policy reads `[plan | scandots]`, and the distilled
/// student (a policy reading the scandots, of the small config's layout)
/// transferred into it acts and values exactly as the student does on the
/// env's own scandots: the plan enters its scan encoder through zero columns,
/// the plan's normalizer statistics are the student's actor-state ones.
#[test]
fn a_scandot_reading_policy_transfers_into_a_unified_policy_reading_plan_and_scandots() {
    let _t = torch_lock();
    use dreampolicy::env::obs::SCAN_DIM;
    use dreampolicy::rl::checkpoint::Checkpoint;
    use dreampolicy::rl::{Agent, VecTask};
    let student = "models/checkpoints/dagger/checkpoints/latest.pt";
    let cfg = common::load_config(
        "unified/small.yaml",
        &[
            "env.n_envs=3",
            "unified.scandots=true",
            &format!("train.init_checkpoint={student}"),
        ],
    );
    let ck = Checkpoint::read(std::path::Path::new(student)).unwrap();
    let mut task = dreampolicy::unified::task::UnifiedTask::new(&cfg).unwrap();
    assert_eq!(task.dims().scan, 8 * OBS_DIM + SCAN_DIM);
    let n = task.n_envs();
    let mut old = Agent::new(&ck.config().unwrap().policy, task.env().dims(), n, true);
    ck.load_agent(&mut old).unwrap();
    let mut new = Agent::new(&cfg.policy, task.dims(), n, true);
    let t = ck.transfer_agent(&mut new).unwrap();
    assert_eq!(t.widened, ["scan_actor.0.weight", "scan_critic.0.weight"]);
    assert!(t.fresh.is_empty(), "{:?}", t.fresh);
    // the plan's normalizer is the actor state's, tiled; the scandots' the student's
    assert_eq!(new.scan_norm.mean[..OBS_DIM], old.obs_norm.mean[..]);
    assert_eq!(
        new.scan_norm.var[7 * OBS_DIM..8 * OBS_DIM],
        old.obs_norm.var[..]
    );
    assert_eq!(new.scan_norm.mean[8 * OBS_DIM..], old.scan_norm.mean[..]);
    assert_eq!(new.scan_norm.count, old.scan_norm.count);
    for a in [&mut old, &mut new] {
        a.set_frozen(true);
    }
    old.reset_history(task.env());
    new.reset_history(&task);
    for _ in 0..6 {
        // the task's rows end with the env's scandots
        let (s, e) = (task.scan(), &task.env().scan);
        let row = task.dims().scan;
        for i in 0..n {
            assert_eq!(
                s[i * row + 8 * OBS_DIM..(i + 1) * row],
                e[i * SCAN_DIM..(i + 1) * SCAN_DIM]
            );
        }
        old.prepare(task.env());
        new.prepare(&task);
        let (a, b) = (old.act_mean(), new.act_mean());
        assert!(common::max_abs_diff(&a, &b) < 1e-6);
        let (vo, vn) = (
            old.values_of(task.env().critic(), &task.env().scan),
            new.values_of(task.critic(), task.scan()),
        );
        assert!(common::max_abs_diff(&vo, &vn) < 1e-5, "{vo:?} {vn:?}");
        task.step(&a);
        old.after_step(task.env());
        new.after_step(&task);
    }
}

/// `export` of a policy reading `[plan | scandots]` (the committed
/// unified_student1): `unified.json` says so and counts the plan's states
/// without the scandots, and `policy.pt` on the task's obs, history and
/// `[plan | scandots]` rows gives the agent's actions.
#[test]
fn a_unified_policy_reading_the_scandots_exports_with_them() {
    let _t = torch_lock();
    use dreampolicy::env::obs::SCAN_DIM;
    use dreampolicy::rl::checkpoint::Checkpoint;
    use dreampolicy::rl::{Agent, VecTask};
    use tch::Tensor;
    let path = "models/checkpoints/unified_student1/checkpoints/latest.pt";
    let ck = Checkpoint::read(std::path::Path::new(path)).unwrap();
    let dir = common::Scratch::new("uni-scan-export");
    let info = dreampolicy::unified::export::write_bundle(&ck, &dir.0.join("b")).unwrap();
    assert!(info.scandots);
    assert_eq!(info.plan_states, 8);
    let text = std::fs::read_to_string(dir.0.join("b/unified.json")).unwrap();
    let spec: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(spec["policy"]["scandots"], true);
    assert_eq!(spec["policy"]["plan_states"], 8);
    assert!(spec["loop"].as_str().unwrap().contains("policy.scandots"));

    let mut cfg = ck.config().unwrap();
    cfg.env.n_envs = 2;
    let mut task = dreampolicy::unified::task::UnifiedTask::new(&cfg).unwrap();
    let (n, d) = (task.n_envs(), task.dims());
    assert_eq!(d.scan, 8 * OBS_DIM + SCAN_DIM);
    let mut agent = Agent::new(&cfg.policy, d, n, cfg.ppo.normalize_obs);
    ck.load_agent(&mut agent).unwrap();
    agent.set_frozen(true);
    agent.reset_history(&task);
    let k = cfg.policy.history.length as i64;
    let policy = tch::CModule::load(dir.0.join("b/policy.pt")).unwrap();
    for _ in 0..3 {
        agent.prepare(&task);
        let ours = agent.act_mean();
        let obs = Tensor::from_slice(task.obs()).view([n as i64, d.obs as i64]);
        let hist = Tensor::from_slice(agent.history()).view([n as i64, k, d.obs as i64]);
        let rows = Tensor::from_slice(VecTask::scan(&task)).view([n as i64, d.scan as i64]);
        let theirs = policy.forward_ts(&[obs, hist, rows]).unwrap();
        let theirs = Vec::<f32>::try_from(theirs.contiguous().view([-1])).unwrap();
        let worst = common::max_abs_diff(&ours, &theirs);
        assert!(worst < 1e-4, "policy.pt differs from the agent by {worst}");
        task.step(&ours);
        agent.after_step(&task);
    }
}
