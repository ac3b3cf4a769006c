//! The Khepera run figure, the paper's figures 7-9: per robot, the states and the heading, the
//! action taken; the shared reward; the paths in the arena.

use std::path::Path;

use anyhow::bail;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::model::arena::Arena;
use fuzzyq_sim::model::khepera::ACTION_NAMES;
use fuzzyq_sim::run::metrics::KheperaRun;
use fuzzyq_sim::run::metrics::Trajectory;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::arena::{arena_chart, draw_arena, draw_goal};
use super::{
    Axes, COLORS, FONT, GOOD, PURPLE, chart_with, circle, emptiest_corner, err, key, legend_at,
    note, range, steps, titled, write_figure,
};

/// The time axes of the Khepera figure line up: room for the action names on the left.
const KHEPERA_AXES: Axes = Axes {
    y_area: 80,
    x_integer: false,
    y_integer: false,
};

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
