//! The point-mass rollout figure, the paper's figures 2-4: per agent, the states and the forces
//! over time; the paths in the plane.

use std::path::Path;

use anyhow::anyhow;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::run::metrics::Trajectory;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{
    COLORS, FONT, chart, draw_origin, err, legend, range, time_chart, titled, write_figure,
};

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
