//! `dreampolicy collect`: roll out every terrain specialist on its own terrain
//! and write the expert dataset (the paper's appendix, "expert data
//! collection") as MCAP shards of [`crate::data::Frame`]s.
//!
//! Layout: for each specialist, `rounds` rounds; a round is a fresh batch of
//! `n_envs` envs (its own seed) in which every env runs `episodes_per_env`
//! episodes, and is written as one shard, numbered `specialist * rounds +
//! round`. The paper's 75M frames are 5 terrains x 6 rounds x 1024 envs x 3
//! episodes. A shard is written to a temporary name and renamed when complete,
//! so a crash loses at most the shard in progress; running the same command
//! again skips the shards that exist (`--resume` semantics by default) and
//! redoes the unfinished one.
//!
//! Each specialist runs in its checkpoint's training environment (terrain map,
//! commands, domain randomization, physics) with the curriculum off and envs
//! spread uniformly over levels `0..=max_level`; actions are the policy's mean
//! (`deterministic`) or sampled from its Gaussian.
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::config::ConfigError;
use crate::data::{
    shard_file_name, DataError, DatasetInfo, DatasetStats, Dims, Frame, ShardWriter, WriterOptions,
};
use crate::env::config::TerrainMode;
use crate::env::obs::{scan_row, ScanGrid, SCAN_DIM};
use crate::env::VecEnv;
use crate::rl::checkpoint::Checkpoint;
use crate::rl::{Agent, RlError, VecTask};
use crate::terrain::TerrainKind;

/// Errors of a collection run.
#[derive(Debug, thiserror::Error)]
pub enum CollectError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Rl(#[from] RlError),
    #[error(transparent)]
    Data(#[from] DataError),
    #[error(transparent)]
    Env(#[from] crate::env::EnvError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("collect config: {0}")]
    Invalid(String),
}

/// One specialist to roll out.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecialistSource {
    /// The terrain it masters (and is rolled out on): flat, uneven, stair, gap, bridge.
    pub terrain: String,
    /// Its checkpoint (`models/checkpoints/<terrain>/checkpoints/latest.pt`).
    pub checkpoint: String,
    /// This specialist's `max_level` (levels `0..=max_level` of its training
    /// map), instead of the config's: each specialist's curriculum topped out
    /// at its own level.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_level: Option<usize>,
    /// This specialist's commands (an `env.commands` block, every key of it),
    /// instead of the config's `commands` (or, without either, its training
    /// ones): turn commands for the experts that turn, the lane's heading for
    /// those that do not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands: Option<crate::env::config::CommandConfig>,
}

/// `configs/collect/*.yaml`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollectConfig {
    pub specialists: Vec<SpecialistSource>,
    /// Envs per round.
    pub n_envs: usize,
    /// Episodes each env runs per round (the paper's 3).
    pub episodes_per_env: usize,
    /// Rounds per specialist (the paper's 6); one shard each.
    pub rounds: usize,
    /// Episode length (s); `None` keeps the checkpoint's.
    pub episode_length_s: Option<f64>,
    /// Mean actions (true) or actions sampled from the policy's Gaussian.
    pub deterministic: bool,
    /// Keep the checkpoint's domain randomization (pushes, friction, mass,
    /// latency); false collects on the nominal model.
    pub domain_rand: bool,
    /// Observation noise on the recorded states (and so on what the policy
    /// sees). Off by default: the world model learns the dynamics of clean
    /// states; with the training noise on, holding the last state is already
    /// ~1 std off after one step.
    pub observation_noise: bool,
    /// Envs start at levels uniform in `0..=max_level` (clamped to the map's top;
    /// `None` = every level).
    pub max_level: Option<usize>,
    /// The commands every specialist is given (an `env.commands` block, every
    /// key of it), instead of its training ones; `None` keeps each
    /// checkpoint's. The specialists train with the heading held along their
    /// lanes, so their own commands put almost no turns into the dataset:
    /// `{heading_command: false, ang_vel_yaw: [-1, 1], ...}` asks for them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands: Option<crate::env::config::CommandConfig>,
    /// Physics threads.
    pub threads: usize,
    /// libtorch threads.
    pub torch_threads: usize,
    pub seed: u64,
    /// zstd level of the chunks.
    pub zstd_level: u32,
    /// Uncompressed bytes per MCAP chunk.
    pub chunk_bytes: u64,
}

impl Default for CollectConfig {
    fn default() -> Self {
        CollectConfig {
            specialists: Vec::new(),
            n_envs: 64,
            episodes_per_env: 3,
            rounds: 1,
            episode_length_s: None,
            deterministic: false,
            domain_rand: true,
            observation_noise: false,
            max_level: None,
            commands: None,
            threads: 2,
            torch_threads: 1,
            seed: 0,
            zstd_level: 3,
            chunk_bytes: 1 << 20,
        }
    }
}

impl CollectConfig {
    /// Read `path`, apply `--set` overrides, validate.
    pub fn load(path: &Path, overrides: &[String]) -> Result<CollectConfig, CollectError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_str(&text, &path.display().to_string(), overrides)
    }

    /// Like [`CollectConfig::load`] from a string; `label` names it in messages.
    pub fn from_str(
        text: &str,
        label: &str,
        overrides: &[String],
    ) -> Result<CollectConfig, CollectError> {
        let parse = |e: serde_yaml::Error| ConfigError::Parse {
            path: label.to_string(),
            message: e.to_string(),
        };
        let mut value: serde_yaml::Value = serde_yaml::from_str(text).map_err(parse)?;
        for arg in overrides {
            crate::config::apply_override(&mut value, arg)?;
        }
        let cfg: CollectConfig = serde_yaml::from_value(value).map_err(parse)?;
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<(), CollectError> {
        let bad = |m: String| Err(CollectError::Invalid(m));
        if self.specialists.is_empty() {
            return bad("specialists is empty: list {terrain, checkpoint} pairs".into());
        }
        for s in &self.specialists {
            TerrainKind::from_name(&s.terrain)
                .map_err(|e| CollectError::Invalid(format!("specialists: {e}")))?;
        }
        if self.n_envs == 0 || self.episodes_per_env == 0 || self.rounds == 0 {
            return bad(format!(
                "n_envs ({}), episodes_per_env ({}) and rounds ({}) must be at least 1",
                self.n_envs, self.episodes_per_env, self.rounds
            ));
        }
        if self.threads == 0 || self.torch_threads == 0 {
            return bad("threads and torch_threads must be at least 1".into());
        }
        if let Some(t) = self.episode_length_s {
            if !(t.is_finite() && t > 0.0) {
                return bad(format!("episode_length_s must be > 0, got {t}"));
            }
        }
        let per_specialist = self.specialists.iter().filter_map(|s| {
            s.commands
                .as_ref()
                .map(|c| (format!("specialists[{}].commands", s.terrain), c))
        });
        for (key, c) in self
            .commands
            .as_ref()
            .map(|c| ("commands".to_string(), c))
            .into_iter()
            .chain(per_specialist)
        {
            c.check_ranges(&key).map_err(CollectError::Invalid)?;
            if c.resample_time_s.is_nan() || c.resample_time_s <= 0.0 {
                return bad(format!(
                    "{key}.resample_time_s must be > 0, got {}",
                    c.resample_time_s
                ));
            }
        }
        if self.chunk_bytes < 4096 {
            return bad(format!(
                "chunk_bytes must be >= 4096, got {}",
                self.chunk_bytes
            ));
        }
        Ok(())
    }

    /// Shards the run writes: specialists x rounds.
    pub fn num_shards(&self) -> usize {
        self.specialists.len() * self.rounds
    }
}

/// SHA-256 of a file, hex.
pub fn sha256_file(path: &Path) -> Result<String, CollectError> {
    use sha2::Digest;
    let io = |source| CollectError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut h = sha2::Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// What one shard holds.
#[derive(Debug, Clone, Serialize)]
pub struct ShardSummary {
    pub shard: u32,
    pub terrain: String,
    pub round: usize,
    pub frames: u64,
    pub episodes: u64,
    /// Episodes that ended in a fall.
    pub falls: u64,
    pub bytes: u64,
    pub seconds: f64,
    /// Already there from an earlier run: skipped.
    pub skipped: bool,
}

/// What a collection run did.
#[derive(Debug, Clone, Serialize)]
pub struct CollectSummary {
    pub dir: String,
    pub shards: Vec<ShardSummary>,
    /// Frames written by this run (skipped shards excluded).
    pub frames: u64,
    pub episodes: u64,
    pub falls: u64,
    /// Bytes of the shards written by this run.
    pub bytes: u64,
    pub seconds: f64,
    pub frames_per_s: f64,
    pub bytes_per_frame: f64,
    /// Raw frame size before compression.
    pub raw_bytes_per_frame: usize,
}

/// Run the collection into `dir`; `progress` gets `(label, done, total)` per
/// finished episode. Writes `stats.json` over the whole dataset at the end.
pub fn collect(
    cfg: &CollectConfig,
    cfg_text: &str,
    dir: &Path,
    quiet: bool,
) -> Result<CollectSummary, CollectError> {
    cfg.validate()?;
    tch::set_num_threads(cfg.torch_threads as i32);
    // checkpoints and their hashes first: a typo fails before any rollout
    let mut cks = Vec::with_capacity(cfg.specialists.len());
    let mut hashes = BTreeMap::new();
    for s in &cfg.specialists {
        let path = Path::new(&s.checkpoint);
        let ck = Checkpoint::read(path)?;
        hashes.insert(s.terrain.clone(), sha256_file(path)?);
        cks.push(ck);
    }
    let info = DatasetInfo {
        config: cfg_text.to_string(),
        checkpoints: hashes,
        mujoco_version: crate::sim::mujoco_version(),
        libtorch_version: env!("DREAMPOLICY_LIBTORCH_VERSION").to_string(),
    };
    std::fs::create_dir_all(dir).map_err(|source| CollectError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let start = Instant::now();
    let mut shards = Vec::new();
    for (si, (spec, ck)) in cfg.specialists.iter().zip(&cks).enumerate() {
        let kind = TerrainKind::from_name(&spec.terrain)
            .map_err(|e| CollectError::Invalid(e.to_string()))?;
        for round in 0..cfg.rounds {
            let shard = (si * cfg.rounds + round) as u32;
            let path = dir.join(shard_file_name(shard));
            if path.exists() {
                let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
                shards.push(ShardSummary {
                    shard,
                    terrain: kind.name().into(),
                    round,
                    frames: 0,
                    episodes: 0,
                    falls: 0,
                    bytes,
                    seconds: 0.0,
                    skipped: true,
                });
                continue;
            }
            let tmp = path.with_extension("mcap.tmp");
            if tmp.exists() {
                std::fs::remove_file(&tmp).map_err(|source| CollectError::Io {
                    path: tmp.clone(),
                    source,
                })?;
            }
            let max_level = spec.max_level.or(cfg.max_level);
            let commands = spec.commands.as_ref().or(cfg.commands.as_ref());
            let s = collect_shard(
                cfg, ck, kind, max_level, commands, shard, round, dir, &info, quiet,
            )?;
            shards.push(s);
        }
    }
    let stats = DatasetStats::compute(
        crate::data::Dataset::open(dir, Default::default())?.frames(),
        Dims::G1,
    )?;
    stats.save(dir)?;
    let written = shards.iter().filter(|s| !s.skipped);
    let (frames, episodes, falls, bytes) = written.fold((0, 0, 0, 0), |a, s| {
        (
            a.0 + s.frames,
            a.1 + s.episodes,
            a.2 + s.falls,
            a.3 + s.bytes,
        )
    });
    let seconds = start.elapsed().as_secs_f64();
    let busy: f64 = shards.iter().map(|s| s.seconds).sum();
    Ok(CollectSummary {
        dir: dir.display().to_string(),
        shards,
        frames,
        episodes,
        falls,
        bytes,
        seconds,
        frames_per_s: if busy > 0.0 {
            frames as f64 / busy
        } else {
            f64::NAN
        },
        bytes_per_frame: if frames > 0 {
            bytes as f64 / frames as f64
        } else {
            f64::NAN
        },
        raw_bytes_per_frame: Dims::G1.frame_bytes(),
    })
}

#[allow(clippy::too_many_arguments)]
fn collect_shard(
    cfg: &CollectConfig,
    ck: &Checkpoint,
    kind: TerrainKind,
    max_level: Option<usize>,
    commands: Option<&crate::env::config::CommandConfig>,
    shard: u32,
    round: usize,
    dir: &Path,
    info: &DatasetInfo,
    quiet: bool,
) -> Result<ShardSummary, CollectError> {
    let start = Instant::now();
    let train = ck.config()?;
    let mut env_cfg = train.env.clone();
    env_cfg.n_envs = cfg.n_envs as i64;
    env_cfg.threads = cfg.threads as i64;
    env_cfg.seed = cfg
        .seed
        .wrapping_mul(1_000_003)
        .wrapping_add(u64::from(shard) * 7919);
    if let Some(t) = cfg.episode_length_s {
        env_cfg.episode_length_s = t;
    }
    env_cfg.domain_rand.enabled &= cfg.domain_rand;
    env_cfg.observation.add_noise &= cfg.observation_noise;
    if let Some(c) = commands {
        env_cfg.commands = c.clone();
    }
    env_cfg.terrain.curriculum = false;
    if env_cfg.terrain.mode == TerrainMode::Map {
        let top = env_cfg.terrain.map.max_level();
        env_cfg.terrain.init_max_level = max_level.map_or(top, |m| m.min(top));
        let kinds = &env_cfg.terrain.map.kinds;
        if !kinds.iter().any(|(k, w)| *k == kind && *w > 0.0) {
            return Err(CollectError::Invalid(format!(
                "{}: the specialist for {} was trained on a map without {} tiles",
                ck.path.display(),
                kind.name(),
                kind.name()
            )));
        }
    } else if kind != TerrainKind::Flat {
        return Err(CollectError::Invalid(format!(
            "{}: the specialist for {} was trained on a plane",
            ck.path.display(),
            kind.name()
        )));
    }
    let mut env = VecEnv::new(&env_cfg)?;
    let n = env.n_envs();
    // The dataset's scandots are the paper's grid (the default), whatever grid
    // the specialist reads: the world model is conditioned on that one. A
    // specialist with another `scan_grid` walks on its own; its frames record
    // the default grid's noise-free heights.
    let oc = &env_cfg.observation;
    let record_own_grid = oc.scan_grid == ScanGrid::default();
    let mut agent = Agent::new(&train.policy, env.dims(), n, train.ppo.normalize_obs);
    ck.load_agent(&mut agent)?;
    agent.set_frozen(true);
    agent.reset_history(&env);
    let mut writer = ShardWriter::create(
        dir,
        shard,
        Dims::G1,
        info.clone(),
        WriterOptions {
            chunk_bytes: cfg.chunk_bytes,
            zstd_level: cfg.zstd_level,
        },
    )?;

    let target = n * cfg.episodes_per_env;
    let label = format!("collect {} round {round}", kind.name());
    let progress = crate::run::Progress::new(&label, target as u64, quiet);
    // per env: episodes finished, the id of its current episode, its step in it
    let mut finished = vec![0usize; n];
    let mut ordinal = 0u32;
    let mut episode: Vec<u64> = (0..n)
        .map(|_| {
            ordinal += 1;
            crate::data::episode_id(shard, ordinal - 1)
        })
        .collect();
    let mut step = vec![0u32; n];
    let (mut done, mut falls) = (0usize, 0u64);
    let dims = env.dims();
    let mut frame = Frame {
        episode: 0,
        env: 0,
        step: 0,
        terrain: kind,
        level: 0,
        terminated: false,
        truncated: false,
        pos: [0.0; 3],
        quat: [1.0, 0.0, 0.0, 0.0],
        state: vec![0.0; dims.obs],
        action: vec![0.0; dims.action],
        scan: vec![0.0; dims.scan],
    };
    // the state, scandots and pose of every env at s_t, before the step
    let mut obs = vec![0.0f32; n * dims.obs];
    let mut scan = vec![0.0f32; n * dims.scan];
    let mut pose = vec![([0.0f64; 3], [0.0f64; 4], 0u32); n];
    while done < target {
        obs.copy_from_slice(env.obs());
        if record_own_grid {
            scan.copy_from_slice(VecTask::scan(&env));
        } else {
            let (grid, sh) = (ScanGrid::default(), env.shared());
            for (e, row) in env.envs().iter().zip(scan.chunks_mut(SCAN_DIM)) {
                let st = e.state();
                let ground = |x: f64, y: f64| e.ground(sh, x, y);
                scan_row(
                    &ground,
                    &grid,
                    st.base_pos,
                    st.yaw.sin_cos(),
                    oc.scan_clip,
                    oc.scales.scan,
                    row,
                );
            }
        }
        for (i, p) in pose.iter_mut().enumerate() {
            let e = &env.envs()[i];
            let q = e.data().qpos();
            *p = (
                [q[0], q[1], q[2]],
                [q[3], q[4], q[5], q[6]],
                e.terrain_level() as u32,
            );
        }
        agent.prepare(&env);
        let actions = if cfg.deterministic {
            agent.act_mean()
        } else {
            agent.act(true).actions
        };
        env.step(&actions);
        agent.after_step(&env);
        for i in 0..n {
            if finished[i] >= cfg.episodes_per_env {
                continue;
            }
            let out = env.outcomes[i];
            frame.episode = episode[i];
            frame.env = i as u32;
            frame.step = step[i];
            (frame.pos, frame.quat, frame.level) = pose[i];
            frame.terminated = out.episode_done && out.terminated;
            frame.truncated = out.episode_done && !out.terminated;
            frame
                .state
                .copy_from_slice(&obs[i * dims.obs..(i + 1) * dims.obs]);
            frame
                .action
                .copy_from_slice(&actions[i * dims.action..(i + 1) * dims.action]);
            frame
                .scan
                .copy_from_slice(&scan[i * dims.scan..(i + 1) * dims.scan]);
            writer.write(&frame)?;
            step[i] += 1;
            if out.episode_done {
                finished[i] += 1;
                done += 1;
                falls += u64::from(out.terminated);
                episode[i] = crate::data::episode_id(shard, ordinal);
                ordinal += 1;
                step[i] = 0;
                progress.set(done as u64, &format!("{} frames", writer.frames()));
            }
        }
    }
    progress.finish();
    let frames = writer.frames();
    let path = writer.finish()?;
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    Ok(ShardSummary {
        shard,
        terrain: kind.name().into(),
        round,
        frames,
        episodes: done as u64,
        falls,
        bytes,
        seconds: start.elapsed().as_secs_f64(),
        skipped: false,
    })
}
