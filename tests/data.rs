//! The expert dataset's storage layer on synthetic frames written here: every
//! field round-trips, windows never cross an episode and count what a hand count
//! gives, the split is by episode and deterministic, the shuffle is seeded and
//! bounded, statistics match a direct computation, and bad input (truncated
//! shards, `.mcap.tmp` leftovers, other dims, empty directories) is reported with
//! the file named.
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use dreampolicy::data::{
    episode_id, shard_file_name, DataError, DataWarning, Dataset, DatasetInfo, DatasetStats, Dims,
    Frame, OnTruncated, ReadOptions, ShardReader, ShardWriter, Shuffle, Split, SplitSpec,
    WindowSpec, WriterOptions,
};
use dreampolicy::terrain::TerrainKind;

fn info() -> DatasetInfo {
    DatasetInfo {
        config: "collect:\n  rounds: 1\n".into(),
        checkpoints: BTreeMap::from([
            ("stair".into(), "ab12".into()),
            ("gap".into(), "cd34".into()),
        ]),
        mujoco_version: "3.3.7".into(),
        libtorch_version: "2.13.0".into(),
    }
}

/// Small chunks so that a shard has many.
fn small_chunks() -> WriterOptions {
    WriterOptions {
        chunk_bytes: 16 * 1024,
        zstd_level: 1,
    }
}

/// `n_envs` envs in lockstep for `steps` steps (step-major, as a collector writes);
/// env `e`'s episodes have lengths `lens(e, k)`; episodes still running at the
/// end are cut without a done flag. state[0] = a small unique episode number,
/// state[1] = step, the rest pseudo-random.
fn synth(
    shard: u32,
    n_envs: u32,
    steps: u32,
    dims: Dims,
    lens: &dyn Fn(u32, u32) -> u32,
) -> Vec<Frame> {
    let mut rng = 0x9E37_79B9_7F4A_7C15u64 ^ u64::from(shard);
    let mut next = |scale: f32| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        ((rng >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * scale
    };
    let mut ordinal = 0u32;
    // per env: (id, ordinal, k-th episode of the env, step)
    let mut ep: Vec<(u64, u32, u32, u32)> = (0..n_envs)
        .map(|_| {
            ordinal += 1;
            (episode_id(shard, ordinal - 1), ordinal - 1, 0, 0)
        })
        .collect();
    let mut out = Vec::new();
    for _ in 0..steps {
        for env in 0..n_envs {
            let (id, ord, k, step) = ep[env as usize];
            let len = lens(env, k);
            let last = step + 1 == len;
            let mut f = Frame::zeros(dims);
            f.episode = id;
            f.env = env;
            f.step = step;
            f.terrain = TerrainKind::ALL[(env as usize + k as usize) % TerrainKind::ALL.len()];
            f.level = env * 3 + k;
            f.terminated = last && k % 2 == 0;
            f.truncated = last && k % 2 == 1;
            f.pos = [step as f64 * 0.01, env as f64 + 1e-12, 0.75 + shard as f64];
            f.quat = [0.5f64.sqrt(), 0.0, -(0.5f64.sqrt()), 1e-300];
            for v in f.state.iter_mut().chain(&mut f.action).chain(&mut f.scan) {
                *v = next(4.0) + 1.5;
            }
            f.state[0] = (shard * 10_000 + ord) as f32;
            f.state[1] = step as f32;
            f.scan[0] = step as f32;
            out.push(f);
            ep[env as usize] = if last {
                ordinal += 1;
                (episode_id(shard, ordinal - 1), ordinal - 1, k + 1, 0)
            } else {
                (id, ord, k, step + 1)
            };
        }
    }
    out
}

fn lens(env: u32, k: u32) -> u32 {
    [7, 3, 12, 1, 5, 9][((env + 2 * k) % 6) as usize]
}

fn write_shard(
    dir: &Path,
    shard: u32,
    frames: &[Frame],
    dims: Dims,
    opts: WriterOptions,
) -> PathBuf {
    let mut w = ShardWriter::create(dir, shard, dims, info(), opts).unwrap();
    for f in frames {
        w.write(f).unwrap();
    }
    assert_eq!(w.frames(), frames.len() as u64);
    w.finish().unwrap()
}

/// Two shards in a fresh directory; the frames of each.
fn two_shards(dir: &Path) -> Vec<Vec<Frame>> {
    let a = synth(0, 4, 40, Dims::G1, &lens);
    let b = synth(1, 3, 25, Dims::G1, &|e, k| lens(e + 1, k) + 2);
    write_shard(dir, 0, &a, Dims::G1, small_chunks());
    write_shard(dir, 1, &b, Dims::G1, small_chunks());
    vec![a, b]
}

fn read_all(ds: &Dataset) -> Vec<(usize, Frame)> {
    ds.frames().collect::<Result<Vec<_>, _>>().unwrap()
}

/// Episodes in stream order: (shard, episode) -> frames.
fn episodes(shards: &[Vec<Frame>]) -> Vec<((usize, u64), Vec<Frame>)> {
    let mut order = Vec::new();
    let mut map: HashMap<(usize, u64), Vec<Frame>> = HashMap::new();
    for (s, frames) in shards.iter().enumerate() {
        for f in frames {
            let key = (s, f.episode);
            if !map.contains_key(&key) {
                order.push(key);
            }
            map.entry(key).or_default().push(f.clone());
        }
    }
    order
        .into_iter()
        .map(|k| (k, map.remove(&k).unwrap()))
        .collect()
}

#[test]
fn every_field_round_trips_through_shards() {
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    assert_eq!(
        names,
        vec![shard_file_name(0), shard_file_name(1)],
        "no .tmp left"
    );
    assert_eq!(shard_file_name(12), "shard-00012.mcap");

    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let read = read_all(&ds);
    let expected: Vec<(usize, Frame)> = written
        .iter()
        .enumerate()
        .flat_map(|(s, fs)| fs.iter().map(move |f| (s, f.clone())))
        .collect();
    assert_eq!(read.len(), expected.len());
    for (i, (r, e)) in read.iter().zip(&expected).enumerate() {
        assert_eq!(r, e, "frame {i}");
    }
    assert!(ds.warnings().is_empty());
    // done flags and every terrain kind made it
    assert!(read.iter().any(|(_, f)| f.terminated) && read.iter().any(|(_, f)| f.truncated));
    let kinds: BTreeSet<_> = read.iter().map(|(_, f)| f.terrain).collect();
    assert_eq!(kinds.len(), TerrainKind::ALL.len());

    let r = ShardReader::open(&dir.path().join(shard_file_name(1)), Dims::G1).unwrap();
    let m = r.meta();
    assert_eq!(m.shard, 1);
    assert_eq!(m.dims, Dims::G1);
    assert_eq!(m.frame_bytes, 1336);
    assert_eq!(Dims::G1.frame_bytes(), 80 + 4 * (98 + 29 + 187));
    assert_eq!(m.info, info());
    assert_eq!(m.terrain_kinds[4], "bridge");
    // a single file opens too
    let one = Dataset::open(&dir.path().join(shard_file_name(0)), ReadOptions::default()).unwrap();
    assert_eq!(read_all(&one).len(), written[0].len());
}

#[test]
fn many_chunks_and_real_compression() {
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 8, 60, Dims::G1, &lens);
    let path = write_shard(dir.path(), 0, &frames, Dims::G1, small_chunks());
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(
        summary.chunk_indexes.len() > 10,
        "{} chunks",
        summary.chunk_indexes.len()
    );
    assert!(summary
        .chunk_indexes
        .iter()
        .all(|c| c.compression == "zstd"));
    assert_eq!(summary.stats.unwrap().message_count, frames.len() as u64);
}

#[test]
fn writer_refuses_frames_of_other_sizes_and_existing_shards() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = ShardWriter::create(dir.path(), 0, Dims::G1, info(), small_chunks()).unwrap();
    let mut f = Frame::zeros(Dims::G1);
    f.action.pop();
    let e = w.write(&f).unwrap_err().to_string();
    assert!(e.contains("28 action values") && e.contains("29"), "{e}");
    w.finish().unwrap();
    let e = ShardWriter::create(dir.path(), 0, Dims::G1, info(), small_chunks())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("shard-00000.mcap already exists"), "{e}");
}

/// One env, episodes of 5, 3 and 7 frames; K = 3, H = 1: 2 + 0 + 4 windows.
#[test]
fn windows_count_what_a_hand_count_gives() {
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 1, 15, Dims::G1, &|_, k| [5, 3, 7][k as usize]);
    write_shard(dir.path(), 0, &frames, Dims::G1, small_chunks());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let spec = WindowSpec::new(3, 1).unwrap();
    let ws: Vec<_> = ds.windows(spec, None).collect::<Result<_, _>>().unwrap();
    let got: Vec<(u64, u32)> = ws.iter().map(|w| (w.episode, w.first_step)).collect();
    let (e0, e2) = (episode_id(0, 0), episode_id(0, 2));
    assert_eq!(
        got,
        vec![(e0, 0), (e0, 1), (e2, 0), (e2, 1), (e2, 2), (e2, 3)]
    );
    assert_eq!(ws[1].anchor_step(), 3);
    assert!(ws[1].ends_episode && !ws[0].ends_episode && ws[5].ends_episode);
    assert_eq!(
        spec.windows_in(5) + spec.windows_in(3) + spec.windows_in(7),
        6
    );
    assert!(WindowSpec::new(0, 4).is_err());
}

#[test]
fn windows_never_cross_an_episode_and_match_a_brute_force_count() {
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    for (k, h) in [(3, 2), (1, 0), (4, 4), (2, 10)] {
        let spec = WindowSpec::new(k, h).unwrap();
        let mut expected = BTreeSet::new();
        for ((_, id), frames) in episodes(&written) {
            for start in 0..(frames.len() + 1).saturating_sub(k + h) {
                expected.insert((id, frames[start].step));
            }
        }
        let mut got = BTreeSet::new();
        let mut n = 0;
        for w in ds.windows(spec, None) {
            let w = w.unwrap();
            n += 1;
            let s = Dims::G1.state;
            assert_eq!(w.states.len(), (k + h) * s);
            assert_eq!(w.actions.len(), (k + h) * Dims::G1.action);
            let ep = w.states[0];
            for row in 0..k + h {
                assert_eq!(w.states[row * s], ep, "row {row} of another episode");
                assert_eq!(w.states[row * s + 1], (w.first_step + row as u32) as f32);
            }
            assert_eq!(w.scan[0], w.anchor_step() as f32, "scandots of the anchor");
            assert_eq!(w.history_states().len(), k * s);
            assert_eq!(w.future_states().len(), h * s);
            got.insert((w.episode, w.first_step));
        }
        assert_eq!(n, expected.len(), "K={k} H={h}");
        assert_eq!(got, expected, "K={k} H={h}");
    }
}

#[test]
fn a_step_gap_restarts_the_window_buffer() {
    let dir = tempfile::tempdir().unwrap();
    let mut frames = synth(0, 1, 10, Dims::G1, &|_, _| 100);
    frames.remove(4); // steps 0..4, then 5..10
    write_shard(dir.path(), 0, &frames, Dims::G1, small_chunks());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let ws: Vec<u32> = ds
        .windows(WindowSpec::new(2, 1).unwrap(), None)
        .map(|w| w.unwrap().first_step)
        .collect();
    assert_eq!(ws, vec![0, 1, 5, 6, 7]);
}

#[test]
fn split_is_by_episode_and_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 16, 120, Dims::G1, &lens);
    write_shard(dir.path(), 0, &frames, Dims::G1, WriterOptions::default());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let all: BTreeSet<u64> = frames.iter().map(|f| f.episode).collect();
    assert!(all.len() > 200, "{} episodes", all.len());
    let spec = SplitSpec::new(0.3, 7).unwrap();
    let side = |spec: SplitSpec, s: Split| -> (BTreeSet<u64>, usize) {
        let fs: Vec<_> = ds
            .split_frames(Some((spec, s)))
            .map(|x| x.unwrap().1)
            .collect();
        (fs.iter().map(|f| f.episode).collect(), fs.len())
    };
    let (train, n_train) = side(spec, Split::Train);
    let (val, n_val) = side(spec, Split::Validation);
    assert!(train.is_disjoint(&val));
    assert_eq!(&train | &val, all);
    assert_eq!(
        n_train + n_val,
        frames.len(),
        "every frame on exactly one side"
    );
    let frac = val.len() as f64 / all.len() as f64;
    assert!((0.2..0.4).contains(&frac), "validation fraction {frac}");
    // the split skips the other side's frames undecoded: what it gives out is
    // exactly the written frames of its episodes, in order
    let got: Vec<_> = ds
        .split_frames(Some((spec, Split::Validation)))
        .map(|x| x.unwrap().1)
        .collect();
    let want: Vec<_> = frames
        .iter()
        .filter(|f| spec.of(f.episode) == Split::Validation)
        .cloned()
        .collect();
    assert!(
        got == want,
        "validation frames differ from the written ones"
    );
    // the same spec gives the same split; the split is a function of the id alone
    assert_eq!(side(spec, Split::Validation).0, val);
    for id in &val {
        assert_eq!(spec.of(*id), Split::Validation);
    }
    let other = side(SplitSpec::new(0.3, 8).unwrap(), Split::Validation).0;
    assert_ne!(other, val, "another seed, another split");
    assert!(side(SplitSpec::new(0.0, 7).unwrap(), Split::Validation)
        .0
        .is_empty());
    assert_eq!(
        side(SplitSpec::new(1.0, 7).unwrap(), Split::Validation).0,
        all
    );
    assert!(SplitSpec::new(1.5, 0).is_err());
    // windows of the two sides partition the windows
    let spec_w = WindowSpec::new(2, 2).unwrap();
    let count = |s| ds.windows(spec_w, s).count();
    assert_eq!(
        count(Some((spec, Split::Train))) + count(Some((spec, Split::Validation))),
        count(None)
    );
}

#[test]
fn train_fractions_nest_and_kinds_filter_whole_episodes() {
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 16, 120, Dims::G1, &lens);
    write_shard(dir.path(), 0, &frames, Dims::G1, WriterOptions::default());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let base = SplitSpec::new(0.2, 3).unwrap();
    let episodes = |spec: SplitSpec, s: Split| -> BTreeSet<u64> {
        ds.split_frames(Some((spec, s)))
            .map(|x| x.unwrap().1.episode)
            .collect()
    };
    let val = episodes(base, Split::Validation);
    let mut last: Option<BTreeSet<u64>> = None;
    let full = episodes(base, Split::Train);
    for f in [0.25, 0.5, 1.0] {
        let spec = base.with_train_fraction(f).unwrap();
        // the validation episodes do not move
        assert_eq!(episodes(spec, Split::Validation), val, "fraction {f}");
        let train = episodes(spec, Split::Train);
        let unused = episodes(spec, Split::Unused);
        assert!(train.is_disjoint(&unused) && train.is_disjoint(&val));
        assert_eq!(
            &train | &unused,
            full,
            "fraction {f}: train + unused = the train side"
        );
        let share = train.len() as f64 / full.len() as f64;
        assert!((share - f).abs() < 0.12, "fraction {f}: {share}");
        // nested: a smaller fraction's episodes are in every larger one's
        if let Some(prev) = &last {
            assert!(prev.is_subset(&train), "fraction {f}");
        }
        last = Some(train);
    }
    assert_eq!(base.with_train_fraction(1.0).unwrap(), base);
    assert!(base.with_train_fraction(0.0).is_err());
    assert!(base.with_train_fraction(1.5).is_err());
    // kinds keep whole episodes of those kinds, and nothing else
    let kinds: BTreeSet<TerrainKind> = frames.iter().map(|f| f.terrain).collect();
    assert!(
        kinds.len() >= 2,
        "the synthetic shard holds several kinds: {kinds:?}"
    );
    let one = *kinds.iter().next().unwrap();
    let got: Vec<Frame> = ds
        .split_frames_of(None, &[one])
        .map(|x| x.unwrap().1)
        .collect();
    let want: Vec<Frame> = frames
        .iter()
        .filter(|f| f.terrain == one)
        .cloned()
        .collect();
    assert!(!want.is_empty() && got == want);
    assert_eq!(ds.split_frames_of(None, &[]).count(), frames.len());
    let spec_w = WindowSpec::new(2, 2).unwrap();
    let per_kind: usize = kinds
        .iter()
        .map(|&k| ds.windows_of(spec_w, None, &[k]).count())
        .sum();
    assert_eq!(per_kind, ds.windows(spec_w, None).count());
}

#[test]
fn shuffle_is_seeded_bounded_and_a_permutation() {
    let items: Vec<Result<u32, ()>> = (0..500).map(Ok).collect();
    let run = |cap, seed| -> Vec<u32> {
        Shuffle::new(items.clone().into_iter(), cap, seed)
            .map(|x| x.unwrap())
            .collect()
    };
    let a = run(32, 1);
    assert_eq!(a, run(32, 1), "same seed, same order");
    assert_ne!(a, run(32, 2), "another seed, another order");
    assert_ne!(a, (0..500).collect::<Vec<_>>());
    let mut sorted = a.clone();
    sorted.sort();
    assert_eq!(sorted, (0..500).collect::<Vec<_>>());
    // bounded: the i-th item out is one of the first i + capacity in
    for (i, v) in a.iter().enumerate() {
        assert!((*v as usize) < i + 32, "item {v} out at {i}");
    }
    assert_eq!(
        run(1, 3),
        (0..500).collect::<Vec<_>>(),
        "capacity 1 keeps the order"
    );
    // errors pass through
    let with_err = vec![Ok(1), Err(()), Ok(2)];
    let out: Vec<_> = Shuffle::new(with_err.into_iter(), 8, 0).collect();
    assert_eq!(out[0], Err(()));

    // on windows
    let dir = tempfile::tempdir().unwrap();
    two_shards(dir.path());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let spec = WindowSpec::new(3, 2).unwrap();
    let keys = |seed| -> Vec<(u64, u32)> {
        Shuffle::new(ds.windows(spec, None), 16, seed)
            .map(|w| w.map(|w| (w.episode, w.first_step)).unwrap())
            .collect()
    };
    let plain: Vec<_> = ds
        .windows(spec, None)
        .map(|w| w.map(|w| (w.episode, w.first_step)).unwrap())
        .collect();
    let s = keys(5);
    assert_eq!(s, keys(5));
    assert_ne!(s, plain);
    assert_eq!(
        s.iter().collect::<BTreeSet<_>>(),
        plain.iter().collect::<BTreeSet<_>>()
    );
}

#[test]
fn stats_match_a_direct_computation_and_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let st = DatasetStats::compute(ds.frames(), ds.dims()).unwrap();
    let all: Vec<&Frame> = written.iter().flatten().collect();
    assert_eq!(st.frames, all.len() as u64);
    assert_eq!(st.episodes, episodes(&written).len() as u64);
    let check = |get: &dyn Fn(&Frame) -> &Vec<f32>, mean: &[f64], std: &[f64]| {
        let n = all.len() as f64;
        for d in 0..mean.len() {
            let m = all.iter().map(|f| f64::from(get(f)[d])).sum::<f64>() / n;
            let v = all
                .iter()
                .map(|f| (f64::from(get(f)[d]) - m).powi(2))
                .sum::<f64>()
                / n;
            assert!(
                (mean[d] - m).abs() <= 1e-9 * (1.0 + m.abs()),
                "mean {d}: {} vs {m}",
                mean[d]
            );
            assert!(
                (std[d] - v.sqrt()).abs() <= 1e-9 * (1.0 + v.sqrt()),
                "std {d}"
            );
        }
    };
    check(&|f| &f.state, &st.state.mean, &st.state.std);
    check(&|f| &f.action, &st.action.mean, &st.action.std);
    check(&|f| &f.scan, &st.scan.mean, &st.scan.std);
    assert!(st.state.std[5] > 0.5, "the random dims vary");

    st.save(dir.path()).unwrap();
    let back = DatasetStats::load(dir.path(), Dims::G1).unwrap();
    assert_eq!(
        (back.dims, back.frames, back.episodes),
        (st.dims, st.frames, st.episodes)
    );
    // serde_json parses floats to within an ulp
    for (a, b) in [
        (&back.state, &st.state),
        (&back.action, &st.action),
        (&back.scan, &st.scan),
    ] {
        for (x, y) in a.mean.iter().chain(&a.std).zip(b.mean.iter().chain(&b.std)) {
            assert!((x - y).abs() <= 1e-15 * y.abs().max(1.0), "{x} vs {y}");
        }
    }
    let other = Dims {
        state: 60,
        ..Dims::G1
    };
    let e = DatasetStats::load(dir.path(), other)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("stats.json") && e.contains("state 98") && e.contains("state 60"),
        "{e}"
    );
    // the shards are still read with stats.json beside them
    assert_eq!(read_all(&ds).len(), all.len());
}

/// Copy `src` to `dst` cut at `len` bytes.
fn truncated_copy(src: &Path, dst: &Path, len: usize) {
    let bytes = std::fs::read(src).unwrap();
    std::fs::write(dst, &bytes[..len]).unwrap();
}

#[test]
fn a_truncated_shard_reads_to_its_last_complete_chunk_or_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 6, 50, Dims::G1, &lens);
    let full = write_shard(dir.path(), 0, &frames, Dims::G1, small_chunks());
    let bytes = std::fs::read(&full).unwrap();
    let chunks = mcap::Summary::read(&bytes).unwrap().unwrap().chunk_indexes;
    assert!(chunks.len() > 5);
    let cut_dir = tempfile::tempdir().unwrap();
    let cut = cut_dir.path().join("shard-00000.mcap");
    for j in [1, chunks.len() / 2, chunks.len() - 1] {
        // kill -9 in the middle of chunk j: chunks 0..j are complete
        let c = &chunks[j];
        truncated_copy(
            &full,
            &cut,
            (c.chunk_start_offset + c.chunk_length / 2) as usize,
        );
        let kept = (chunks[j - 1].message_end_time + 1) as usize; // log_time = frame index
        let ds = Dataset::open(cut_dir.path(), ReadOptions::default()).unwrap();
        let read: Vec<Frame> = read_all(&ds).into_iter().map(|x| x.1).collect();
        assert_eq!(read.len(), kept, "cut in chunk {j}");
        assert_eq!(&read[..], &frames[..kept]);
        assert_eq!(
            ds.warnings(),
            vec![DataWarning::Truncated {
                path: cut.clone(),
                frames: kept as u64
            }]
        );
        assert!(ds.warnings()[0]
            .to_string()
            .contains("shard-00000.mcap: truncated"));
        // windows still never cross an episode
        for w in ds.windows(WindowSpec::new(2, 2).unwrap(), None) {
            let w = w.unwrap();
            assert_eq!(w.states[0], w.states[3 * Dims::G1.state]);
        }
        let strict = ReadOptions {
            on_truncated: OnTruncated::Fail,
            ..Default::default()
        };
        let ds = Dataset::open(cut_dir.path(), strict).unwrap();
        let err = ds.frames().find_map(|x| x.err()).expect("an error");
        assert!(matches!(err, DataError::Truncated { frames, .. } if frames == kept as u64));
        let msg = err.to_string();
        assert!(
            msg.contains(&cut.display().to_string()) && msg.contains("truncated"),
            "{msg}"
        );
    }
    // cut inside the header or the metadata: nothing to read, still named
    for len in [5, 40] {
        truncated_copy(&full, &cut, len);
        let ds = Dataset::open(cut_dir.path(), ReadOptions::default()).unwrap();
        assert!(read_all(&ds).is_empty());
        assert_eq!(
            ds.warnings(),
            vec![DataWarning::Truncated {
                path: cut.clone(),
                frames: 0
            }]
        );
    }
    // a flipped byte inside a chunk is a CRC error naming the shard
    let mut bad = bytes.clone();
    let mid = (chunks[2].chunk_start_offset + chunks[2].chunk_length / 2) as usize;
    bad[mid] ^= 0x55;
    std::fs::write(&cut, &bad).unwrap();
    let ds = Dataset::open(cut_dir.path(), ReadOptions::default()).unwrap();
    let err = ds
        .frames()
        .find_map(|x| x.err())
        .expect("an error")
        .to_string();
    assert!(err.contains("shard-00000.mcap"), "{err}");
}

#[test]
fn a_leftover_tmp_is_skipped_with_a_warning_and_readable_on_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    // shard 1 "killed mid-write": only its .mcap.tmp, cut mid-file
    let full = dir.path().join(shard_file_name(1));
    let tmp = dir.path().join("shard-00001.mcap.tmp");
    let len = std::fs::metadata(&full).unwrap().len() as usize * 2 / 3;
    truncated_copy(&full, &tmp, len);
    std::fs::remove_file(&full).unwrap();

    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    assert_eq!(ds.leftovers(), std::slice::from_ref(&tmp));
    assert_eq!(
        read_all(&ds).len(),
        written[0].len(),
        "only the finished shard"
    );
    assert_eq!(
        ds.warnings(),
        vec![DataWarning::Leftover { path: tmp.clone() }]
    );
    assert!(ds.warnings()[0]
        .to_string()
        .contains("shard-00001.mcap.tmp: unfinished shard"));

    // named explicitly, the .tmp reads up to its last complete chunk
    let one = Dataset::open(&tmp, ReadOptions::default()).unwrap();
    let frames: Vec<Frame> = read_all(&one).into_iter().map(|x| x.1).collect();
    assert!(!frames.is_empty() && frames.len() < written[1].len());
    assert_eq!(&frames[..], &written[1][..frames.len()]);
    assert!(matches!(&one.warnings()[..], [DataWarning::Truncated { path, .. }] if *path == tmp));

    // a writer that never finishes leaves only its .tmp
    let crash = tempfile::tempdir().unwrap();
    let mut w = ShardWriter::create(crash.path(), 3, Dims::G1, info(), small_chunks()).unwrap();
    for f in &written[0] {
        w.write(f).unwrap();
    }
    assert!(w.tmp_path().ends_with("shard-00003.mcap.tmp"));
    std::mem::forget(w); // as kill -9: no footer, no rename
    assert!(!crash.path().join(shard_file_name(3)).exists());
    let e = Dataset::open(crash.path(), ReadOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("no dataset shards") && e.contains("1 unfinished"),
        "{e}"
    );
}

#[test]
fn other_dimensions_are_refused_with_both_shapes_named() {
    let dir = tempfile::tempdir().unwrap();
    let dims = Dims {
        state: 98,
        action: 12,
        scan: 187,
    };
    let frames = synth(0, 2, 10, dims, &lens);
    write_shard(dir.path(), 0, &frames, dims, small_chunks());
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let err = ds.frames().next().unwrap().unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, DataError::DimMismatch { found, expected, .. } if found == dims && expected == Dims::G1)
    );
    assert!(
        msg.contains("shard-00000.mcap")
            && msg.contains("(state 98, action 12, scandots 187)")
            && msg.contains("(state 98, action 29, scandots 187)"),
        "{msg}"
    );
    // read with the dims it has, it reads
    let ok = Dataset::open(
        dir.path(),
        ReadOptions {
            expected: dims,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(read_all(&ok).len(), frames.len());
}

#[test]
fn empty_and_missing_directories_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("notes.txt"), "not a shard").unwrap();
    let e = Dataset::open(dir.path(), ReadOptions::default())
        .err()
        .unwrap();
    assert!(matches!(e, DataError::Empty { leftovers: 0, .. }));
    let msg = e.to_string();
    assert!(
        msg.contains(&dir.path().display().to_string())
            && msg.contains("no dataset shards (*.mcap)"),
        "{msg}"
    );
    let missing = dir.path().join("nope");
    let msg = Dataset::open(&missing, ReadOptions::default())
        .err()
        .unwrap()
        .to_string();
    assert!(msg.contains("nope"), "{msg}");
    // a file that is not MCAP is named
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, vec![7u8; 4000]).unwrap();
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let msg = ds.frames().next().unwrap().unwrap_err().to_string();
    assert!(msg.contains("junk.mcap"), "{msg}");
}

#[test]
fn verify_names_the_bad_shards() {
    use dreampolicy::data::inspect::verify;
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    let checks = verify(dir.path(), Dims::G1).unwrap();
    assert_eq!(checks.len(), 2);
    assert!(checks.iter().all(|c| c.error.is_none()), "{checks:?}");
    assert_eq!(checks[0].frames, written[0].len() as u64);
    assert_eq!(checks[1].episodes, episodes(&written[1..]).len() as u64);

    // a shard whose episode skips a step, a truncated one, a leftover .tmp
    let mut gap = synth(2, 2, 10, Dims::G1, &|_, _| 100);
    gap.remove(5);
    write_shard(dir.path(), 2, &gap, Dims::G1, small_chunks());
    let full = dir.path().join(shard_file_name(0));
    let len = std::fs::metadata(&full).unwrap().len() as usize / 2;
    truncated_copy(&full, &dir.path().join(shard_file_name(3)), len);
    truncated_copy(&full, &dir.path().join("shard-00004.mcap.tmp"), len);
    let checks = verify(dir.path(), Dims::G1).unwrap();
    let verdict: Vec<(String, Option<String>)> = checks
        .iter()
        .map(|c| {
            (
                c.path.file_name().unwrap().to_string_lossy().into_owned(),
                c.error.clone(),
            )
        })
        .collect();
    assert_eq!(verdict.len(), 5);
    assert!(verdict[0].1.is_none() && verdict[1].1.is_none());
    assert!(
        verdict[2]
            .1
            .as_deref()
            .unwrap()
            .contains("jumps from step 1 to step 3"),
        "{verdict:?}"
    );
    assert!(
        verdict[3].1.as_deref().unwrap().contains("truncated"),
        "{verdict:?}"
    );
    assert_eq!(verdict[4].0, "shard-00004.mcap.tmp");
    assert!(verdict[4].1.as_deref().unwrap().contains("unfinished"));
}

#[test]
fn cli_inspect_and_verify() {
    let exe = env!("CARGO_BIN_EXE_dreampolicy");
    let dir = tempfile::tempdir().unwrap();
    let written = two_shards(dir.path());
    let n: usize = written.iter().map(Vec::len).sum();
    let out = std::process::Command::new(exe)
        .args(["data", "inspect"])
        .arg(dir.path())
        .arg("--save-stats")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains(&format!("2 shards, {n} frames")), "{text}");
    assert!(
        text.contains("stair") && text.contains("episode length") && text.contains("dof_vel"),
        "{text}"
    );
    assert!(text.contains('#'), "a histogram bar: {text}");
    assert!(dir.path().join("stats.json").exists());

    let json = std::process::Command::new(exe)
        .args(["data", "inspect", "--json"])
        .arg(dir.path().join(shard_file_name(0)))
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(v["frames"], written[0].len() as u64);
    let per_terrain: u64 = v["terrains"]
        .as_object()
        .unwrap()
        .values()
        .map(|t| t["frames"].as_u64().unwrap())
        .sum();
    assert_eq!(per_terrain, written[0].len() as u64);

    let ok = std::process::Command::new(exe)
        .args(["data", "verify"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );

    let full = dir.path().join(shard_file_name(1));
    let len = std::fs::metadata(&full).unwrap().len() as usize / 2;
    truncated_copy(&full, &dir.path().join(shard_file_name(2)), len);
    let bad = std::process::Command::new(exe)
        .args(["data", "verify"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("1 of 3 shards are bad") && err.contains("shard-00002.mcap"),
        "{err}"
    );

    let empty = tempfile::tempdir().unwrap();
    let e = std::process::Command::new(exe)
        .args(["data", "inspect"])
        .arg(empty.path())
        .output()
        .unwrap();
    assert!(!e.status.success());
    assert!(String::from_utf8_lossy(&e.stderr).contains("no dataset shards"));
}

/// The corruption suite over a shard (issue 22): seeded byte flips, cuts and
/// zeroed blocks. Each damaged copy is refused with an error naming it, or read
/// to its last good chunk with a warning (its frames a prefix of the real
/// ones), or, where the damage hit no frame's bytes (the summary or an index),
/// read back exactly; never a panic, never other frames as if intact.
#[test]
fn damaged_shards_are_refused_or_read_to_their_last_good_chunk() {
    use rand::{Rng, SeedableRng};
    let dir = tempfile::tempdir().unwrap();
    let frames = synth(0, 6, 50, Dims::G1, &lens);
    let full = write_shard(dir.path(), 0, &frames, Dims::G1, small_chunks());
    let bytes = std::fs::read(&full).unwrap();
    let bad_dir = tempfile::tempdir().unwrap();
    let bad = bad_dir.path().join("shard-00000.mcap");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(22);
    let (mut refused, mut prefix, mut intact) = (0, 0, 0);
    for case in 0..60 {
        let mut b = bytes.clone();
        match case % 3 {
            0 => {
                for _ in 0..8 {
                    let at = rng.random_range(0..b.len());
                    b[at] ^= rng.random_range(1..=255u8);
                }
            }
            1 => b.truncate(rng.random_range(0..b.len())),
            _ => {
                let at = rng.random_range(0..b.len() - 64);
                b[at..at + 64].fill(0);
                if b == bytes {
                    b[at] = 1;
                }
            }
        }
        std::fs::write(&bad, &b).unwrap();
        let name = bad.display().to_string();
        let ds = match Dataset::open(bad_dir.path(), ReadOptions::default()) {
            Ok(ds) => ds,
            Err(e) => {
                assert!(e.to_string().contains(&name), "case {case}: {e}");
                refused += 1;
                continue;
            }
        };
        let mut read = Vec::new();
        let mut error = None;
        for x in ds.frames() {
            match x {
                Ok((_, f)) => read.push(f),
                Err(e) => {
                    error = Some(e.to_string());
                    break;
                }
            }
        }
        if let Some(e) = error {
            assert!(e.contains(&name), "case {case}: {e}");
            refused += 1;
        } else if read.len() < frames.len() {
            assert!(
                !ds.warnings().is_empty(),
                "case {case}: {} frames, no warning",
                read.len()
            );
            assert_eq!(&read[..], &frames[..read.len()], "case {case}");
            prefix += 1;
        } else {
            assert_eq!(read, frames, "case {case}: other frames read as if intact");
            intact += 1;
        }
    }
    eprintln!(
        "60 damaged shards: {refused} refused, {prefix} read to a good prefix, {intact} intact"
    );
    assert_eq!(refused + prefix + intact, 60);
    assert!(refused > 0 && prefix > 0);
}

/// `interleaved_windows_of` reads the shards side by side: the same windows as
/// the in-order stream (with a split and a kinds filter too), but every stretch
/// of it holds every shard in proportion, while the first quarter of the
/// in-order stream is shard 0 alone; the order is fixed by the seed.
#[test]
fn interleaved_windows_mix_the_shards_and_keep_every_window() {
    let dir = tempfile::tempdir().unwrap();
    for shard in 0..4u32 {
        let frames = synth(shard, 4, 60, Dims::G1, &lens);
        write_shard(dir.path(), shard, &frames, Dims::G1, small_chunks());
    }
    let ds = Dataset::open(dir.path(), ReadOptions::default()).unwrap();
    let spec = WindowSpec::new(3, 2).unwrap();
    let shard_of = |w: &dreampolicy::data::Window| (w.states[0] as u32 / 10_000) as usize;
    let key = |w: &dreampolicy::data::Window| (w.episode, w.first_step);
    let in_order: Vec<_> = ds.windows(spec, None).map(|w| w.unwrap()).collect();
    let mixed: Vec<_> = ds
        .interleaved_windows_of(spec, None, &[], 7)
        .map(|w| w.unwrap())
        .collect();
    assert_eq!(mixed.len(), in_order.len());
    let set = |ws: &[dreampolicy::data::Window]| ws.iter().map(key).collect::<BTreeSet<_>>();
    assert_eq!(set(&mixed), set(&in_order));
    // the stream's first quarter: in order one shard, interleaved all four in proportion
    let quarter = in_order.len() / 4;
    let shards_in = |ws: &[dreampolicy::data::Window]| {
        let mut n = [0usize; 4];
        ws.iter().for_each(|w| n[shard_of(w)] += 1);
        n
    };
    let first = shards_in(&in_order[..quarter]);
    assert!(first[1..].iter().all(|&n| n == 0), "{first:?}");
    let total = shards_in(&in_order);
    for (part, ws) in [(0, &mixed[..quarter]), (1, &mixed[quarter..2 * quarter])] {
        let n = shards_in(ws);
        for s in 0..4 {
            let share = n[s] as f64 / quarter as f64;
            let whole = total[s] as f64 / in_order.len() as f64;
            assert!(
                (share - whole).abs() < 0.1,
                "quarter {part}, shard {s}: {share:.2} of the windows against {whole:.2} overall"
            );
        }
    }
    // seeded
    let again: Vec<_> = ds
        .interleaved_windows_of(spec, None, &[], 7)
        .map(|w| key(&w.unwrap()))
        .collect();
    assert_eq!(again, mixed.iter().map(key).collect::<Vec<_>>());
    let other: Vec<_> = ds
        .interleaved_windows_of(spec, None, &[], 8)
        .map(|w| key(&w.unwrap()))
        .collect();
    assert_ne!(other, again);
    // a split side and a kinds filter keep the same windows as in order
    let split = Some((SplitSpec::new(0.3, 1).unwrap(), Split::Train));
    let kinds = [TerrainKind::ALL[0], TerrainKind::ALL[2]];
    let a: Vec<_> = ds
        .windows_of(spec, split, &kinds)
        .map(|w| w.unwrap())
        .collect();
    let b: Vec<_> = ds
        .interleaved_windows_of(spec, split, &kinds, 3)
        .map(|w| w.unwrap())
        .collect();
    assert!(!a.is_empty() && a.len() < in_order.len());
    assert_eq!(set(&a), set(&b));
}
