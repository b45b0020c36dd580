//! A map drawn as a heat map (PNG and SVG): one rectangle per cell of the grid, in the
//! axes' ranks (the values written on the ticks), coloured on the viridis scale
//! (log10 when the values are positive and span more than two decades), grey where no
//! flight had the metric, crossed where a map that requires exit 0 has a flight that did
//! not; the theory's boundary drawn over it in red.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};

use super::map::Grid;
use super::spec::{MapSpec, Theory};

const SIZE: (u32, u32) = (900, 700);

/// Writes `stem.png` and `stem.svg`.
///
/// # Errors
/// A file that cannot be drawn or written, named.
pub fn heat_map(
    stem: &Path,
    spec: &MapSpec,
    grid: &Grid,
    boundary: Option<&[Option<f64>]>,
) -> Result<(), String> {
    crate::plot::register_font();
    let png = stem.with_extension("png");
    let area = BitMapBackend::new(&png, SIZE).into_drawing_area();
    draw(&area, spec, grid, boundary).map_err(|e| format!("{}: {e}", png.display()))?;
    area.present()
        .map_err(|e| format!("{}: {e}", png.display()))?;
    let svg = stem.with_extension("svg");
    let area = SVGBackend::new(&svg, SIZE).into_drawing_area();
    draw(&area, spec, grid, boundary).map_err(|e| format!("{}: {e}", svg.display()))?;
    area.present()
        .map_err(|e| format!("{}: {e}", svg.display()))?;
    Ok(())
}

/// Ranks of `values` in ascending order: `order[r]` is the index of the r-th smallest.
fn order(values: &[f64]) -> Vec<usize> {
    let mut o: Vec<usize> = (0..values.len()).collect();
    o.sort_by(|a, b| values[*a].total_cmp(&values[*b]));
    o
}

/// `y` in rank coordinates of the ascending values `sorted` (cell r spans [r, r + 1],
/// its value at r + 0.5), interpolated linearly (geometrically when both are positive).
fn rank_of(sorted: &[f64], y: f64) -> f64 {
    let n = sorted.len();
    if n == 1 {
        return 0.5;
    }
    for r in 0..n - 1 {
        let (a, b) = (sorted[r], sorted[r + 1]);
        if y <= b || r == n - 2 {
            let t = if a > 0.0 && b > 0.0 && y > 0.0 {
                (y / a).ln() / (b / a).ln()
            } else {
                (y - a) / (b - a)
            };
            return (r as f64 + 0.5 + t).clamp(0.0, n as f64);
        }
    }
    n as f64
}

/// The tick label at `v` (cell centres at whole ranks): the value of that rank, none
/// between ranks.
fn label(sorted: &[f64], v: f64, fmt: &dyn Fn(f64) -> String) -> String {
    let r = v.round();
    if (v - r).abs() < 1e-6 && r >= 0.0 && (r as usize) < sorted.len() {
        fmt(sorted[r as usize])
    } else {
        String::new()
    }
}

fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    spec: &MapSpec,
    grid: &Grid,
    boundary: Option<&[Option<f64>]>,
) -> Result<(), String> {
    let e = |e: plotters::drawing::DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    area.fill(&WHITE).map_err(e)?;
    let (xo, yo) = (order(&grid.xs), order(&grid.ys));
    let xs: Vec<f64> = xo.iter().map(|&i| grid.xs[i]).collect();
    let ys: Vec<f64> = yo.iter().map(|&j| grid.ys[j]).collect();
    let present: Vec<f64> = grid.values.iter().flatten().flatten().copied().collect();
    let lo = present.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = present.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let log = lo > 0.0 && hi / lo > 100.0;
    let scale = |v: f64| if log { v.log10() } else { v };
    let (slo, shi) = if present.is_empty() {
        (0.0, 1.0)
    } else if scale(hi) > scale(lo) {
        (scale(lo), scale(hi))
    } else {
        (scale(lo) - 0.5, scale(lo) + 0.5)
    };
    let (main, bar) = area.split_horizontally(SIZE.0 - 140);
    let title = format!(
        "{} of {} over {} × {}",
        spec.reduce.name(),
        spec.metric,
        spec.x,
        spec.y
    );
    let fmt = |v: f64| {
        if v != 0.0 && (v.abs() < 0.01 || v.abs() >= 1e4) {
            format!("{v:.2e}")
        } else {
            format!("{}", (v * 1000.0).round() / 1000.0)
        }
    };
    let mut chart = ChartBuilder::on(&main)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..xs.len() as f64 - 0.5, -0.5..ys.len() as f64 - 0.5)
        .map_err(e)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(spec.x.as_str())
        .y_desc(spec.y.as_str())
        .x_labels(xs.len().min(12))
        .y_labels(ys.len().min(16))
        .x_label_formatter(&|v| label(&xs, *v, &fmt))
        .y_label_formatter(&|v| label(&ys, *v, &fmt))
        .draw()
        .map_err(e)?;
    for (r, &i) in xo.iter().enumerate() {
        for (q, &j) in yo.iter().enumerate() {
            let fill = match grid.values[i][j] {
                Some(v) => ViridisRGB.get_color_normalized(scale(v), slo, shi),
                None => RGBColor(200, 200, 200),
            };
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [
                        (r as f64 - 0.5, q as f64 - 0.5),
                        (r as f64 + 0.5, q as f64 + 0.5),
                    ],
                    fill.filled(),
                )))
                .map_err(e)?;
            if spec.require_exit_0 && !grid.exited_0[i][j] {
                let (x, y) = (r as f64, q as f64);
                for (a, b) in [((-0.3, -0.3), (0.3, 0.3)), ((-0.3, 0.3), (0.3, -0.3))] {
                    chart
                        .draw_series(std::iter::once(PathElement::new(
                            vec![(x + a.0, y + a.1), (x + b.0, y + b.1)],
                            BLACK.mix(0.6).stroke_width(1),
                        )))
                        .map_err(e)?;
                }
            }
        }
    }
    if spec.require_exit_0 {
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(e)?
            .label("crossed: a flight did not exit 0 (not good)")
            .legend(|(x, y)| {
                PathElement::new(vec![(x, y - 5), (x + 10, y + 5)], BLACK.stroke_width(1))
            });
    }
    if let Some(boundary) = boundary {
        let points: Vec<(f64, f64)> = xo
            .iter()
            .enumerate()
            .filter_map(|(r, &i)| boundary[i].map(|y| (r as f64, rank_of(&ys, y) - 0.5)))
            .collect();
        chart
            .draw_series(LineSeries::new(points.clone(), RED.stroke_width(3)))
            .map_err(e)?
            .label(spec.theory.map_or("theory", Theory::label))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(3)));
        chart
            .draw_series(points.iter().map(|p| Circle::new(*p, 4, RED.filled())))
            .map_err(e)?;
    }
    if boundary.is_some() || spec.require_exit_0 {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(e)?;
    }
    // The colour bar.
    let mut bar_chart = ChartBuilder::on(&bar)
        .margin_top(40)
        .margin_bottom(57)
        .margin_right(10)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..1.0, slo..shi)
        .map_err(e)?;
    bar_chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(if log {
            format!("log10 {}", spec.metric)
        } else {
            spec.metric.clone()
        })
        .axis_desc_style(("sans-serif", 14))
        .label_style(("sans-serif", 12))
        // A tick a rounding error away from zero is zero.
        .y_label_formatter(&|v| {
            fmt(if v.abs() < 1e-9 * (shi - slo) {
                0.0
            } else {
                *v
            })
        })
        .draw()
        .map_err(e)?;
    let steps = 100;
    bar_chart
        .draw_series((0..steps).map(|s| {
            let a = slo + (shi - slo) * s as f64 / steps as f64;
            let b = slo + (shi - slo) * (s + 1) as f64 / steps as f64;
            Rectangle::new(
                [(0.0, a), (1.0, b)],
                ViridisRGB.get_color_normalized(a, slo, shi).filled(),
            )
        }))
        .map_err(e)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_between_two_cells_lies_between_their_centres() {
        let ys = [0.5, 1.0, 2.0, 4.0];
        assert_eq!(rank_of(&ys, 1.0), 1.5);
        // Geometric halfway between 1 and 2.
        assert!((rank_of(&ys, 2f64.sqrt()) - 2.0).abs() < 1e-12);
        assert_eq!(rank_of(&[0.0, 1.0], 0.25), 0.75);
        assert_eq!(rank_of(&ys, 100.0), 4.0);
        assert_eq!(rank_of(&[3.0], 3.0), 0.5);
    }
}
