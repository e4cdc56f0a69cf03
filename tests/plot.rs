//! Training-curve PNGs: a CSV written here is plotted into a grid of panels of the
//! documented size, every panel shows its lines in their colours, and bad input
//! (missing column, empty CSV, a bad row) is a typed error that says what is wrong.
use std::fmt::Write as _;
use std::path::Path;

use dreampolicy::plot::{
    axis_tick_label, grid, image_size, plot_csv, tick_label, MetricsTable, Panel, PlotError,
    COLORS, PANEL_SIZE, TITLE_HEIGHT,
};

/// 200 rows of `step, reward, loss, entropy, kl`, with NaN gaps in `reward`, an
/// empty field in `loss` and `kl` all NaN.
fn metrics_csv(dir: &Path) -> std::path::PathBuf {
    let mut text = String::from("step,reward,loss,entropy,kl\n");
    for i in 0..200 {
        let t = i as f64;
        let reward = if (50..55).contains(&i) {
            "NaN".to_string()
        } else {
            format!("{}", (t / 20.0).sin() * 3.0 + t / 50.0)
        };
        let loss = if i == 120 {
            String::new()
        } else {
            format!("{}", 1.0 / (1.0 + t / 10.0))
        };
        writeln!(text, "{},{reward},{loss},{},NaN", i * 1000, 1.5 - t / 400.0).unwrap();
    }
    let path = dir.join("metrics.csv");
    std::fs::write(&path, text).unwrap();
    path
}

fn panels() -> Vec<Panel> {
    vec![
        Panel::new("reward", "step", &["reward"]),
        Panel::new("losses", "step", &["loss", "entropy"]),
        Panel::new("kl (all NaN)", "step", &["kl"]),
    ]
}

/// Decoded RGB pixels of a PNG and its size.
fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// Pixels of the rectangle `[x0, x0 + w) x [y0, y0 + h)`.
fn pixels(img: &(u32, u32, Vec<u8>), x0: u32, y0: u32, w: u32, h: u32) -> Vec<(u8, u8, u8)> {
    let (width, _, rgb) = img;
    let mut out = Vec::new();
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            let i = 3 * (y * width + x) as usize;
            out.push((rgb[i], rgb[i + 1], rgb[i + 2]));
        }
    }
    out
}

#[test]
fn grid_and_size_follow_the_panel_count() {
    assert_eq!(grid(1), (1, 1));
    assert_eq!(grid(3), (2, 2));
    assert_eq!(grid(4), (2, 2));
    assert_eq!(grid(5), (3, 2));
    assert_eq!(
        image_size(3),
        (2 * PANEL_SIZE.0, 2 * PANEL_SIZE.1 + TITLE_HEIGHT)
    );
}

#[test]
fn tick_labels_are_compact() {
    for (v, label) in [
        (0.0, "0"),
        (1.0, "1"),
        (-0.25, "-0.25"),
        (0.1 + 0.2, "0.3"),
        (2500.0, "2500"),
        (20_000.0, "20k"),
        (120_000.0, "120k"),
        (1.5e6, "1.5M"),
        (3e9, "3G"),
        (1e-5, "1.00e-5"),
    ] {
        assert_eq!(tick_label(v), label, "{v}");
    }
    // rounding noise at zero reads as zero on its axis; small ticks of a small
    // axis keep their value
    assert_eq!(axis_tick_label(-0.1 + 0.1 + 6.9e-18, (-0.5, 0.5)), "0");
    assert_eq!(axis_tick_label(2e-5, (0.0, 1e-4)), "2.00e-5");
}

#[test]
fn plots_every_panel_with_its_lines() {
    let dir = tempfile::tempdir().unwrap();
    let csv = metrics_csv(dir.path());
    let out = dir.path().join("curves.png");
    plot_csv(&csv, &out, "test run", &panels()).unwrap();

    let img = decode(&out);
    assert_eq!(
        (img.0, img.1),
        (1280, 850),
        "2 x 2 panels of 640 x 400 + title"
    );
    let white = (255, 255, 255);
    let (pw, ph) = PANEL_SIZE;
    // the title is drawn (text needs the font)
    let title = pixels(&img, 0, 0, img.0, TITLE_HEIGHT);
    assert!(title.iter().filter(|&&p| p != white).count() > 100);
    // panel k at column k % 2, row k / 2: drawn, with each of its y columns' colour
    let expected_colors: [&[usize]; 3] = [&[0], &[0, 1], &[]];
    for (k, colors) in expected_colors.iter().enumerate() {
        let (col, row) = ((k % 2) as u32, (k / 2) as u32);
        let px = pixels(&img, col * pw, TITLE_HEIGHT + row * ph, pw, ph);
        let ink = px.iter().filter(|&&p| p != white).count();
        assert!(ink > 2000, "panel {k}: {ink} non-background pixels");
        for &c in *colors {
            let n = px.iter().filter(|&&p| p == COLORS[c]).count();
            assert!(n > 300, "panel {k}: {n} pixels of line colour {c}");
        }
    }
    // the empty grid cell stays blank
    let blank = pixels(&img, pw, TITLE_HEIGHT + ph, pw, ph);
    assert!(blank.iter().all(|&p| p == white));
    assert!(!dir.path().join("curves.png.tmp").exists());
}

#[test]
fn missing_column_error_names_it() {
    let dir = tempfile::tempdir().unwrap();
    let csv = metrics_csv(dir.path());
    let out = dir.path().join("curves.png");
    for (panel, missing) in [
        (
            Panel::new("p", "step", &["reward", "value_loss"]),
            "value_loss",
        ),
        (Panel::new("p", "iteration", &["reward"]), "iteration"),
    ] {
        let err = plot_csv(&csv, &out, "t", &[panel]).unwrap_err();
        match &err {
            PlotError::MissingColumn { column, .. } => assert_eq!(column, missing),
            other => panic!("expected MissingColumn, got {other:?}"),
        }
        let msg = err.to_string();
        assert!(msg.contains(&format!("'{missing}'")), "{msg}");
        assert!(msg.contains("step, reward, loss, entropy, kl"), "{msg}");
    }
    assert!(!out.exists(), "nothing is written on error");
}

#[test]
fn empty_csv_and_no_panels_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("curves.png");
    let panel = [Panel::new("p", "step", &["reward"])];
    for (text, what) in [("", "no header row"), ("step,reward\n", "no data rows")] {
        let csv = dir.path().join("m.csv");
        std::fs::write(&csv, text).unwrap();
        let err = plot_csv(&csv, &out, "t", &panel).unwrap_err();
        assert!(matches!(err, PlotError::Empty { .. }), "{err:?}");
        assert!(err.to_string().contains(what), "{err}");
    }
    let csv = metrics_csv(dir.path());
    let err = plot_csv(&csv, &out, "t", &[]).unwrap_err();
    assert!(matches!(err, PlotError::NoPanels), "{err:?}");
    let err = plot_csv(&dir.path().join("none.csv"), &out, "t", &panel).unwrap_err();
    assert!(matches!(err, PlotError::Io { .. }), "{err:?}");
}

#[test]
fn csv_rows_parse_with_nan_and_bad_rows_name_their_line() {
    let p = Path::new("m.csv");
    let t = MetricsTable::parse("a, b\n1,NaN\n\n2, \n3,inf\n", p).unwrap();
    assert_eq!(t.names, ["a", "b"]);
    assert_eq!(t.len(), 3);
    assert_eq!(t.column("a").unwrap(), [1.0, 2.0, 3.0]);
    let b = t.column("b").unwrap();
    assert!(b[0].is_nan() && b[1].is_nan() && b[2] == f64::INFINITY);

    // a last row without its newline that does not parse is being written: skipped;
    // one that parses is kept
    assert_eq!(MetricsTable::parse("a,b\n1,2\n3", p).unwrap().len(), 1);
    assert_eq!(MetricsTable::parse("a,b\n1,2\n3,4", p).unwrap().len(), 2);
    // ... a finished bad row is an error with its line
    for (text, line, what) in [
        ("a,b\n1,2\n3\n", 3, "expected 2 values, got 1"),
        ("a,b\n1,2,3\n", 2, "expected 2 values, got 3"),
        ("a,b\n1,x\n2,3\n", 2, "'x' in column 'b'"),
        ("a,a\n1,2\n", 1, "twice"),
    ] {
        let err = MetricsTable::parse(text, p).unwrap_err();
        match &err {
            PlotError::Parse {
                line: l, message, ..
            } => {
                assert_eq!(*l, line, "{text:?}");
                assert!(message.contains(what), "{message}");
            }
            other => panic!("expected Parse, got {other:?}"),
        }
    }
}
