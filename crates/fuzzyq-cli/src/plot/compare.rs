//! The paths of every learner of `fuzzyq compare` from one start.

use std::path::Path;

use anyhow::bail;
use fuzzyq_core::NamedOption;
use fuzzyq_sim::compare::{Comparison, Learner};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::{chart, draw_origin, err, key, legend_at, range, titled, write_figure};

/// One colour per learner of the comparison (as many as there are learners).
pub(super) const LEARNER_COLORS: [RGBColor; 9] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0x17, 0xbe, 0xcf),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x7f, 0x7f, 0x7f),
];

/// How learner `k`'s path is stroked: solid, dashed or dotted, in turn, so that paths that
/// coincide stay distinguishable where they part.
#[derive(Clone, Copy)]
enum Stroke {
    Solid,
    Dashed,
    Dotted,
}

impl Stroke {
    fn of(k: usize) -> Self {
        [Self::Solid, Self::Dashed, Self::Dotted][k % 3]
    }
}

/// Draws `path` with `stroke` in `style` on `chart`; returns the series for its legend entry.
fn draw_path<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    path: &[(f64, f64)],
    stroke: Stroke,
    style: ShapeStyle,
) -> anyhow::Result<()> {
    let points = path.iter().copied();
    let series = match stroke {
        Stroke::Solid => chart.draw_series(LineSeries::new(points, style)),
        Stroke::Dashed => chart.draw_series(DashedLineSeries::new(points, 10, 6, style)),
        Stroke::Dotted => chart.draw_series(DashedLineSeries::new(points, 3, 4, style)),
    };
    series.map(|_| ()).map_err(err)
}

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
            // A learner's colour and line style are its own, whichever learners run.
            let own = Learner::ALL
                .iter()
                .position(|&l| l == r.learner)
                .unwrap_or(k);
            let color = LEARNER_COLORS[own % LEARNER_COLORS.len()];
            let xy = |t: &fuzzyq_sim::run::metrics::Trajectory| -> Vec<(f64, f64)> {
                t.states.iter().map(|x| (x[4 * i], x[4 * i + 1])).collect()
            };
            // The spread over seeds: the further seeds' paths, thin and light.
            for other in c.seed_trajectories.get(k).into_iter().flatten() {
                let path = xy(other);
                draw_path(
                    &mut chart,
                    &path,
                    Stroke::of(own),
                    color.mix(0.35).stroke_width(1),
                )?;
                chart
                    .draw_series(std::iter::once(Circle::new(
                        *path.last().expect("a non-empty path"),
                        3,
                        color.mix(0.35).filled(),
                    )))
                    .map_err(err)?;
            }
            let path = xy(t);
            // Earlier learners drawn wider, so that a path another one covers shows as its
            // border (the learned model's path is fuzzy Q-iteration's here).
            let width = 2 + (c.reports.len() - 1 - k) as u32 / 2;
            draw_path(
                &mut chart,
                &path,
                Stroke::of(own),
                color.stroke_width(width),
            )?;
            let seeds = c.seed_trajectories.get(k).map_or(0, Vec::len);
            let label = if seeds > 0 {
                format!("{} ({} seeds)", r.learner.name(), seeds + 1)
            } else {
                r.learner.name().to_string()
            };
            chart
                .draw_series(std::iter::once(Circle::new(
                    *path.last().expect("a non-empty path"),
                    4,
                    color.filled(),
                )))
                .map_err(err)?
                .label(label)
                .legend(key(color));
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
