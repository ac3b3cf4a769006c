//! The arena from above, shared by the Khepera and the starts figures: a chart with equal
//! scales, the walls and obstacles, and the goal.

use fuzzyq_sim::model::arena::{Arena, Obstacle};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{Chart, FONT, circle, draw_origin, err};

/// Obstacles.
const GREY: RGBColor = RGBColor(0xa0, 0xa0, 0xa0);
/// The paper's reward region `||x|| < 0.2` (eq 42), drawn around the origin for reference.
const GOAL_RADIUS: f64 = 0.2;

/// The corners of a box rotated `angle_deg` counter-clockwise (closed).
fn box_corners(center: [f64; 2], half: [f64; 2], angle_deg: f64) -> Vec<(f64, f64)> {
    let (s, c) = angle_deg.to_radians().sin_cos();
    [
        (-1.0, -1.0),
        (1.0, -1.0),
        (1.0, 1.0),
        (-1.0, 1.0),
        (-1.0, -1.0),
    ]
    .iter()
    .map(|&(sx, sy)| {
        let (dx, dy) = (sx * half[0], sy * half[1]);
        (center[0] + c * dx - s * dy, center[1] + s * dx + c * dy)
    })
    .collect()
}

/// A chart of the arena from above with equal scales on both axes, covering the walls and
/// `points`, filling `area` (which carries no caption: the caller titles it).
pub(super) fn arena_chart<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    arena: &Arena,
    points: &[(f64, f64)],
) -> anyhow::Result<Chart<'b, DB>>
where
    'a: 'b,
{
    const X_LABELS: u32 = 40;
    const Y_LABELS: u32 = 50;
    let fold = |lo: f64, hi: f64, v: f64| (lo.min(v), hi.max(v));
    let (mut x0, mut x1) = (arena.x[0].min(0.0), arena.x[1].max(0.0));
    let (mut y0, mut y1) = (arena.y[0].min(0.0), arena.y[1].max(0.0));
    for &(x, y) in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        (x0, x1) = fold(x0, x1, x);
        (y0, y1) = fold(y0, y1, y);
    }
    let pad = 0.04 * (x1 - x0).max(y1 - y0);
    let (dx, dy) = (x1 - x0 + 2.0 * pad, y1 - y0 + 2.0 * pad);
    // Equal scales: widen the range of the direction with room to spare.
    let (w, h) = area.dim_in_pixel();
    let pw = f64::from(w.saturating_sub(Y_LABELS).max(1));
    let ph = f64::from(h.saturating_sub(X_LABELS).max(1));
    let per_pixel = (dx / pw).max(dy / ph);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let (hx, hy) = (per_pixel * pw / 2.0, per_pixel * ph / 2.0);
    let mut chart = ChartBuilder::on(area)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d((cx - hx)..(cx + hx), (cy - hy)..(cy + hy))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(BLACK.mix(0.05))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

/// The walls and the obstacles (filled grey). Returns the number of legend entries added.
pub(super) fn draw_arena<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    arena: &Arena,
) -> anyhow::Result<usize> {
    let mut entries = 0;
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(arena.x[0], arena.y[0]), (arena.x[1], arena.y[1])],
            BLACK.stroke_width(3),
        )))
        .map_err(err)?;
    let outlines: Vec<Vec<(f64, f64)>> = arena
        .obstacles
        .iter()
        .map(|o| match *o {
            Obstacle::Box {
                center,
                half_extents,
                angle_deg,
            } => box_corners(center, half_extents, angle_deg),
            Obstacle::Disc { center, radius } => circle((center[0], center[1]), radius),
        })
        .collect();
    if !outlines.is_empty() {
        chart
            .draw_series(
                outlines
                    .iter()
                    .map(|p| Polygon::new(p.clone(), GREY.filled())),
            )
            .map_err(err)?
            .label("obstacle")
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], GREY.filled()));
        chart
            .draw_series(
                outlines
                    .iter()
                    .map(|p| PathElement::new(p.clone(), BLACK.mix(0.6).stroke_width(1))),
            )
            .map_err(err)?;
        entries += 1;
    }
    Ok(entries)
}

/// The goal, over everything else: a cross at the origin and the reward region's circle.
/// Returns the number of legend entries added.
pub(super) fn draw_goal<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
) -> anyhow::Result<usize> {
    draw_origin(chart, 7)?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            circle((0.0, 0.0), GOAL_RADIUS),
            BLACK.mix(0.7).stroke_width(1),
        )))
        .map_err(err)?
        .label(format!("reward region (r = {GOAL_RADIUS} m)"))
        .legend(|(x, y)| Circle::new((x + 9, y), 6, BLACK.mix(0.7).stroke_width(1)));
    Ok(2)
}
