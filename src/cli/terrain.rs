//! `dreampolicy terrain render`: a height image of one kind's lane, a combined
//! lane, or the whole curriculum map.
use std::path::PathBuf;

use anyhow::Result;
use clap::Subcommand;

use dreampolicy::terrain::{render, TerrainConfig, TerrainKind, TerrainMap};

#[derive(Subcommand)]
pub enum TerrainCommand {
    /// Draw a height image with a colour bar: one kind's lane (`--kind`, optionally
    /// joined with `--then`), or the whole curriculum map (`--map`).
    Render(RenderArgs),
}

/// Arguments of `terrain render`.
#[derive(clap::Args)]
pub struct RenderArgs {
    /// Terrain kind: flat, uneven, stair, gap, bridge, wave, slope, balancing_beam, slope_bridge.
    #[arg(long, required_unless_present = "map")]
    kind: Option<String>,
    /// Second kind of a combined lane (the paper's pairs, e.g. --kind stair --then gap).
    #[arg(long, requires = "kind")]
    then: Option<String>,
    /// Curriculum level (0 = easiest).
    #[arg(long, default_value_t = 5)]
    level: usize,
    /// Render the whole map of the config instead of one lane.
    #[arg(long, conflicts_with = "kind")]
    map: bool,
    /// Experiment config whose env.terrain.map is used (default: built-in terrain defaults).
    #[arg(long)]
    config: Option<PathBuf>,
    #[arg(long = "set")]
    sets: Vec<String>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long)]
    out: PathBuf,
}

pub fn run(which: TerrainCommand) -> Result<()> {
    match which {
        TerrainCommand::Render(a) => render_cmd(a),
    }
}

fn render_cmd(a: RenderArgs) -> Result<()> {
    let RenderArgs {
        kind,
        then,
        level,
        map,
        config,
        sets,
        seed,
        out,
    } = a;
    let cfg = match config {
        Some(path) => dreampolicy::rl::config::load(&path, &sets)?.env.terrain.map,
        None => TerrainConfig::default(),
    };
    cfg.validate()?;
    if map {
        let m = TerrainMap::generate(&cfg, seed)?;
        render::render_map(&m, &out)?;
        println!(
            "{}: {} levels x {} columns, {:.1} x {:.1} m",
            out.display(),
            m.num_levels(),
            m.num_cols(),
            m.extent()[0],
            m.extent()[1]
        );
        return Ok(());
    }
    let first = TerrainKind::from_name(kind.as_deref().unwrap_or_default())?;
    let lane = match then {
        None => render::render_kind(&cfg, first, level, seed, &out)?,
        Some(second) => {
            let second = TerrainKind::from_name(&second)?;
            let lane = TerrainMap::combined_lane(
                &cfg,
                first,
                second,
                level,
                first.default_lane_length(),
                cfg.tile_width,
                seed,
            )?;
            render::render_lane(&lane, &out)?;
            lane
        }
    };
    println!(
        "{}: level {level}, {:.1} m from spawn to goal",
        out.display(),
        lane.length()
    );
    Ok(())
}
