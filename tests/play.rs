//! `dreampolicy play` on the committed flat walker: short rollouts on a plane and
//! on an `uneven` lane, read back with the `mcap` crate (channels, Foxglove
//! schema names and encodings, one transform per body with unit quaternions,
//! message counts against the summary's frames, increasing timestamps, feet on
//! the ground where the state says they touch it), byte-identical files for the
//! same seed, and the errors for bad input.
mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use common::Scratch;
use dreampolicy::play::file::{Topic, METADATA_NAME};
use dreampolicy::play::{play, Ending, PlayError, PlayOptions, PlaySummary};
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::terrain::TerrainKind;
use serde_json::Value;

fn walker() -> Checkpoint {
    Checkpoint::read(&common::walker_path()).unwrap()
}

/// Every message of a play file, by topic: (log time, JSON).
struct PlayFile {
    messages: BTreeMap<String, Vec<(u64, Value)>>,
    summary: mcap::Summary,
    metadata: BTreeMap<String, String>,
}

fn read(path: &Path) -> PlayFile {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
    let mut messages: BTreeMap<String, Vec<(u64, Value)>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let json: Value = serde_json::from_slice(&m.data)
            .unwrap_or_else(|e| panic!("{}: a message that is not JSON: {e}", m.channel.topic));
        messages
            .entry(m.channel.topic.clone())
            .or_default()
            .push((m.log_time, json));
    }
    let index = summary
        .metadata_indexes
        .iter()
        .find(|i| i.name == METADATA_NAME)
        .expect("the dreampolicy.play metadata record");
    let metadata = mcap::read::metadata(&bytes, index).unwrap().metadata;
    PlayFile {
        messages,
        summary,
        metadata,
    }
}

fn f(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("{key} is not a number in {v}"))
}

/// Rotate `v` by a Foxglove quaternion `{x, y, z, w}`.
fn rotate(q: &Value, v: [f64; 3]) -> [f64; 3] {
    let (x, y, z, w) = (f(q, "x"), f(q, "y"), f(q, "z"), f(q, "w"));
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

fn vec3(v: &Value) -> [f64; 3] {
    [f(v, "x"), f(v, "y"), f(v, "z")]
}

/// What every play file must hold, whatever the rollout did.
fn check_file(p: &PlayFile, s: &PlaySummary) {
    // channels: topic, schema name, encodings; schema text is JSON naming itself
    assert_eq!(p.summary.channels.len(), Topic::ALL.len());
    for c in p.summary.channels.values() {
        let topic = Topic::ALL
            .into_iter()
            .find(|t| t.name() == c.topic)
            .unwrap_or_else(|| panic!("unexpected channel {}", c.topic));
        let schema = c.schema.as_ref().expect("every channel has a schema");
        assert_eq!(schema.name, topic.schema_name());
        assert_eq!(schema.encoding, "jsonschema");
        assert_eq!(c.message_encoding, "json");
        let text: Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(text["title"], schema.name.as_str());
    }
    let names: BTreeSet<&str> = p
        .summary
        .schemas
        .values()
        .map(|s| s.name.as_str())
        .collect();
    for n in ["foxglove.FrameTransforms", "foxglove.SceneUpdate"] {
        assert!(names.contains(n), "{n} in {names:?}");
    }

    // counts: one per frame, /reward one per step after frame 0, the scene once
    let count = |t: Topic| p.messages.get(t.name()).map_or(0, |v| v.len() as u64);
    assert!(s.frames >= 1);
    for t in [Topic::Tf, Topic::State, Topic::Command] {
        assert_eq!(count(t), s.frames, "{}", t.name());
    }
    assert_eq!(count(Topic::Reward), s.frames - 1);
    assert_eq!(count(Topic::Robot), 1);
    assert_eq!(count(Topic::Terrain), 1);
    let total: u64 = Topic::ALL.into_iter().map(count).sum();
    assert_eq!(total, p.summary.stats.as_ref().unwrap().message_count);
    match s.ending {
        Ending::TimeUp => assert_eq!(s.steps, s.frames - 1),
        _ => assert_eq!(s.steps, s.frames, "the step that ended it writes no frame"),
    }

    // timestamps increase on every topic; frame k is stamped 1 s + k x 20 ms
    for (topic, msgs) in &p.messages {
        for w in msgs.windows(2) {
            assert!(w[1].0 > w[0].0, "{topic}: {} after {}", w[1].0, w[0].0);
        }
    }
    for (k, (t, state)) in p.messages["/state"].iter().enumerate() {
        assert_eq!(state["step"], k as u64);
        assert_eq!(*t, 1_000_000_000 + k as u64 * 20_000_000);
    }

    // /tf: one transform per body, in world, unit quaternions, stamped as logged
    let robot = &p.messages["/robot"][0].1["entities"];
    let frames: BTreeSet<&str> = robot
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["frame_id"].as_str().unwrap())
        .collect();
    assert_eq!(frames.len(), s.bodies);
    assert_eq!(s.bodies, 30, "the G1 has 30 bodies besides the world");
    for (t, tf) in &p.messages["/tf"] {
        let tfs = tf["transforms"].as_array().unwrap();
        assert_eq!(tfs.len(), s.bodies);
        let children: BTreeSet<&str> = tfs
            .iter()
            .map(|x| x["child_frame_id"].as_str().unwrap())
            .collect();
        assert_eq!(children, frames);
        for x in tfs {
            assert_eq!(x["parent_frame_id"], "world");
            let q = &x["rotation"];
            let n = (f(q, "x").powi(2) + f(q, "y").powi(2) + f(q, "z").powi(2) + f(q, "w").powi(2))
                .sqrt();
            assert!((n - 1.0).abs() < 1e-5, "|q| = {n}");
            let stamp = &x["timestamp"];
            assert_eq!(
                stamp["sec"].as_u64().unwrap() * 1_000_000_000 + stamp["nsec"].as_u64().unwrap(),
                *t
            );
        }
    }
    for e in robot.as_array().unwrap() {
        assert_eq!(e["frame_locked"], true);
        let n = ["spheres", "cylinders", "cubes"]
            .iter()
            .map(|k| e[k].as_array().unwrap().len())
            .sum::<usize>();
        assert!(n > 0, "{} draws nothing", e["id"]);
    }
    assert_eq!(p.metadata["terrain"], s.terrain);
}

/// Lowest point of a foot's spheres (world z) at frame `k`, through `/tf`.
fn foot_bottom(p: &PlayFile, foot: &str, k: usize) -> f64 {
    let entity = p.messages["/robot"][0].1["entities"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["frame_id"] == foot)
        .unwrap()
        .clone();
    let tf = p.messages["/tf"][k].1["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["child_frame_id"] == foot)
        .unwrap()
        .clone();
    let t = vec3(&tf["translation"]);
    entity["spheres"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let c = rotate(&tf["rotation"], vec3(&s["pose"]["position"]));
            c[2] + t[2] - 0.5 * f(&s["size"], "z")
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn play_on_a_plane_writes_a_foxglove_file() {
    let dir = Scratch::new("play-flat");
    let ck = walker();
    let mut o = PlayOptions::new(TerrainKind::Flat, dir.0.join("sub/flat.mcap"));
    o.seconds = 2.5;
    let s = play(&ck, &o).unwrap();
    assert_eq!(s.ending, Ending::TimeUp, "the flat walker walks: {s:?}");
    assert!(!s.fell);
    assert_eq!((s.steps, s.frames), (125, 126));
    assert!(s.distance > 0.3, "walked {} m", s.distance);
    assert_eq!(s.commanded_speed, 0.75, "the middle of eval.lin_vel_x");
    assert_eq!((s.level, s.lane_length, s.reached_goal), (None, None, None));
    assert_eq!(
        s.file_bytes,
        std::fs::metadata(&o.out).unwrap().len(),
        "the reported size is the file's"
    );
    assert!(!dir.0.join("sub/flat.mcap.tmp").exists());

    let p = read(&o.out);
    check_file(&p, &s);
    // the command is what was asked; the state's distance is the summary's
    for (_, c) in &p.messages["/command"] {
        assert_eq!(f(c, "vx"), 0.75);
        assert_eq!(f(c, "vy"), 0.0);
    }
    let last = &p.messages["/state"].last().unwrap().1;
    assert!((f(last, "distance") - s.distance).abs() < 1e-4);
    // reward terms are named and add up to the step's total
    for (_, r) in &p.messages["/reward"] {
        let terms = r["terms"].as_object().unwrap();
        assert!(terms.contains_key("tracking_lin_vel"), "{terms:?}");
        let sum: f64 = terms.values().map(|v| v.as_f64().unwrap()).sum();
        assert!(
            (sum - f(r, "total")).abs() < 1e-4,
            "{sum} vs {}",
            r["total"]
        );
    }
    // the drawn feet stand on the plane whenever the state says they touch it
    // (within MuJoCo's soft-contact penetration at a touchdown: up to ~1 cm)
    let mut checked = 0;
    for (k, (_, st)) in p.messages["/state"].iter().enumerate() {
        for (foot, key) in [
            ("left_ankle_roll_link", "left_contact"),
            ("right_ankle_roll_link", "right_contact"),
        ] {
            if st[key] == 1 {
                let z = foot_bottom(&p, foot, k);
                assert!(z.abs() < 0.015, "frame {k}: {foot} bottom at {z} m");
                checked += 1;
            }
        }
    }
    assert!(checked > 100, "{checked} foot contacts checked");
    // the floor: checker tiles under the walk
    let ground = &p.messages["/terrain"][0].1["entities"][0];
    assert_eq!(ground["frame_id"], "world");
    assert!(ground["cubes"].as_array().unwrap().len() > 20);

    // the same options write the same bytes
    let mut again = o.clone();
    again.out = dir.0.join("again.mcap");
    play(&ck, &again).unwrap();
    assert_eq!(
        std::fs::read(&o.out).unwrap(),
        std::fs::read(&again.out).unwrap()
    );
}

#[test]
fn play_on_an_uneven_lane_draws_its_heightfield() {
    let dir = Scratch::new("play-uneven");
    let ck = walker();
    let mut o = PlayOptions::new(TerrainKind::Uneven, dir.0.join("uneven.mcap"));
    o.seconds = 2.0;
    o.level = Some(1);
    o.full_collision = true;
    let s = play(&ck, &o).unwrap();
    assert_eq!((s.level, s.lane_length), (Some(1), Some(10.0)));
    assert_eq!(s.table.as_deref(), Some("the paper's table"));
    assert!(s.full_collision);
    assert!(matches!(s.ending, Ending::TimeUp | Ending::Fell), "{s:?}");
    assert_eq!(s.fell, s.ending == Ending::Fell);
    let p = read(&o.out);
    check_file(&p, &s);
    assert_eq!(p.metadata["level"], "1");
    assert_eq!(p.metadata["full_collision"], "true");

    let ground = &p.messages["/terrain"][0].1["entities"][0];
    let tri = &ground["triangles"][0];
    let points = tri["points"].as_array().unwrap();
    let colors = tri["colors"].as_array().unwrap();
    let indices = tri["indices"].as_array().unwrap();
    assert_eq!(points.len(), colors.len());
    assert!(!indices.is_empty() && indices.len().is_multiple_of(3));
    assert!(indices
        .iter()
        .all(|i| (i.as_u64().unwrap() as usize) < points.len()));
    // uneven blocks stand out of the 5 mm roughness
    let (lo, hi) = points
        .iter()
        .map(|q| f(q, "z"))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), z| {
            (lo.min(z), hi.max(z))
        });
    assert!(hi - lo > 0.1, "heights {lo}..{hi}");
    // the mesh is the ground the physics sees, and base_height is measured from
    // its closing (`env.terrain.support_radius`, 0.2 m: a max, then a min filter
    // over 9 x 9 samples): under the pelvis, at every frame, the closed mesh's
    // height (MuJoCo's diagonal split) is pelvis z - base_height
    let xs: BTreeSet<i64> = points.iter().map(|q| (f(q, "x") * 1e4) as i64).collect();
    let w = xs.len();
    let (x0, y0) = (f(&points[0], "x"), f(&points[0], "y"));
    let hs = f(&points[1], "x") - x0;
    let rows = points.len() / w;
    let radius = (0.2 / hs - 1e-9).ceil() as usize;
    let raw: Vec<f64> = points.iter().map(|q| f(q, "z")).collect();
    let filter = |src: &[f64], max: bool| -> Vec<f64> {
        let mut out = vec![0.0; src.len()];
        for j in 0..rows {
            for i in 0..w {
                let (i0, i1) = (i.saturating_sub(radius), (i + radius).min(w - 1));
                let (j0, j1) = (j.saturating_sub(radius), (j + radius).min(rows - 1));
                let cells = (j0..=j1).flat_map(|jj| (i0..=i1).map(move |ii| jj * w + ii));
                let vals = cells.map(|k| src[k]);
                out[j * w + i] = if max {
                    vals.fold(f64::NEG_INFINITY, f64::max)
                } else {
                    vals.fold(f64::INFINITY, f64::min)
                };
            }
        }
        out
    };
    let closed = filter(&filter(&raw, true), false);
    assert!(
        closed.iter().zip(&raw).all(|(c, r)| c >= r),
        "a closing only fills"
    );
    let z = |i: usize, j: usize| closed[j * w + i];
    for (_, st) in &p.messages["/state"] {
        let (u, v) = ((f(st, "x") - x0) / hs, (f(st, "y") - y0) / hs);
        let (i, j) = (u.floor() as usize, v.floor() as usize);
        let (u, v) = (u - i as f64, v - j as f64);
        let (a, b, c, d) = (z(i, j), z(i + 1, j), z(i, j + 1), z(i + 1, j + 1));
        let mesh = if u >= v {
            a + u * (b - a) + v * (d - b)
        } else {
            a + v * (c - a) + u * (d - c)
        };
        let ground = f(st, "z") - f(st, "base_height");
        assert!(
            (mesh - ground).abs() < 1e-3,
            "mesh {mesh} vs ground {ground}"
        );
    }
    // the robot starts on the lane's centre line, 1 m into its tile
    let first = &p.messages["/state"][0].1;
    assert!(f(first, "base_height") > 0.7);
    assert!(f(first, "x") > 5.0, "spawned inside the map's border");
}

#[test]
fn play_draws_the_lane_that_eval_scores() {
    // a stair specialist trained on 3 cm risers at level 0: play's level-0 lane is
    // eval's (the paper's 15 cm risers), not the training curriculum's
    let dir = Scratch::new("play-evallane");
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models/checkpoints/stair/checkpoints/latest.pt");
    let ck = Checkpoint::read(&path).unwrap();
    let cfg = ck.config().unwrap();
    assert!(cfg.env.terrain.map != cfg.eval.terrain);
    let mut o = PlayOptions::new(TerrainKind::Stair, dir.0.join("stair.mcap"));
    (o.seconds, o.level, o.seed) = (0.2, Some(0), 4);
    let s = play(&ck, &o).unwrap();
    let lane = dreampolicy::eval::eval_lane(&cfg, TerrainKind::Stair, 0, 4).unwrap();
    assert_eq!(s.lane_length, Some(lane.length()));
    let p = read(&o.out);
    let points = p.messages["/terrain"][0].1["entities"][0]["triangles"][0]["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| f(q, "z"))
        .fold(f64::MIN, f64::max);
    let [lo, hi] = lane.map().height_range();
    assert!(
        (points - hi).abs() < 1e-3 && hi - lo > 0.1,
        "drawn top {points}, lane {lo}..{hi}"
    );
}

#[test]
fn bad_input_is_a_clear_error() {
    let dir = Scratch::new("play-bad");
    let ck = walker();
    let mut o = PlayOptions::new(TerrainKind::Flat, dir.0.join("x.mcap"));
    o.seconds = -1.0;
    let e = play(&ck, &o).unwrap_err();
    assert!(matches!(e, PlayError::Invalid(_)), "{e}");
    assert!(e.to_string().contains("--seconds"), "{e}");
    o.seconds = 1.0;
    o.speed = Some(f64::NAN);
    assert!(play(&ck, &o).unwrap_err().to_string().contains("--speed"));
    o.speed = None;
    o.terrain = TerrainKind::Stair;
    o.level = Some(99);
    let e = play(&ck, &o).unwrap_err().to_string();
    assert!(e.contains("99"), "{e}");
    assert!(!o.out.exists() && !dir.0.join("x.mcap.tmp").exists());

    // the CLI: an unknown terrain lists the valid names; a missing checkpoint is named
    let cli = |checkpoint: &Path, terrain: &str| {
        let out = Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
            .args(["play", "--terrain", terrain, "--checkpoint"])
            .arg(checkpoint)
            .arg("--out")
            .arg(dir.0.join("y.mcap"))
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = cli(&common::walker_path(), "stairs");
    assert!(
        err.contains("stairs") && err.contains("flat, uneven, stair"),
        "{err}"
    );
    let err = cli(&dir.0.join("missing.pt"), "flat");
    assert!(
        err.contains("missing.pt") && err.contains("no such file"),
        "{err}"
    );
    assert!(!dir.0.join("y.mcap").exists());
}
