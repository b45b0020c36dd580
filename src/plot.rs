//! The paper's figures from a flight's [`Trace`], as PNG and SVG in the run directory:
//! 3-D trajectories, x–y paths with the final formation, altitude, velocity components
//! with the predicted final velocity (dashed), roll/pitch/yaw, and the commanded thrust
//! and horizontal acceleration against the envelope. One colour per vehicle. Text is
//! drawn with an embedded DejaVu Sans, so no system font is needed.

use std::path::Path;
use std::sync::Once;

use nalgebra::Vector2;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::control::Envelope;
use crate::control::GRAVITY_MPS2;
use crate::record::trace::Trace;

/// What the figures need besides the trace.
#[derive(Debug, Clone)]
pub struct PlotInfo {
    /// Scenario name, for titles.
    pub title: String,
    /// Predicted final velocity (m/s, ENU).
    pub predicted_mps: Option<Vector2<f64>>,
    /// Formation altitude (m).
    pub altitude_m: f64,
    /// The envelope.
    pub envelope: Envelope,
    /// Lower and upper thrust limits.
    pub thrust_limits: (f64, f64),
}

impl PlotInfo {
    /// What the plots need from the swarm, titled `title`.
    pub fn new(swarm: &crate::swarm::Swarm, title: &str) -> Self {
        let setup = swarm.setup();
        Self {
            title: title.to_owned(),
            predicted_mps: swarm.predicted_final_velocity(),
            altitude_m: setup.altitude_m,
            envelope: setup.envelope,
            thrust_limits: (
                setup.envelope.min_thrust_norm(),
                setup.envelope.max_thrust_norm(),
            ),
        }
    }
}

/// A plotting failure, as text.
pub type PlotResult = Result<(), String>;

const FONT: &str = "sans-serif";
const SIZE: (u32, u32) = (1100, 700);

/// Registers the embedded font once (every figure's text is drawn with it).
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_err()
        {
            tracing::error!("the embedded font could not be loaded: plots will have no text");
        }
    });
}

fn colour(i: usize) -> RGBColor {
    let c = Palette99::pick(i).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Writes every figure as `<name>.png` and `<name>.svg` into `dir`.
///
/// # Errors
/// A figure that cannot be drawn or written, named.
pub fn write_all(dir: &Path, trace: &Trace, info: &PlotInfo) -> PlotResult {
    register_font();
    // The flight, and 5 s of the end (landing is long and flat).
    let trace = &trace.until(trace.end_s.map(|t| t + 5.0));
    if trace.t_s.len() < 2 {
        return Err("too few samples to plot".to_owned());
    }
    for name in FIGURES {
        let png_path = dir.join(format!("{name}.png"));
        let area = BitMapBackend::new(&png_path, SIZE).into_drawing_area();
        draw(name, &area, trace, info).map_err(|e| format!("{name}.png: {e}"))?;
        area.present().map_err(|e| format!("{name}.png: {e}"))?;
        let svg_path = dir.join(format!("{name}.svg"));
        let area = SVGBackend::new(&svg_path, SIZE).into_drawing_area();
        draw(name, &area, trace, info).map_err(|e| format!("{name}.svg: {e}"))?;
        area.present().map_err(|e| format!("{name}.svg: {e}"))?;
    }
    Ok(())
}

/// The figures, by file name.
pub const FIGURES: [&str; 6] = [
    "trajectories-3d",
    "paths-xy",
    "altitude",
    "velocity",
    "attitude",
    "commands",
];

fn draw<DB: DrawingBackend>(
    name: &str,
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    match name {
        "trajectories-3d" => trajectories_3d(area, trace, info),
        "paths-xy" => paths_xy(area, trace, info),
        "altitude" => altitude(area, trace, info),
        "velocity" => velocity(area, trace, info),
        "attitude" => attitude(area, trace, info),
        "commands" => commands(area, trace, info),
        other => Err(format!("unknown figure {other}")),
    }
}

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Range of `values` padded by 5 % (and at least ±`min_half`).
fn range(values: impl Iterator<Item = f64>, min_half: f64) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return -1.0..1.0;
    }
    let mid = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo) * 1.05).max(min_half);
    (mid - half)..(mid + half)
}

fn t_range(trace: &Trace) -> std::ops::Range<f64> {
    let first = trace.t_s.first().copied().unwrap_or(0.0);
    let last = trace.t_s.last().copied().unwrap_or(1.0);
    first..last.max(first + 1.0)
}

type Chart2d<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn legend<'a, DB: DrawingBackend + 'a>(chart: &mut Chart2d<'a, DB>, n: usize) -> PlotResult {
    if n <= 12 {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 14))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// One panel of per-vehicle time series.
fn time_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    caption: &str,
    y_label: &str,
    f: &dyn Fn(&crate::record::trace::Sample) -> f64,
    reference: Option<(f64, &str)>,
    limits: &[(f64, &str)],
) -> PlotResult {
    let n = trace.vehicles();
    let series: Vec<Vec<(f64, f64)>> = (0..n).map(|i| trace.series(i, f)).collect();
    let mut ys: Vec<f64> = series.iter().flatten().map(|p| p.1).collect();
    ys.extend(reference.iter().map(|r| r.0));
    ys.extend(limits.iter().map(|l| l.0));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(t_range(trace), range(ys.into_iter(), 0.5))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_label)
        .label_style((FONT, 14))
        .draw()
        .map_err(err)?;
    for (i, s) in series.into_iter().enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(
                s.into_iter().filter(|p| p.1.is_finite()),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label(format!("vehicle {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    let (t0, t1) = (t_range(trace).start, t_range(trace).end);
    if let Some((value, label)) = reference {
        chart
            .draw_series(DashedLineSeries::new(
                vec![(t0, value), (t1, value)],
                10,
                6,
                BLACK.stroke_width(2),
            ))
            .map_err(err)?
            .label(label.to_owned())
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    }
    for (value, label) in limits {
        chart
            .draw_series(DashedLineSeries::new(
                vec![(t0, *value), (t1, *value)],
                4,
                4,
                RED.stroke_width(2),
            ))
            .map_err(err)?
            .label((*label).to_owned())
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    }
    legend(&mut chart, n)
}

fn trajectories_3d<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    let n = trace.vehicles();
    let all = || trace.samples.iter().flatten();
    let xr = range(all().map(|s| s.pos_m.x), 1.0);
    let yr = range(all().map(|s| s.pos_m.y), 1.0);
    let zr = range(all().map(|s| s.pos_m.z), 1.0);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{}: trajectories (ENU, m)", info.title), (FONT, 22))
        .margin(20)
        .build_cartesian_3d(xr, zr, yr)
        .map_err(err)?;
    chart.with_projection(|mut p| {
        p.pitch = 0.15;
        p.yaw = 0.5;
        p.scale = 0.8;
        p.into_matrix()
    });
    chart
        .configure_axes()
        .label_style((FONT, 13))
        .draw()
        .map_err(err)?;
    for i in 0..n {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(
                trace
                    .samples
                    .iter()
                    .map(|row| (row[i].pos_m.x, row[i].pos_m.z, row[i].pos_m.y)),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label(format!("vehicle {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    if n <= 12 {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((FONT, 14))
            .draw()
            .map_err(err)?;
    }
    area.draw(&Text::new(
        "x east, y north (depth), z up",
        (20, SIZE.1 as i32 - 30),
        (FONT, 14),
    ))
    .map_err(err)?;
    Ok(())
}

fn paths_xy<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    let n = trace.vehicles();
    let all = || trace.samples.iter().flatten();
    let xr = range(all().map(|s| s.pos_m.x), 1.0);
    let yr = range(all().map(|s| s.pos_m.y), 1.0);
    // Same scale on both axes.
    let half = 0.5 * (xr.end - xr.start).max(yr.end - yr.start);
    let (cx, cy) = (0.5 * (xr.start + xr.end), 0.5 * (yr.start + yr.end));
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{}: x–y paths and the final formation", info.title),
            (FONT, 22),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (cx - half * 1.57)..(cx + half * 1.57),
            (cy - half)..(cy + half),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x east (m)")
        .y_desc("y north (m)")
        .label_style((FONT, 14))
        .draw()
        .map_err(err)?;
    for i in 0..n {
        let c = colour(i);
        let path = trace.path_xy(i);
        chart
            .draw_series(LineSeries::new(
                path.iter().map(|p| (p.x, p.y)),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label(format!("vehicle {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        if let Some(start) = path.first() {
            chart
                .draw_series(std::iter::once(Cross::new(
                    (start.x, start.y),
                    5,
                    c.stroke_width(2),
                )))
                .map_err(err)?;
        }
    }
    // The final formation: the positions when the flight ended, joined in ring order.
    if let Some(last) = trace.at(trace.end_s).or(trace.samples.last()) {
        let mut ring: Vec<(f64, f64)> = last.iter().map(|s| (s.pos_m.x, s.pos_m.y)).collect();
        if let Some(first) = ring.first().copied() {
            ring.push(first);
        }
        chart
            .draw_series(LineSeries::new(ring, BLACK.stroke_width(2)))
            .map_err(err)?
            .label("final formation (ring order)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        chart
            .draw_series(
                last.iter()
                    .enumerate()
                    .map(|(i, s)| Circle::new((s.pos_m.x, s.pos_m.y), 6, colour(i).filled())),
            )
            .map_err(err)?;
    }
    legend(&mut chart, n)
}

fn altitude<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    time_panel(
        area,
        trace,
        &format!("{}: altitude", info.title),
        "z up (m)",
        &|s| s.pos_m.z,
        Some((info.altitude_m, "commanded altitude")),
        &[],
    )
}

fn velocity<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    let panels = area.split_evenly((2, 1));
    let p = info.predicted_mps;
    time_panel(
        &panels[0],
        trace,
        &format!("{}: velocity east", info.title),
        "vx (m/s)",
        &|s| s.vel_mps.x,
        p.map(|p| (p.x, "predicted final velocity")),
        &[],
    )?;
    time_panel(
        &panels[1],
        trace,
        "velocity north",
        "vy (m/s)",
        &|s| s.vel_mps.y,
        p.map(|p| (p.y, "predicted final velocity")),
        &[],
    )
}

fn attitude<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    let panels = area.split_evenly((3, 1));
    let tilt = info.envelope.max_tilt_rad().to_degrees();
    let limits = [(tilt, "tilt limit"), (-tilt, "tilt limit")];
    time_panel(
        &panels[0],
        trace,
        &format!("{}: roll", info.title),
        "roll (deg)",
        &|s| s.rpy_rad.x.to_degrees(),
        None,
        &limits,
    )?;
    time_panel(
        &panels[1],
        trace,
        "pitch",
        "pitch (deg)",
        &|s| s.rpy_rad.y.to_degrees(),
        None,
        &limits,
    )?;
    time_panel(
        &panels[2],
        trace,
        "yaw",
        "yaw (deg)",
        &|s| s.rpy_rad.z.to_degrees(),
        None,
        &[],
    )
}

fn commands<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    trace: &Trace,
    info: &PlotInfo,
) -> PlotResult {
    area.fill(&WHITE).map_err(err)?;
    let panels = area.split_evenly((2, 1));
    let (lo, hi) = info.thrust_limits;
    time_panel(
        &panels[0],
        trace,
        &format!("{}: commanded thrust", info.title),
        "thrust (0..1)",
        &|s| s.thrust_norm,
        None,
        &[(lo, "thrust limits"), (hi, "thrust limits")],
    )?;
    // At hover the tilt limit allows g·tan θ horizontally.
    let at_hover = GRAVITY_MPS2 * info.envelope.max_tilt_rad().tan();
    time_panel(
        &panels[1],
        trace,
        "commanded horizontal acceleration",
        "|u_xy| (m/s²)",
        &|s| s.cmd_mps2.xy().norm(),
        None,
        &[(at_hover, "tilt limit at hover (g·tan θ)")],
    )
}
