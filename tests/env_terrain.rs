//! The env on the procedural terrain map: scandots against mj_ray, the curriculum,
//! falls and map edges, terrain config errors.
use dreampolicy::env::obs::{self, SCAN_DIM};
use dreampolicy::env::VecEnv;
use dreampolicy::rl::config::ExperimentConfig;
use dreampolicy::robot::NUM_JOINTS;

mod common;

/// terrain_small.yaml without randomization or noise, plus `sets`.
fn cfg(sets: &[&str]) -> ExperimentConfig {
    let mut all = vec![
        "env.domain_rand.enabled=false",
        "env.observation.add_noise=false",
    ];
    all.extend_from_slice(sets);
    common::load_config("terrain_small.yaml", &all)
}

/// Every scandot of `grid` (the `env.observation.scan_grid` set by `sets`) equals
/// the ground height that mj_ray finds at that point.
fn scandots_match_mj_ray_on(sets: &[&str]) {
    let mut all = vec!["env.n_envs=5", "env.terrain.init_max_level=5"];
    all.extend_from_slice(sets);
    let c = cfg(&all);
    let grid = c.env.observation.scan_grid;
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 5 * NUM_JOINTS];
    for _ in 0..5 {
        v.step(&zeros);
    }
    // the ground geom (heightfield, or the plane of Flat-column envs) is group 0
    let only_ground = [1u8, 0, 0, 0, 0, 0];
    let mut worst: f64 = 0.0;
    let mut varied = 0.0f64;
    for (i, env) in v.envs().iter().enumerate() {
        let st = env.state();
        let (sy, cy) = st.yaw.sin_cos();
        let scan = &v.scan[i * SCAN_DIM..(i + 1) * SCAN_DIM];
        for (k, &got) in scan.iter().enumerate() {
            let (px, py) = grid.point(k);
            let x = st.base_pos[0] + cy * px - sy * py;
            let y = st.base_pos[1] + sy * px + cy * py;
            let top = st.base_pos[2] + 5.0;
            let (dist, _) = env
                .data()
                .ray(
                    [x, y, top],
                    [0.0, 0.0, -1.0],
                    Some(&only_ground),
                    true,
                    None,
                )
                .expect("the ray hits the terrain");
            let want = (top - dist - st.base_pos[2]).clamp(-1.0, 1.0);
            worst = worst.max((got as f64 - want).abs());
            varied = varied.max((got - scan[0]).abs() as f64);
        }
    }
    assert!(
        worst < 1e-3,
        "worst |scandot - mj_ray| = {worst} m ({grid:?})"
    );
    assert!(varied > 0.05, "some scan sees terrain relief ({grid:?})");
}

#[test]
fn scandots_match_mj_ray() {
    scandots_match_mj_ray_on(&[]);
}

/// A finer grid (0.05 m, 0.8 m x 0.5 m around the feet) is read where it says,
/// and the default grid is the one every older checkpoint saw.
#[test]
fn a_finer_scan_grid_reads_its_own_points() {
    let d = obs::ScanGrid::default();
    assert_eq!(d.point(0), (-0.6, -0.5));
    let far = d.far_corner();
    assert!((far.0 - 1.0).abs() < 1e-12 && (far.1 - 0.5).abs() < 1e-12);
    scandots_match_mj_ray_on(&[
        "env.observation.scan_grid.x0=-0.25",
        "env.observation.scan_grid.y0=-0.25",
        "env.observation.scan_grid.spacing=0.05",
    ]);
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/terrain_small.yaml");
    let bad = dreampolicy::rl::config::load(&path, &["env.observation.scan_grid.spacing=0".into()]);
    let msg = format!("{}", bad.expect_err("a zero spacing is refused"));
    assert!(msg.contains("scan_grid"), "{msg}");
}

/// Move env `i`'s robot `dx` along x, `height` above the ground; `fallen` lays it
/// on its side (a fall that the next step reports whatever the ground).
fn teleport(v: &mut VecEnv, i: usize, dx: f64, height: f64, fallen: bool) {
    let (x, y) = {
        let p = v.envs()[i].state().base_pos;
        (p[0] + dx, p[1])
    };
    let ground = v.envs()[i].ground(v.shared(), x, y);
    let d = v.data_mut(i).unwrap();
    d.qpos_mut()[0] = x;
    d.qpos_mut()[2] = ground + height;
    if fallen {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        d.qpos_mut()[3..7].copy_from_slice(&[h, h, 0.0, 0.0]);
    }
    d.forward();
}

#[test]
fn curriculum_promotes_walkers_and_demotes_fallers() {
    let c = cfg(&["env.n_envs=4", "env.terrain.init_max_level=4"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 4 * NUM_JOINTS];
    v.step(&zeros);
    let before: Vec<usize> = v.envs().iter().map(|e| e.terrain_level()).collect();
    // env 0 "walked" 5 m (more than half a tile) before falling; env 1 fell where it stood
    teleport(&mut v, 0, 5.0, 0.3, true);
    teleport(&mut v, 1, 0.0, 0.3, true);
    v.step(&zeros);
    assert!(
        v.outcomes[0].terminated && v.outcomes[1].terminated,
        "{:?}",
        &v.outcomes[..2]
    );
    assert!(!v.outcomes[2].episode_done && !v.outcomes[3].episode_done);
    let after: Vec<usize> = v.envs().iter().map(|e| e.terrain_level()).collect();
    assert_eq!(after[0], before[0] + 1, "promoted");
    assert_eq!(after[1], before[1].saturating_sub(1), "demoted");
    assert_eq!(&after[2..], &before[2..]);
    // the reset env stands at its new tile's spawn point
    let spawn = v.envs()[0].state().base_pos;
    let m = v.shared().scene.terrain.as_ref().unwrap();
    let b = m.tile_bounds(after[0], 0);
    assert!(spawn[0] > b.x[0] && spawn[0] < b.x[1], "{spawn:?} in {b:?}");
}

/// `levels_by_kind` (the `level_<kind>` columns of `metrics.csv`): each kind's
/// mean over the envs on its columns, counted by hand, and following a
/// promotion; nothing on a single-kind map or without a curriculum.
#[test]
fn levels_by_kind_average_each_kinds_envs() {
    use dreampolicy::env::task::VecTask;
    use dreampolicy::terrain::TerrainKind;
    let c = cfg(&["env.n_envs=10", "env.terrain.init_max_level=4"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let by_hand = |v: &VecEnv| -> Vec<(TerrainKind, f64)> {
        let m = v.shared().scene.terrain.as_ref().unwrap();
        TerrainKind::TRAINING
            .into_iter()
            .map(|k| {
                let ls: Vec<f64> = v
                    .envs()
                    .iter()
                    .filter(|e| m.tile_kind(e.column()) == k)
                    .map(|e| e.terrain_level() as f64)
                    .collect();
                (k, ls.iter().sum::<f64>() / ls.len() as f64)
            })
            .collect()
    };
    let got = VecTask::levels_by_kind(&v);
    assert_eq!(got.len(), 5, "{got:?}");
    assert_eq!(got, by_hand(&v));
    let kind_of = |v: &VecEnv, i: usize| {
        let m = v.shared().scene.terrain.as_ref().unwrap();
        m.tile_kind(v.envs()[i].column())
    };
    let n_on = (0..10)
        .filter(|&i| kind_of(&v, i) == kind_of(&v, 0))
        .count();
    let zeros = vec![0.0f32; 10 * NUM_JOINTS];
    v.step(&zeros);
    let kind0 = kind_of(&v, 0);
    let before = VecTask::levels_by_kind(&v);
    teleport(&mut v, 0, 5.0, 0.3, true);
    v.step(&zeros);
    let after = VecTask::levels_by_kind(&v);
    assert_eq!(after, by_hand(&v));
    let level = |l: &[(TerrainKind, f64)]| l.iter().find(|(k, _)| *k == kind0).unwrap().1;
    assert!(
        (level(&after) - level(&before) - 1.0 / n_on as f64).abs() < 1e-12,
        "{before:?} -> {after:?}"
    );
    // the kinds' means weighted by their envs make up the batch's mean
    let weighted: f64 = after
        .iter()
        .map(|(k, l)| l * (0..10).filter(|&i| kind_of(&v, i) == *k).count() as f64)
        .sum::<f64>()
        / 10.0;
    assert!((weighted - v.mean_terrain_level()).abs() < 1e-12);

    let single = cfg(&["env.n_envs=2", "env.terrain.map.kinds={stair: 1.0}"]);
    assert!(VecTask::levels_by_kind(&VecEnv::new(&single.env).unwrap()).is_empty());
    let fixed = cfg(&["env.n_envs=2", "env.terrain.curriculum=false"]);
    assert!(VecTask::levels_by_kind(&VecEnv::new(&fixed.env).unwrap()).is_empty());
}

#[test]
fn a_fall_remembers_the_condition_that_ended_it() {
    use dreampolicy::env::FallCause;
    // on its side in the air: tilted (before anything touches)
    let c = cfg(&["env.n_envs=2"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 2 * NUM_JOINTS];
    v.step(&zeros);
    teleport(&mut v, 0, 0.0, 0.7, true);
    v.step(&zeros);
    assert!(v.outcomes[0].terminated && !v.outcomes[1].episode_done);
    assert_eq!(v.envs()[0].last_episode_end().fall, Some(FallCause::Tilt));
    // dropped on its side with the tilt and height conditions off (the full
    // collision set gives the pelvis and torso their geoms): a contact ends it
    let c = cfg(&[
        "env.n_envs=1",
        "env.sim.collision=full",
        "env.termination.max_tilt_deg=179",
        "env.termination.min_base_height=0",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&zeros[..NUM_JOINTS]);
    teleport(&mut v, 0, 0.0, 0.3, true);
    let fell = (0..100).any(|_| {
        v.step(&zeros[..NUM_JOINTS]);
        v.outcomes[0].terminated
    });
    assert!(fell, "lying on the ground without a contact end");
    assert_eq!(
        v.envs()[0].last_episode_end().fall,
        Some(FallCause::Contact)
    );
    // an upright pelvis below termination.min_base_height
    let c = cfg(&["env.n_envs=1", "env.termination.min_base_height=2.0"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&zeros[..NUM_JOINTS]);
    assert!(v.outcomes[0].terminated);
    assert_eq!(
        v.envs()[0].last_episode_end().fall,
        Some(FallCause::BaseHeight)
    );
    // a truncation is not a fall
    let c = cfg(&["env.n_envs=1"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&zeros[..NUM_JOINTS]);
    let x = v.envs()[0].state().base_pos[0];
    teleport(&mut v, 0, 0.5 - x, 0.8, false);
    v.step(&zeros[..NUM_JOINTS]);
    assert!(v.outcomes[0].truncated);
    assert_eq!(v.envs()[0].last_episode_end().fall, None);
}

#[test]
fn leaving_the_map_truncates_without_terminating() {
    let c = cfg(&["env.n_envs=2"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 2 * NUM_JOINTS];
    v.step(&zeros);
    let x = v.envs()[0].state().base_pos[0];
    teleport(&mut v, 0, 0.5 - x, 0.8, false); // x = 0.5 m: inside the 1 m margin
    v.step(&zeros);
    assert!(v.outcomes[0].truncated && !v.outcomes[0].terminated);
    // the final observation is the one before the reset: upright, at the map's edge
    assert!(v.final_obs[..obs::OBS_DIM].iter().all(|x| x.is_finite()));
    assert!(
        v.final_critic[obs::OBS_DIM + 3] > 0.5,
        "pelvis still above ground at the end"
    );
}

#[test]
fn terrain_config_errors_are_clear() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/terrain_small.yaml");
    let e = dreampolicy::rl::config::load(&path, &["env.terrain.map.kinds={lava: 1.0}".into()])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown terrain kind 'lava'") && e.contains("balancing_beam"),
        "{e}"
    );
    let e = dreampolicy::rl::config::load(&path, &["env.terrain.map.num_levels=0".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("num_levels"), "{e}");
    let e = dreampolicy::rl::config::load(&path, &["env.terrain.map.tile_length=-2".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("tile_length"), "{e}");
}

#[test]
fn envs_on_flat_columns_step_on_a_plane() {
    use dreampolicy::terrain::TerrainKind;
    let c = cfg(&["env.n_envs=5"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let map = v.shared().scene.terrain.clone().unwrap();
    v.step(&vec![0.0f32; 5 * NUM_JOINTS]);
    for (i, env) in v.envs().iter().enumerate() {
        let flat = map.tile_kind(i % map.num_cols()) == TerrainKind::Flat;
        assert_eq!(env.on_plane(), flat, "env {i}");
        let st = env.state();
        if flat {
            // the plane is the ground: physics, height above ground and scandots agree
            let m = env.data().model();
            let g = m.id(dreampolicy::sim::ObjType::Geom, "terrain").unwrap();
            assert_eq!(m.geom_type()[g], mujoco_sys::mjGEOM_PLANE as i32);
            let (dist, geom) = env
                .data()
                .ray(
                    [st.base_pos[0], st.base_pos[1], 3.0],
                    [0.0, 0.0, -1.0],
                    Some(&[1, 0, 0, 0, 0, 0]),
                    true,
                    None,
                )
                .unwrap();
            assert_eq!(
                env.data()
                    .model()
                    .id2name(dreampolicy::sim::ObjType::Geom, geom),
                Some("terrain")
            );
            assert!((3.0 - dist).abs() < 1e-9);
            assert!((st.base_height - st.base_pos[2]).abs() < 1e-12);
            let scan = &v.scan[i * SCAN_DIM..(i + 1) * SCAN_DIM];
            assert!(scan
                .iter()
                .all(|h| (*h as f64 + st.base_pos[2]).abs() < 1e-5));
        }
    }
    assert!(v.envs().iter().any(|e| e.on_plane()) && v.envs().iter().any(|e| !e.on_plane()));
    // off: every env steps on the heightfield
    let c = cfg(&["env.n_envs=5", "env.terrain.flat_on_plane=false"]);
    let v = VecEnv::new(&c.env).unwrap();
    assert!(v.envs().iter().all(|e| !e.on_plane()));
    assert!(v.shared().scene.plane_models.is_empty());
}

/// G1s holding their default pose (zero actions) on an exactly flat heightfield:
/// (1) how many fall in `steps` control steps, (2) the largest tilt (1 - n_z)
/// of a terrain contact normal over the first 25 steps.
fn stand_on_flat_heightfield(hfield_contacts: &str, steps: usize) -> (usize, f64) {
    let contacts = format!("env.sim.hfield_contacts={hfield_contacts}");
    let c = common::load_config(
        "specialist/uneven.yaml",
        &[
            "env.domain_rand.enabled=false",
            "env.sim.integrator=implicit",
            "env.observation.add_noise=false",
            "env.n_envs=24",
            "env.terrain.map.kinds={flat: 1.0}",
            "env.terrain.flat_on_plane=false",
            "env.terrain.map.min_roughness=0.0",
            "env.terrain.map.base_roughness=0.0",
            &contacts,
        ],
    );
    let mut v = VecEnv::new(&c.env).unwrap();
    assert!(v.envs().iter().all(|e| !e.on_plane()));
    let zeros = vec![0.0f32; 24 * NUM_JOINTS];
    let (mut falls, mut tilt) = (0, 0.0f64);
    for step in 0..steps {
        falls += v.step(&zeros).episodes_done;
        if step < 25 {
            for env in v.envs() {
                let m = env.data().model();
                let terrain = m.id(dreampolicy::sim::ObjType::Geom, "terrain").unwrap() as i32;
                for con in env.data().contacts() {
                    let (g1, g2) = dreampolicy::sim::contact_geoms(con);
                    if g1 == terrain || g2 == terrain {
                        tilt = tilt.max(1.0 - con.frame[2].abs());
                    }
                }
            }
        }
    }
    (falls, tilt)
}

#[test]
fn g1_stands_on_a_flat_heightfield_as_on_a_plane() {
    // surface contacts (the default): normals straight up, nobody falls in 6 s,
    // as on the plane
    let (falls, tilt) = stand_on_flat_heightfield("surface", 300);
    assert!(
        tilt < 1e-9,
        "a terrain contact normal tilted: 1 - n_z = {tilt}"
    );
    assert_eq!(falls, 0, "G1s fell standing still on a flat heightfield");
    // MuJoCo's prisms (the cause): their side faces tilt contact normals
    let (_, tilt) = stand_on_flat_heightfield("prisms", 25);
    assert!(
        tilt > 0.05,
        "prism contacts on a flat heightfield: 1 - n_z = {tilt}"
    );
}

/// On a gap map the state measures heights from the surface the feet step
/// over: a paper-table gap (0.2 m wide, 1 m deep) is filled in it, at the
/// platforms' level, while the physics and the scandots keep the pit.
#[test]
fn gaps_are_filled_in_the_support_surface_only() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.terrain.map.kinds={gap: 1.0}",
        "env.terrain.map.gap.gap=[0.2,0.2]",
        "env.terrain.map.base_roughness=0.0",
        "env.terrain.map.min_roughness=0.0",
    ]);
    let v = VecEnv::new(&c.env).unwrap();
    let scene = &v.shared().scene;
    let [lx, ly] = scene.terrain.as_ref().unwrap().extent();
    let (mut pits, mut filled) = (0, 0);
    let mut x = 0.0;
    while x < lx {
        let y = ly / 2.0;
        if scene.ground(x, y) < -0.5 {
            pits += 1;
            // the platforms' level: the higher rim 0.3 m either side
            let rim = scene.ground(x - 0.3, y).max(scene.ground(x + 0.3, y));
            if (scene.support(x, y) - rim).abs() < 0.05 {
                filled += 1;
            }
        }
        x += 0.01;
    }
    assert!(pits > 50, "the map has gaps ({pits} samples in pits)");
    assert!(
        filled * 10 >= pits * 9,
        "{filled} of {pits} pit samples filled"
    );
    // a support radius of 0 is the raw terrain
    let raw = cfg(&[
        "env.n_envs=1",
        "env.terrain.support_radius=0.0",
        "env.terrain.map.kinds={gap: 1.0}",
    ]);
    let v = VecEnv::new(&raw.env).unwrap();
    let s = &v.shared().scene;
    for k in 0..1000 {
        let (x, y) = (lx * k as f64 / 1000.0, ly / 3.0);
        assert_eq!(s.support(x, y), s.ground(x, y));
    }
}

/// Stand env 0's robot `dx` along the lane from `start`, its pelvis at standing
/// height above the support surface, still, and step once; false when the
/// step ended its episode.
fn stand_at(v: &mut VecEnv, start: [f64; 3], dx: f64) -> bool {
    let zeros = vec![0.0f32; NUM_JOINTS];
    let x = start[0] + dx;
    let z = v.shared().scene.support(x, start[1]) + 0.8;
    let d = v.data_mut(0).unwrap();
    d.qpos_mut()[0] = x;
    d.qpos_mut()[2] = z;
    d.qvel_mut().iter_mut().for_each(|q| *q = 0.0);
    d.forward();
    v.step(&zeros);
    !v.outcomes[0].episode_done
}

/// `feet_over_pit` and `feet_straddle` (the `feet_gap` and `feet_straddle`
/// terms' inputs) against the raw terrain under the sole's ends: a heel or toe
/// above a 1 m pit is over it, a sole with both ends on platforms is not, and
/// one with an end on each straddles the edge.
#[test]
fn feet_over_pit_reads_the_soles_ends() {
    let c = cfg(&[
        "env.n_envs=1",
        "env.terrain.map.kinds={gap: 1.0}",
        "env.terrain.map.gap.gap=[0.2,0.2]",
        "env.terrain.map.gap.depth=[1.0,1.0]",
        "env.terrain.map.base_roughness=0.0",
        "env.terrain.map.min_roughness=0.0",
        "env.terrain.init_max_level=0",
    ]);
    let mut v = VecEnv::new(&c.env).unwrap();
    v.step(&[0.0f32; NUM_JOINTS]);
    let start = v.envs()[0].state().base_pos;
    let (mut over, mut across, mut clear) = (0, 0, 0);
    for k in 0..80 {
        if !stand_at(&mut v, start, 0.025 * k as f64) {
            continue;
        }
        let s = v.envs()[0].state();
        let scene = &v.shared().scene;
        for f in 0..2 {
            let [fx, fy, _] = s.feet_pos[f];
            let ends =
                [-0.05, 0.13].map(|a| scene.ground(fx + a * s.yaw.cos(), fy + a * s.yaw.sin()));
            let at = format!("foot {f} at {:?}: ends {ends:?}", s.feet_pos[f]);
            if ends.iter().any(|&h| h < -0.5) {
                assert!(s.feet_over_pit[f], "{at}");
                over += 1;
                if ends.iter().any(|&h| h.abs() < 0.01) {
                    assert!(s.feet_straddle[f], "{at}");
                    across += 1;
                }
            } else if [-0.09, -0.05, 0.13, 0.17].iter().all(|&a| {
                // both ends on a platform with 4 cm to spare (the foot's own
                // yaw moves its corners by a few mm against the pelvis's)
                scene
                    .ground(fx + a * s.yaw.cos(), fy + a * s.yaw.sin())
                    .abs()
                    < 0.01
            }) {
                assert!(!s.feet_over_pit[f] && !s.feet_straddle[f], "{at}");
                clear += 1;
            }
        }
    }
    assert!(
        over > 5 && across > 2 && clear > 5,
        "{over} feet over pits ({across} across an edge), {clear} on platforms"
    );
}

/// `swing_lookahead`: the swing terms' ground is the highest support surface
/// from under the foot to the lookahead ahead, so it rises before a riser
/// reaches the foot; without a lookahead it is the ground under the foot.
#[test]
fn swing_ground_looks_ahead_on_stairs() {
    let stairs = |ahead: &str| {
        cfg(&[
            "env.n_envs=1",
            "env.terrain.map.kinds={stair: 1.0}",
            "env.terrain.map.base_roughness=0.0",
            "env.terrain.map.min_roughness=0.0",
            "env.terrain.init_max_level=0",
            ahead,
        ])
    };
    for (ahead, lookahead) in [
        ("env.rewards.params.swing_lookahead=0.3", 0.3),
        ("env.rewards.params.swing_lookahead=0.0", 0.0),
    ] {
        let mut v = VecEnv::new(&stairs(ahead).env).unwrap();
        v.step(&[0.0f32; NUM_JOINTS]);
        let start = v.envs()[0].state().base_pos;
        let mut raised = 0;
        for k in 0..120 {
            if !stand_at(&mut v, start, 0.025 * k as f64) {
                continue;
            }
            let s = v.envs()[0].state();
            for f in 0..2 {
                let (under, swing) = (s.feet_ground[f], s.feet_swing_ground[f]);
                assert!(swing >= under, "foot {f}: {swing} below {under}");
                if lookahead == 0.0 {
                    assert_eq!(swing, under);
                } else if swing > under + 0.02 {
                    // a riser within the lookahead: the support there is this high
                    let scene = &v.shared().scene;
                    let [fx, fy, _] = s.feet_pos[f];
                    let top = (0..=6)
                        .map(|i| {
                            let d = 0.05 * i as f64;
                            scene.support(fx + d * s.yaw.cos(), fy + d * s.yaw.sin())
                        })
                        .fold(f64::NEG_INFINITY, f64::max);
                    assert!((top - swing).abs() < 1e-9, "foot {f}: {swing} vs {top}");
                    raised += 1;
                }
            }
        }
        assert!(
            lookahead == 0.0 || raised > 5,
            "{raised} feet before a riser"
        );
    }
}
