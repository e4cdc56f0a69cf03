//! TensorBoard event files beside `metrics.csv`: the record framing and the
//! `Event` encoding byte by byte (CRC32C's check value, a hand-encoded event,
//! unknown fields skipped), damaged and cut files refused naming the file and
//! the record, the tag map; then real runs read back with the CRC-checked
//! reader: a PPO run (cart-pole) and a world-model run (tiny synthetic dataset)
//! hold every non-NaN cell of `metrics.csv` at the row's iteration, and a run
//! resumed from a checkpoint older than its last row (with a torn record and a
//! stale file left behind) ends with one file that logs every step once.
mod common;

use std::path::{Path, PathBuf};

use common::{load_config, metrics_column as column, Scratch};
use dreampolicy::rl::runner;
use dreampolicy::run::latest_checkpoint;
use dreampolicy::run::tensorboard::{
    self, crc32c, event_files, masked_crc32c, read_events, record, tag, Event, EventFileError,
    FILE_VERSION,
};

static TORCH: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Training seeds libtorch's global generator: the tests that train take turns.
fn torch_lock() -> std::sync::MutexGuard<'static, ()> {
    TORCH.lock().unwrap_or_else(|e| e.into_inner())
}

fn scalar_event(step: i64, scalars: &[(&str, f32)]) -> Event {
    Event {
        wall_time: 1.7e9 + step as f64,
        step,
        file_version: None,
        scalars: scalars.iter().map(|(t, v)| (t.to_string(), *v)).collect(),
    }
}

#[test]
fn records_and_events_are_encoded_byte_by_byte() {
    // CRC-32C's check value, and the mask of the TFRecord format
    assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    assert_eq!(crc32c(b""), 0);
    // ((crc >> 15) | (crc << 17)) + 0xa282ead8
    let c = crc32c(b"abc");
    assert_eq!(
        masked_crc32c(b"abc"),
        c.rotate_right(15).wrapping_add(0xa282_ead8)
    );
    // Event{wall_time 1.5, step 3, summary {value {tag "a", simple_value 2}}}
    let e = Event {
        wall_time: 1.5,
        step: 3,
        file_version: None,
        scalars: vec![("a".into(), 2.0)],
    };
    let mut want = vec![0x09];
    want.extend(1.5f64.to_le_bytes());
    want.extend([0x10, 0x03, 0x2a, 0x0a, 0x0a, 0x08, 0x0a, 0x01, b'a', 0x15]);
    want.extend(2.0f32.to_le_bytes());
    assert_eq!(e.encode(), want);
    assert_eq!(Event::decode(&want).unwrap(), e);
    // the file-version event, and a negative step (ten-byte varint)
    for e in [
        Event {
            wall_time: 0.25,
            step: 0,
            file_version: Some(FILE_VERSION.into()),
            scalars: vec![],
        },
        scalar_event(-2, &[("Loss/x", -0.5), ("Train/y", f32::INFINITY)]),
    ] {
        assert_eq!(Event::decode(&e.encode()).unwrap(), e);
    }
    // fields we do not write (graph_def bytes, a varint field 7) are skipped
    let mut other = e.encode();
    other.extend([0x22, 0x02, 0xff, 0xff, 0x38, 0x96, 0x01]);
    assert_eq!(Event::decode(&other).unwrap(), e);
    assert!(Event::decode(&[0x09, 0x00]).is_err(), "cut double");
    // one record: length, its masked CRC, the data, the data's masked CRC
    let r = record(b"xyz");
    assert_eq!(&r[..8], &3u64.to_le_bytes());
    assert_eq!(&r[8..12], &masked_crc32c(&3u64.to_le_bytes()).to_le_bytes());
    assert_eq!(&r[12..15], b"xyz");
    assert_eq!(&r[15..], &masked_crc32c(b"xyz").to_le_bytes());
}

#[test]
fn damaged_and_cut_event_files_are_clear_errors() {
    let dir = Scratch::new("tb-damaged");
    let events: Vec<Event> = (1..=3)
        .map(|s| scalar_event(s, &[("Train/a", s as f32)]))
        .collect();
    let bytes: Vec<u8> = events.iter().flat_map(|e| record(&e.encode())).collect();
    let rec = record(&events[0].encode()).len();
    let path = dir.0.join("events.out.tfevents.1.test");
    std::fs::write(&path, &bytes).unwrap();
    assert_eq!(read_events(&path).unwrap(), events);
    let check = |bytes: &[u8], what: &str, offset: u64| {
        std::fs::write(&path, bytes).unwrap();
        let e = read_events(&path).unwrap_err();
        let ok = match (&e, what) {
            (
                EventFileError::Crc {
                    what: w, offset: o, ..
                },
                _,
            ) => *w == what && *o == offset,
            (EventFileError::Truncated { offset: o, .. }, "cut") => *o == offset,
            _ => false,
        };
        assert!(ok, "{what} at {offset}: {e:?}");
        assert!(e.to_string().contains(&path.display().to_string()), "{e}");
    };
    // a flipped byte in the second record's data, in its length, in the last CRC
    let mut b = bytes.clone();
    b[rec + 14] ^= 0x01;
    check(&b, "data", rec as u64);
    let mut b = bytes.clone();
    b[rec + 1] ^= 0x40;
    check(&b, "length", rec as u64);
    let mut b = bytes.clone();
    let n = b.len();
    b[n - 1] ^= 0x80;
    check(&b, "data", 2 * rec as u64);
    // cut inside the third record, inside its header
    check(&bytes[..bytes.len() - 3], "cut", 2 * rec as u64);
    check(&bytes[..2 * rec + 5], "cut", 2 * rec as u64);
    // a good record that is not an Event
    let junk = [bytes[..rec].to_vec(), record(&[0x0b])].concat();
    std::fs::write(&path, junk).unwrap();
    assert!(matches!(
        read_events(&path),
        Err(EventFileError::Proto { offset, .. }) if offset == rec as u64
    ));
    let missing = dir.0.join("nothing");
    let e = read_events(&missing).unwrap_err();
    assert!(e.to_string().contains("nothing"), "{e}");
}

#[test]
fn every_metrics_column_has_a_grouped_tag() {
    // rsl_rl's names
    for (col, want) in [
        ("mean_return", "Train/mean_reward"),
        ("value_loss", "Loss/value_function"),
        ("learning_rate", "Loss/learning_rate"),
        ("mean_std", "Policy/mean_noise_std"),
        ("env_steps_per_s", "Perf/total_fps"),
        ("rew_tracking_lin_vel", "Episode/rew_tracking_lin_vel"),
        ("terrain_level", "Episode/terrain_level"),
        ("kl", "Policy/kl"),
        ("time_physics_s", "Perf/time_physics_s"),
        ("env_steps", "Train/env_steps"),
        ("loss", "Loss/loss"),
        ("val_rollout_mse", "Loss/val_rollout_mse"),
        ("samples_per_s", "Perf/samples_per_s"),
        ("amp_grad_penalty", "Loss/amp_grad_penalty"),
        ("track_pos", "Episode/track_pos"),
        ("wm_time_s", "Perf/wm_time_s"),
        ("a_new_column", "Train/a_new_column"),
    ] {
        assert_eq!(tag(col), want, "{col}");
    }
    // every column of every trainer: a known group, and no two columns share a tag
    let g1 = load_config("test/g1_tiny.yaml", &[]);
    let env = dreampolicy::env::VecEnv::new(&g1.env).unwrap();
    let mut cols = runner::columns(&env);
    cols.extend(
        dreampolicy::world_model::trainer::COLUMNS
            .iter()
            .map(|c| c.to_string()),
    );
    cols.extend(
        dreampolicy::unified::task::METRICS
            .iter()
            .map(|c| c.to_string()),
    );
    let mut tags = std::collections::BTreeMap::new();
    for c in &cols {
        let t = tag(c);
        let group = t.split('/').next().unwrap();
        assert!(
            ["Train", "Loss", "Policy", "Perf", "Episode"].contains(&group),
            "{c} -> {t}"
        );
        if let Some(other) = tags.insert(t.clone(), c.clone()) {
            // the world model and PPO share a few column names (same meaning)
            assert_eq!(&other, c, "{other} and {c} both map to {t}");
        }
    }
}

/// The columns and rows of `dir/metrics.csv`.
fn metrics(dir: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let t = common::metrics_table(dir);
    let rows = (0..t.len())
        .map(|r| t.columns.iter().map(|c| c[r]).collect())
        .collect();
    (t.names, rows)
}

/// The one event file of `dir`, checked against `metrics.csv`: the version
/// event first, then one event per row at the row's iteration holding exactly
/// its non-NaN cells (as f32) under their tags. Returns the file and its events.
fn check_events(dir: &Path) -> (PathBuf, Vec<Event>) {
    let files = event_files(dir).unwrap();
    assert_eq!(files.len(), 1, "{files:?}");
    let name = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("events.out.tfevents."), "{name}");
    let events = read_events(&files[0]).unwrap();
    assert_eq!(events[0].file_version.as_deref(), Some(FILE_VERSION));
    assert!(events[0].scalars.is_empty());
    let (cols, rows) = metrics(dir);
    assert!(!rows.is_empty());
    assert_eq!(events.len(), rows.len() + 1, "one event per metrics row");
    for (row, e) in rows.iter().zip(&events[1..]) {
        assert_eq!(e.step as f64, row[0], "step = the iteration column");
        assert!(e.wall_time > 1.6e9, "unix wall time: {}", e.wall_time);
        let want: Vec<(String, f32)> = cols
            .iter()
            .zip(row)
            .skip(1)
            .filter(|(_, v)| !v.is_nan())
            .map(|(c, v)| (tag(c), *v as f32))
            .collect();
        assert_eq!(e.scalars.len(), want.len(), "step {}", e.step);
        for ((t, v), (wt, wv)) in e.scalars.iter().zip(&want) {
            assert_eq!(t, wt);
            assert_eq!(v.to_bits(), wv.to_bits(), "{t} at step {}", e.step);
        }
    }
    (files[0].clone(), events)
}

fn value(e: &Event, tag: &str) -> Option<f32> {
    e.scalars.iter().find(|(t, _)| t == tag).map(|(_, v)| *v)
}

#[test]
fn a_ppo_run_logs_its_metrics_as_events() {
    let _t = torch_lock();
    let dir = Scratch::new("tb-ppo");
    let cfg = load_config(
        "test/cartpole.yaml",
        &["train.iterations=3", "train.save_interval=3"],
    );
    runner::train(&cfg, &dir.0, false, true).unwrap();
    let (file, events) = check_events(&dir.0);
    let steps: Vec<i64> = events[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [1, 2, 3]);
    // rsl_rl's tags, and the env steps as a scalar
    let last = events.last().unwrap();
    for t in [
        "Train/mean_reward",
        "Loss/value_function",
        "Policy/mean_noise_std",
        "Perf/total_fps",
        "Loss/learning_rate",
    ] {
        assert!(value(last, t).is_some_and(f32::is_finite), "{t} missing");
    }
    // the cart-pole keeps no per-term episode means: its NaN column is not logged
    assert_eq!(
        column(&dir.0, "rew_upright").last().map(|v| v.is_nan()),
        Some(true)
    );
    assert_eq!(value(last, "Episode/rew_upright"), None);
    assert_eq!(value(last, "Train/env_steps"), Some((3 * 32 * 16) as f32));
    let log = std::fs::read_to_string(dir.0.join("log.txt")).unwrap();
    assert!(
        log.contains(&format!("tensorboard: {}", file.display())),
        "{log}"
    );
}

#[test]
fn a_resumed_run_logs_every_step_once() {
    let _t = torch_lock();
    let dir = Scratch::new("tb-resume");
    let sets = [
        "train.iterations=4",
        "train.save_interval=2",
        "train.keep_interval=2",
    ];
    let cfg = load_config("test/cartpole.yaml", &sets);
    runner::train(&cfg, &dir.0, false, true).unwrap();
    let (first_file, first) = check_events(&dir.0);
    // as if the run had been killed after logging iteration 4 but before its
    // checkpoint: the resume checkpoint is iteration 2's
    std::fs::copy(
        dir.0.join("checkpoints/iter_000002.pt"),
        latest_checkpoint(&dir.0),
    )
    .unwrap();
    // ... with half a record at the end of the file, and a stale file of
    // another session holding a step past the checkpoint
    let half = record(&scalar_event(5, &[("Train/mean_reward", 1.0)]).encode());
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&first_file)
        .unwrap();
    std::io::Write::write_all(&mut f, &half[..half.len() / 2]).unwrap();
    drop(f);
    let stale = dir.0.join("events.out.tfevents.1000.elsewhere");
    let bytes = [
        record(&first[0].encode()),
        record(&scalar_event(3, &[("Train/mean_reward", -7.0)]).encode()),
    ]
    .concat();
    std::fs::write(&stale, bytes).unwrap();
    assert_eq!(event_files(&dir.0).unwrap().len(), 2);

    let more = |n: &'static str| [&sets[1..], &[n]].concat();
    let cfg6 = load_config("test/cartpole.yaml", &more("train.iterations=6"));
    runner::train(&cfg6, &dir.0, true, true).unwrap();
    // one file; steps 1..6 once each, every one the value metrics.csv holds
    let (file, events) = check_events(&dir.0);
    assert!(!stale.exists());
    let steps: Vec<i64> = events[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [1, 2, 3, 4, 5, 6]);
    // steps up to the checkpoint keep their first session's wall times; the
    // steps logged again are new
    assert_eq!(events[1].wall_time, first[1].wall_time);
    assert_eq!(events[2].wall_time, first[2].wall_time);
    assert!(events[3].wall_time > first[4].wall_time);
    assert!(value(&events[3], "Train/mean_reward") != Some(-7.0));
    // a second resume at the last row keeps everything and adds nothing twice
    let cfg7 = load_config("test/cartpole.yaml", &more("train.iterations=7"));
    runner::train(&cfg7, &dir.0, true, true).unwrap();
    let (file2, events2) = check_events(&dir.0);
    let steps: Vec<i64> = events2[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [1, 2, 3, 4, 5, 6, 7]);
    for (a, b) in events[1..].iter().zip(&events2[1..]) {
        assert_eq!(a, b);
    }
    if file2 != file {
        assert!(!file.exists());
    }
}

#[test]
fn a_failing_event_file_operation_names_the_file() {
    let dir = Scratch::new("tb-error");
    let mut run = dreampolicy::run::RunDir::create(&dir.0, &"x", &["iteration", "a"]).unwrap();
    // an old "event file" that cannot be deleted: a non-empty directory
    let blocker = dir.0.join("events.out.tfevents.5.blocker");
    std::fs::create_dir_all(blocker.join("inside")).unwrap();
    let e = run.start_tensorboard().unwrap_err();
    assert!(
        e.to_string().contains("events.out.tfevents.5.blocker"),
        "{e}"
    );
    std::fs::remove_dir_all(&blocker).unwrap();
    let path = run.start_tensorboard().unwrap();
    run.metrics_row(&[1.0, f64::NAN]).unwrap();
    run.metrics_row(&[2.0, 0.5]).unwrap();
    let ev = read_events(&path).unwrap();
    assert_eq!(ev.len(), 3);
    assert!(ev[1].scalars.is_empty(), "NaN cells are not logged");
    assert_eq!(ev[2].scalars, [("Train/a".to_string(), 0.5)]);
    assert_eq!(tensorboard::FILE_PREFIX, "events.out.tfevents.");
}

#[test]
fn a_world_model_run_logs_its_metrics_as_events() {
    let _t = torch_lock();
    tch::set_num_threads(1);
    let dir = Scratch::new("tb-wm");
    let data = dir.0.join("data");
    common::write_synthetic_shard(
        &data,
        3,
        40,
        |env| 20 + 5 * env,
        |f, ord, _env, step| {
            for (j, v) in f.state.iter_mut().enumerate() {
                *v = (0.2 * step as f32 * (1.0 + 0.01 * j as f32) + ord as f32).sin();
            }
        },
    );
    let tiny = |iterations: usize| {
        let text = format!(
            "data: {{path: '{}', val_fraction: 0.2, shuffle: 64}}
model: {{history: 2, horizon: 4, layers: 1, hidden: 16, heads: 2, mlp_ratio: 2, terrain_hidden: [16], terrain_dim: 8, step_features: 8}}
diffusion: {{steps: 10, schedule: cosine}}
sampling: {{sampler: ddim, ddim_steps: 2, guidance: 2.0}}
train: {{iterations: {iterations}, batch_size: 8, learning_rate: 1.0e-3, rollout_windows: 2,
  supervised_iterations: 2, scheduled_iterations: 2,
  rollout_sampling: {{sampler: ddim, ddim_steps: 2, guidance: 2.0}},
  log_interval: 2, eval_interval: 4, val_sequences: 4, save_interval: 4,
  seed: 3, torch_threads: 1}}
",
            data.display()
        );
        dreampolicy::world_model::config::world_model_from_str(&text, "tiny", &[]).unwrap()
    };
    let run = dir.0.join("run");
    dreampolicy::world_model::train(&tiny(4), &run, false, true).unwrap();
    let (_, events) = check_events(&run);
    let steps: Vec<i64> = events[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [2, 4]);
    // validation only at step 4; the optimizer step is the axis
    assert_eq!(value(&events[1], "Loss/val_loss"), None);
    assert!(value(&events[2], "Loss/val_loss").is_some_and(f32::is_finite));
    assert!(value(&events[1], "Loss/loss").is_some_and(f32::is_finite));
    dreampolicy::world_model::train(&tiny(8), &run, true, true).unwrap();
    let (_, events) = check_events(&run);
    let steps: Vec<i64> = events[1..].iter().map(|e| e.step).collect();
    assert_eq!(steps, [2, 4, 6, 8]);
}

#[test]
fn a_run_begun_before_event_files_gets_one_from_its_metrics() {
    let dir = Scratch::new("tb-legacy");
    let cols = ["iteration", "wall_time_s", "mean_return"];
    let mut run = dreampolicy::run::RunDir::create(&dir.0, &"x", &cols).unwrap();
    for (i, wall, ret) in [(1.0, 10.0, f64::NAN), (2.0, 20.0, 1.5), (3.0, 30.5, 2.5)] {
        run.metrics_row(&[i, wall, ret]).unwrap();
    }
    assert!(event_files(&dir.0).unwrap().is_empty());
    let path = run.start_tensorboard().unwrap();
    run.metrics_row(&[4.0, 41.0, 3.5]).unwrap();
    let (_, ev) = check_events(&dir.0);
    assert_eq!(check_events(&dir.0).0, path);
    // the old rows sit their wall_time_s apart, the last one at the start
    assert!((ev[3].wall_time - ev[1].wall_time - 20.5).abs() < 1e-5);
    assert_eq!(ev[3].wall_time, ev[0].wall_time);
    assert!(ev[4].wall_time >= ev[3].wall_time);
    assert_eq!(
        ev[2].scalars,
        [
            ("Perf/wall_time_s".to_string(), 20.0),
            ("Train/mean_reward".to_string(), 1.5)
        ]
    );
}
