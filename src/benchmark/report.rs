//! The benchmark's report: `results.md` (a table per paper table and level,
//! our cells with their 95 % intervals, the paper's published numbers in a
//! column group of their own), `<table>_success.png` (a heatmap of success,
//! methods x lanes) and `<table>_bars.png` (success and completion bars with
//! the intervals) per table, at the first level of the config.
use std::fmt::Write as _;
use std::path::Path;

use plotters::prelude::*;

use super::{BenchmarkConfig, BenchmarkError, PaperMethod, Row, Table};

/// The paper's published numbers (percent): (success, completion) per lane, in
/// [`Table::lanes`] order. The unseen table is the paper's Table 1, the
/// combined one its Table 2 (only distillation and ours); the single-terrain
/// results are a radar figure without numbers.
pub fn paper_numbers(table: Table, method: PaperMethod) -> Option<Vec<(f64, f64)>> {
    use PaperMethod::*;
    let v: &[(f64, f64)] = match (table, method) {
        (Table::Unseen, Ours) => &[
            (92.77, 60.48),
            (96.35, 90.32),
            (100.0, 100.0),
            (100.0, 100.0),
        ],
        (Table::Unseen, Distillation) => &[
            (65.48, 40.16),
            (74.36, 60.24),
            (100.0, 100.0),
            (100.0, 100.0),
        ],
        (Table::Unseen, WithoutDiffusion) => {
            &[(0.0, 10.35), (20.14, 35.78), (97.32, 98.46), (98.65, 99.16)]
        }
        (Table::Unseen, WithoutGcrl) => &[(0.0, 1.35), (0.0, 5.34), (60.38, 80.26), (94.35, 90.63)],
        (Table::Combined, Ours) => &[
            (88.46, 96.25),
            (84.78, 90.64),
            (95.79, 98.68),
            (91.45, 84.65),
            (94.68, 96.58),
        ],
        (Table::Combined, Distillation) => &[
            (50.48, 76.45),
            (62.33, 74.58),
            (88.42, 90.35),
            (86.76, 72.17),
            (91.34, 82.65),
        ],
        _ => return None,
    };
    Some(v.to_vec())
}

fn paper_name(m: PaperMethod) -> &'static str {
    match m {
        PaperMethod::Ours => "DreamPolicy",
        PaperMethod::Distillation => "Distillation",
        PaperMethod::WithoutDiffusion => "w/o diffusion",
        PaperMethod::WithoutGcrl => "w/o GCRL",
    }
}

fn pct(v: f64) -> String {
    if v.is_finite() {
        format!("{:.0}", 100.0 * v)
    } else {
        "—".into()
    }
}

/// The row measuring (table, method, lane, level), if there is one.
fn find<'a>(
    rows: &'a [Row],
    table: Table,
    method: &str,
    lane: &str,
    level: usize,
) -> Option<&'a Row> {
    rows.iter()
        .find(|r| r.table == table && r.method == method && r.lane == lane && r.level == level)
}

/// Our cell as `success [lo–hi] · completion`, or a dash.
fn cell_text(r: Option<&Row>) -> String {
    match r {
        Some(r) => format!(
            "{} [{}–{}] · {}",
            pct(r.success_rate),
            pct(r.success_lo),
            pct(r.success_hi),
            pct(r.completion_rate)
        ),
        None => "—".into(),
    }
}

/// What our measurements say of one order the paper publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Our success intervals lie apart, in the paper's order.
    Holds,
    /// Our success intervals lie apart, in the other order.
    Reversed,
    /// Our intervals overlap: these episodes do not tell.
    Open,
}

impl Verdict {
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Holds => "holds",
            Verdict::Reversed => "reversed",
            Verdict::Open => "open",
        }
    }
}

/// One of the paper's published orders on one lane checked against our
/// cells: the paper's method with the higher success (`better`) and the
/// lower, the methods of ours named beside them (`paper:` in the config),
/// both success rates (percent) and the verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderCheck {
    pub table: Table,
    pub level: usize,
    pub lane: String,
    pub better: PaperMethod,
    pub worse: PaperMethod,
    pub ours_better: String,
    pub ours_worse: String,
    pub paper: (f64, f64),
    pub ours: (f64, f64),
    pub verdict: Verdict,
}

/// The paper's success differences smaller than this (percentage points)
/// state no order.
pub const PAPER_TIE_POINTS: f64 = 1.0;

/// Every order the paper's published success rates state between two of its
/// methods on a lane (differences of [`PAPER_TIE_POINTS`] or more), for the
/// pairs the config names methods for (the first method of each `paper:`
/// row), checked against our cells with their 95 % intervals: `Holds` when
/// our better one's interval lies wholly above the other's, `Reversed` when
/// wholly below, `Open` when they overlap. Lanes without both our cells are
/// left out.
pub fn orderings(cfg: &BenchmarkConfig, rows: &[Row]) -> Vec<OrderCheck> {
    let ours_of = |p: PaperMethod| {
        cfg.methods
            .iter()
            .find(|m| m.paper == Some(p))
            .map(|m| m.name.clone())
    };
    let mut out = Vec::new();
    for table in &cfg.tables {
        let lanes = table.lane_names();
        let methods = PaperMethod::ALL;
        for (i, &a) in methods.iter().enumerate() {
            for &b in &methods[i + 1..] {
                let (Some(pa), Some(pb)) = (paper_numbers(*table, a), paper_numbers(*table, b))
                else {
                    continue;
                };
                let (Some(ma), Some(mb)) = (ours_of(a), ours_of(b)) else {
                    continue;
                };
                for level in &cfg.levels {
                    for (k, lane) in lanes.iter().enumerate() {
                        let (sa, sb) = (pa[k].0, pb[k].0);
                        if (sa - sb).abs() < PAPER_TIE_POINTS {
                            continue;
                        }
                        let (Some(ra), Some(rb)) = (
                            find(rows, *table, &ma, lane, *level),
                            find(rows, *table, &mb, lane, *level),
                        ) else {
                            continue;
                        };
                        // (paper's method, ours, our row, paper's success) of the
                        // paper's better one, then of its worse one
                        let (hi, lo) = if sa > sb {
                            ((a, &ma, ra, sa), (b, &mb, rb, sb))
                        } else {
                            ((b, &mb, rb, sb), (a, &ma, ra, sa))
                        };
                        let verdict = if hi.2.success_lo > lo.2.success_hi {
                            Verdict::Holds
                        } else if lo.2.success_lo > hi.2.success_hi {
                            Verdict::Reversed
                        } else {
                            Verdict::Open
                        };
                        out.push(OrderCheck {
                            table: *table,
                            level: *level,
                            lane: lane.clone(),
                            better: hi.0,
                            worse: lo.0,
                            ours_better: hi.1.clone(),
                            ours_worse: lo.1.clone(),
                            paper: (hi.3, lo.3),
                            ours: (100.0 * hi.2.success_rate, 100.0 * lo.2.success_rate),
                            verdict,
                        });
                    }
                }
            }
        }
    }
    out
}

/// The orderings of one table and level as a Markdown table (empty when
/// there are none).
fn orderings_markdown(checks: &[OrderCheck], table: Table, level: usize) -> String {
    let mine: Vec<&OrderCheck> = checks
        .iter()
        .filter(|c| c.table == table && c.level == level)
        .collect();
    if mine.is_empty() {
        return String::new();
    }
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\nDoes the paper's order hold here? Success, the paper's then ours; \
         `holds`: our 95 % intervals lie apart in the paper's order, `reversed`: apart the \
         other way, `open`: they overlap.\n"
    );
    let _ = writeln!(md, "| lane | paper's order | paper | ours | verdict |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for c in &mine {
        let _ = writeln!(
            md,
            "| {} | {} > {} | {:.1} > {:.1} | {} {:.0} vs {} {:.0} | {} |",
            c.lane,
            paper_name(c.better),
            paper_name(c.worse),
            c.paper.0,
            c.paper.1,
            c.ours_better,
            c.ours.0,
            c.ours_worse,
            c.ours.1,
            c.verdict.name()
        );
    }
    let (h, r, o) = mine.iter().fold((0, 0, 0), |(h, r, o), c| match c.verdict {
        Verdict::Holds => (h + 1, r, o),
        Verdict::Reversed => (h, r + 1, o),
        Verdict::Open => (h, r, o + 1),
    });
    let _ = writeln!(md, "\nholds: {h}, reversed: {r}, open: {o}.");
    md
}

/// The Markdown report.
pub fn markdown(cfg: &BenchmarkConfig, rows: &[Row]) -> String {
    let mut md = String::new();
    let title = cfg.name.as_deref().unwrap_or("benchmark");
    let _ = writeln!(md, "# {title}\n");
    let _ = writeln!(
        md,
        "Each cell: success rate % [95 % Wilson interval] · completion rate %, over {} \
         episodes on 10 m lanes ({} scene, seed {}); MuJoCo {}. The paper's columns are its \
         published numbers (success · completion), not measured here.\n",
        cfg.episodes,
        if cfg.full_collision {
            "full-collision"
        } else {
            "each checkpoint's training"
        },
        cfg.seed,
        crate::sim::mujoco_version()
    );
    let checks = orderings(cfg, rows);
    for table in &cfg.tables {
        let lanes = table.lane_names();
        for level in &cfg.levels {
            let _ = writeln!(md, "## {} terrains, level {level}\n", table.name());
            let _ = writeln!(md, "| method | {} |", lanes.join(" | "));
            let _ = writeln!(md, "|---|{}", "---|".repeat(lanes.len()));
            for m in &cfg.methods {
                let cells: Vec<String> = lanes
                    .iter()
                    .map(|lane| cell_text(find(rows, *table, &m.name, lane, *level)))
                    .collect();
                let _ = writeln!(md, "| {} | {} |", m.name, cells.join(" | "));
            }
            let paper: Vec<(PaperMethod, Vec<(f64, f64)>)> = PaperMethod::ALL
                .into_iter()
                .filter_map(|p| paper_numbers(*table, p).map(|v| (p, v)))
                .collect();
            if !paper.is_empty() {
                let _ = writeln!(
                    md,
                    "\nThe paper (published, Isaac Gym; its level is not stated):\n"
                );
                let _ = writeln!(md, "| paper's method | {} |", lanes.join(" | "));
                let _ = writeln!(md, "|---|{}", "---|".repeat(lanes.len()));
                for (p, v) in paper {
                    let cells: Vec<String> =
                        v.iter().map(|(s, c)| format!("{s:.1} · {c:.1}")).collect();
                    let ours: Vec<&str> = cfg
                        .methods
                        .iter()
                        .filter(|m| m.paper == Some(p))
                        .map(|m| m.name.as_str())
                        .collect();
                    let beside = if ours.is_empty() {
                        String::new()
                    } else {
                        format!(" (ours: {})", ours.join(", "))
                    };
                    let _ = writeln!(md, "| {}{beside} | {} |", paper_name(p), cells.join(" | "));
                }
            }
            md.push_str(&orderings_markdown(&checks, *table, *level));
            let _ = writeln!(md);
        }
    }
    md
}

/// Write `results.md` and the figures into `out`.
pub fn write(cfg: &BenchmarkConfig, rows: &[Row], out: &Path) -> Result<(), BenchmarkError> {
    let md = out.join("results.md");
    std::fs::write(&md, markdown(cfg, rows)).map_err(|e| BenchmarkError::io(&md, e))?;
    let level = cfg.levels[0];
    for table in &cfg.tables {
        let lanes = table.lane_names();
        let methods: Vec<String> = cfg.methods.iter().map(|m| m.name.clone()).collect();
        // a row per method, a cell per lane
        let cells: Vec<Vec<Option<&Row>>> = methods
            .iter()
            .map(|m| {
                lanes
                    .iter()
                    .map(|l| find(rows, *table, m, l, level))
                    .collect()
            })
            .collect();
        let success: Vec<Vec<f64>> = cells
            .iter()
            .map(|row| {
                row.iter()
                    .map(|r| r.map_or(f64::NAN, |r| r.success_rate))
                    .collect()
            })
            .collect();
        crate::plot::heatmap(
            &out.join(format!("{}_success.png", table.name())),
            &format!("success rate, {} terrains, level {level}", table.name()),
            &methods,
            &lanes,
            &success,
        )?;
        bar_chart(
            &out.join(format!("{}_bars.png", table.name())),
            &format!("{} terrains, level {level}", table.name()),
            &methods,
            &lanes,
            &cells,
        )?;
    }
    Ok(())
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Two panels (success, completion): a group of bars per lane, a bar per
/// method, the 95 % interval as a whisker; missing cells leave a gap.
fn bar_chart(
    path: &Path,
    title: &str,
    methods: &[String],
    lanes: &[String],
    cells: &[Vec<Option<&Row>>],
) -> Result<(), BenchmarkError> {
    crate::plot::register_font()?;
    let (w, h) = (160 * lanes.len() as u32 + 200, 760u32);
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    let draw = |e: &dyn std::fmt::Display| BenchmarkError::Invalid {
        path: path.to_path_buf(),
        message: format!("drawing: {e}"),
    };
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw(&e))?;
        let root = root
            .titled(title, ("sans-serif", 22))
            .map_err(|e| draw(&e))?;
        let panels = root.split_evenly((2, 1));
        let n = methods.len().max(1) as f64;
        for (p, area) in panels.iter().enumerate() {
            let what = if p == 0 { "success %" } else { "completion %" };
            let mut chart = ChartBuilder::on(area)
                .margin(10)
                .x_label_area_size(if p == 1 { 40 } else { 10 })
                .y_label_area_size(50)
                .build_cartesian_2d(0f64..lanes.len() as f64, 0f64..105f64)
                .map_err(|e| draw(&e))?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .light_line_style(WHITE)
                .y_labels(6)
                .x_labels(lanes.len() * 2 + 1)
                .x_label_formatter(&|x| {
                    let i = (x - 0.5).round();
                    if (x - 0.5 - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < lanes.len() {
                        lanes[i as usize].clone()
                    } else {
                        String::new()
                    }
                })
                .y_desc(what)
                .draw()
                .map_err(|e| draw(&e))?;
            for (mi, row) in cells.iter().enumerate() {
                let color = COLORS[mi % COLORS.len()];
                for (li, r) in row.iter().enumerate() {
                    let Some(r) = r else { continue };
                    let (v, lo, hi) = if p == 0 {
                        (r.success_rate, r.success_lo, r.success_hi)
                    } else {
                        (r.completion_rate, r.completion_lo, r.completion_hi)
                    };
                    let x0 = li as f64 + 0.1 + 0.8 * mi as f64 / n;
                    let x1 = x0 + 0.8 / n * 0.9;
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [(x0, 0.0), (x1, 100.0 * v)],
                            color.filled(),
                        )))
                        .map_err(|e| draw(&e))?;
                    let xm = 0.5 * (x0 + x1);
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            vec![(xm, 100.0 * lo), (xm, 100.0 * hi)],
                            BLACK.stroke_width(2),
                        )))
                        .map_err(|e| draw(&e))?;
                }
            }
            if p == 0 {
                for (mi, m) in methods.iter().enumerate() {
                    let color = COLORS[mi % COLORS.len()];
                    chart
                        .draw_series(std::iter::once(Rectangle::new(
                            [(0.0, 0.0), (0.0, 0.0)],
                            color.filled(),
                        )))
                        .map_err(|e| draw(&e))?
                        .label(m.as_str())
                        .legend(move |(x, y)| {
                            Rectangle::new([(x, y - 6), (x + 14, y + 6)], color.filled())
                        });
                }
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .position(SeriesLabelPosition::UpperRight)
                    .draw()
                    .map_err(|e| draw(&e))?;
            }
        }
        root.present().map_err(|e| draw(&e))?;
    }
    crate::plot::write_png(path, w, h, &rgb)?;
    Ok(())
}
