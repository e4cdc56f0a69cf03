//! Damaged checkpoint files are refused, never loaded as if intact: seeded byte
//! flips, truncations and zeroed blocks over a tiny checkpoint, a world-model
//! checkpoint and the committed walker (the 24-flip experiment of issue 22:
//! every copy refused by `eval` with a one-line error), a run directory's
//! `config.yaml`, a dataset's `stats.json` and an export bundle (each of its
//! three files); files without a seal, and `checkpoint verify` / `checkpoint
//! seal`. The shards' suite is in `tests/data.rs` (it reuses that file's
//! synthetic shards).
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{walker_path, Scratch};
use dreampolicy::checkpoint::{save_named, seal_bytes, verify, NamedTensors, SealError};
use rand::{Rng, SeedableRng};
use tch::Tensor;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

/// `dreampolicy checkpoint <verb> <path>`.
fn checkpoint_cmd(verb: &str, path: &Path) -> std::process::Output {
    bin().args(["checkpoint", verb]).arg(path).output().unwrap()
}

fn assert_success(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Run `cmd` without backtraces; it must fail with one line on stderr, returned.
fn one_line_failure(cmd: &mut Command) -> String {
    let out = cmd.env_remove("RUST_BACKTRACE").output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "succeeded: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(!err.contains("frame #"), "{err}");
    err
}

/// Copies of `bytes`, each damaged one way, seeded: `flips` copies with 8
/// random bytes flipped, `cuts` truncations, `zeros` 64-byte blocks zeroed.
fn damaged(
    bytes: &[u8],
    seed: u64,
    flips: usize,
    cuts: usize,
    zeros: usize,
) -> Vec<(String, Vec<u8>)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for i in 0..flips {
        let mut b = bytes.to_vec();
        for _ in 0..8 {
            let at = rng.random_range(0..b.len());
            b[at] ^= rng.random_range(1..=255u8);
        }
        out.push((format!("flip{i}"), b));
    }
    for i in 0..cuts {
        let len = rng.random_range(0..bytes.len());
        out.push((format!("cut{i}"), bytes[..len].to_vec()));
    }
    for i in 0..zeros {
        let mut b = bytes.to_vec();
        let at = rng.random_range(0..b.len() - 64);
        if b[at..at + 64].iter().all(|&x| x == 0) {
            b[at] = 1; // a block already zero: damage it anyway
        } else {
            b[at..at + 64].fill(0);
        }
        out.push((format!("zero{i}"), b));
    }
    out
}

fn tiny_checkpoint(path: &Path) {
    let named = vec![
        (
            "actor.w".to_string(),
            Tensor::from_slice(&[1.0f32, -2.0, 3.5, 0.25]).reshape([2, 2]),
        ),
        ("critic.b".to_string(), Tensor::from_slice(&[0.5f64; 7])),
    ];
    save_named(
        path,
        named,
        &serde_json::json!({"iteration": 12, "note": "tiny"}),
    )
    .unwrap();
}

#[test]
fn a_checkpoint_is_sealed_and_reads_back() {
    let dir = Scratch::new("seal");
    let p = dir.0.join("t.pt");
    tiny_checkpoint(&p);
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(verify(&bytes), Ok(()));
    let f = NamedTensors::<serde_json::Value>::read(&p).unwrap();
    assert_eq!(f.meta["iteration"], 12);
    let w = f.tensor("actor.w").unwrap();
    assert_eq!(
        Vec::<f32>::try_from(w.flatten(0, -1)).unwrap(),
        [1.0, -2.0, 3.5, 0.25]
    );
    // sealing twice is refused
    assert_eq!(seal_bytes(bytes.clone()), Err(SealError::AlreadySealed));
}

#[test]
fn every_damaged_copy_of_a_checkpoint_is_refused_with_one_line() {
    let dir = Scratch::new("damage");
    let p = dir.0.join("t.pt");
    tiny_checkpoint(&p);
    let bytes = std::fs::read(&p).unwrap();
    let copies = damaged(&bytes, 7, 60, 20, 20);
    for (name, b) in &copies {
        let q = dir.0.join(format!("{name}.pt"));
        std::fs::write(&q, b).unwrap();
        let e = match NamedTensors::<serde_json::Value>::read(&q) {
            Ok(_) => panic!("{name} loaded as if intact"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(&q.display().to_string()), "{name}: {e}");
        assert!(!e.contains('\n'), "{name}: more than one line: {e}");
    }
}

#[test]
fn a_file_without_a_seal_is_refused_until_sealed_explicitly() {
    let dir = Scratch::new("unsealed");
    let p = dir.0.join("t.pt");
    tiny_checkpoint(&p);
    let mut bytes = std::fs::read(&p).unwrap();
    // strip the seal: the archive exactly as libtorch wrote it
    let n = bytes.len() - 83;
    bytes.truncate(n);
    bytes[n - 2..].copy_from_slice(&[0, 0]);
    let old = dir.0.join("old.pt");
    std::fs::write(&old, &bytes).unwrap();
    // libtorch itself reads it
    assert_eq!(Tensor::load_multi(&old).unwrap().len(), 3);
    let e = NamedTensors::<serde_json::Value>::read(&old)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no integrity seal") && e.contains("checkpoint seal"),
        "{e}"
    );
    let out = bin()
        .args(["checkpoint", "verify"])
        .arg(&old)
        .arg(&p)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("BAD") && text.contains("ok   "), "{text}");
    let out = bin()
        .args(["checkpoint", "seal"])
        .arg(&old)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("warning"));
    assert_eq!(
        std::fs::read(&old).unwrap(),
        std::fs::read(&p).unwrap(),
        "the same seal as at save"
    );
    NamedTensors::<serde_json::Value>::read(&old).unwrap();
    let out = bin()
        .args(["checkpoint", "seal"])
        .arg(&old)
        .output()
        .unwrap();
    assert!(!out.status.success(), "a sealed file is not sealed again");
}

#[test]
fn the_committed_walker_refuses_24_copies_with_8_flipped_bytes_in_eval() {
    let dir = Scratch::new("walker24");
    let bytes = std::fs::read(walker_path()).unwrap();
    assert_eq!(verify(&bytes), Ok(()), "the committed walker is sealed");
    let mut copies = damaged(&bytes, 2026, 24, 0, 0);
    copies.extend(damaged(&bytes, 5, 0, 1, 0));
    for (name, b) in &copies {
        let q: PathBuf = dir.0.join(format!("{name}.pt"));
        std::fs::write(&q, b).unwrap();
        let err = one_line_failure(
            bin()
                .args(["eval", "--episodes", "1", "--checkpoint"])
                .arg(&q),
        );
        assert!(err.contains(&format!("{name}.pt")), "{name}: {err}");
    }
}

#[test]
fn a_damaged_world_model_checkpoint_is_refused() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/checkpoints/world_model_expert/checkpoints/latest.pt");
    let dir = Scratch::new("wmdamage");
    let bytes = std::fs::read(&path).unwrap();
    dreampolicy::world_model::WmCheckpoint::read(&path).unwrap();
    for (name, b) in damaged(&bytes, 11, 6, 2, 2) {
        let q = dir.0.join(format!("{name}.pt"));
        std::fs::write(&q, &b).unwrap();
        let e = match dreampolicy::world_model::WmCheckpoint::read(&q) {
            Ok(_) => panic!("{name} loaded as if intact"),
            Err(e) => e.to_string(),
        };
        assert!(
            e.contains(&format!("{name}.pt")) && !e.contains('\n'),
            "{name}: {e}"
        );
    }
}

/// A run directory's `config.yaml` is sealed; every damaged copy is refused by
/// the resume check, with one line naming it, and an unsealed one needs
/// `checkpoint seal`.
#[test]
fn every_damaged_copy_of_a_run_config_is_refused() {
    let dir = Scratch::new("cfgdamage");
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/flat_small.yaml");
    let cfg = dreampolicy::rl::config::load(&base, &[]).unwrap();
    let run = dir.0.join("run");
    dreampolicy::run::RunDir::create(&run, &cfg, &["iteration"]).unwrap();
    let path = run.join("config.yaml");
    dreampolicy::config::require_seal(&path).unwrap();
    let yaml = |c: &dreampolicy::rl::config::ExperimentConfig| serde_yaml::to_string(c).unwrap();
    assert_eq!(
        yaml(&dreampolicy::rl::config::load(&path, &[]).unwrap()),
        yaml(&cfg)
    );
    let bytes = std::fs::read(&path).unwrap();
    for (name, b) in damaged(&bytes, 31, 30, 10, 10) {
        let q = dir.0.join(format!("{name}.yaml"));
        std::fs::write(&q, &b).unwrap();
        let e = match dreampolicy::config::require_seal(&q)
            .and_then(|()| dreampolicy::rl::config::load(&q, &[]))
        {
            Ok(_) => panic!("{name} loaded as if intact"),
            Err(e) => e.to_string(),
        };
        assert!(
            e.contains(&format!("{name}.yaml")) && !e.contains('\n'),
            "{name}: {e}"
        );
    }
    // a config a person wrote loads as it is; as a run's config it needs a seal
    let e = dreampolicy::config::require_seal(&base)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no seal") && e.contains("checkpoint seal"),
        "{e}"
    );
    // a hand edit of a sealed config is refused by every loader until sealed again
    let edited = dir.0.join("edited.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("n_envs:"))
        .unwrap();
    let indent = &line[..line.len() - line.trim_start().len()];
    std::fs::write(
        &edited,
        text.replacen(line, &format!("{indent}n_envs: 7"), 1),
    )
    .unwrap();
    let e = dreampolicy::rl::config::load(&edited, &[])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("corrupt") && e.contains("--set"), "{e}");
    assert_success(&checkpoint_cmd("seal", &edited));
    let cfg7 = dreampolicy::rl::config::load(&edited, &[]).unwrap();
    assert_eq!(cfg7.env.n_envs, 7);
    // `train --resume` refuses a damaged run config in one line
    std::fs::write(&path, &damaged(&bytes, 4, 1, 0, 0)[0].1).unwrap();
    let err = one_line_failure(bin().args(["train", "specialist", "--resume"]).arg(&run));
    assert!(err.contains("config.yaml"), "{err}");
}

/// A dataset's `stats.json` is sealed; every damaged copy is refused naming it.
#[test]
fn every_damaged_copy_of_dataset_stats_is_refused() {
    use dreampolicy::data::{DatasetStats, Dims};
    let dir = Scratch::new("statsdamage");
    let dims = Dims {
        state: 5,
        action: 2,
        scan: 3,
    };
    let dim = |n: usize, k: f64| {
        serde_json::json!({"mean": (0..n).map(|i| k * i as f64 + 0.125).collect::<Vec<_>>(),
                           "std": (0..n).map(|i| 1.0 + i as f64 / 8.0).collect::<Vec<_>>()})
    };
    let stats: DatasetStats = serde_json::from_value(serde_json::json!({
        "dims": dims, "frames": 1234, "episodes": 17,
        "state": dim(5, 0.5), "action": dim(2, -1.5), "scan": dim(3, 0.0625)
    }))
    .unwrap();
    stats.save(&dir.0).unwrap();
    assert_eq!(DatasetStats::load(&dir.0, dims).unwrap(), stats);
    let path = dir.0.join("stats.json");
    let bytes = std::fs::read(&path).unwrap();
    assert!(String::from_utf8_lossy(&bytes).starts_with("{\n  \"sha256\": \""));
    for (name, b) in damaged(&bytes, 41, 30, 10, 10) {
        std::fs::write(&path, &b).unwrap();
        let e = match DatasetStats::load(&dir.0, dims) {
            Ok(_) => panic!("{name} loaded as if intact"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("stats.json") && !e.contains('\n'), "{name}: {e}");
    }
    // unsealed (written before stats were sealed): refused with the way out
    std::fs::write(&path, serde_json::to_string_pretty(&stats).unwrap()).unwrap();
    let e = DatasetStats::load(&dir.0, dims).err().unwrap().to_string();
    assert!(
        e.contains("no integrity seal") && e.contains("--save-stats"),
        "{e}"
    );
}

/// An export bundle: `deploy.yaml` is sealed and holds the SHA-256 of its
/// policy files; a damaged copy of any of the three is refused by the
/// controller (and by `deploy-sim`) with one line naming the file.
#[test]
fn every_damaged_bundle_is_refused_with_one_line() {
    use dreampolicy::deploy::{write_bundle, Bundle, Controller};
    let dir = Scratch::new("bundledamage");
    let ck = dreampolicy::rl::checkpoint::Checkpoint::read(&walker_path()).unwrap();
    let good = dir.0.join("good");
    write_bundle(&ck, &good, false).unwrap();
    Bundle::read(&good).unwrap();
    assert_success(&checkpoint_cmd("verify", &good));
    let mut n = 0;
    for (file, seed, flips, cuts, zeros) in [
        ("deploy.yaml", 51, 12, 4, 4),
        ("policy.pt", 52, 6, 2, 2),
        ("policy.npz", 53, 6, 2, 2),
    ] {
        let bytes = std::fs::read(good.join(file)).unwrap();
        for (name, b) in damaged(&bytes, seed, flips, cuts, zeros) {
            let bad = dir.0.join(format!("{file}-{name}"));
            std::fs::create_dir_all(&bad).unwrap();
            for f in ["deploy.yaml", "policy.pt", "policy.npz"] {
                std::fs::copy(good.join(f), bad.join(f)).unwrap();
            }
            std::fs::write(bad.join(file), &b).unwrap();
            let e = match Controller::load(&bad, None) {
                Ok(_) => panic!("{file} {name} loaded as if intact"),
                Err(e) => e.to_string(),
            };
            assert!(
                e.contains(&bad.join(file).display().to_string()) && !e.contains('\n'),
                "{file} {name}: {e}"
            );
            n += 1;
        }
    }
    assert_eq!(n, 40);
    // the CLI: one line, non-zero exit
    let bad = dir.0.join("policy.pt-flip0");
    let err = one_line_failure(bin().args(["deploy-sim", "--bundle"]).arg(&bad));
    assert!(
        err.contains("policy.pt") && err.contains("corrupt"),
        "{err}"
    );
    // an edited bundle is refused until sealed again, then reads
    let edited = dir.0.join("edited");
    std::fs::create_dir_all(&edited).unwrap();
    for f in ["deploy.yaml", "policy.pt", "policy.npz"] {
        std::fs::copy(good.join(f), edited.join(f)).unwrap();
    }
    let text = std::fs::read_to_string(good.join("deploy.yaml")).unwrap();
    let body = &text[..text.rfind("# dreampolicy-sha256").unwrap()];
    std::fs::write(edited.join("deploy.yaml"), body).unwrap();
    let e = Bundle::read(&edited).err().unwrap().to_string();
    assert!(e.contains("no integrity seal"), "{e}");
    assert_success(&checkpoint_cmd("seal", &edited));
    Bundle::read(&edited).unwrap();
}
