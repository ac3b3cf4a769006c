//! The time series of a classic benchmark's run.

use std::path::Path;

use anyhow::bail;
use fuzzyq_sim::run::metrics::Trajectory;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{COLORS, PURPLE, err, range, steps, time_chart, titled, write_figure};

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
