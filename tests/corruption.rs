//! Damaged checkpoint files are refused, never loaded as if intact: seeded byte
//! flips, truncations and zeroed blocks over a tiny checkpoint, a world-model
//! checkpoint and the committed walker (the 24-flip experiment of issue 22:
//! every copy refused by `eval` with a one-line error), files without a seal,
//! and `checkpoint verify` / `checkpoint seal`.
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
        let out = bin()
            .args(["eval", "--episodes", "1", "--checkpoint"])
            .arg(&q)
            .env_remove("RUST_BACKTRACE")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name} evaluated: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.contains(&format!("{name}.pt")), "{name}: {err}");
        assert!(!err.contains("frame #"), "{name}: {err}");
    }
}

#[test]
fn a_damaged_world_model_checkpoint_is_refused() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/checkpoints/world_model/checkpoints/latest.pt");
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
