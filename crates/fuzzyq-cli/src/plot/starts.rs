//! Success or failure from many random starts, drawn in the arena.

use std::path::Path;

use anyhow::bail;
use fuzzyq_sim::model::arena::Arena;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::arena::{arena_chart, draw_arena, draw_goal};
use super::{BAD, GOOD, emptiest_corner, err, legend_at, titled, write_figure};

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
