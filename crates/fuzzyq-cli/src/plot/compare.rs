//! The paths of every learner of `fuzzyq compare` from one start.

use std::path::Path;

use anyhow::bail;
use fuzzyq_sim::compare::Comparison;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{chart, draw_origin, err, key, legend_at, range, titled, write_figure};

/// One colour per learner of the comparison.
pub(super) const LEARNER_COLORS: [RGBColor; 6] = [
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
