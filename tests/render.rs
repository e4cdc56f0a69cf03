//! Headless rendering (`sim::render`, OSMesa) and `dreampolicy render`: frames
//! of the G1 that are not blank, that are the same for the same state and
//! change when the robot moves; a video of the committed flat walker that
//! ffmpeg decodes back into as many frames as the summary says, with the legs
//! moving between them; a PNG still; the errors a person can act on.
mod common;

use std::path::Path;
use std::process::Command;

use common::Scratch;
use dreampolicy::env::VecEnv;
use dreampolicy::rl::checkpoint::Checkpoint;
use dreampolicy::sim::render::{root_body, CameraView, Renderer};
use serde_json::Value;

/// One env of the walker's config (its scene: the G1 on a plane).
fn walker_env() -> VecEnv {
    let ck = Checkpoint::read(&common::walker_path()).unwrap();
    let mut env = ck.config().unwrap().env;
    env.n_envs = 1;
    env.threads = 1;
    VecEnv::new(&env).unwrap()
}

/// Pixel statistics that tell a drawn scene from a blank one: the standard
/// deviation of the bytes and the number of distinct colours (quantized to 5
/// bits a channel).
fn contents(rgb: &[u8]) -> (f64, usize) {
    let n = rgb.len() as f64;
    let mean = rgb.iter().map(|&b| b as f64).sum::<f64>() / n;
    let var = rgb.iter().map(|&b| (b as f64 - mean).powi(2)).sum::<f64>() / n;
    let colours: std::collections::BTreeSet<[u8; 3]> = rgb
        .chunks_exact(3)
        .map(|p| [p[0] >> 3, p[1] >> 3, p[2] >> 3])
        .collect();
    (var.sqrt(), colours.len())
}

/// Fraction of pixels whose colour differs by more than 24 (of 255) in some channel.
fn changed(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len());
    let n = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.abs_diff(*y) > 24))
        .count();
    n as f64 / (a.len() / 3) as f64
}

fn assert_drawn(rgb: &[u8], what: &str) {
    let (std, colours) = contents(rgb);
    assert!(
        std > 10.0 && colours > 20,
        "{what} looks blank: byte std {std:.1}, {colours} colours"
    );
}

#[test]
fn renderer_draws_the_robot_and_sees_it_move() {
    let mut env = walker_env();
    let data = env.envs()[0].data();
    let mut r = Renderer::new(data.model(), 160, 120).unwrap();
    assert!(
        r.gl_version().contains("Mesa"),
        "OSMesa's GL: {}",
        r.gl_version()
    );
    let a = r.render(data).unwrap().to_vec();
    assert_eq!(a.len(), 160 * 120 * 3);
    assert_drawn(&a, "the standing G1");
    // software rendering: the same state, the same frame
    let again = r.render(env.envs()[0].data()).unwrap().to_vec();
    assert_eq!(changed(&a, &again), 0.0, "the same state drew two frames");

    // the robot in the middle of the frame differs from the empty scene: a
    // camera turned 180 degrees and 3 m further sees it smaller
    let pelvis = root_body(env.envs()[0].data().model());
    r.set_view(CameraView {
        distance: 8.0,
        azimuth: 300.0,
        ..CameraView::follow(pelvis)
    });
    let far = r.render(env.envs()[0].data()).unwrap().to_vec();
    assert_drawn(&far, "the far view");
    assert!(
        changed(&a, &far) > 0.05,
        "turning the camera changed nothing"
    );

    // bend the left knee and hip (qpos after the free joint: 7 + joint index)
    r.set_view(CameraView::follow(pelvis));
    {
        let d = env.data_mut(0).unwrap();
        let q = d.qpos_mut();
        q[7] -= 1.2; // left hip pitch
        q[10] += 1.8; // left knee
        d.forward();
    }
    let bent = r.render(env.envs()[0].data()).unwrap().to_vec();
    let moved = changed(&a, &bent);
    assert!(
        moved > 0.005,
        "a bent leg changed {:.4} of the pixels",
        moved
    );
    assert!(moved < 0.5, "a bent leg changed {moved:.3} of the pixels");
}

#[test]
fn renderer_rejects_bad_sizes_and_foreign_states() {
    let env = walker_env();
    let data = env.envs()[0].data();
    let e = Renderer::new(data.model(), 8, 120)
        .err()
        .expect("too small");
    assert!(e.to_string().contains("16..="), "{e}");
    let cartpole = dreampolicy::sim::Model::from_xml_str(
        "<mujoco><worldbody><body><joint type='slide'/><geom size='.1'/></body></worldbody></mujoco>",
        Path::new("."),
        "slider",
    )
    .unwrap();
    let other = dreampolicy::sim::Data::new(std::sync::Arc::new(cartpole)).unwrap();
    let mut r = Renderer::new(data.model(), 32, 32).unwrap();
    let e = r.render(&other).expect_err("another model's state");
    assert!(e.to_string().contains("another model"), "{e}");
}

fn dreampolicy() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dreampolicy"))
}

/// Decode a video with ffmpeg into raw RGB frames of `w` x `h`.
fn decode(video: &Path, w: usize, h: usize) -> Vec<Vec<u8>> {
    let out = common::run_ok_bytes(
        Command::new("ffmpeg")
            .args(["-loglevel", "error", "-i"])
            .arg(video)
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-"]),
    );
    assert_eq!(out.len() % (w * h * 3), 0);
    out.chunks_exact(w * h * 3).map(|c| c.to_vec()).collect()
}

#[test]
fn render_writes_a_video_of_the_walker_walking() {
    let dir = Scratch::new("render");
    let video = dir.0.join("sub/walk.mp4");
    let still = dir.0.join("still.png");
    let out = common::run_ok(
        dreampolicy()
            .args(["render", "--checkpoint"])
            .arg(common::walker_path())
            .args(["--terrain", "flat", "--seconds", "1.2", "--width", "160"])
            .args([
                "--height",
                "96",
                "--fps",
                "25",
                "--still-at",
                "0.5",
                "--json",
            ])
            .arg("--out")
            .arg(&video)
            .arg("--still")
            .arg(&still),
    );
    let s: Value = serde_json::from_str(out.trim()).unwrap();
    // 1.2 s at 50 Hz, every second control step, frame 0 included
    assert_eq!(s["frames"], 31, "{s}");
    assert_eq!(s["fps"], 25.0);
    assert_eq!(s["format"], "mp4");
    assert_eq!(s["rollout"]["ending"], "time_up", "{s}");
    assert_eq!(s["still_time"], 0.5);
    let bytes = std::fs::read(&video).unwrap();
    assert_eq!(&bytes[4..8], b"ftyp", "not an MP4");
    assert_eq!(s["video_bytes"], bytes.len() as u64);
    assert!(!dir.0.join("sub/walk.mp4.tmp").exists());

    let frames = decode(&video, 160, 96);
    assert_eq!(frames.len(), 31);
    for (i, f) in frames.iter().enumerate() {
        assert_drawn(f, &format!("frame {i}"));
    }
    // the walker walks: its legs are elsewhere 0.4 s later
    let moved = changed(&frames[10], &frames[20]);
    assert!(
        moved > 0.01,
        "frames 10 and 20 differ in {moved:.4} of the pixels"
    );

    let png = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(&still).unwrap(),
    ));
    let reader = png.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (160, 96));
}

#[test]
fn render_writes_a_gif_too() {
    let dir = Scratch::new("render-gif");
    let gif = dir.0.join("walk.gif");
    common::run_ok(
        dreampolicy()
            .args(["render", "--checkpoint"])
            .arg(common::walker_path())
            .args([
                "--seconds",
                "0.3",
                "--width",
                "64",
                "--height",
                "48",
                "--fps",
                "10",
            ])
            .arg("--out")
            .arg(&gif),
    );
    let bytes = std::fs::read(&gif).unwrap();
    assert_eq!(&bytes[..6], b"GIF89a");
    // 0.3 s at 10 fps (every fifth control step): frames 0, 5, 10, 15
    assert_eq!(decode(&gif, 64, 48).len(), 4);
}

#[test]
fn render_errors_say_what_to_do() {
    let dir = Scratch::new("render-err");
    let run = |extra: &[&str], out: &str| {
        let o = dreampolicy()
            .args(["render", "--checkpoint"])
            .arg(common::walker_path())
            .args(["--seconds", "0.1"])
            .args(extra)
            .arg("--out")
            .arg(dir.0.join(out))
            .output()
            .unwrap();
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = run(&[], "walk.avi");
    assert!(e.contains(".mp4 or .gif"), "{e}");
    let e = run(&["--width", "161"], "walk.mp4");
    assert!(e.contains("even width"), "{e}");
    let e = run(&["--ffmpeg", "/nonexistent/ffmpeg"], "walk.mp4");
    assert!(e.contains("install Debian's ffmpeg"), "{e}");
    assert!(!dir.0.join("walk.mp4").exists() && !dir.0.join("walk.mp4.tmp").exists());
    let e = run(&["--fps", "60"], "walk.gif");
    assert!(e.contains("--fps"), "{e}");
}
