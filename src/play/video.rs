//! `dreampolicy render`: a [`super::play`] rollout drawn by MuJoCo's own
//! offscreen renderer ([`crate::sim::render`], OSMesa, no display) with a
//! camera that follows the pelvis, encoded as MP4 (H.264) or GIF by Debian's
//! `ffmpeg`, frames piped raw into its standard input.
//!
//! The rollout is `play`'s (same env, lane, seed, ending); frames are taken
//! every `stride` control steps, `stride = round(50 Hz / fps)`, so the video
//! plays in real time at `50 / stride` frames a second. `--still` saves one
//! frame as PNG (the README's picture). The video goes to `<out>.tmp` first
//! and is renamed when ffmpeg has finished, as every file this crate writes.
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::Instant;

use serde::Serialize;

use super::{play_into, FrameSink, PlayError, PlayOptions, PlaySummary};
use crate::env::VecEnv;
use crate::rl::checkpoint::Checkpoint;
use crate::sim::render::{root_body, CameraView, Renderer};

/// Video container, from the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VideoFormat {
    /// H.264 in MP4 (`.mp4`): yuv420p, so width and height must be even.
    Mp4,
    /// Animated GIF (`.gif`), a palette made from the video.
    Gif,
}

impl VideoFormat {
    /// The format of `path` by its extension.
    pub fn of(path: &Path) -> Result<VideoFormat, PlayError> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("mp4") => Ok(VideoFormat::Mp4),
            Some("gif") => Ok(VideoFormat::Gif),
            _ => Err(PlayError::Invalid(format!(
                "{}: the video must end in .mp4 or .gif",
                path.display()
            ))),
        }
    }

    /// ffmpeg's arguments after the input: codec, filters, container.
    fn ffmpeg_args(self) -> &'static [&'static str] {
        match self {
            VideoFormat::Mp4 => &[
                "-c:v",
                "libx264",
                "-preset",
                "veryfast",
                "-crf",
                "23",
                "-pix_fmt",
                "yuv420p",
                "-movflags",
                "+faststart",
                "-f",
                "mp4",
            ],
            VideoFormat::Gif => &[
                "-vf",
                "split[a][b];[a]palettegen=stats_mode=diff[p];[b][p]paletteuse",
                "-loop",
                "0",
                "-f",
                "gif",
            ],
        }
    }
}

/// How to draw and encode.
#[derive(Debug, Clone)]
pub struct RenderOptions {
    pub width: usize,
    pub height: usize,
    /// Frames a second asked for (the video gets 50 / round(50 / fps)).
    pub fps: f64,
    /// Camera distance (m), azimuth and elevation (degrees), as [`CameraView`].
    pub distance: f64,
    pub azimuth: f64,
    pub elevation: f64,
    /// Draw shadows (2-3x slower in software).
    pub shadows: bool,
    /// Also save the frame nearest this time (s) as a PNG.
    pub still: Option<(PathBuf, f64)>,
    /// Also write `play`'s MCAP file here.
    pub mcap: Option<PathBuf>,
    /// The ffmpeg program (default "ffmpeg", found on PATH).
    pub ffmpeg: String,
}

impl Default for RenderOptions {
    fn default() -> Self {
        let v = CameraView::follow(1);
        RenderOptions {
            width: 640,
            height: 360,
            fps: 25.0,
            distance: v.distance,
            azimuth: v.azimuth,
            elevation: v.elevation,
            shadows: false,
            still: None,
            mcap: None,
            ffmpeg: "ffmpeg".into(),
        }
    }
}

/// What a render did and wrote.
#[derive(Debug, Clone, Serialize)]
pub struct RenderSummary {
    /// The rollout (its `out` is the video; `file_bytes` the MCAP file's, 0 without one).
    pub rollout: PlaySummary,
    pub video: String,
    pub format: VideoFormat,
    pub video_bytes: u64,
    pub width: usize,
    pub height: usize,
    /// Frames in the video, and their rate.
    pub frames: u64,
    pub fps: f64,
    /// Wall seconds spent drawing and reading back frames, per frame (ms).
    pub ms_per_frame: f64,
    /// The OpenGL the frames were drawn with.
    pub gl: String,
    /// The PNG still and the time of its frame (s), if asked.
    pub still: Option<String>,
    pub still_time: Option<f64>,
}

fn check(r: &RenderOptions, format: VideoFormat) -> Result<(), PlayError> {
    if !(r.fps.is_finite() && r.fps > 0.0 && r.fps <= 50.0) {
        return Err(PlayError::Invalid(format!(
            "--fps must be in (0, 50] (the control rate), got {}",
            r.fps
        )));
    }
    if format == VideoFormat::Mp4 && (r.width % 2 == 1 || r.height % 2 == 1) {
        return Err(PlayError::Invalid(format!(
            "an MP4 needs an even width and height, got {}x{}",
            r.width, r.height
        )));
    }
    if !(r.distance.is_finite() && r.distance > 0.0) {
        return Err(PlayError::Invalid(format!(
            "--distance must be positive, got {}",
            r.distance
        )));
    }
    if !(r.azimuth.is_finite() && r.elevation.is_finite() && r.elevation.abs() < 90.0) {
        return Err(PlayError::Invalid(format!(
            "--azimuth must be finite and --elevation in (-90, 90), got {} and {}",
            r.azimuth, r.elevation
        )));
    }
    if let Some((_, t)) = &r.still {
        if !(t.is_finite() && *t >= 0.0) {
            return Err(PlayError::Invalid(format!(
                "--still-at must be a time >= 0 s, got {t}"
            )));
        }
    }
    Ok(())
}

/// `path` with `.tmp` appended.
fn tmp_path(path: &Path) -> PathBuf {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    PathBuf::from(tmp)
}

/// An ffmpeg process reading raw RGB frames on its standard input.
struct Encoder {
    child: Child,
    stdin: Option<ChildStdin>,
    tmp: PathBuf,
    frames: u64,
}

impl Encoder {
    fn start(
        r: &RenderOptions,
        format: VideoFormat,
        fps: f64,
        out: &Path,
    ) -> Result<Encoder, PlayError> {
        if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| PlayError::io(dir, e))?;
        }
        let tmp = tmp_path(out);
        let size = format!("{}x{}", r.width, r.height);
        let rate = format!("{fps}");
        let mut cmd = Command::new(&r.ffmpeg);
        cmd.args(["-y", "-nostdin", "-loglevel", "error", "-f", "rawvideo"])
            .args([
                "-pix_fmt",
                "rgb24",
                "-s",
                &size,
                "-framerate",
                &rate,
                "-i",
                "pipe:0",
            ])
            .args(format.ffmpeg_args())
            .arg(&tmp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        // -nostdin only stops ffmpeg's interactive keys; the frames still come on pipe:0
        let mut child = cmd.spawn().map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                PlayError::Invalid(format!(
                    "`{}` not found: install Debian's ffmpeg (scripts/setup.sh does) or pass --ffmpeg PATH",
                    r.ffmpeg
                ))
            } else {
                PlayError::Invalid(format!("starting `{}`: {e}", r.ffmpeg))
            }
        })?;
        let stdin = child.stdin.take();
        Ok(Encoder {
            child,
            stdin,
            tmp,
            frames: 0,
        })
    }

    fn push(&mut self, rgb: &[u8]) -> Result<(), PlayError> {
        let stdin = self.stdin.as_mut().expect("stdin lives until finish");
        if stdin.write_all(rgb).is_err() {
            // ffmpeg quit: its own message says why
            return Err(self.failure());
        }
        self.frames += 1;
        Ok(())
    }

    /// ffmpeg's exit and last words, as an error.
    fn failure(&mut self) -> PlayError {
        self.stdin.take();
        let status = self.child.wait();
        let mut text = String::new();
        if let Some(mut err) = self.child.stderr.take() {
            let _ = err.read_to_string(&mut text);
        }
        let _ = std::fs::remove_file(&self.tmp);
        let tail: Vec<&str> = text.lines().rev().take(5).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        PlayError::Invalid(format!(
            "ffmpeg failed ({}): {}",
            status.map_or_else(|e| e.to_string(), |s| s.to_string()),
            if tail.is_empty() {
                "no message".to_string()
            } else {
                tail.join(" | ")
            }
        ))
    }

    /// Close the input, wait for ffmpeg, rename the video into place; its bytes.
    fn finish(mut self, out: &Path) -> Result<u64, PlayError> {
        drop(self.stdin.take());
        let status = self
            .child
            .wait()
            .map_err(|e| PlayError::Invalid(format!("waiting for ffmpeg: {e}")))?;
        if !status.success() {
            return Err(self.failure());
        }
        std::fs::rename(&self.tmp, out).map_err(|e| PlayError::io(out, e))?;
        let bytes = std::fs::metadata(out)
            .map_err(|e| PlayError::io(out, e))?
            .len();
        Ok(bytes)
    }
}

impl Drop for Encoder {
    /// An unfinished video is removed and ffmpeg stopped.
    fn drop(&mut self) {
        if self.stdin.take().is_some() {
            let _ = self.child.kill();
            let _ = self.child.wait();
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// The frame sink of a render: draws every `stride`-th frame into ffmpeg.
struct VideoSink<'a> {
    r: &'a RenderOptions,
    format: VideoFormat,
    out: &'a Path,
    stride: u64,
    fps: f64,
    /// Frame index (control steps) of the still.
    still_at: Option<u64>,
    renderer: Option<Renderer>,
    encoder: Option<Encoder>,
    /// The latest frame drawn at or before `still_at` and its index: the
    /// still, or its stand-in should the rollout end (a fall) before its time.
    still: Option<(u64, Vec<u8>)>,
    render_s: f64,
}

impl FrameSink for VideoSink<'_> {
    fn frame(&mut self, env: &VecEnv, k: u64) -> Result<(), PlayError> {
        let want_still = self.still_at == Some(k);
        if !k.is_multiple_of(self.stride) && !want_still {
            return Ok(());
        }
        let data = env.envs()[0].data();
        if self.renderer.is_none() {
            let mut renderer = Renderer::new(data.model(), self.r.width, self.r.height)?;
            renderer.set_view(CameraView {
                track_body: root_body(data.model()),
                distance: self.r.distance,
                azimuth: self.r.azimuth,
                elevation: self.r.elevation,
            });
            renderer.set_shadows(self.r.shadows);
            self.renderer = Some(renderer);
            self.encoder = Some(Encoder::start(self.r, self.format, self.fps, self.out)?);
        }
        let renderer = self.renderer.as_mut().expect("made above");
        let t0 = Instant::now();
        let rgb = renderer.render(data)?;
        self.render_s += t0.elapsed().as_secs_f64();
        if self.still_at.is_some_and(|s| k <= s) {
            let (at, still) = self.still.get_or_insert_with(|| (k, Vec::new()));
            *at = k;
            still.clear();
            still.extend_from_slice(rgb);
        }
        if k.is_multiple_of(self.stride) {
            self.encoder.as_mut().expect("made above").push(rgb)?;
        }
        Ok(())
    }
}

/// Roll the checkpoint's policy out as `play` does and write the video `o.out`
/// (and, as asked, a PNG still and the MCAP file).
pub fn render(
    ck: &Checkpoint,
    o: &PlayOptions,
    r: &RenderOptions,
) -> Result<RenderSummary, PlayError> {
    let format = VideoFormat::of(&o.out)?;
    check(r, format)?;
    let dt = ck.config()?.env.sim.control_dt();
    let stride = ((1.0 / (dt * r.fps)).round() as u64).max(1);
    let fps = 1.0 / (dt * stride as f64);
    let mut sink = VideoSink {
        r,
        format,
        out: &o.out,
        stride,
        fps,
        still_at: r.still.as_ref().map(|(_, t)| (t / dt).round() as u64),
        renderer: None,
        encoder: None,
        still: None,
        render_s: 0.0,
    };
    let rollout = play_into(ck, o, r.mcap.as_deref(), &mut sink)?;
    let encoder = sink
        .encoder
        .take()
        .ok_or_else(|| PlayError::Invalid("the rollout produced no frame to render".into()))?;
    let frames = encoder.frames;
    let video_bytes = encoder.finish(&o.out)?;
    let (still, still_time) = match (&r.still, sink.still.take()) {
        (Some((path, _)), Some((k, rgb))) => {
            crate::plot::write_png(path, r.width as u32, r.height as u32, &rgb)?;
            (Some(path.display().to_string()), Some(k as f64 * dt))
        }
        _ => (None, None),
    };
    let gl = sink
        .renderer
        .as_ref()
        .map(|x| x.gl_version().to_string())
        .unwrap_or_default();
    let drawn = frames.max(1) as f64;
    Ok(RenderSummary {
        rollout,
        video: o.out.display().to_string(),
        format,
        video_bytes,
        width: r.width,
        height: r.height,
        frames,
        fps,
        ms_per_frame: 1e3 * sink.render_s / drawn,
        gl,
        still,
        still_time,
    })
}
