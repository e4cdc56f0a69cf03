//! Top-down PNGs of terrain: heights through a viridis colour map (x to the
//! right, y up), a vertical colour bar labelled with the lowest and highest
//! height in metres (a built-in 5x7 bitmap font), thin white tile grid lines on
//! a map, and the spawn point, goal line and segment boundary on a lane.
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use super::{Lane, TerrainConfig, TerrainError, TerrainKind, TerrainMap};

/// The heights image is scaled up (nearest sample) to at least this many pixels
/// across, and down to at most [`MAX_WIDTH`].
pub const MIN_WIDTH: usize = 400;
/// Widest heights image; larger maps are subsampled.
pub const MAX_WIDTH: usize = 4096;
const MARGIN: usize = 10;
const BAR_GAP: usize = 14;
const BAR_WIDTH: usize = 18;
const LABEL_SCALE: usize = 2;
const MIN_HEIGHT: usize = 160;
/// Metres of border shown around a lane.
pub const LANE_MARGIN: f64 = 1.0;

/// matplotlib's viridis at 0, 0.1, ..., 1.
const VIRIDIS: [[u8; 3]; 11] = [
    [0x44, 0x01, 0x54],
    [0x48, 0x24, 0x75],
    [0x41, 0x44, 0x87],
    [0x35, 0x5f, 0x8d],
    [0x2a, 0x78, 0x8e],
    [0x21, 0x91, 0x8c],
    [0x22, 0xa8, 0x84],
    [0x44, 0xbf, 0x70],
    [0x7a, 0xd1, 0x51],
    [0xbd, 0xdf, 0x26],
    [0xfd, 0xe7, 0x25],
];

/// Viridis colour of `t` in `[0, 1]` (clamped), linearly interpolated.
pub fn viridis(t: f64) -> [u8; 3] {
    let f = t.clamp(0.0, 1.0) * 10.0;
    let k = (f as usize).min(9);
    let u = f - k as f64;
    let (a, b) = (VIRIDIS[k], VIRIDIS[k + 1]);
    [0, 1, 2].map(|c| (a[c] as f64 + u * (b[c] as f64 - a[c] as f64)).round() as u8)
}

/// 5x7 glyphs (bit 4 = leftmost column) for the colour bar labels.
fn glyph(ch: char) -> [u8; 7] {
    match ch {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        'm' => [0, 0, 0x1A, 0x15, 0x15, 0x11, 0x11],
        _ => [0; 7],
    }
}

/// Pixel width of `text` at `scale`.
fn text_width(text: &str, scale: usize) -> usize {
    text.chars().count() * 6 * scale
}

/// An RGB image being drawn.
struct Image {
    w: usize,
    h: usize,
    rgb: Vec<u8>,
}

impl Image {
    fn new(w: usize, h: usize) -> Image {
        Image {
            w,
            h,
            rgb: vec![255; w * h * 3],
        }
    }

    /// Blend `c` over pixel `(x, y)` with opacity `a`; off-image pixels are ignored.
    fn blend(&mut self, x: usize, y: usize, c: [u8; 3], a: f64) {
        if x < self.w && y < self.h {
            let p = &mut self.rgb[(y * self.w + x) * 3..][..3];
            for k in 0..3 {
                p[k] = (p[k] as f64 * (1.0 - a) + c[k] as f64 * a).round() as u8;
            }
        }
    }

    fn text(&mut self, x: usize, y: usize, text: &str, scale: usize) {
        for (n, ch) in text.chars().enumerate() {
            for (r, bits) in glyph(ch).iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        for (dy, dx) in (0..scale * scale).map(|k| (k / scale, k % scale)) {
                            let px = x + (n * 6 + col) * scale + dx;
                            self.blend(px, y + r * scale + dy, [30, 30, 30], 1.0);
                        }
                    }
                }
            }
        }
    }

    fn write(&self, path: &Path) -> Result<(), TerrainError> {
        let io = |source| TerrainError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        let png = |source| TerrainError::Png {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(&tmp).map_err(io)?;
        let mut enc = png::Encoder::new(BufWriter::new(file), self.w as u32, self.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(png)?;
        writer.write_image_data(&self.rgb).map_err(png)?;
        writer.finish().map_err(png)?;
        std::fs::rename(&tmp, path).map_err(io)
    }
}

/// What to draw over the heights, in world metres.
#[derive(Debug, Default)]
struct Overlay {
    /// Thin white lines at these x (vertical) and y (horizontal).
    grid_x: Vec<f64>,
    grid_y: Vec<f64>,
    /// A red vertical line (the goal).
    goal_x: Option<f64>,
    /// Dashed white vertical lines (segment boundaries).
    dashed_x: Vec<f64>,
    /// Red dots (spawn points).
    dots: Vec<[f64; 2]>,
}

/// The samples an image shows: `nx x ny` from sample `(i0, j0)`.
#[derive(Debug, Clone, Copy)]
struct View {
    i0: usize,
    j0: usize,
    nx: usize,
    ny: usize,
}

impl View {
    fn all(map: &TerrainMap) -> View {
        View {
            i0: 0,
            j0: 0,
            nx: map.nx(),
            ny: map.ny(),
        }
    }

    /// A lane's tile plus [`LANE_MARGIN`] of its border.
    fn lane(lane: &Lane) -> View {
        let map = lane.map();
        let hs = map.horizontal_scale();
        let b = map.tile_bounds(0, 0);
        let cell = |v: f64| (v / hs).round().max(0.0) as usize;
        let (i0, j0) = (cell(b.x[0] - LANE_MARGIN), cell(b.y[0] - LANE_MARGIN));
        let i1 = cell(b.x[1] + LANE_MARGIN).min(map.nx() - 1);
        let j1 = cell(b.y[1] + LANE_MARGIN).min(map.ny() - 1);
        View {
            i0,
            j0,
            nx: i1 - i0 + 1,
            ny: j1 - j0 + 1,
        }
    }

    fn range(&self, map: &TerrainMap) -> [f64; 2] {
        let mut r = [f64::INFINITY, f64::NEG_INFINITY];
        for j in self.j0..self.j0 + self.ny {
            for i in self.i0..self.i0 + self.nx {
                let h = map.height_at(i, j);
                r = [r[0].min(h), r[1].max(h)];
            }
        }
        r
    }
}

/// Pixels per sample: the smallest integer factor reaching [`MIN_WIDTH`], or a
/// fraction bringing a huge map down to [`MAX_WIDTH`].
fn scale_factor(nx: usize) -> f64 {
    if nx < MIN_WIDTH {
        MIN_WIDTH.div_ceil(nx) as f64
    } else if nx > MAX_WIDTH {
        MAX_WIDTH as f64 / nx as f64
    } else {
        1.0
    }
}

/// Sizes and labels of one PNG.
struct Frame {
    view: View,
    /// Image pixels per sample.
    f: f64,
    /// Size of the heights part.
    w: usize,
    h: usize,
    range: [f64; 2],
    labels: [String; 2],
    /// Size of the whole PNG.
    width: usize,
    height: usize,
}

fn frame(map: &TerrainMap, view: View) -> Frame {
    let f = scale_factor(view.nx);
    let (w, h) = (
        (view.nx as f64 * f).round() as usize,
        (view.ny as f64 * f).round().max(1.0) as usize,
    );
    let range = view.range(map);
    let labels = range.map(|v| format!("{v:.2}m"));
    let label_w = labels
        .iter()
        .map(|l| text_width(l, LABEL_SCALE))
        .max()
        .unwrap_or(0);
    Frame {
        view,
        f,
        w,
        h,
        range,
        labels,
        width: MARGIN + w + BAR_GAP + BAR_WIDTH + 6 + label_w + MARGIN,
        height: 2 * MARGIN + h.max(MIN_HEIGHT),
    }
}

/// The size in pixels `(width, height)` of the PNG [`render_map`] writes.
pub fn png_size(map: &TerrainMap) -> (usize, usize) {
    let fr = frame(map, View::all(map));
    (fr.width, fr.height)
}

/// The size in pixels `(width, height)` of the PNG [`render_lane`] writes.
pub fn lane_png_size(lane: &Lane) -> (usize, usize) {
    let fr = frame(lane.map(), View::lane(lane));
    (fr.width, fr.height)
}

fn render(
    map: &TerrainMap,
    fr: &Frame,
    overlay: &Overlay,
    path: &Path,
) -> Result<(), TerrainError> {
    let (v, f, w, h, hs) = (fr.view, fr.f, fr.w, fr.h, map.horizontal_scale());
    let [lo, hi] = fr.range;
    let mut img = Image::new(fr.width, fr.height);
    let span = (hi - lo).max(1e-9);
    // heights: pixel row 0 is the highest y
    for py in 0..h {
        let j = v.j0 + (v.ny - 1).saturating_sub((py as f64 / f) as usize);
        for px in 0..w {
            let i = v.i0 + ((px as f64 / f) as usize).min(v.nx - 1);
            let c = viridis((map.height_at(i, j) - lo) / span);
            img.blend(MARGIN + px, MARGIN + py, c, 1.0);
        }
    }
    // world metres -> pixel column / row of the heights image
    let to_px = |x: f64| MARGIN as f64 + (x / hs - v.i0 as f64) * f;
    let to_py = |y: f64| MARGIN as f64 + h as f64 - 1.0 - (y / hs - v.j0 as f64) * f;
    let (top, bottom) = (MARGIN, MARGIN + h);
    let (left, right) = (MARGIN, MARGIN + w);
    let white = [255, 255, 255];
    for &x in &overlay.grid_x {
        let px = to_px(x).round() as usize;
        (top..bottom).for_each(|py| img.blend(px, py, white, 0.6));
    }
    for &y in &overlay.grid_y {
        let py = to_py(y).round() as usize;
        (left..right).for_each(|px| img.blend(px, py, white, 0.6));
    }
    for &x in &overlay.dashed_x {
        let px = to_px(x).round() as usize;
        (top..bottom)
            .filter(|py| py / 4 % 2 == 0)
            .for_each(|py| img.blend(px, py, white, 0.9));
    }
    let red = [230, 40, 40];
    if let Some(x) = overlay.goal_x {
        let px = to_px(x).round() as usize;
        for py in top..bottom {
            img.blend(px, py, red, 1.0);
            img.blend(px + 1, py, red, 1.0);
        }
    }
    for &[x, y] in &overlay.dots {
        let (cx, cy) = (to_px(x), to_py(y));
        for dy in -4i32..=4 {
            for dx in -4i32..=4 {
                if dx * dx + dy * dy <= 16 {
                    let (px, py) = (cx + dx as f64, cy + dy as f64);
                    if px >= 0.0 && py >= 0.0 {
                        img.blend(px.round() as usize, py.round() as usize, red, 1.0);
                    }
                }
            }
        }
    }
    // colour bar: highest at the top, labels level with its ends
    let bar_h = h.max(MIN_HEIGHT);
    let bx = MARGIN + w + BAR_GAP;
    for py in 0..bar_h {
        let c = viridis(1.0 - py as f64 / (bar_h - 1) as f64);
        (0..BAR_WIDTH).for_each(|dx| img.blend(bx + dx, MARGIN + py, c, 1.0));
    }
    let tx = bx + BAR_WIDTH + 6;
    img.text(tx, MARGIN, &fr.labels[1], LABEL_SCALE);
    img.text(
        tx,
        MARGIN + bar_h - 7 * LABEL_SCALE,
        &fr.labels[0],
        LABEL_SCALE,
    );
    img.write(path)
}

/// A whole map with its tile grid and every tile's spawn point.
pub fn render_map(map: &TerrainMap, path: impl AsRef<Path>) -> Result<(), TerrainError> {
    let mut o = Overlay::default();
    for level in 0..map.num_levels() {
        let b = map.tile_bounds(level, 0);
        o.grid_x.extend(b.x);
    }
    for col in 0..map.num_cols() {
        let b = map.tile_bounds(0, col);
        o.grid_y.extend(b.y);
        for level in 0..map.num_levels() {
            let [x, y, _] = map.spawn(level, col);
            o.dots.push([x, y]);
        }
    }
    render(map, &frame(map, View::all(map)), &o, path.as_ref())
}

/// A lane (its tile and [`LANE_MARGIN`] of border): its outline, spawn point,
/// segment boundary (dashed) and goal line (red).
pub fn render_lane(lane: &Lane, path: impl AsRef<Path>) -> Result<(), TerrainError> {
    let b = lane.map().tile_bounds(0, 0);
    let [x, y, _] = lane.spawn();
    let o = Overlay {
        grid_x: b.x.to_vec(),
        grid_y: b.y.to_vec(),
        goal_x: Some(lane.goal_x()),
        dashed_x: lane.segments().iter().skip(1).map(|s| s.x[0]).collect(),
        dots: vec![[x, y]],
    };
    render(
        lane.map(),
        &frame(lane.map(), View::lane(lane)),
        &o,
        path.as_ref(),
    )
}

/// Generate and render the evaluation lane of `kind` at `level` (its default
/// length, the config's tile width); returns the lane it drew.
pub fn render_kind(
    cfg: &TerrainConfig,
    kind: TerrainKind,
    level: usize,
    seed: u64,
    path: impl AsRef<Path>,
) -> Result<Lane, TerrainError> {
    let lane = TerrainMap::lane(
        cfg,
        kind,
        level,
        kind.default_lane_length(),
        cfg.tile_width,
        seed,
    )?;
    render_lane(&lane, path)?;
    Ok(lane)
}
