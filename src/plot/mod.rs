//! PNG training curves from a run's `metrics.csv`: the CSV reader
//! ([`MetricsTable`]) and [`plot_csv`], which draws a grid of line-chart panels
//! (one [`Panel`] each: named y columns against an x column, with a legend) into one
//! PNG with a title; [`plot_series`] draws the same grid from in-memory lines.
//!
//! The CSV is what `run::RunDir` writes: a header row of column names, then rows of
//! numbers (`NaN`, `inf` and empty fields are allowed; non-finite points are left
//! out and break a line). A last line without its newline that does not parse is a
//! row still being written and is skipped, so a live run can be plotted.
//!
//! Drawing is `plotters` on an in-memory RGB buffer, encoded with `png`. Text needs a
//! TrueType font, read at run time from `$DREAMPOLICY_FONT`, else [`DEFAULT_FONT`]
//! (Debian's `fonts-dejavu-core`, installed by `scripts/setup.sh`).
//!
//! Layout: panels of [`PANEL_SIZE`] pixels in a grid of [`grid`] columns and rows
//! under a title band of [`TITLE_HEIGHT`] pixels; see [`image_size`].
mod heatmap;
pub use heatmap::heatmap;

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use plotters::coord::Shift;
use plotters::prelude::*;

/// The font used when `$DREAMPOLICY_FONT` is not set (package `fonts-dejavu-core`).
pub const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
/// Width and height of one panel (pixels).
pub const PANEL_SIZE: (u32, u32) = (640, 400);
/// Height of the title band above the panels (pixels).
pub const TITLE_HEIGHT: u32 = 50;
/// Line colours, in the order of a panel's y columns (matplotlib's tab10).
pub const COLORS: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

/// Errors of reading a metrics CSV and plotting it.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// No header row, or a header and no data rows.
    #[error("{path}: {what}; nothing to plot")]
    Empty { path: PathBuf, what: &'static str },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A panel names a column the CSV does not have.
    #[error("{path}: no column named '{column}' (the columns are: {available})")]
    MissingColumn {
        path: PathBuf,
        column: String,
        available: String,
    },
    #[error("no panels to plot")]
    NoPanels,
    #[error("font {path}: {message} (install fonts-dejavu-core, e.g. by scripts/setup.sh, or set DREAMPOLICY_FONT to a .ttf)")]
    Font { path: PathBuf, message: String },
    #[error("drawing {path}: {message}")]
    Draw { path: PathBuf, message: String },
    #[error("writing {path}: {source}")]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}

/// One subplot: the `ys` columns against the `x` column.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub title: String,
    pub x: String,
    pub ys: Vec<String>,
}

impl Panel {
    pub fn new(title: &str, x: &str, ys: &[&str]) -> Panel {
        Panel {
            title: title.into(),
            x: x.into(),
            ys: ys.iter().map(|s| s.to_string()).collect(),
        }
    }
}

/// A metrics CSV in memory, column by column.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricsTable {
    pub path: PathBuf,
    pub names: Vec<String>,
    /// `columns[c][row]`.
    pub columns: Vec<Vec<f64>>,
}

impl MetricsTable {
    /// The column names of `path`'s header row alone (the rest of the file is
    /// not read): which trainer wrote a run, which optional columns it has.
    /// The error is the bare I/O error; the caller names the file.
    pub fn header(path: &Path) -> std::io::Result<Vec<String>> {
        use std::io::BufRead;
        let mut first = String::new();
        std::fs::File::open(path)
            .map(std::io::BufReader::new)
            .and_then(|mut f| f.read_line(&mut first))?;
        Ok(first
            .trim_end()
            .split(',')
            .map(|c| c.trim().to_string())
            .collect())
    }

    /// Read and parse `path` (format in the module doc).
    pub fn read(path: &Path) -> Result<MetricsTable, PlotError> {
        let text = std::fs::read_to_string(path).map_err(|source| PlotError::Io {
            path: path.into(),
            source,
        })?;
        MetricsTable::parse(&text, path)
    }

    /// Parse CSV text; `path` only names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<MetricsTable, PlotError> {
        let err = |line: usize, message: String| PlotError::Parse {
            path: path.into(),
            line,
            message,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let Some((header_index, header)) = lines.next() else {
            return Err(PlotError::Empty {
                path: path.into(),
                what: "no header row",
            });
        };
        let names: Vec<String> = header
            .split(',')
            .map(|s| s.trim().trim_matches('"').to_string())
            .collect();
        for (i, n) in names.iter().enumerate() {
            if names[..i].contains(n) {
                return Err(err(header_index + 1, format!("column '{n}' appears twice")));
            }
        }
        let mut columns = vec![Vec::new(); names.len()];
        let mut row = Vec::with_capacity(names.len());
        let last = text.lines().count();
        for (i, line) in lines {
            let lineno = i + 1;
            match parse_row(line, &names, &mut row) {
                Ok(()) => {
                    for (c, v) in columns.iter_mut().zip(&row) {
                        c.push(*v);
                    }
                }
                // a row still being written (no newline yet)
                Err(_) if lineno == last && !text.ends_with('\n') => {}
                Err(message) => return Err(err(lineno, message)),
            }
        }
        if columns.first().is_none_or(|c| c.is_empty()) {
            return Err(PlotError::Empty {
                path: path.into(),
                what: "no data rows",
            });
        }
        Ok(MetricsTable {
            path: path.into(),
            names,
            columns,
        })
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of column `name`, or an error naming it.
    pub fn column(&self, name: &str) -> Result<&[f64], PlotError> {
        match self.names.iter().position(|n| n == name) {
            Some(c) => Ok(&self.columns[c]),
            None => Err(PlotError::MissingColumn {
                path: self.path.clone(),
                column: name.into(),
                available: self.names.join(", "),
            }),
        }
    }
}

/// Parse one data row into `out` (empty field = NaN).
fn parse_row(line: &str, names: &[String], out: &mut Vec<f64>) -> Result<(), String> {
    out.clear();
    let n = line.split(',').count();
    if n != names.len() {
        return Err(format!("expected {} values, got {n}", names.len()));
    }
    for (field, name) in line.split(',').zip(names) {
        let field = field.trim();
        out.push(if field.is_empty() {
            f64::NAN
        } else {
            field
                .parse::<f64>()
                .map_err(|_| format!("'{field}' in column '{name}' is not a number"))?
        });
    }
    Ok(())
}

/// Columns and rows of the panel grid for `n` panels.
pub fn grid(n: usize) -> (usize, usize) {
    let cols = match n {
        0 | 1 => 1,
        2..=4 => 2,
        _ => 3,
    };
    (cols, n.div_ceil(cols).max(1))
}

/// Width and height of the PNG for `n` panels.
pub fn image_size(n: usize) -> (u32, u32) {
    let (cols, rows) = grid(n);
    (
        cols as u32 * PANEL_SIZE.0,
        rows as u32 * PANEL_SIZE.1 + TITLE_HEIGHT,
    )
}

/// Plot `panels` of the metrics CSV `csv` into `out_png` (written via a temporary
/// name, so a viewer never sees half a file). Every column is checked before
/// anything is drawn.
pub fn plot_csv(
    csv: &Path,
    out_png: &Path,
    title: &str,
    panels: &[Panel],
) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::NoPanels);
    }
    let table = MetricsTable::read(csv)?;
    let mut data = Vec::with_capacity(panels.len());
    for p in panels {
        let x = table.column(&p.x)?;
        let ys =
            p.ys.iter()
                .map(|y| table.column(y))
                .collect::<Result<Vec<_>, _>>()?;
        data.push((p, x, ys));
    }
    draw_grid(out_png, title, data)
}

/// One subplot of in-memory lines: `lines[i].1` against `x` (NaN breaks a line).
#[derive(Debug, Clone, PartialEq)]
pub struct SeriesPanel {
    pub title: String,
    /// The x axis' label.
    pub x_label: String,
    pub x: Vec<f64>,
    /// `(legend name, values)`, each as long as `x`.
    pub lines: Vec<(String, Vec<f64>)>,
}

/// Plot in-memory [`SeriesPanel`]s into `out_png` in the same grid and style as
/// [`plot_csv`].
pub fn plot_series(out_png: &Path, title: &str, panels: &[SeriesPanel]) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::NoPanels);
    }
    let heads: Vec<Panel> = panels
        .iter()
        .map(|p| Panel {
            title: p.title.clone(),
            x: p.x_label.clone(),
            ys: p.lines.iter().map(|l| l.0.clone()).collect(),
        })
        .collect();
    let data = heads
        .iter()
        .zip(panels)
        .map(|(h, p)| {
            let ys: Vec<&[f64]> = p.lines.iter().map(|l| l.1.as_slice()).collect();
            (h, p.x.as_slice(), ys)
        })
        .collect();
    draw_grid(out_png, title, data)
}

/// A panel with its x values and its lines' y values.
type PanelData<'a> = (&'a Panel, &'a [f64], Vec<&'a [f64]>);

/// Draw `(panel, x, ys)` triples in a grid under a title band.
/// A drawing backend's error while drawing `path`, as a [`PlotError`].
fn draw_error(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.into(),
        message: e.to_string(),
    }
}

fn draw_grid(out_png: &Path, title: &str, data: Vec<PanelData>) -> Result<(), PlotError> {
    register_font()?;

    let (w, h) = image_size(data.len());
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    let draw_err = draw_error(out_png);
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&e))?;
        let (top, body) = root.split_vertically(TITLE_HEIGHT);
        top.titled(title, ("sans-serif", 26))
            .map_err(|e| draw_err(&e))?;
        let (cols, rows) = grid(data.len());
        for ((panel, x, ys), area) in data.into_iter().zip(body.split_evenly((rows, cols))) {
            draw_panel(&area, panel, x, &ys).map_err(|e| draw_err(&e))?;
        }
        root.present().map_err(|e| draw_err(&e))?;
    }
    write_png(out_png, w, h, &rgb)
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type DrawResult<'a> =
    Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

/// Runs of consecutive points where x and y are both finite.
fn segments(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out = vec![Vec::new()];
    for (&a, &b) in x.iter().zip(y) {
        if a.is_finite() && b.is_finite() {
            out.last_mut().expect("never empty").push((a, b));
        } else if !out.last().expect("never empty").is_empty() {
            out.push(Vec::new());
        }
    }
    out.retain(|s| !s.is_empty());
    out
}

/// `[lo, hi]` of the values, widened when it is a single value; `[0, 1]` when empty.
fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo > hi {
        (0.0, 1.0)
    } else if lo == hi {
        let d = if lo == 0.0 { 0.5 } else { lo.abs() * 0.05 };
        (lo - d, hi + d)
    } else {
        let d = (hi - lo) * pad;
        (lo - d, hi + d)
    }
}

fn draw_panel<'a>(area: &Area<'a>, panel: &Panel, x: &[f64], ys: &[&[f64]]) -> DrawResult<'a> {
    let lines: Vec<Vec<Vec<(f64, f64)>>> = ys.iter().map(|y| segments(x, y)).collect();
    let points = || lines.iter().flatten().flatten();
    let xr = range(points().map(|p| p.0), 0.0);
    let yr = range(points().map(|p| p.1), 0.05);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?;
    let xfmt = |v: &f64| axis_tick_label(*v, xr);
    let yfmt = |v: &f64| axis_tick_label(*v, yr);
    chart
        .configure_mesh()
        .x_desc(panel.x.as_str())
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&xfmt)
        .y_label_formatter(&yfmt)
        .max_light_lines(4)
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(242, 242, 242))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .draw()?;
    for (k, (name, segs)) in panel.ys.iter().zip(&lines).enumerate() {
        let (r, g, b) = COLORS[k % COLORS.len()];
        // 1 px: plotters' bitmap backend strokes wider polylines with joins that
        // shoot out of the chart at steep spikes (plotters-rs/plotters#549)
        let style = RGBColor(r, g, b).stroke_width(1);
        // one legend entry per column, on an empty series so it exists without data
        let label = if segs.is_empty() {
            format!("{name} (no data)")
        } else {
            name.clone()
        };
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        for seg in segs {
            if seg.len() == 1 {
                chart.draw_series(std::iter::once(Circle::new(seg[0], 2, style.filled())))?;
            } else {
                chart.draw_series(LineSeries::new(seg.iter().copied(), style))?;
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .draw()
}

/// [`tick_label`] of a tick on an axis spanning `range`: a tick within 1e-9 of
/// the span from zero is zero (the tick generator's `-0.1 + 0.1` would otherwise
/// read `6.94e-18`).
pub fn axis_tick_label(v: f64, range: (f64, f64)) -> String {
    let span = (range.1 - range.0).abs();
    tick_label(if v.abs() <= span * 1e-9 { 0.0 } else { v })
}

/// Compact axis label: `0`, `0.25`, `1.5`, `2500`, `20k`, `1.2M`, `3G`, `1.00e-5`.
pub fn tick_label(v: f64) -> String {
    fn trimmed(v: f64, decimals: usize) -> String {
        let s = format!("{v:.decimals$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.')
        } else {
            &s
        };
        if s == "-0" {
            "0".into()
        } else {
            s.into()
        }
    }
    let a = v.abs();
    if a == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if !(1e-3..1e15).contains(&a) {
        format!("{v:.2e}")
    } else if a >= 1e4 {
        let (unit, suffix) = [(1e12, "T"), (1e9, "G"), (1e6, "M"), (1e3, "k")]
            .into_iter()
            .find(|(u, _)| a >= *u)
            .expect("a >= 1e4");
        format!("{}{suffix}", trimmed(v / unit, 3))
    } else {
        trimmed(v, 4)
    }
}

/// Register the TrueType font under plotters' "sans-serif" once per process
/// (plotters keeps `&'static` font bytes, so they are leaked once).
pub fn register_font() -> Result<(), PlotError> {
    static DONE: Mutex<bool> = Mutex::new(false);
    let mut done = DONE.lock().unwrap_or_else(|e| e.into_inner());
    if *done {
        return Ok(());
    }
    let path = std::env::var_os("DREAMPOLICY_FONT")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DEFAULT_FONT));
    let bytes = std::fs::read(&path).map_err(|e| PlotError::Font {
        path: path.clone(),
        message: e.to_string(),
    })?;
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).map_err(|_| {
        PlotError::Font {
            path,
            message: "not a TrueType/OpenType font".into(),
        }
    })?;
    *done = true;
    Ok(())
}

/// Encode an RGB buffer as PNG at `path`, via `path.tmp` and a rename.
pub fn write_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<(), PlotError> {
    let io = |source| PlotError::Io {
        path: path.into(),
        source,
    };
    let png = |source| PlotError::Png {
        path: path.into(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let encode = || {
        let file = std::fs::File::create(&tmp).map_err(io)?;
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(png)?;
        writer.write_image_data(rgb).map_err(png)?;
        writer.finish().map_err(png)?;
        std::fs::rename(&tmp, path).map_err(io)
    };
    encode().inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })
}
