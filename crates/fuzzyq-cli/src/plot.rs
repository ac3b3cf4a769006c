//! Figures with plotters, each one composite image written atomically as PNG or SVG.
//!
//! - [`rollout_figure`]: the paper's figures 2-4. Left, per agent (columns): states over time
//!   (top) and forces over time (bottom), as in figures 2 and 3. Right: both paths in the
//!   plane, as in figure 4.
//! - [`khepera_figure`]: the same for the robots (figures 7-9): states and heading, the action
//!   taken and the reward over time, and the paths in the arena with its obstacles.
//! - [`learning_curve_figure`]: the learning curve of fuzzy Q-learning.
//! - [`success_figure`]: success or failure from many random starts, in the arena.
//! - [`compare_figure`]: the paths of every learner of `fuzzyq compare` from one start.
//!
//! PNG text is rendered with the embedded DejaVu Sans, so no system fonts are needed.

use std::path::Path;
use std::sync::Once;

use anyhow::{Context, anyhow, bail};
use fuzzyq_sim::compare::Comparison;
use fuzzyq_sim::learn::fql::EpisodeRecord;
use fuzzyq_sim::model::arena::{Arena, Obstacle};
use fuzzyq_sim::model::khepera::ACTION_NAMES;
use fuzzyq_sim::run::policy::PolicyKind;
use fuzzyq_sim::run::robots::KheperaRun;
use fuzzyq_sim::run::rollout::Trajectory;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;
use plotters::style::text_anchor::{HPos, Pos, VPos};

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
    let title = format!("fuzzyq rollout ({} policy, T = {} s)", kind.name(), t.dt);
    rollout_figure_titled(path, t, &title)
}

/// [`rollout_figure`] with a given title.
pub(crate) fn rollout_figure_titled(
    path: &Path,
    t: &Trajectory,
    title: &str,
) -> anyhow::Result<()> {
    if t.agents == 0 || t.states.is_empty() {
        return Err(anyhow!("cannot plot an empty rollout"));
    }
    let size = (600 * t.agents as u32 + 640, 900);
    write_figure(
        path,
        size,
        |root| draw(root, t, title),
        |root| draw(root, t, title),
    )
}

/// Renders a figure of `size` pixels into `path` (PNG or SVG by extension), atomically: the
/// figure is drawn into a temporary file beside `path`, which is then renamed over it. The two
/// closures are the same drawing for the two backends.
fn write_figure(
    path: &Path,
    size: (u32, u32),
    png: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> anyhow::Result<()>,
    svg: impl FnOnce(&DrawingArea<SVGBackend<'_>, Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let ext = extension(path).unwrap_or_default();
    if ext != "png" && ext != "svg" {
        return Err(anyhow!(
            "plot {}: the file name must end in .png or .svg",
            path.display()
        ));
    }
    register_font();
    // Render next to the destination (the bitmap encoder picks the format from the
    // extension), then rename over it.
    let tmp = fuzzyq_sim::io::policy_file::temp_file_beside(path, &format!(".{ext}"))
        .with_context(|| format!("cannot write plot {}", path.display()))?;
    {
        if ext == "svg" {
            let root = SVGBackend::new(tmp.path(), size).into_drawing_area();
            svg(&root)?;
            root.present().map_err(err)?;
        } else {
            let root = BitMapBackend::new(tmp.path(), size).into_drawing_area();
            png(&root)?;
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
    title: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
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
    legend_at(chart, SeriesLabelPosition::UpperRight)
}

/// A chart with a caption, axis labels and a light grid.
fn chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    desc: (&str, &str),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    chart_with(area, Some(caption), desc, x, y, Axes::default())
}

/// How [`chart_with`] lays out the axes.
#[derive(Clone, Copy)]
struct Axes {
    /// Width of the y labels' area (px).
    y_area: u32,
    /// Label the x axis at integers only (episodes).
    x_integer: bool,
    /// Label the y axis at integers only (counts).
    y_integer: bool,
}

impl Default for Axes {
    fn default() -> Self {
        Self {
            y_area: 50,
            x_integer: false,
            y_integer: false,
        }
    }
}

/// An integer label for integers, nothing between them.
fn integer_label(v: &f64) -> String {
    if (v - v.round()).abs() < 1e-9 {
        format!("{:.0}", v.round() + 0.0)
    } else {
        String::new()
    }
}

/// [`chart`] with the axes laid out by `axes`; without a caption, also without the margin
/// (the caller has titled the area itself).
fn chart_with<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: Option<&str>,
    (x_desc, y_desc): (&str, &str),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    axes: Axes,
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    let mut builder = ChartBuilder::on(area);
    if let Some(caption) = caption {
        builder.caption(caption, (FONT, 20)).margin(12);
    }
    let mut chart = builder
        .x_label_area_size(40)
        .y_label_area_size(axes.y_area)
        .build_cartesian_2d(x, y)
        .map_err(err)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(x_desc)
        .y_desc(y_desc)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05));
    if axes.x_integer {
        mesh.x_label_formatter(&integer_label);
    }
    if axes.y_integer {
        mesh.y_label_formatter(&integer_label);
    }
    mesh.draw().map_err(err)?;
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
    draw_origin(&mut chart, 8)?;
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

// ---------------------------------------------------------------------------------------------
// Shared helpers of the robot and learning figures.

/// Heading (rad) and the fifth series of a panel.
const PURPLE: RGBColor = RGBColor(0x94, 0x67, 0xbd);
/// Obstacles.
const GREY: RGBColor = RGBColor(0xa0, 0xa0, 0xa0);
/// Success and failure.
const GOOD: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
const BAD: RGBColor = RGBColor(0xd6, 0x27, 0x28);
/// The paper's reward region `||x|| < 0.2` (eq 42), drawn around the origin for reference.
const GOAL_RADIUS: f64 = 0.2;
/// The time axes of the Khepera figure line up: room for the action names on the left.
const KHEPERA_AXES: Axes = Axes {
    y_area: 80,
    x_integer: false,
    y_integer: false,
};
/// The axes of the learning curve: episodes on x.
const EPISODE_AXES: Axes = Axes {
    y_area: 60,
    x_integer: true,
    y_integer: false,
};
/// Episodes in the moving averages of the learning curve.
const MA_WINDOW: usize = 20;

/// The goal: a cross at the origin, with its legend entry.
fn draw_origin<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    size: u32,
) -> anyhow::Result<()> {
    chart
        .draw_series(std::iter::once(Cross::new(
            (0.0, 0.0),
            size,
            BLACK.stroke_width(2),
        )))
        .map_err(err)?
        .label("origin (goal)")
        .legend(|(x, y)| Cross::new((x + 9, y), 6, BLACK.stroke_width(2)));
    Ok(())
}

/// A short line in the series' colour, for legends.
fn key(color: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
}

/// Draws the figure's title, shrinking the font until it fits the width.
fn titled<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
) -> anyhow::Result<DrawingArea<DB, Shift>> {
    let (w, _) = root.dim_in_pixel();
    let mut size = 26.0;
    loop {
        let font = (FONT, size).into_font().style(FontStyle::Bold);
        let (tw, _) = root
            .estimate_text_size(title, &font.clone().into())
            .map_err(err)?;
        if tw + 40 <= w || size <= 12.0 {
            return root.titled(title, font).map_err(err);
        }
        size -= 2.0;
    }
}

/// The legend at `position`.
fn legend_at<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    position: SeriesLabelPosition,
) -> anyhow::Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font((FONT, 15))
        .position(position)
        .draw()
        .map_err(err)
}

/// The corner of the chart whose legend-sized box (of `entries` labels up to `chars` long)
/// covers the fewest of `points`; upper right on ties.
fn emptiest_corner<DB: DrawingBackend>(
    chart: &Chart<'_, DB>,
    points: &[(f64, f64)],
    entries: usize,
    chars: usize,
) -> SeriesLabelPosition {
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let xr = chart.x_range();
    let yr = chart.y_range();
    let fw = ((chars as f64 * 8.5 + 50.0) / f64::from(pw.max(1))).min(1.0);
    let fh = ((entries as f64 * 20.0 + 16.0) / f64::from(ph.max(1))).min(1.0);
    let bx = (xr.end - xr.start) * fw;
    let by = (yr.end - yr.start) * fh;
    let mut counts = [0usize; 4];
    for &(px, py) in points {
        let (left, right) = (px <= xr.start + bx, px >= xr.end - bx);
        let (lower, upper) = (py <= yr.start + by, py >= yr.end - by);
        counts[0] += usize::from(upper && right);
        counts[1] += usize::from(upper && left);
        counts[2] += usize::from(lower && right);
        counts[3] += usize::from(lower && left);
    }
    let best = (0..4).min_by_key(|&c| counts[c]).unwrap_or(0);
    [
        SeriesLabelPosition::UpperRight,
        SeriesLabelPosition::UpperLeft,
        SeriesLabelPosition::LowerRight,
        SeriesLabelPosition::LowerLeft,
    ][best]
        .clone()
}

/// A grey note in the middle of an empty chart.
fn note<'a, DB: DrawingBackend + 'a>(chart: &mut Chart<'a, DB>, text: &str) -> anyhow::Result<()> {
    let (x, y) = (chart.x_range(), chart.y_range());
    let grey = BLACK.mix(0.55);
    let style = (FONT, 18)
        .into_font()
        .color(&grey)
        .pos(Pos::new(HPos::Center, VPos::Center));
    chart
        .draw_series(std::iter::once(Text::new(
            text.to_string(),
            ((x.start + x.end) / 2.0, (y.start + y.end) / 2.0),
            style,
        )))
        .map_err(err)?;
    Ok(())
}

/// A zero-order-hold step line: value `k` holds over `[time(k), time(k + 1))`.
fn steps(values: impl Iterator<Item = f64>, dt: f64) -> Vec<(f64, f64)> {
    values
        .enumerate()
        .flat_map(|(k, v)| [(k as f64 * dt, v), ((k + 1) as f64 * dt, v)])
        .collect()
}

/// Points of a circle (closed: the first point repeats at the end).
fn circle(c: (f64, f64), r: f64) -> Vec<(f64, f64)> {
    (0..=48)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 48.0;
            (c.0 + r * a.cos(), c.1 + r * a.sin())
        })
        .collect()
}

/// The corners of a box rotated `angle_deg` counter-clockwise (closed).
fn box_corners(center: [f64; 2], half: [f64; 2], angle_deg: f64) -> Vec<(f64, f64)> {
    let (s, c) = angle_deg.to_radians().sin_cos();
    [
        (-1.0, -1.0),
        (1.0, -1.0),
        (1.0, 1.0),
        (-1.0, 1.0),
        (-1.0, -1.0),
    ]
    .iter()
    .map(|&(sx, sy)| {
        let (dx, dy) = (sx * half[0], sy * half[1]);
        (center[0] + c * dx - s * dy, center[1] + s * dx + c * dy)
    })
    .collect()
}

/// A chart of the arena from above with equal scales on both axes, covering the walls and
/// `points`, filling `area` (which carries no caption: the caller titles it).
fn arena_chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    arena: &Arena,
    points: &[(f64, f64)],
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    const X_LABELS: u32 = 40;
    const Y_LABELS: u32 = 50;
    let fold = |lo: f64, hi: f64, v: f64| (lo.min(v), hi.max(v));
    let (mut x0, mut x1) = (arena.x[0].min(0.0), arena.x[1].max(0.0));
    let (mut y0, mut y1) = (arena.y[0].min(0.0), arena.y[1].max(0.0));
    for &(x, y) in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        (x0, x1) = fold(x0, x1, x);
        (y0, y1) = fold(y0, y1, y);
    }
    let pad = 0.04 * (x1 - x0).max(y1 - y0);
    let (dx, dy) = (x1 - x0 + 2.0 * pad, y1 - y0 + 2.0 * pad);
    // Equal scales: widen the range of the direction with room to spare.
    let (w, h) = area.dim_in_pixel();
    let pw = f64::from(w.saturating_sub(Y_LABELS).max(1));
    let ph = f64::from(h.saturating_sub(X_LABELS).max(1));
    let per_pixel = (dx / pw).max(dy / ph);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let (hx, hy) = (per_pixel * pw / 2.0, per_pixel * ph / 2.0);
    let mut chart = ChartBuilder::on(area)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d((cx - hx)..(cx + hx), (cy - hy)..(cy + hy))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// The walls and the obstacles (filled grey). Returns the number of legend entries added.
fn draw_arena<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    arena: &Arena,
) -> anyhow::Result<usize> {
    let mut entries = 0;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(arena.x[0], arena.y[0]), (arena.x[1], arena.y[1])],
            BLACK.stroke_width(3),
        )))
        .map_err(err)?;
    let outlines: Vec<Vec<(f64, f64)>> = arena
        .obstacles
        .iter()
        .map(|o| match *o {
            Obstacle::Box {
                center,
                half_extents,
                angle_deg,
            } => box_corners(center, half_extents, angle_deg),
            Obstacle::Disc { center, radius } => circle((center[0], center[1]), radius),
        })
        .collect();
    if !outlines.is_empty() {
        chart
            .draw_series(
                outlines
                    .iter()
                    .map(|p| Polygon::new(p.clone(), GREY.filled())),
            )
            .map_err(err)?
            .label("obstacle")
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], GREY.filled()));
        chart
            .draw_series(
                outlines
                    .iter()
                    .map(|p| PathElement::new(p.clone(), BLACK.mix(0.6).stroke_width(1))),
            )
            .map_err(err)?;
        entries += 1;
    }
    Ok(entries)
}

/// The goal, over everything else: a cross at the origin and the reward region's circle.
/// Returns the number of legend entries added.
fn draw_goal<'a, DB: DrawingBackend + 'a>(chart: &mut Chart<'a, DB>) -> anyhow::Result<usize> {
    draw_origin(chart, 7)?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            circle((0.0, 0.0), GOAL_RADIUS),
            BLACK.mix(0.7).stroke_width(1),
        )))
        .map_err(err)?
        .label(format!("reward region (r = {GOAL_RADIUS} m)"))
        .legend(|(x, y)| Circle::new((x + 9, y), 6, BLACK.mix(0.7).stroke_width(1)));
    Ok(2)
}

// ---------------------------------------------------------------------------------------------
// Khepera robots: the paper's figures 7-9.

/// Draws the Khepera run into `path` (PNG or SVG), atomically: per robot, the states and the
/// heading over time (top) and the action taken (middle); the shared reward (bottom); the
/// paths in the arena (right).
pub(crate) fn khepera_figure(
    path: &Path,
    run: &KheperaRun,
    arena: &Arena,
    robot_radius: f64,
    kind: PolicyKind,
    title: &str,
) -> anyhow::Result<()> {
    check_khepera(run, robot_radius)?;
    let size = (560 * run.trajectory.agents as u32 + 820, 980);
    write_figure(
        path,
        size,
        |root| draw_khepera(root, run, arena, robot_radius, kind, title),
        |root| draw_khepera(root, run, arena, robot_radius, kind, title),
    )
}

fn check_khepera(run: &KheperaRun, radius: f64) -> anyhow::Result<()> {
    let t = &run.trajectory;
    let n = t.agents;
    if n == 0 || t.states.is_empty() {
        bail!("cannot plot an empty Khepera run");
    }
    if !(t.dt.is_finite() && t.dt > 0.0) {
        bail!("cannot plot a run with sample time {} s", t.dt);
    }
    if !(radius.is_finite() && radius > 0.0) {
        bail!("the robot radius must be positive, got {radius}");
    }
    if let Some(x) = t.states.iter().find(|x| x.len() != 4 * n) {
        bail!("a state has {} values; {n} robots need {}", x.len(), 4 * n);
    }
    let steps = t.states.len() - 1;
    if run.poses.len() != t.states.len() || run.poses.iter().any(|p| p.len() != n) {
        bail!(
            "the run needs {} poses of {n} robots (one per state), got {}",
            t.states.len(),
            run.poses.len()
        );
    }
    if t.rewards.len() != steps {
        bail!("the run has {} rewards for {steps} steps", t.rewards.len());
    }
    if run.action_indices.len() != steps || run.action_indices.iter().any(|a| a.len() != n) {
        bail!(
            "the run needs {steps} action indices of {n} robots (one per step), got {}",
            run.action_indices.len()
        );
    }
    Ok(())
}

fn draw_khepera<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    run: &KheperaRun,
    arena: &Arena,
    radius: f64,
    kind: PolicyKind,
    title: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    let t = &run.trajectory;
    let n = t.agents;
    let (w, h) = root.dim_in_pixel();
    let (left, right) = root.split_horizontally(w.saturating_sub(820));
    let (top, rest) = left.split_vertically(h * 43 / 100);
    let (middle, bottom) = rest.split_vertically(h * 28 / 100);
    let states = top.split_evenly((1, n));
    let actions = middle.split_evenly((1, n));
    let t_end = t.time(t.states.len() - 1).max(t.dt);
    for i in 0..n {
        draw_robot_states(&states[i], run, i, t_end)?;
        draw_robot_actions(&actions[i], run, i, t_end, kind)?;
    }
    draw_rewards(&bottom, t, t_end)?;
    draw_khepera_arena(&right, run, arena, radius)
}

/// A named, coloured series drawn as one or more line segments.
type Series<'s> = (&'s str, RGBColor, Vec<Vec<(f64, f64)>>);

fn draw_robot_states<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    run: &KheperaRun,
    robot: usize,
    t_end: f64,
) -> anyhow::Result<()> {
    let t = &run.trajectory;
    let mut series: Vec<Series<'_>> = ["s_x (m)", "s_y (m)", "v_x (m/s)", "v_y (m/s)"]
        .iter()
        .enumerate()
        .map(|(j, &name)| {
            let line = t
                .states
                .iter()
                .enumerate()
                .map(|(k, x)| (t.time(k), x[4 * robot + j]))
                .collect();
            (name, COLORS[j], vec![line])
        })
        .collect();
    // The heading wraps at +-pi: break the line there instead of drawing the jump.
    let mut heading: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (k, p) in run.poses.iter().enumerate() {
        let h = p[robot][2];
        let last = heading.last_mut().expect("one segment");
        if last
            .last()
            .is_some_and(|&(_, prev)| (h - prev).abs() > std::f64::consts::PI)
        {
            heading.push(Vec::new());
        }
        heading
            .last_mut()
            .expect("one segment")
            .push((t.time(k), h));
    }
    series.push(("heading (rad)", PURPLE, heading));
    let points: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.2.iter().flatten().copied())
        .collect();
    let y = range(points.iter().map(|p| p.1));
    // Five series crowd a corner legend: a row of keys under the caption instead.
    let area = area
        .margin(12, 12, 12, 12)
        .titled(&format!("Robot {}: states", robot + 1), (FONT, 20))
        .map_err(err)?;
    let keys: Vec<(&str, RGBColor)> = series.iter().map(|s| (s.0, s.1)).collect();
    let area = legend_rows(&area, &keys)?;
    let mut chart = chart_with(
        &area,
        None,
        ("time (s)", "m, m/s, rad"),
        0.0..t_end,
        y,
        KHEPERA_AXES,
    )?;
    for (_, color, lines) in series {
        for line in lines {
            chart
                .draw_series(LineSeries::new(line, color.stroke_width(2)))
                .map_err(err)?;
        }
    }
    Ok(())
}

/// Draws a legend as rows of keys across the top of `area` (as many rows as the width
/// needs) and returns the area below it.
fn legend_rows<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[(&str, RGBColor)],
) -> anyhow::Result<DrawingArea<DB, Shift>> {
    const ROW: i32 = 20;
    const KEY: i32 = 22;
    const GAP: i32 = 16;
    let (w, _) = area.dim_in_pixel();
    let w = i32::try_from(w).unwrap_or(i32::MAX);
    let style = TextStyle::from((FONT, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    let mut widths = Vec::with_capacity(entries.len());
    for (text, _) in entries {
        let (tw, _) = area.estimate_text_size(text, &style).map_err(err)?;
        widths.push(KEY + i32::try_from(tw).unwrap_or(0) + GAP);
    }
    let mut rows: Vec<Vec<usize>> = vec![Vec::new()];
    let mut used = 0;
    for (i, &width) in widths.iter().enumerate() {
        let row = rows.last_mut().expect("one row");
        if used + width - GAP > w && !row.is_empty() {
            rows.push(Vec::new());
            used = 0;
        }
        rows.last_mut().expect("one row").push(i);
        used += width;
    }
    for (r, row) in rows.iter().enumerate() {
        let total: i32 = row.iter().map(|&i| widths[i]).sum::<i32>() - GAP;
        let mut x = ((w - total) / 2).max(0);
        let y = ROW / 2 + ROW * i32::try_from(r).unwrap_or(0);
        for &i in row {
            let (text, color) = entries[i];
            area.draw(&PathElement::new(
                vec![(x, y), (x + KEY - 4, y)],
                color.stroke_width(2),
            ))
            .map_err(err)?;
            area.draw(&Text::new(text.to_string(), (x + KEY, y), style.clone()))
                .map_err(err)?;
            x += widths[i];
        }
    }
    let height = u32::try_from(ROW * i32::try_from(rows.len()).unwrap_or(1) + 6).unwrap_or(0);
    Ok(area.split_vertically(height).1)
}

fn draw_robot_actions<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    run: &KheperaRun,
    robot: usize,
    t_end: f64,
    kind: PolicyKind,
) -> anyhow::Result<()> {
    let t = &run.trajectory;
    let top = run
        .action_indices
        .iter()
        .map(|a| a[robot])
        .max()
        .unwrap_or(0)
        .max(ACTION_NAMES.len() - 1);
    let caption = match kind {
        PolicyKind::Greedy => format!("Robot {}: action", robot + 1),
        PolicyKind::Interpolated => format!("Robot {}: action (nearest of the four)", robot + 1),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(KHEPERA_AXES.y_area)
        .build_cartesian_2d(0.0..t_end, -0.5..top as f64 + 0.5)
        .map_err(err)?;
    // Labels at the integers only, by name.
    let name = |v: &f64| {
        if (v - v.round()).abs() > 1e-9 || *v < 0.0 {
            return String::new();
        }
        let a = v.round() as usize;
        ACTION_NAMES
            .get(a)
            .map_or_else(|| a.to_string(), |s| (*s).to_string())
    };
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_labels(top + 2)
        .y_max_light_lines(0)
        .y_label_formatter(&name)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(err)?;
    let color = COLORS[robot % COLORS.len()];
    let line = steps(run.action_indices.iter().map(|a| a[robot] as f64), t.dt);
    chart
        .draw_series(LineSeries::new(line, color.stroke_width(2)))
        .map_err(err)?;
    Ok(())
}

fn draw_rewards<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    t: &Trajectory,
    t_end: f64,
) -> anyhow::Result<()> {
    let y = range(t.rewards.iter().copied().chain([0.0]));
    let mut chart = chart_with(
        area,
        Some("Reward (shared by the robots)"),
        ("time (s)", "reward"),
        0.0..t_end,
        y,
        KHEPERA_AXES,
    )?;
    if t.rewards.is_empty() {
        return note(&mut chart, "no steps");
    }
    chart
        .draw_series(LineSeries::new(
            steps(t.rewards.iter().copied(), t.dt),
            GOOD.stroke_width(2),
        ))
        .map_err(err)?;
    Ok(())
}

fn draw_khepera_arena<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    run: &KheperaRun,
    arena: &Arena,
    radius: f64,
) -> anyhow::Result<()> {
    let area = area
        .margin(12, 12, 12, 12)
        .titled("Paths in the arena", (FONT, 20))
        .map_err(err)?;
    let n = run.trajectory.agents;
    let points: Vec<(f64, f64)> = run
        .poses
        .iter()
        .flat_map(|p| p.iter().map(|q| (q[0], q[1])))
        .collect();
    let mut chart = arena_chart(&area, arena, &points)?;
    let mut entries = draw_arena(&mut chart, arena)?;
    let span = {
        let x = chart.x_range();
        x.end - x.start
    };
    let tick = (2.5 * radius).max(0.02 * span);
    for i in 0..n {
        let color = COLORS[i % COLORS.len()];
        let path: Vec<(f64, f64)> = run.poses.iter().map(|p| (p[i][0], p[i][1])).collect();
        chart
            .draw_series(LineSeries::new(path.iter().copied(), color.stroke_width(2)))
            .map_err(err)?
            .label(format!("robot {}", i + 1))
            .legend(key(color));
        let first = run.poses[0][i];
        let last = run.poses[run.poses.len() - 1][i];
        for (pose, filled) in [(first, false), (last, true)] {
            let c = (pose[0], pose[1]);
            let disc = circle(c, radius);
            if filled {
                chart
                    .draw_series(std::iter::once(Polygon::new(disc, color.filled())))
                    .map_err(err)?;
            } else {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        disc,
                        color.stroke_width(2),
                    )))
                    .map_err(err)?;
            }
            let end = (c.0 + tick * pose[2].cos(), c.1 + tick * pose[2].sin());
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![c, end],
                    color.stroke_width(2),
                )))
                .map_err(err)?;
        }
    }
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        .map_err(err)?
        .label("start (hollow)")
        .legend(|(x, y)| Circle::new((x + 9, y), 5, BLACK.stroke_width(2)));
    chart
        .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
        .map_err(err)?
        .label("end (filled)")
        .legend(|(x, y)| Circle::new((x + 9, y), 5, BLACK.filled()));
    entries += n + 2 + draw_goal(&mut chart)?;
    let corner = emptiest_corner(&chart, &points, entries, 22);
    legend_at(&mut chart, corner)
}

// ---------------------------------------------------------------------------------------------
// Success over random starts.

/// Draws every start in the arena (PNG or SVG), atomically: the robots of one start as small
/// markers (robot 1 a circle, robot 2 a triangle, further robots a square) joined by a thin
/// line, green if the run from it succeeded and red if not.
pub(crate) fn success_figure(
    path: &Path,
    starts: &[Vec<[f64; 3]>],
    success: &[bool],
    arena: &Arena,
    title: &str,
) -> anyhow::Result<()> {
    if starts.is_empty() {
        bail!("cannot plot success over no starts");
    }
    if success.len() != starts.len() {
        bail!(
            "{} starts but {} success flags",
            starts.len(),
            success.len()
        );
    }
    if starts.iter().any(Vec::is_empty) {
        bail!("a start has no robots");
    }
    write_figure(
        path,
        (1000, 1040),
        |root| draw_success(root, starts, success, arena, title),
        |root| draw_success(root, starts, success, arena, title),
    )
}

fn draw_success<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    starts: &[Vec<[f64; 3]>],
    success: &[bool],
    arena: &Arena,
    title: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    let area = root.margin(4, 12, 12, 16);
    let points: Vec<(f64, f64)> = starts
        .iter()
        .flat_map(|s| s.iter().map(|p| (p[0], p[1])))
        .collect();
    let mut chart = arena_chart(&area, arena, &points)?;
    let mut entries = draw_arena(&mut chart, arena)?;
    let robots = starts.iter().map(Vec::len).max().unwrap_or(0);
    let total = starts.len();
    let good = success.iter().filter(|&&s| s).count();
    // Successes first, failures on top.
    for want in [true, false] {
        let color = if want { GOOD } else { BAD };
        let chosen: Vec<&Vec<[f64; 3]>> = starts
            .iter()
            .zip(success)
            .filter(|&(_, &ok)| ok == want)
            .map(|(s, _)| s)
            .collect();
        for s in &chosen {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    s.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                    color.mix(0.6).stroke_width(1),
                )))
                .map_err(err)?;
        }
        let at = |i: usize| {
            chosen
                .iter()
                .filter_map(move |s| s.get(i))
                .map(|p| (p[0], p[1]))
        };
        for i in 0..robots {
            let style = color.filled();
            match i {
                0 => chart.draw_series(at(i).map(|p| Circle::new(p, 4, style))),
                1 => chart.draw_series(at(i).map(|p| TriangleMarker::new(p, 6, style))),
                _ => {
                    chart.draw_series(at(i).map(|p| Rectangle::new([p, p], style.stroke_width(7))))
                }
            }
            .map_err(err)?;
        }
        let label = if want {
            format!("success: {good} of {total}")
        } else {
            format!("failure: {} of {total}", total - good)
        };
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], color.filled()));
    }
    for i in 0..robots.min(2) {
        let label = format!("robot {}", i + 1);
        let anno = chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(err)?
            .label(label);
        if i == 0 {
            anno.legend(|(x, y)| Circle::new((x + 9, y), 4, BLACK.filled()));
        } else {
            anno.legend(|(x, y)| TriangleMarker::new((x + 9, y), 6, BLACK.filled()));
        }
    }
    entries += 2 + robots.min(2) + draw_goal(&mut chart)?;
    let corner = emptiest_corner(&chart, &points, entries, 22);
    legend_at(&mut chart, corner)
}

// ---------------------------------------------------------------------------------------------
// The learning curve of fuzzy Q-learning.

/// Draws the learning curve (PNG or SVG), atomically: the return per episode with its moving
/// average and the greedy evaluations; the mean |TD error|; the steps per episode; epsilon and
/// alpha; the evaluation success rate; the windowed parameter change (log scale).
pub(crate) fn learning_curve_figure(
    path: &Path,
    curve: &[EpisodeRecord],
    title: &str,
) -> anyhow::Result<()> {
    if curve.is_empty() {
        bail!("cannot plot an empty learning curve");
    }
    write_figure(
        path,
        (1800, 960),
        |root| draw_learning(root, curve, title),
        |root| draw_learning(root, curve, title),
    )
}

/// Trailing mean over the last [`MA_WINDOW`] points (fewer at the start).
fn moving_average(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut sum = 0.0;
    points
        .iter()
        .enumerate()
        .map(|(k, &(x, y))| {
            sum += y;
            if k >= MA_WINDOW {
                sum -= points[k - MA_WINDOW].1;
            }
            (x, sum / (k + 1).min(MA_WINDOW) as f64)
        })
        .collect()
}

fn draw_learning<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    curve: &[EpisodeRecord],
    title: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    let panels = root.split_evenly((2, 3));
    let (first, last) = (
        curve[0].episode as f64,
        curve[curve.len() - 1].episode as f64,
    );
    let (lo, hi) = (first.min(last), first.max(last));
    let pad = (0.02 * (hi - lo)).max(0.5);
    let x = (lo - pad)..(hi + pad);
    let at = |f: fn(&EpisodeRecord) -> f64| -> Vec<(f64, f64)> {
        curve
            .iter()
            .map(|r| (r.episode as f64, f(r)))
            .filter(|p| p.1.is_finite())
            .collect()
    };
    let evals: Vec<(f64, f64)> = curve
        .iter()
        .filter_map(|r| r.eval_mean_return.map(|v| (r.episode as f64, v)))
        .filter(|p| p.1.is_finite())
        .collect();
    trend(
        &panels[0],
        ("Return per episode", "return"),
        x.clone(),
        &at(|r| r.ret),
        COLORS[0],
        Some(("greedy evaluation (mean)", &evals)),
        false,
    )?;
    trend(
        &panels[1],
        ("Mean |TD error| per episode", "mean |delta|"),
        x.clone(),
        &at(|r| r.mean_abs_td),
        COLORS[1],
        None,
        false,
    )?;
    trend(
        &panels[2],
        ("Steps per episode", "steps"),
        x.clone(),
        &at(|r| r.steps as f64),
        COLORS[2],
        None,
        true,
    )?;
    draw_schedule(&panels[3], x.clone(), &at(|r| r.epsilon), &at(|r| r.alpha))?;
    let rates: Vec<(f64, f64)> = curve
        .iter()
        .filter_map(|r| r.eval_success_rate.map(|v| (r.episode as f64, v)))
        .filter(|p| p.1.is_finite())
        .collect();
    draw_eval_success(&panels[4], x.clone(), &rates)?;
    draw_param_change(&panels[5], x, &at(|r| r.param_change))
}

/// A noisy series (thin) with its moving average (bold) and optional extra points.
/// `labels` are the caption and the y axis' description; `counts` labels y at integers.
fn trend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (caption, y_desc): (&str, &str),
    x: std::ops::Range<f64>,
    values: &[(f64, f64)],
    color: RGBColor,
    extra: Option<(&str, &[(f64, f64)])>,
    counts: bool,
) -> anyhow::Result<()> {
    let extra = extra.filter(|e| !e.1.is_empty());
    let all = values.iter().chain(extra.iter().flat_map(|e| e.1.iter()));
    let y = range(all.map(|p| p.1));
    let axes = Axes {
        y_integer: counts,
        ..EPISODE_AXES
    };
    let mut chart = chart_with(area, Some(caption), ("episode", y_desc), x, y, axes)?;
    if values.is_empty() {
        return note(&mut chart, "no finite values");
    }
    chart
        .draw_series(LineSeries::new(
            values.iter().copied(),
            color.mix(0.35).stroke_width(1),
        ))
        .map_err(err)?
        .label("per episode")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.mix(0.35)));
    let ma = moving_average(values);
    chart
        .draw_series(LineSeries::new(ma.iter().copied(), color.stroke_width(2)))
        .map_err(err)?
        .label(format!("moving average ({MA_WINDOW})"))
        .legend(key(color));
    let mut points: Vec<(f64, f64)> = values.to_vec();
    let mut entries = 2;
    if let Some((name, pts)) = extra {
        let c = BLACK;
        chart
            .draw_series(LineSeries::new(
                pts.iter().copied(),
                c.mix(0.6).stroke_width(1),
            ))
            .map_err(err)?;
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| Circle::new((x + 9, y), 3, c.filled()));
        points.extend_from_slice(pts);
        entries += 1;
    }
    let corner = emptiest_corner(&chart, &points, entries, 20);
    legend_at(&mut chart, corner)
}

fn draw_schedule<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x: std::ops::Range<f64>,
    epsilon: &[(f64, f64)],
    alpha: &[(f64, f64)],
) -> anyhow::Result<()> {
    let y = range(epsilon.iter().chain(alpha).map(|p| p.1).chain([0.0]));
    let mut chart = chart_with(
        area,
        Some("Exploration and step size"),
        ("episode", "value"),
        x,
        y,
        EPISODE_AXES,
    )?;
    for (name, color, pts) in [
        ("epsilon (exploration)", COLORS[3], epsilon),
        ("alpha (step size)", PURPLE, alpha),
    ] {
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
            .map_err(err)?
            .label(name)
            .legend(key(color));
    }
    let points: Vec<(f64, f64)> = epsilon.iter().chain(alpha).copied().collect();
    let corner = emptiest_corner(&chart, &points, 2, 21);
    legend_at(&mut chart, corner)
}

fn draw_eval_success<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x: std::ops::Range<f64>,
    rates: &[(f64, f64)],
) -> anyhow::Result<()> {
    let mut chart = chart_with(
        area,
        Some("Greedy evaluation: success rate"),
        ("episode", "success rate"),
        x,
        -0.05..1.05,
        EPISODE_AXES,
    )?;
    if rates.is_empty() {
        return note(&mut chart, "no evaluation ran");
    }
    chart
        .draw_series(LineSeries::new(rates.iter().copied(), GOOD.stroke_width(2)))
        .map_err(err)?;
    chart
        .draw_series(rates.iter().map(|&p| Circle::new(p, 4, GOOD.filled())))
        .map_err(err)?;
    Ok(())
}

fn draw_param_change<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x: std::ops::Range<f64>,
    changes: &[(f64, f64)],
) -> anyhow::Result<()> {
    const CAPTION: &str = "Parameter change over the window";
    const LOG_CAPTION: &str = "Parameter change over the window (log scale)";
    const Y_DESC: &str = "max |phi - phi_window ago|";
    let positive: Vec<(f64, f64)> = changes.iter().copied().filter(|p| p.1 > 0.0).collect();
    if positive.is_empty() {
        // Nothing to put on a log scale: zeros (or nothing yet) on a linear one.
        let y = range(changes.iter().map(|p| p.1).chain([0.0]));
        let mut chart = chart_with(area, Some(CAPTION), ("episode", Y_DESC), x, y, EPISODE_AXES)?;
        if changes.is_empty() {
            return note(&mut chart, "no full window yet");
        }
        chart
            .draw_series(LineSeries::new(
                changes.iter().copied(),
                COLORS[0].stroke_width(2),
            ))
            .map_err(err)?;
        return Ok(());
    }
    let (lo, hi) = positive.iter().fold((f64::INFINITY, 0.0_f64), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    // Zeros (converged parameters) sit on a floor below the smallest positive change.
    let floor = lo / 3.0;
    let zeros = changes.len() > positive.len();
    let y = if zeros { floor / 2.0 } else { lo / 2.0 }..hi * 2.0;
    let mut chart = ChartBuilder::on(area)
        .caption(LOG_CAPTION, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(EPISODE_AXES.y_area)
        .build_cartesian_2d(x, y.log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("episode")
        .y_desc(Y_DESC)
        .x_label_formatter(&integer_label)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(
            changes
                .iter()
                .map(|&(e, v)| (e, if v > 0.0 { v } else { floor })),
            COLORS[0].stroke_width(2),
        ))
        .map_err(err)?
        .label("per episode")
        .legend(key(COLORS[0]));
    if zeros {
        chart
            .draw_series(
                changes
                    .iter()
                    .filter(|p| p.1 <= 0.0)
                    .map(|&(e, _)| Circle::new((e, floor), 3, COLORS[0].stroke_width(1))),
            )
            .map_err(err)?
            .label("zero (drawn at the floor)")
            .legend(|(x, y)| Circle::new((x + 9, y), 3, COLORS[0].stroke_width(1)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font((FONT, 15))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The comparison of learners (`fuzzyq compare`).

/// One colour per learner of the comparison.
const LEARNER_COLORS: [RGBColor; 6] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
];

/// The paths of every learner from the comparison's start, one panel per agent.
pub(crate) fn compare_figure(path: &Path, c: &Comparison) -> anyhow::Result<()> {
    let agents = c.trajectories.first().map_or(0, |t| t.agents);
    if agents == 0 || c.trajectories.iter().any(|t| t.states.is_empty()) {
        bail!("cannot plot an empty comparison");
    }
    let size = (620 * agents as u32, 700);
    write_figure(
        path,
        size,
        |root| draw_compare(root, c, agents),
        |root| draw_compare(root, c, agents),
    )
}

fn draw_compare<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: &Comparison,
    agents: usize,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let title = format!(
        "Paths of every learner from x0 = {:?} ({} steps of {} s)",
        c.x0, c.steps, c.dt
    );
    let root = titled(root, &title)?;
    // One square range for all panels: every path and the goal.
    let all = || {
        c.trajectories
            .iter()
            .flat_map(|t| t.states.iter())
            .flat_map(move |x| (0..agents).map(move |i| (x[4 * i], x[4 * i + 1])))
            .chain([(0.0, 0.0)])
    };
    let (xs, ys) = (range(all().map(|p| p.0)), range(all().map(|p| p.1)));
    let half = ((xs.end - xs.start).max(ys.end - ys.start)) / 2.0;
    let (cx, cy) = ((xs.start + xs.end) / 2.0, (ys.start + ys.end) / 2.0);
    for (i, area) in root.split_evenly((1, agents)).iter().enumerate() {
        let mut chart = chart(
            area,
            &format!("Agent {}", i + 1),
            ("s_x (m)", "s_y (m)"),
            (cx - half)..(cx + half),
            (cy - half)..(cy + half),
        )?;
        draw_origin(&mut chart, 8)?;
        for (k, (r, t)) in c.reports.iter().zip(&c.trajectories).enumerate() {
            let color = LEARNER_COLORS[k % LEARNER_COLORS.len()];
            let path: Vec<(f64, f64)> = t.states.iter().map(|x| (x[4 * i], x[4 * i + 1])).collect();
            chart
                .draw_series(LineSeries::new(path.iter().copied(), color.stroke_width(2)))
                .map_err(err)?
                .label(r.learner.name())
                .legend(key(color));
            chart
                .draw_series(std::iter::once(Circle::new(
                    *path.last().expect("a non-empty path"),
                    4,
                    color.filled(),
                )))
                .map_err(err)?;
        }
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (c.x0[4 * i], c.x0[4 * i + 1]),
                9,
                BLACK.filled(),
            )))
            .map_err(err)?;
        legend_at(&mut chart, SeriesLabelPosition::LowerRight)?;
    }
    Ok(())
}

/// The time series of a classic benchmark's run: one panel per state variable, the action
/// (held over each sample time) and the reward.
pub(crate) fn series_figure(
    path: &Path,
    t: &Trajectory,
    title: &str,
    state_names: &[&str],
    action_names: &[&str],
) -> anyhow::Result<()> {
    if t.states.is_empty() || t.actions.is_empty() {
        bail!("cannot plot an empty run");
    }
    let panels = state_names.len() + action_names.len() + 1;
    let cols = 2;
    let rows = panels.div_ceil(cols);
    let size = (1200, 360 * rows as u32 + 50);
    write_figure(
        path,
        size,
        |root| draw_series_figure(root, t, title, state_names, action_names, (rows, cols)),
        |root| draw_series_figure(root, t, title, state_names, action_names, (rows, cols)),
    )
}

fn draw_series_figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    t: &Trajectory,
    title: &str,
    state_names: &[&str],
    action_names: &[&str],
    layout: (usize, usize),
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    let areas = root.split_evenly(layout);
    let t_end = t.time(t.states.len() - 1).max(t.dt);
    let mut panel = 0;
    for (j, name) in state_names.iter().enumerate() {
        let values: Vec<(f64, f64)> = t
            .states
            .iter()
            .enumerate()
            .map(|(k, x)| (t.time(k), x[j]))
            .collect();
        line_panel(&areas[panel], name, values, COLORS[j % COLORS.len()], t_end)?;
        panel += 1;
    }
    for (j, name) in action_names.iter().enumerate() {
        let values = steps(t.actions.iter().map(|u| u[j]), t.dt);
        line_panel(
            &areas[panel],
            name,
            values,
            COLORS[(j + 2) % COLORS.len()],
            t_end,
        )?;
        panel += 1;
    }
    let rewards = steps(t.rewards.iter().copied(), t.dt);
    line_panel(&areas[panel], "reward", rewards, PURPLE, t_end)
}

/// One time series in its own panel.
fn line_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    name: &str,
    values: Vec<(f64, f64)>,
    color: RGBColor,
    t_end: f64,
) -> anyhow::Result<()> {
    let y = range(values.iter().map(|p| p.1));
    let mut chart = time_chart(area, name, name, 0.0..t_end, y)?;
    chart
        .draw_series(LineSeries::new(values, color.stroke_width(2)))
        .map_err(err)?;
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Heat maps over a 2-D state space (value function and policy of the classic benchmarks).

/// One heat map: `values[j * xs.len() + i]` is the value at `(xs[i], ys[j])`, sampled on a
/// regular lattice.
pub(crate) struct HeatMap {
    /// Panel caption.
    pub caption: String,
    /// Sample abscissae, increasing and evenly spaced.
    pub xs: Vec<f64>,
    /// Sample ordinates, increasing and evenly spaced.
    pub ys: Vec<f64>,
    /// Row-major samples (`ys` rows of `xs` values).
    pub values: Vec<f64>,
}

/// Draws heat maps side by side, each with its own colour bar, into `path` (PNG or SVG).
pub(crate) fn heat_maps_figure(
    path: &Path,
    title: &str,
    axes: (&str, &str),
    maps: &[HeatMap],
) -> anyhow::Result<()> {
    for m in maps {
        if m.xs.len() < 2 || m.ys.len() < 2 || m.values.len() != m.xs.len() * m.ys.len() {
            bail!(
                "cannot draw a heat map of {} x {} samples",
                m.xs.len(),
                m.ys.len()
            );
        }
    }
    let size = (600 * maps.len().max(1) as u32 + 40, 560);
    write_figure(
        path,
        size,
        |root| draw_heat_maps(root, title, axes, maps),
        |root| draw_heat_maps(root, title, axes, maps),
    )
}

fn draw_heat_maps<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    axes: (&str, &str),
    maps: &[HeatMap],
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    for (area, m) in root.split_evenly((1, maps.len())).iter().zip(maps) {
        let (w, _) = area.dim_in_pixel();
        let (plot, bar) = area.split_horizontally(w.saturating_sub(120));
        let (dx, dy) = ((m.xs[1] - m.xs[0]) / 2.0, (m.ys[1] - m.ys[0]) / 2.0);
        let (x0, x1) = (m.xs[0] - dx, m.xs[m.xs.len() - 1] + dx);
        let (y0, y1) = (m.ys[0] - dy, m.ys[m.ys.len() - 1] + dy);
        let mut chart = chart(&plot, &m.caption, axes, x0..x1, y0..y1)?;
        let finite = m.values.iter().copied().filter(|v| v.is_finite());
        let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() && hi > lo {
            (lo, hi)
        } else {
            (lo.min(0.0) - 0.5, lo.max(0.0) + 0.5)
        };
        let nx = m.xs.len();
        chart
            .draw_series(m.values.iter().enumerate().map(|(k, &v)| {
                let (x, y) = (m.xs[k % nx], m.ys[k / nx]);
                let c = ViridisRGB::get_color_normalized(v, lo, hi);
                Rectangle::new([(x - dx, y - dy), (x + dx, y + dy)], c.filled())
            }))
            .map_err(err)?;
        // The colour bar: 100 bands from lo (bottom) to hi (top), labelled on its right.
        let mut bar_chart = ChartBuilder::on(&bar.margin(40, 40, 10, 5))
            .build_cartesian_2d(0.0..3.0, lo..hi)
            .map_err(err)?;
        let step = (hi - lo) / 100.0;
        bar_chart
            .draw_series((0..100).map(|b| {
                let v = lo + step * f64::from(b);
                let c = ViridisRGB::get_color_normalized(v + step / 2.0, lo, hi);
                Rectangle::new([(0.0, v), (1.0, v + step)], c.filled())
            }))
            .map_err(err)?;
        let style = TextStyle::from((FONT, 13).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
        bar_chart
            .draw_series((0..=4).map(|k| {
                let v = lo + (hi - lo) * f64::from(k) / 4.0;
                let text = if hi - lo >= 10.0 {
                    format!("{v:.0}")
                } else {
                    format!("{v:.2}")
                };
                Text::new(text, (1.2, v), style.clone())
            }))
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two robots spiralling in towards the origin; robot 2's heading crosses +-pi.
    fn khepera_run(steps: usize) -> KheperaRun {
        let dt = 0.25;
        let starts = [(-4.0_f64, 5.0_f64), (5.0, 3.0)];
        let poses: Vec<Vec<[f64; 3]>> = (0..=steps)
            .map(|k| {
                let s = k as f64 / steps.max(1) as f64;
                starts
                    .iter()
                    .enumerate()
                    .map(|(i, &(x0, y0))| {
                        let r = (x0.hypot(y0)) * (1.0 - 0.97 * s);
                        let a = y0.atan2(x0) + (1.0 + i as f64) * 2.5 * s;
                        let (x, y) = (r * a.cos(), r * a.sin());
                        let heading = fuzzyq_sim::model::khepera::wrap_angle(a + 2.0 + 3.0 * s);
                        [x, y, heading]
                    })
                    .collect()
            })
            .collect();
        let states: Vec<Vec<f64>> = (0..=steps)
            .map(|k| {
                (0..2)
                    .flat_map(|i| {
                        let p = poses[k][i];
                        let q = if k == 0 { p } else { poses[k - 1][i] };
                        [p[0], p[1], (p[0] - q[0]) / dt, (p[1] - q[1]) / dt]
                    })
                    .collect()
            })
            .collect();
        let action_indices: Vec<Vec<usize>> = (0..steps)
            .map(|k| vec![(k / 5) % 4, (k / 3 + 1) % 4])
            .collect();
        let actions = action_indices
            .iter()
            .map(|a| a.iter().flat_map(|&i| [0.1 * i as f64, -0.1]).collect())
            .collect();
        let rewards = (0..steps)
            .map(|k| if k + 5 >= steps { 1.0 } else { 0.0 })
            .collect();
        KheperaRun {
            trajectory: Trajectory {
                dt,
                agents: 2,
                states,
                actions,
                rewards,
            },
            poses,
            action_indices,
            sonar: vec![vec![vec![1.0; 8]; 2]; steps + 1],
        }
    }

    fn arena() -> Arena {
        Arena {
            x: [-6.0, 6.0],
            y: [-6.0, 6.0],
            obstacles: vec![
                Obstacle::Box {
                    center: [-2.0, 2.5],
                    half_extents: [0.6, 0.05],
                    angle_deg: 38.66,
                },
                Obstacle::Disc {
                    center: [2.0, -2.0],
                    radius: 0.3,
                },
            ],
        }
    }

    fn curve(episodes: usize) -> Vec<EpisodeRecord> {
        (0..episodes)
            .map(|e| {
                let s = e as f64 / episodes as f64;
                let noise = ((e * 7919) % 13) as f64 / 13.0 - 0.5;
                EpisodeRecord {
                    episode: e,
                    steps: 200 - (150.0 * s) as usize,
                    ret: -20.0 + 25.0 * s + 6.0 * noise,
                    discounted_return: -10.0 + 12.0 * s,
                    mean_abs_td: if e % 17 == 3 {
                        f64::NAN
                    } else {
                        1.0 - 0.8 * s + 0.1 * noise
                    },
                    max_abs_td: 2.0,
                    epsilon: 0.3 * (1.0 - s) + 0.05,
                    alpha: 0.5 / (1.0 + 0.01 * e as f64),
                    param_change: match e {
                        e if e < 10 => f64::NAN,
                        e if e + 10 >= episodes => 0.0,
                        e => 2.0 * (-(e as f64) / 40.0).exp(),
                    },
                    terminal: e % 3 == 0,
                    eval_mean_return: (e % 25 == 24).then_some(-15.0 + 25.0 * s),
                    eval_success_rate: (e % 25 == 24).then_some(s.min(1.0)),
                }
            })
            .collect()
    }

    fn starts(count: usize) -> (Vec<Vec<[f64; 3]>>, Vec<bool>) {
        let starts: Vec<Vec<[f64; 3]>> = (0..count)
            .map(|k| {
                let a = k as f64 * 2.399;
                let r = 1.0 + (k % 5) as f64;
                vec![
                    [r * a.cos(), r * a.sin(), 0.0],
                    [r * a.cos() + 0.8, r * a.sin() - 0.5, 1.0],
                ]
            })
            .collect();
        let ok = (0..count).map(|k| k % 3 != 0).collect();
        (starts, ok)
    }

    /// Renders with `draw` to PNG and SVG in a fresh directory and checks the files.
    fn renders(draw: impl Fn(&Path) -> anyhow::Result<()>) {
        let dir = tempfile::tempdir().unwrap();
        for ext in ["png", "svg"] {
            let path = dir.path().join(format!("fig.{ext}"));
            draw(&path).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert!(bytes.len() > 10_000, "{ext}: only {} bytes", bytes.len());
            if ext == "png" {
                assert_eq!(&bytes[1..4], b"PNG");
            } else {
                assert!(String::from_utf8_lossy(&bytes).contains("<svg"));
            }
        }
        // Nothing but the figures: the temporary files were renamed away.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    #[test]
    fn khepera_figure_renders() {
        let run = khepera_run(80);
        renders(|p| khepera_figure(p, &run, &arena(), 0.07, PolicyKind::Greedy, "test run"));
        // One robot, no obstacles, no steps.
        let mut one = khepera_run(0);
        one.trajectory.agents = 1;
        for x in &mut one.trajectory.states {
            x.truncate(4);
        }
        for p in &mut one.poses {
            p.truncate(1);
        }
        renders(|p| {
            khepera_figure(
                p,
                &one,
                &Arena::default(),
                0.07,
                PolicyKind::Interpolated,
                "one robot",
            )
        });
    }

    #[test]
    fn khepera_figure_refuses_bad_runs() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.png");
        let mut empty = khepera_run(10);
        empty.trajectory.states.clear();
        empty.poses.clear();
        let k = PolicyKind::Greedy;
        assert!(khepera_figure(&path, &empty, &arena(), 0.07, k, "").is_err());
        let mut short = khepera_run(10);
        short.action_indices.pop();
        assert!(khepera_figure(&path, &short, &arena(), 0.07, k, "").is_err());
        let run = khepera_run(10);
        assert!(khepera_figure(&path, &run, &arena(), 0.0, k, "").is_err());
        let pdf = dir.path().join("fig.pdf");
        assert!(khepera_figure(&pdf, &run, &arena(), 0.07, k, "").is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn learning_curve_figure_renders() {
        let c = curve(300);
        renders(|p| learning_curve_figure(p, &c, "learning curve"));
        // No evaluations, no full window, a single episode.
        let mut bare = curve(1);
        bare[0].eval_mean_return = None;
        bare[0].eval_success_rate = None;
        bare[0].param_change = f64::NAN;
        bare[0].mean_abs_td = f64::NAN;
        renders(|p| learning_curve_figure(p, &bare, "one episode"));
        let dir = tempfile::tempdir().unwrap();
        assert!(learning_curve_figure(&dir.path().join("fig.svg"), &[], "").is_err());
    }

    #[test]
    fn success_figure_renders() {
        let (s, ok) = starts(60);
        renders(|p| success_figure(p, &s, &ok, &arena(), "40 of 60 random starts succeed"));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.png");
        assert!(success_figure(&path, &[], &[], &arena(), "").is_err());
        assert!(success_figure(&path, &s, &ok[1..], &arena(), "").is_err());
        assert!(success_figure(&path, &[vec![]], &[true], &arena(), "").is_err());
    }

    #[test]
    fn moving_average_is_trailing() {
        let pts: Vec<(f64, f64)> = (0..30).map(|k| (k as f64, 1.0)).collect();
        assert!(
            moving_average(&pts)
                .iter()
                .all(|p| (p.1 - 1.0).abs() < 1e-12)
        );
        let ramp: Vec<(f64, f64)> = (0..30).map(|k| (k as f64, k as f64)).collect();
        let ma = moving_average(&ramp);
        assert_eq!(ma[1].1, 0.5);
        // Mean of 10..=29.
        assert!((ma[29].1 - 19.5).abs() < 1e-12);
    }

    #[test]
    #[ignore = "writes /tmp/fig-*.png for a look"]
    fn write_examples() {
        let run = khepera_run(80);
        khepera_figure(
            Path::new("/tmp/fig-khepera.png"),
            &run,
            &arena(),
            0.07,
            PolicyKind::Greedy,
            "Khepera IV robots, greedy policy on the rapier plant: both arrive, no collision",
        )
        .unwrap();
        learning_curve_figure(
            Path::new("/tmp/fig-learning.png"),
            &curve(300),
            "Fuzzy Q-learning on the Khepera model",
        )
        .unwrap();
        let (s, ok) = starts(60);
        success_figure(
            Path::new("/tmp/fig-success.png"),
            &s,
            &ok,
            &arena(),
            "greedy policy: 40 of 60 random starts succeed (seed 1)",
        )
        .unwrap();
    }
}
