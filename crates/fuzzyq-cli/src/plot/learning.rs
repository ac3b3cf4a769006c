//! The learning curve of fuzzy Q-learning: returns, TD errors, steps, the schedules, the
//! greedy evaluations and the parameter change, per episode.

use std::path::Path;

use anyhow::bail;
use fuzzyq_sim::learn::fql::EpisodeRecord;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{
    Axes, COLORS, FONT, GOOD, PURPLE, chart_with, emptiest_corner, err, integer_label, key,
    legend_at, note, range, titled, write_figure,
};

/// The axes of the learning curve: episodes on x.
const EPISODE_AXES: Axes = Axes {
    y_area: 60,
    x_integer: true,
    y_integer: false,
};
/// Episodes in the moving averages of the learning curve.
const MA_WINDOW: usize = 20;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
