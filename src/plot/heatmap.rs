//! The success-rate heatmap of `eval`'s cross-terrain matrix.
use std::path::Path;

use plotters::prelude::*;

use super::{draw_error, register_font, write_png, PlotError};

/// A matrix of values in `[0, 1]` (success rates) as a PNG heatmap: one cell per
/// (row, column), coloured from red (0) through yellow to green (1), with the
/// value printed in it; NaN cells are grey.
pub fn heatmap(
    out_png: &Path,
    title: &str,
    rows: &[String],
    cols: &[String],
    values: &[Vec<f64>],
) -> Result<(), PlotError> {
    if rows.is_empty() || cols.is_empty() {
        return Err(PlotError::NoPanels);
    }
    register_font()?;
    let (cell_w, cell_h, left, top) = (130u32, 60u32, 170u32, 90u32);
    let (w, h) = (
        left + cell_w * cols.len() as u32 + 20,
        top + cell_h * rows.len() as u32 + 20,
    );
    let mut rgb = vec![0u8; w as usize * h as usize * 3];
    let draw_err = draw_error(out_png);
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&e))?;
        let font = ("sans-serif", 18).into_font();
        let centered = |size: u32| {
            ("sans-serif", size).into_font().color(&BLACK).pos(
                plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Center,
                    plotters::style::text_anchor::VPos::Center,
                ),
            )
        };
        root.draw(&Text::new(title.to_string(), (10, 10), ("sans-serif", 22)))
            .map_err(|e| draw_err(&e))?;
        for (j, c) in cols.iter().enumerate() {
            let x = (left + cell_w * j as u32 + cell_w / 2) as i32;
            root.draw(&Text::new(c.clone(), (x, top as i32 - 20), centered(18)))
                .map_err(|e| draw_err(&e))?;
        }
        for (i, r) in rows.iter().enumerate() {
            let y = (top + cell_h * i as u32) as i32;
            root.draw(&Text::new(
                r.clone(),
                (10, y + cell_h as i32 / 2 - 9),
                font.clone(),
            ))
            .map_err(|e| draw_err(&e))?;
            for j in 0..cols.len() {
                let v = values
                    .get(i)
                    .and_then(|r| r.get(j))
                    .copied()
                    .unwrap_or(f64::NAN);
                let x = (left + cell_w * j as u32) as i32;
                let color = if v.is_finite() {
                    let t = v.clamp(0.0, 1.0);
                    // red -> yellow -> green
                    let (r, g) = if t < 0.5 {
                        (230.0, 80.0 + 2.0 * t * 150.0)
                    } else {
                        (
                            230.0 - 2.0 * (t - 0.5) * 170.0,
                            230.0 - 2.0 * (t - 0.5) * 50.0,
                        )
                    };
                    RGBColor(r as u8, g as u8, 80)
                } else {
                    RGBColor(200, 200, 200)
                };
                root.draw(&Rectangle::new(
                    [
                        (x + 1, y + 1),
                        (x + cell_w as i32 - 1, y + cell_h as i32 - 1),
                    ],
                    color.filled(),
                ))
                .map_err(|e| draw_err(&e))?;
                let label = if v.is_finite() {
                    format!("{v:.2}")
                } else {
                    "-".into()
                };
                root.draw(&Text::new(
                    label,
                    (x + cell_w as i32 / 2, y + cell_h as i32 / 2),
                    centered(20),
                ))
                .map_err(|e| draw_err(&e))?;
            }
        }
        root.present().map_err(|e| draw_err(&e))?;
    }
    write_png(out_png, w, h, &rgb)
}
