//! Heat maps over a 2-D state space: the value function and the policy of the classic
//! benchmarks.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{FONT, chart, err, titled, write_figure};

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
