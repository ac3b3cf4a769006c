//! The sample-efficiency curve of `fuzzyq compare --curve`: success over the random starts
//! against the transitions each learner from samples learned from.

use std::path::Path;

use anyhow::bail;
use fuzzyq_core::NamedOption;
use fuzzyq_sim::compare::{EfficiencyPoint, Learner};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::compare::LEARNER_COLORS;
use super::{Axes, chart_with, err, key, legend_at, titled, write_figure};

/// Draws the curve (PNG or SVG), atomically: one line per learner, transitions on a log scale,
/// and `reference` (a name and a success rate, such as fuzzy Q-iteration on the true model) as
/// a dashed line. Lines that coincide stay visible: each is drawn thinner than the one before.
pub(crate) fn efficiency_figure(
    path: &Path,
    points: &[EfficiencyPoint],
    reference: Option<(&str, f64)>,
    title: &str,
) -> anyhow::Result<()> {
    if points.is_empty() {
        bail!("cannot plot an empty sample-efficiency curve");
    }
    write_figure(
        path,
        (1000, 640),
        |root| draw(root, points, reference, title),
        |root| draw(root, points, reference, title),
    )
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[EfficiencyPoint],
    reference: Option<(&str, f64)>,
    title: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(err)?;
    let root = titled(root, title)?;
    let xs = points.iter().map(|p| (p.transitions as f64).log10());
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    let x = (lo.floor() - 0.2)..(hi.ceil() + 0.2);
    let axes = Axes {
        x_integer: true,
        ..Axes::default()
    };
    let mut chart = chart_with(
        &root,
        None,
        ("transitions (log10)", "success over the random starts"),
        x,
        -0.05..1.05,
        axes,
    )?;
    if let Some((name, rate)) = reference {
        let grey = BLACK.mix(0.6);
        let ends = [(lo.floor() - 0.2, rate), (hi.ceil() + 0.2, rate)];
        chart
            .draw_series(DashedLineSeries::new(ends, 8, 6, grey.stroke_width(2)))
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], grey));
    }
    let mut width = 7;
    for (i, &learner) in Learner::ALL.iter().enumerate() {
        let line: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.learner == learner)
            .map(|p| ((p.transitions as f64).log10(), p.success_rate))
            .collect();
        if line.is_empty() {
            continue;
        }
        let color = LEARNER_COLORS[i % LEARNER_COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                line.iter().copied(),
                color.stroke_width(width),
            ))
            .map_err(err)?
            .label(learner.name())
            .legend(key(color));
        chart
            .draw_series(
                line.iter()
                    .map(|&p| Circle::new(p, width + 1, color.filled())),
            )
            .map_err(err)?;
        width = (width - 2).max(2);
    }
    legend_at(&mut chart, SeriesLabelPosition::MiddleRight)
}
