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
//! - [`efficiency_figure`]: success against transitions for the learners from samples.
//! - [`series_figure`]: the time series of a classic benchmark's run.
//! - [`heat_maps_figure`]: heat maps over a 2-D state space (value function and policy).
//!
//! PNG text is rendered with the embedded DejaVu Sans, so no system fonts are needed.
//!
//! Each figure kind lives in its own file; this module holds what they share: the font, the
//! atomic writing, the colours, the chart, legend and note helpers. `arena.rs` draws the
//! arena from above for the Khepera and the starts figures.

use std::path::Path;
use std::sync::Once;

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

mod arena;
mod compare;
mod efficiency;
mod khepera;
mod learning;
mod maps;
mod rollout;
mod series;
mod starts;
#[cfg(test)]
mod tests;

pub(crate) use compare::compare_figure;
pub(crate) use efficiency::efficiency_figure;
pub(crate) use khepera::khepera_figure;
pub(crate) use learning::learning_curve_figure;
pub(crate) use maps::{HeatMap, heat_maps_figure};
pub(crate) use rollout::{rollout_figure, rollout_figure_titled};
pub(crate) use series::series_figure;
pub(crate) use starts::success_figure;

const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Refuses extensions other than `.png` and `.svg` before any work is done.
pub(crate) fn check_extension(path: &Path, flag: &str) -> anyhow::Result<()> {
    match extension(path).as_deref() {
        Some("png" | "svg") => Ok(()),
        _ => Err(anyhow!(
            "{flag} {}: the file name must end in .png or .svg",
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

/// Heading (rad) and the fifth series of a panel.
const PURPLE: RGBColor = RGBColor(0x94, 0x67, 0xbd);
/// Success and failure.
const GOOD: RGBColor = RGBColor(0x2c, 0xa0, 0x2c);
const BAD: RGBColor = RGBColor(0xd6, 0x27, 0x28);

/// Renders a figure of `size` pixels for the output `path` (PNG or SVG by extension): the
/// figure is drawn into a staged temporary file that replaces `path` when the command succeeds
/// ([`crate::output::stage`]). The two closures are the same drawing for the two backends.
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
    // The staged temporary keeps the extension: the bitmap encoder picks the format from it.
    crate::output::stage(path, |tmp| {
        if ext == "svg" {
            let root = SVGBackend::new(tmp, size).into_drawing_area();
            svg(&root)?;
            root.present().map_err(err)?;
        } else {
            let root = BitMapBackend::new(tmp, size).into_drawing_area();
            png(&root)?;
            root.present().map_err(err)?;
        }
        Ok(())
    })
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
