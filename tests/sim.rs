//! The safe MuJoCo layer: loading errors, stepping, instability, threads, heightfields.
mod common;

use std::sync::Arc;

use common::Scratch;
use dreampolicy::sim::{Data, HeightField, Instability, Model, ObjType, SimError};
use rand::{Rng, SeedableRng};

const BALL: &str = r#"<mujoco model="ball">
  <worldbody>
    <geom name="floor" type="plane" size="5 5 0.1"/>
    <body name="ball" pos="0 0 1"><freejoint name="free"/><geom name="g" type="sphere" size="0.1"/></body>
  </worldbody>
  <keyframe><key name="high" qpos="0 0 2 1 0 0 0"/></keyframe>
</mujoco>"#;

fn ball() -> (Scratch, Arc<Model>) {
    let dir = Scratch::new("ball");
    let path = dir.write("ball.xml", BALL);
    let model = Model::from_xml_path(&path).expect("ball loads");
    (dir, Arc::new(model))
}

#[test]
fn model_and_data_are_send_and_sync_as_designed() {
    fn send_sync<T: Send + Sync>() {}
    fn send<T: Send>() {}
    send_sync::<Model>();
    send::<Data>();
}

#[test]
fn missing_file_is_a_clear_error() {
    let err = Model::from_xml_path("/no/such/dir/robot.xml").unwrap_err();
    assert!(matches!(err, SimError::NotFound(_)));
    let msg = err.to_string();
    assert!(
        msg.contains("/no/such/dir/robot.xml") && msg.contains("does not exist"),
        "{msg}"
    );
}

#[test]
fn malformed_xml_carries_mujocos_text_and_the_file_name() {
    let dir = Scratch::new("bad-xml");
    let path = dir.write(
        "broken.xml",
        "<mujoco><worldbody><body></worldbody></mujoco>",
    );
    let err = Model::from_xml_path(&path).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, SimError::Load { .. }), "{msg}");
    assert!(msg.contains("broken.xml"), "{msg}");
    assert!(
        msg.to_lowercase().contains("xml"),
        "MuJoCo's parser text expected: {msg}"
    );
}

#[test]
fn unknown_element_is_reported_with_its_name() {
    let dir = Scratch::new("bad-elem");
    let path = dir.write(
        "elem.xml",
        "<mujoco><worldbody><blob/></worldbody></mujoco>",
    );
    let msg = Model::from_xml_path(&path).unwrap_err().to_string();
    assert!(msg.contains("elem.xml") && msg.contains("blob"), "{msg}");
}

#[test]
fn missing_mesh_names_the_mesh_file() {
    let dir = Scratch::new("mesh");
    let path = dir.write(
        "mesh.xml",
        r#"<mujoco><asset><mesh name="m" file="nowhere.stl"/></asset>
           <worldbody><geom type="mesh" mesh="m"/></worldbody></mujoco>"#,
    );
    let msg = Model::from_xml_path(&path).unwrap_err().to_string();
    assert!(
        msg.contains("mesh.xml") && msg.contains("nowhere.stl"),
        "{msg}"
    );
}

#[test]
fn xml_string_loads_and_errors_name_the_label() {
    let dir = Scratch::new("str");
    let m = Model::from_xml_str(BALL, &dir.0, "ball-string").unwrap();
    assert_eq!(m.nq(), 7);
    assert_eq!(m.source(), "ball-string");
    let msg = Model::from_xml_str("<mujoco><nonsense/></mujoco>", &dir.0, "my-scene")
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("my-scene") && msg.contains("nonsense"),
        "{msg}"
    );
    // the temporary file is gone
    assert_eq!(std::fs::read_dir(&dir.0).unwrap().count(), 0);
}

#[test]
fn name_lookups_and_their_errors() {
    let (_d, m) = ball();
    assert_eq!(m.id(ObjType::Body, "ball").unwrap(), 1);
    assert_eq!(m.id(ObjType::Joint, "free").unwrap(), 0);
    assert_eq!(m.id(ObjType::Geom, "floor").unwrap(), 0);
    assert_eq!(m.id(ObjType::Key, "high").unwrap(), 0);
    assert_eq!(m.id2name(ObjType::Body, 1), Some("ball"));
    let msg = m.id(ObjType::Site, "imu").unwrap_err().to_string();
    assert!(
        msg.contains("site") && msg.contains("'imu'") && msg.contains("ball.xml"),
        "{msg}"
    );
}

#[test]
fn step_reset_and_keyframes() {
    let (_d, m) = ball();
    let mut d = Data::new(m.clone()).unwrap();
    d.reset_keyframe(0).unwrap();
    assert_eq!(d.qpos()[2], 2.0);
    for _ in 0..50 {
        d.step().unwrap();
    }
    assert!(d.qpos()[2] < 2.0 && d.qvel()[2] < 0.0);
    assert!((d.time() - 50.0 * m.timestep()).abs() < 1e-12);
    d.reset();
    assert_eq!(d.qpos()[2], 1.0);
    let err = d.reset_keyframe(3).unwrap_err();
    assert_eq!(
        err.to_string(),
        "keyframe index 3 out of range: the model has 1"
    );
    // slices have the model's sizes
    assert_eq!(d.xpos().len(), m.nbody());
    assert_eq!(d.xquat().len(), m.nbody());
    assert_eq!(d.cvel().len(), m.nbody());
    assert_eq!(d.ctrl().len(), 0);
}

#[test]
fn contacts_are_listed_with_forces() {
    let (_d, m) = ball();
    let mut d = Data::new(m).unwrap();
    for _ in 0..1500 {
        d.step().unwrap();
    }
    // resting on the floor: one contact floor-ball carrying the ball's weight
    assert_eq!(d.contacts().len(), 1);
    let (g1, g2) = dreampolicy::sim::contact_geoms(&d.contacts()[0]);
    assert_eq!((g1.min(g2), g1.max(g2)), (0, 1));
    let f = d.contact_force(0).unwrap();
    let weight = d.model().body_mass()[1] * 9.81;
    assert!(
        (f[0] - weight).abs() < 0.05 * weight,
        "normal force {} vs weight {weight}",
        f[0]
    );
    assert!(d.contact_force(1).is_none());
}

#[test]
fn nan_state_is_an_instability_and_is_counted() {
    let (_d, m) = ball();
    let mut d = Data::new(m).unwrap();
    d.qvel_mut()[0] = f64::NAN;
    let err = d.step().unwrap_err();
    match err {
        SimError::Unstable { reason, .. } => assert!(
            matches!(
                reason,
                Instability::BadQvel { .. }
                    | Instability::BadQacc { .. }
                    | Instability::NonFinite { .. }
            ),
            "{reason:?}"
        ),
        other => panic!("expected Unstable, got {other}"),
    }
    assert!(
        d.warning_totals().iter().sum::<u64>() >= 1,
        "MuJoCo's warning was counted"
    );
    // MuJoCo reset the state; after our reset the next step is clean again
    d.reset();
    d.step().unwrap();
    assert!(d.qpos().iter().all(|v| v.is_finite()));
}

#[test]
fn velocity_bound_is_an_instability() {
    let (_d, m) = ball();
    let mut d = Data::new(m).unwrap();
    d.set_max_qvel(50.0);
    d.qvel_mut()[0] = 80.0;
    let msg = d.step().unwrap_err().to_string();
    assert!(
        msg.contains("unstable") && msg.contains("bound 50"),
        "{msg}"
    );
}

#[test]
fn threads_share_one_model_and_agree() {
    let (_d, m) = ball();
    let run = |m: Arc<Model>, vx: f64| {
        let mut d = Data::new(m).unwrap();
        d.qvel_mut()[0] = vx;
        for _ in 0..300 {
            d.step().unwrap();
        }
        d.qpos().to_vec()
    };
    let serial: Vec<_> = [0.5, -1.0].iter().map(|&v| run(m.clone(), v)).collect();
    let threaded: Vec<_> = std::thread::scope(|s| {
        let hs: Vec<_> = [0.5, -1.0]
            .iter()
            .map(|&v| {
                let m = m.clone();
                s.spawn(move || run(m, v))
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(serial, threaded);
}

/// A model with one heightfield geom, placed off-centre to exercise the frame.
fn hfield_model(dir: &Scratch, nrow: usize, ncol: usize) -> Model {
    let xml = format!(
        r#"<mujoco><asset><hfield name="terrain" nrow="{nrow}" ncol="{ncol}" size="2.0 1.5 0.6 0.1"/></asset>
        <worldbody><geom name="ground" type="hfield" hfield="terrain" pos="0.3 -0.2 0.05"/></worldbody></mujoco>"#
    );
    Model::from_xml_str(&xml, &dir.0, "hfield").unwrap()
}

fn ray_height(d: &Data, x: f64, y: f64) -> f64 {
    let (dist, _) = d
        .ray([x, y, 3.0], [0.0, 0.0, -1.0], None, true, None)
        .expect("ray hits");
    3.0 - dist
}

#[test]
fn hfield_lookup_matches_mj_ray_on_rough_terrain() {
    let dir = Scratch::new("hf");
    let (nrow, ncol) = (31, 41);
    let mut model = hfield_model(&dir, nrow, ncol);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let data: Vec<f32> = (0..nrow * ncol).map(|_| rng.random::<f32>()).collect();
    model.set_hfield_data(0, &data).unwrap();
    let geom = model.id(ObjType::Geom, "ground").unwrap();
    let hf = HeightField::from_model(&model, geom).unwrap();
    let model = Arc::new(model);
    let mut d = Data::new(model).unwrap();
    d.forward();
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        let x = 0.3 + rng.random_range(-1.95..1.95);
        let y = -0.2 + rng.random_range(-1.45..1.45);
        worst = worst.max((hf.height(x, y) - ray_height(&d, x, y)).abs());
    }
    assert!(worst < 1e-3, "worst |lookup - mj_ray| = {worst} m");
}

#[test]
fn bilinear_lookup_matches_mj_ray_on_smooth_terrain() {
    let dir = Scratch::new("hf-smooth");
    let (nrow, ncol) = (61, 81);
    let mut model = hfield_model(&dir, nrow, ncol);
    let data: Vec<f32> = (0..nrow * ncol)
        .map(|i| {
            let (r, c) = ((i / ncol) as f32, (i % ncol) as f32);
            0.5 + 0.4 * (0.15 * c).sin() * (0.1 * r).cos()
        })
        .collect();
    model.set_hfield_data(0, &data).unwrap();
    let hf = HeightField::from_model(&model, 0).unwrap();
    let mut d = Data::new(Arc::new(model)).unwrap();
    d.forward();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut worst: f64 = 0.0;
    for _ in 0..2000 {
        let x = 0.3 + rng.random_range(-1.95..1.95);
        let y = -0.2 + rng.random_range(-1.45..1.45);
        worst = worst.max((hf.height_bilinear(x, y) - ray_height(&d, x, y)).abs());
    }
    assert!(worst < 1e-3, "worst |bilinear - mj_ray| = {worst} m");
}

#[test]
fn hfield_upload_changes_collisions() {
    let dir = Scratch::new("hf-coll");
    let xml = r#"<mujoco><asset><hfield name="t" nrow="11" ncol="11" size="1 1 1 0.1"/></asset>
      <worldbody><geom type="hfield" hfield="t"/>
      <body pos="0 0 2"><freejoint/><geom type="sphere" size="0.1"/></body></worldbody></mujoco>"#;
    let mut model = Model::from_xml_str(xml, &dir.0, "drop").unwrap();
    model.set_hfield_data(0, &[0.5; 121]).unwrap();
    let mut d = Data::new(Arc::new(model)).unwrap();
    for _ in 0..1500 {
        d.step().unwrap();
    }
    // the ball rests on the raised surface (0.5 m) instead of falling to z = 0
    assert!((d.qpos()[2] - 0.6).abs() < 0.01, "z = {}", d.qpos()[2]);
}

#[test]
fn hfield_upload_rejects_bad_input() {
    let dir = Scratch::new("hf-bad");
    let mut model = hfield_model(&dir, 5, 5);
    let msg = model
        .set_hfield_data(0, &[0.5; 24])
        .unwrap_err()
        .to_string();
    assert_eq!(
        msg,
        "heightfield data (nrow * ncol): expected 25 values, got 24"
    );
    let mut bad = vec![0.5f32; 25];
    bad[7] = 1.5;
    let msg = model.set_hfield_data(0, &bad).unwrap_err().to_string();
    assert!(msg.contains("1.5") && msg.contains("index 7"), "{msg}");
    let msg = model
        .set_hfield_data(3, &[0.0; 25])
        .unwrap_err()
        .to_string();
    assert_eq!(msg, "hfield index 3 out of range: the model has 1");
}

/// MuJoCo's fatal errors must not exit silently: the handler prints MuJoCo's
/// text and aborts. Run in a child process (this same test binary).
#[test]
fn mujoco_fatal_error_aborts_with_a_clear_message() {
    if std::env::var_os("DREAMPOLICY_FATAL_CHILD").is_some() {
        dreampolicy::sim::handlers::install();
        // SAFETY: deliberately triggers MuJoCo's error path; the handler aborts.
        unsafe { mujoco_sys::mju_error(c"deliberate test error".as_ptr()) };
        unreachable!("mju_error returned");
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "mujoco_fatal_error_aborts_with_a_clear_message",
            "--nocapture",
        ])
        .env("DREAMPOLICY_FATAL_CHILD", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("MuJoCo fatal error: deliberate test error") && stderr.contains("aborting"),
        "{stderr}"
    );
}

#[test]
fn warnings_are_counted_by_the_handler() {
    dreampolicy::sim::handlers::install();
    let before = dreampolicy::sim::handlers::warning_count();
    // SAFETY: mju_warning only formats and reports the message.
    unsafe { mujoco_sys::mju_warning(c"deliberate test warning".as_ptr()) };
    assert_eq!(dreampolicy::sim::handlers::warning_count(), before + 1);
    assert_eq!(
        dreampolicy::sim::handlers::last_warning().as_deref(),
        Some("deliberate test warning")
    );
}

/// The closing fills a pit narrower than its square to the lower rim, and
/// leaves a step, a wide pit and a bump where they are.
#[test]
fn hfield_closing_fills_narrow_pits_only() {
    // one row along x, copied into 7 rows: a 3-sample pit, a 9-sample pit, a step
    let profile: [f32; 30] = [
        0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.5, 0.5, 0.5, 0.5, 0.9, 0.5, 0.7, 0.7, 0.7, 0.7,
    ];
    let (nrow, ncol) = (7, profile.len());
    let data: Vec<f32> = (0..nrow).flat_map(|_| profile).collect();
    let size = [1.45, 0.3, 1.0, 0.1];
    let field = HeightField::new(nrow, ncol, size, [0.0; 3], data).unwrap();
    let closed = field.closed(2);
    let at = |h: &HeightField, c: usize| h.height(-size[0] + c as f64 * 0.1, 0.0);
    for c in 4..7 {
        assert!(
            (at(&closed, c) - 0.5).abs() < 1e-6,
            "narrow pit at {c} not filled"
        );
    }
    for c in 11..20 {
        assert!(at(&closed, c).abs() < 1e-6, "wide pit at {c} filled");
    }
    assert!((at(&closed, 24) - 0.9).abs() < 1e-6, "the bump moved");
    for c in [0, 3, 7, 10, 20, 23, 26, 29] {
        assert!(
            (at(&closed, c) - at(&field, c)).abs() < 1e-9,
            "sample {c} changed"
        );
    }
    assert_eq!(field.closed(0).height(0.3, 0.1), field.height(0.3, 0.1));
}

/// A foot of three parallel capsules (the G1's sole, 1 cm radius) resting on a
/// 10 cm block's rim, its centre 3 cm inside, 6 cm of it over the drop; the
/// block's vertical face is a one-cell ramp of the 5 cm grid. `user` picks the
/// heightfield contacts (`sim::hfield_contact`). Returns the contacts' smallest
/// normal z at rest and how far the foot moved (m) in 1 s.
fn foot_on_a_rim(user: f64) -> (f64, f64) {
    let dir = Scratch::new("hf-rim");
    let xml = format!(
        r#"<mujoco><asset><hfield name="t" nrow="21" ncol="41" size="1 0.5 0.2 0.1"/></asset>
      <worldbody><geom name="ground" type="hfield" hfield="t" user="{user}"/>
      <body name="foot" pos="-0.03 0 0.11"><freejoint/>
        <geom type="capsule" size="0.01" fromto="-0.09 -0.03 0 0.09 -0.03 0" mass="0.4"/>
        <geom type="capsule" size="0.01" fromto="-0.09 0 0 0.09 0 0" mass="0.4"/>
        <geom type="capsule" size="0.01" fromto="-0.09 0.03 0 0.09 0.03 0" mass="0.4"/>
      </body></worldbody></mujoco>"#
    );
    let mut model = Model::from_xml_str(&xml, &dir.0, "rim").unwrap();
    // x <= 0 (columns 0..=20) is the block's top, 10 cm up; beyond, the floor
    let data: Vec<f32> = (0..21 * 41)
        .map(|i| if i % 41 <= 20 { 0.5 } else { 0.0 })
        .collect();
    model.set_hfield_data(0, &data).unwrap();
    let mut d = Data::new(Arc::new(model)).unwrap();
    d.forward();
    let nz = d
        .contacts()
        .iter()
        .map(|c| c.frame[2])
        .fold(f64::INFINITY, f64::min);
    assert!(!d.contacts().is_empty(), "no contact at rest");
    let start = [d.qpos()[0], d.qpos()[1], d.qpos()[2]];
    for _ in 0..500 {
        d.step().unwrap();
    }
    let q = d.qpos();
    let moved =
        ((q[0] - start[0]).powi(2) + (q[1] - start[1]).powi(2) + (q[2] - start[2]).powi(2)).sqrt();
    (nz, moved)
}

#[test]
fn surface_contacts_hold_a_foot_on_a_rim() {
    // the surface's closest points: every normal up, the foot stays
    let (nz, moved) = foot_on_a_rim(1.0);
    eprintln!("surface: min normal z {nz:.4}, moved {moved:.4} m");
    assert!(nz > 0.999, "a contact normal tilted at the rim: n_z = {nz}");
    assert!(
        moved < 0.002,
        "the foot moved {moved} m off a rim it rests on"
    );
    // the triangles' planes (before 2026-12-04): the ramp's plane, extended
    // under the rim, gives a contact along the ramp's normal (63 degrees from
    // the vertical) that shoves the foot off the block
    let (nz, moved) = foot_on_a_rim(2.0);
    eprintln!("surface_planes: min normal z {nz:.4}, moved {moved:.4} m");
    assert!(
        nz < 0.5,
        "no tilted contact from the ramp's plane: n_z = {nz}"
    );
    assert!(
        moved > 0.01,
        "the ramp's contact left the foot in place ({moved} m)"
    );
}
