//! The env on the procedural terrain map: scandots against mj_ray, the curriculum,
//! falls and map edges, terrain config errors.
use dreampolicy::config::{self, ExperimentConfig};
use dreampolicy::env::obs::{self, SCAN_DIM};
use dreampolicy::env::VecEnv;
use dreampolicy::robot::NUM_JOINTS;

fn cfg(sets: &[&str]) -> ExperimentConfig {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/terrain_small.yaml");
    let mut all = vec![
        "env.domain_rand.enabled=false".to_string(),
        "env.observation.add_noise=false".to_string(),
    ];
    all.extend(sets.iter().map(|s| s.to_string()));
    config::load(&path, &all).unwrap()
}

#[test]
fn scandots_match_mj_ray() {
    let c = cfg(&["env.n_envs=5", "env.terrain.init_max_level=5"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 5 * NUM_JOINTS];
    for _ in 0..5 {
        v.step(&zeros);
    }
    let only_ground = [1u8, 0, 0, 0, 0, 0];
    let mut worst: f64 = 0.0;
    let mut varied = 0.0f64;
    for (i, env) in v.envs().iter().enumerate() {
        let st = env.state();
        let (sy, cy) = st.yaw.sin_cos();
        let scan = &v.scan[i * SCAN_DIM..(i + 1) * SCAN_DIM];
        for (k, &got) in scan.iter().enumerate() {
            let (px, py) = obs::scan_point(k);
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
    assert!(worst < 1e-3, "worst |scandot - mj_ray| = {worst} m");
    assert!(varied > 0.05, "some scan sees terrain relief");
}

fn teleport(v: &mut VecEnv, i: usize, dx: f64, height: f64) {
    let (x, y) = {
        let p = v.envs()[i].state().base_pos;
        (p[0] + dx, p[1])
    };
    let ground = v.shared().scene.ground(x, y);
    let d = v.data_mut(i).unwrap();
    d.qpos_mut()[0] = x;
    d.qpos_mut()[2] = ground + height;
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
    teleport(&mut v, 0, 5.0, 0.1);
    teleport(&mut v, 1, 0.0, 0.1);
    v.step(&zeros);
    assert!(v.outcomes[0].terminated && v.outcomes[1].terminated);
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

#[test]
fn leaving_the_map_truncates_without_terminating() {
    let c = cfg(&["env.n_envs=2"]);
    let mut v = VecEnv::new(&c.env).unwrap();
    let zeros = vec![0.0f32; 2 * NUM_JOINTS];
    v.step(&zeros);
    let x = v.envs()[0].state().base_pos[0];
    teleport(&mut v, 0, 0.5 - x, 0.8); // x = 0.5 m: inside the 1 m margin
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
    let e = config::load(&path, &["env.terrain.map.kinds={lava: 1.0}".into()])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("unknown terrain kind 'lava'") && e.contains("balancing_beam"),
        "{e}"
    );
    let e = config::load(&path, &["env.terrain.map.num_levels=0".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("num_levels"), "{e}");
    let e = config::load(&path, &["env.terrain.map.tile_length=-2".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("tile_length"), "{e}");
}

#[test]
fn flat_tiles_are_boxes_over_a_lowered_heightfield() {
    use dreampolicy::env::scene::{Scene, FLAT_BOX_CLEARANCE};
    use dreampolicy::terrain::TerrainKind;
    let c = cfg(&["env.n_envs=1"]);
    let scene = Scene::build(&c.env).unwrap();
    let map = scene.terrain.as_ref().unwrap();
    let flat_cols = (0..map.num_cols())
        .filter(|&k| map.tile_kind(k) == TerrainKind::Flat)
        .count();
    assert_eq!(scene.flat_boxes.len(), flat_cols * map.num_levels());
    let hf = scene.heights.as_ref().unwrap();
    for b in &scene.flat_boxes {
        let (x, y) = (0.5 * (b.x[0] + b.x[1]), 0.5 * (b.y[0] + b.y[1]));
        assert_eq!(scene.ground(x, y), b.top);
        assert!(hf.height(x, y) <= b.top - FLAT_BOX_CLEARANCE + 1e-6);
    }
    // without boxes, flat tiles keep their roughness in the heightfield
    let c = cfg(&["env.n_envs=1", "env.terrain.flat_boxes=false"]);
    let scene = Scene::build(&c.env).unwrap();
    assert!(scene.flat_boxes.is_empty());
}
