//! Figures with plotters: the paper's figures 2-4 in one image.
//!
//! Left, per agent (columns): states over time (top) and forces over time (bottom), as in
//! the paper's figures 2 and 3. Right: both paths in the plane, as in figure 4. PNG text is
//! rendered with the embedded DejaVu Sans, so no system fonts are needed.

use std::path::Path;
use std::sync::Once;

use anyhow::{Context, anyhow};
use fuzzyq_sim::policy::PolicyKind;
use fuzzyq_sim::rollout::Trajectory;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Refuses extensions other than `.png` and `.svg` before any work is done.
pub(crate) fn check_extension(path: &Path) -> anyhow::Result<()> {
    match extension(path).as_deref() {
        Some("png" | "svg") => Ok(()),
        _ => Err(anyhow!(
            "--plot {}: the file name must end in .png or .svg",
            path.display()
        )),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("drawing failed: {e}")
}

const COLORS: [RGBColor; 4] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
];

/// Draws the rollout figure into `path` (PNG or SVG), atomically.
pub(crate) fn rollout_figure(path: &Path, t: &Trajectory, kind: PolicyKind) -> anyhow::Result<()> {
    register_font();
    let ext = extension(path).unwrap_or_default();
    // Render next to the destination (the bitmap encoder picks the format from the
    // extension), then rename over it.
    let tmp = fuzzyq_sim::artifact::temp_file_beside(path, &format!(".{ext}"))
        .with_context(|| format!("cannot write plot {}", path.display()))?;
    let size = (600 * t.agents as u32 + 640, 900);
    {
        if ext == "svg" {
            let root = SVGBackend::new(tmp.path(), size).into_drawing_area();
            draw(&root, t, kind)?;
            root.present().map_err(err)?;
        } else {
            let root = BitMapBackend::new(tmp.path(), size).into_drawing_area();
            draw(&root, t, kind)?;
            root.present().map_err(err)?;
        }
    }
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("cannot write plot {}", path.display()))?;
    Ok(())
}

fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return -1.0..1.0;
    }
    let pad = ((hi - lo) * 0.08).max(0.1);
    (lo - pad)..(hi + pad)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    t: &Trajectory,
    kind: PolicyKind,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let title = format!("fuzzyq rollout ({} policy, T = {} s)", kind.name(), t.dt);
    let root = root
        .titled(&title, (FONT, 26).into_font().style(FontStyle::Bold))
        .map_err(err)?;
    let (w, _) = root.dim_in_pixel();
    let (left, right) = root.split_horizontally(w.saturating_sub(640));
    let panels = left.split_evenly((2, t.agents));
    let t_end = t.time(t.states.len() - 1);
    for i in 0..t.agents {
        draw_states(&panels[i], t, i, t_end)?;
        draw_forces(&panels[t.agents + i], t, i, t_end)?;
    }
    draw_paths(&right, t)?;
    Ok(())
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn legend<'a, DB: DrawingBackend + 'a>(chart: &mut Chart<'a, DB>) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT, 15))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)
}

/// A chart with a caption, axis labels and a light grid.
fn chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    (x_desc, y_desc): (&str, &str),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x, y)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// A chart over time.
fn time_chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    y_desc: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    chart(area, caption, ("time (s)", y_desc), x, y)
}

fn draw_states<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    t: &Trajectory,
    agent: usize,
    t_end: f64,
) -> anyhow::Result<()> {
    let col = |j: usize| t.states.iter().map(move |x| x[4 * agent + j]);
    let y = range((0..4).flat_map(col));
    let caption = format!("Agent {}: states", agent + 1);
    let mut chart = time_chart(area, &caption, "m, m/s", 0.0..t_end.max(t.dt), y)?;
    for (j, name) in ["s_x (m)", "s_y (m)", "v_x (m/s)", "v_y (m/s)"]
        .iter()
        .enumerate()
    {
        let color = COLORS[j];
        chart
            .draw_series(LineSeries::new(
                col(j).enumerate().map(|(k, v)| (t.time(k), v)),
                color.stroke_width(2),
            ))
            .map_err(err)?
            .label(*name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    legend(&mut chart)
}

fn draw_forces<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    t: &Trajectory,
    agent: usize,
    t_end: f64,
) -> anyhow::Result<()> {
    let col = |j: usize| t.actions.iter().map(move |u| u[2 * agent + j]);
    let y = range((0..2).flat_map(col).chain([-0.1, 0.1]));
    let caption = format!("Agent {}: forces", agent + 1);
    let mut chart = time_chart(area, &caption, "N", 0.0..t_end.max(t.dt), y)?;
    for (j, name) in ["u_x (N)", "u_y (N)"].iter().enumerate() {
        let color = COLORS[j];
        // Zero-order hold: each force holds over its sample time.
        let steps = col(j)
            .enumerate()
            .flat_map(|(k, v)| [(t.time(k), v), (t.time(k + 1), v)]);
        chart
            .draw_series(LineSeries::new(steps, color.stroke_width(2)))
            .map_err(err)?
            .label(*name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
    }
    legend(&mut chart)
}

fn draw_paths<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    t: &Trajectory,
) -> anyhow::Result<()> {
    let xs = range(
        (0..t.agents)
            .flat_map(|i| t.states.iter().map(move |x| x[4 * i]))
            .chain([0.0]),
    );
    let ys = range(
        (0..t.agents)
            .flat_map(|i| t.states.iter().map(move |x| x[4 * i + 1]))
            .chain([0.0]),
    );
    // Equal scales on both axes: widen the shorter range.
    let half = ((xs.end - xs.start).max(ys.end - ys.start)) / 2.0;
    let (cx, cy) = ((xs.start + xs.end) / 2.0, (ys.start + ys.end) / 2.0);
    let (w, h) = area.dim_in_pixel();
    let side = w.min(h);
    let area = area.margin(
        (h.saturating_sub(side)) / 2,
        (h.saturating_sub(side)) / 2,
        (w.saturating_sub(side)) / 2,
        (w.saturating_sub(side)) / 2,
    );
    let mut chart = chart(
        &area,
        "Paths in the plane",
        ("s_x (m)", "s_y (m)"),
        (cx - half)..(cx + half),
        (cy - half)..(cy + half),
    )?;
    chart
        .draw_series(std::iter::once(Cross::new(
            (0.0, 0.0),
            8,
            BLACK.stroke_width(2),
        )))
        .map_err(err)?
        .label("origin (goal)")
        .legend(|(x, y)| Cross::new((x + 9, y), 6, BLACK.stroke_width(2)));
    for i in 0..t.agents {
        let color = COLORS[i % COLORS.len()];
        let path: Vec<(f64, f64)> = t.states.iter().map(|x| (x[4 * i], x[4 * i + 1])).collect();
        chart
            .draw_series(LineSeries::new(path.iter().copied(), color.stroke_width(2)))
            .map_err(err)?
            .label(format!("agent {}", i + 1))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        chart
            .draw_series(path.iter().map(|&p| Circle::new(p, 3, color.filled())))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                path[0],
                9,
                color.filled(),
            )))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT, 15))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(err)?;
    Ok(())
}
