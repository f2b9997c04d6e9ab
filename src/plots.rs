//! PNG plots of a run: the learning curve and a top view of the evaluated paths.

use agvrl_sim::Scene;
use anyhow::{Context, Result, anyhow};
use plotters::prelude::*;
use plotters::style::FontStyle;
use rapier3d::prelude::{Pose, SharedShape, Vector};
use std::path::Path;

static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

fn ensure_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE.get_or_init(|| plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok());
    ok.then_some(())
        .ok_or_else(|| anyhow!("the embedded plot font did not load"))
}

/// Draw into an RGB buffer with plotters, then write it as a PNG through a temp file.
fn render_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> Result<()>,
) -> Result<()> {
    ensure_font()?;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        draw(root.clone())?;
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().context("png header")?;
        wr.write_image_data(&buf).context("png data")?;
    }
    Ok(agvrl_run::write_atomic(path, &bytes)?)
}

/// `(step, mean return)` points of a metrics.csv.
pub fn curve_of_csv(csv: &str) -> Vec<(f64, f64)> {
    csv.lines()
        .skip(1)
        .filter_map(|l| {
            let mut f = l.split(',');
            let step = f.next()?.parse().ok()?;
            let mean = f.nth(1)?.parse().ok()?;
            Some((step, mean))
        })
        .collect()
}

/// The moving-average return against environment steps, like the paper's figures.
pub fn learning_curve(path: &Path, points: &[(f64, f64)], title: &str) -> Result<()> {
    render_png(path, (900, 560), |root| {
        let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
        let (x1, mut y0, mut y1) = points.iter().fold((1.0f64, f64::INFINITY, f64::NEG_INFINITY), |a, p| {
            (a.0.max(p.0), a.1.min(p.1), a.2.max(p.1))
        });
        if !y0.is_finite() {
            (y0, y1) = (0.0, 1.0);
        }
        let pad = ((y1 - y0) * 0.05).max(1e-3);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x1, (y0 - pad)..(y1 + pad))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("environment steps")
            .y_desc("mean episode return (recent 100)")
            .x_label_formatter(&|v| steps_label(*v))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(e)?;
        chart
            .draw_series(LineSeries::new(points.iter().copied(), BLUE.stroke_width(2)))
            .map_err(e)?;
        if points.is_empty() {
            root.draw(&Text::new(
                "no episode finished during training",
                (300, 280),
                ("sans-serif", 18),
            ))
            .map_err(e)?;
        }
        Ok(())
    })
}

/// The series' legend in the lower right corner, on a light box.
fn legend_lower_right<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<()> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| anyhow!("plot: {e}"))
}

/// Mean coverage against time of each `(label, csv)` (`agvrl eval --coverage-csv` output: an
/// episode that ended early keeps its last coverage to the end).
pub fn coverage_over_time(path: &Path, series: &[(String, String)], title: &str) -> Result<()> {
    let mut lines = Vec::new();
    for (label, csv) in series {
        let mut episodes: Vec<Vec<(f64, f64)>> = Vec::new();
        for (n, l) in csv.lines().enumerate().skip(1) {
            let f: Vec<&str> = l.split(',').collect();
            let bad = || anyhow!("{label}: line {} is not episode,step,time_s,coverage", n + 1);
            let [e, _, t, c] = f[..] else { return Err(bad()) };
            let (e, t, c): (usize, f64, f64) = (
                e.parse().map_err(|_| bad())?,
                t.parse().map_err(|_| bad())?,
                c.parse().map_err(|_| bad())?,
            );
            if e >= episodes.len() {
                episodes.resize(e + 1, Vec::new());
            }
            episodes[e].push((t, c));
        }
        let longest = episodes.iter().map(Vec::len).max().unwrap_or(0);
        let Some(times) = episodes
            .iter()
            .find(|e| e.len() == longest)
            .map(|e| e.iter().map(|p| p.0).collect::<Vec<_>>())
        else {
            return Err(anyhow!("{label}: no coverage rows"));
        };
        let mean: Vec<(f64, f64)> = times
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let sum: f64 = episodes
                    .iter()
                    .map(|e| e.get(k).or(e.last()).map_or(0.0, |p| p.1))
                    .sum();
                (*t, sum / episodes.len().max(1) as f64)
            })
            .collect();
        lines.push((label.clone(), mean));
    }
    render_png(path, (900, 560), |root| {
        let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
        let t1 = lines
            .iter()
            .flat_map(|l| l.1.last())
            .map(|p| p.0)
            .fold(1.0f64, f64::max);
        let c1 = lines
            .iter()
            .flat_map(|l| l.1.iter())
            .map(|p| p.1)
            .fold(0.1f64, f64::max);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t1, 0.0..(c1 * 1.05).min(1.0))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time, s")
            .y_desc("mean coverage")
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(e)?;
        for (k, (label, pts)) in lines.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            // A driver whose episodes all ended early keeps its coverage to the plot's end.
            let hold = pts.last().filter(|p| p.0 < t1).map(|p| (t1, p.1));
            chart
                .draw_series(LineSeries::new(pts.iter().copied().chain(hold), color.stroke_width(2)))
                .map_err(e)?
                .label(label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        }
        legend_lower_right(&mut chart)
    })
}

/// One car's gap to car 0 over a race, and the moments its figures changed.
pub struct GapSeries {
    /// The legend's name.
    pub label: String,
    /// (time s, car 0's distance ahead of this car along the centre line, m).
    pub gap: Vec<(f64, f64)>,
    /// Times car 0 passed this car (drawn as circles on the line).
    pub passes_s: Vec<f64>,
    /// Times car 0 began a contact it caused (drawn as crosses on the line).
    pub at_fault_s: Vec<f64>,
}

/// Car 0's gap to every other car over one race (`agvrl race --gap-plot`): above zero it is
/// ahead. Passes are circles, contacts car 0 caused crosses; the band of an encounter (0-3 m
/// behind) is shaded.
pub fn race_gaps(path: &Path, series: &[GapSeries], title: &str) -> Result<()> {
    let t1 = series
        .iter()
        .flat_map(|s| s.gap.last())
        .map(|p| p.0)
        .fold(1.0f64, f64::max);
    let (lo, hi) = series
        .iter()
        .flat_map(|s| s.gap.iter())
        .fold((-5.0f64, 5.0f64), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    render_png(path, (900, 560), |root| {
        let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t1, (lo - 1.0)..(hi + 1.0))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time, s")
            .y_desc("car 0 ahead by, m")
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, -3.0), (t1, 0.0)],
                RGBColor(230, 230, 230).filled(),
            )))
            .map_err(e)?;
        for (k, s) in series.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let at = |t: f64| {
                s.gap
                    .iter()
                    .find(|p| p.0 >= t)
                    .or(s.gap.last())
                    .copied()
                    .unwrap_or((t, 0.0))
            };
            chart
                .draw_series(LineSeries::new(s.gap.iter().copied(), color.stroke_width(2)))
                .map_err(e)?
                .label(s.label.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            chart
                .draw_series(s.passes_s.iter().map(|&t| Circle::new(at(t), 7, BLACK.stroke_width(2))))
                .map_err(e)?;
            chart
                .draw_series(s.at_fault_s.iter().map(|&t| Cross::new(at(t), 7, RED.stroke_width(2))))
                .map_err(e)?;
        }
        legend_lower_right(&mut chart)
    })
}

/// An evaluated path: world (x, y) points and whether it ended in a collision.
pub struct Path2 {
    pub xy: Vec<(f32, f32)>,
    pub collided: bool,
    /// The legend's name (`None`: "episode k").
    pub label: Option<String>,
}

/// A filled footprint in the top view.
enum Footprint {
    Poly(Vec<(f32, f32)>),
    Circle((f32, f32), f32),
}

/// Shapes whose bottom is above this height (m) cannot touch the car.
const OVERHEAD_M: f32 = 1.0;

fn footprints(shape: &SharedShape, pose: &Pose, out: &mut Vec<Footprint>) {
    let xy = |v: Vector| (v.x, v.y);
    if let Some(c) = shape.as_compound() {
        for (p, s) in c.shapes() {
            footprints(s, &(*pose * *p), out);
        }
    } else if let Some(b) = shape.as_cuboid() {
        let h = b.half_extents;
        let pts = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(sx, sy)| xy(*pose * Vector::new(sx * h.x, sy * h.y, 0.0)))
            .collect();
        out.push(Footprint::Poly(pts));
    } else if let Some(c) = shape.as_cylinder()
        && (pose.rotation * Vector::Y).z.abs() > 0.9
    {
        out.push(Footprint::Circle(xy(pose.translation), c.radius));
    } else if let Some(b) = shape.as_ball() {
        out.push(Footprint::Circle(xy(pose.translation), b.radius));
    } else if let Some(c) = shape.as_convex_polyhedron() {
        out.push(Footprint::Poly(hull(
            c.points().iter().map(|p| xy(*pose * *p)).collect(),
        )));
    } else {
        let a = shape.compute_aabb(pose);
        let (lo, hi) = (a.mins, a.maxs);
        out.push(Footprint::Poly(vec![
            (lo.x, lo.y),
            (hi.x, lo.y),
            (hi.x, hi.y),
            (lo.x, hi.y),
        ]));
    }
}

/// Convex hull of planar points (monotone chain).
fn hull(mut p: Vec<(f32, f32)>) -> Vec<(f32, f32)> {
    p.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f32, f32), a: (f32, f32), b: (f32, f32)| (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0);
    let mut h: Vec<(f32, f32)> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        let it: Box<dyn Iterator<Item = &(f32, f32)>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in it {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

fn rgb(c: [f32; 3]) -> RGBColor {
    let u = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    RGBColor(u(c[0]), u(c[1]), u(c[2]))
}

/// Ground, then the objects' footprints: parts above the car (tree canopies) faint and first,
/// so the trunks the car can hit stay visible under them.
fn draw_scene<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf32, plotters::coord::types::RangedCoordf32>,
    >,
    scene: &Scene,
) -> Result<()> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e}");
    let g = &scene.file.ground;
    let (hx, hy) = (g.size_m[0] / 2.0, g.size_m[1] / 2.0);
    let ground = rgb(g.color).mix(0.35);
    chart
        .draw_series(std::iter::once(Rectangle::new([(-hx, -hy), (hx, hy)], ground.filled())))
        .map_err(e)?;
    let overhead = |s: &agvrl_sim::urdf::ShapeSpec| s.shape.compute_aabb(&s.pose).mins.z > OVERHEAD_M;
    let layers = [true, false].map(|high| {
        scene
            .objects
            .iter()
            .flat_map(|o| &o.shapes)
            .filter(move |s| overhead(s) == high)
    });
    for (layer, shapes) in layers.into_iter().enumerate() {
        for s in shapes {
            let mut fp = Vec::new();
            footprints(&s.shape, &s.pose, &mut fp);
            let style = match layer {
                0 => rgb(s.color).mix(0.3).filled(),
                _ => rgb(s.color).filled(),
            };
            for f in fp {
                let p = match f {
                    Footprint::Poly(p) => p,
                    // A circle in data units: a polygon keeps the radius in metres.
                    Footprint::Circle(c, r) => (0..24)
                        .map(|k| {
                            let a = k as f32 * std::f32::consts::TAU / 24.0;
                            (c.0 + r * a.cos(), c.1 + r * a.sin())
                        })
                        .collect(),
                };
                chart.draw_series(std::iter::once(Polygon::new(p, style))).map_err(e)?;
            }
        }
    }
    Ok(())
}

/// An RGB image (row-major, 3 bytes a pixel) of the scene from above with the car and, given a
/// scan, its LiDAR rays (hits red, misses grey): what a Gymnasium `rgb_array` render shows.
/// The longer side of the map gets `px` pixels.
pub fn top_view(
    sim: &agvrl_sim::Sim,
    scan: Option<&agvrl_sim::msg::LaserScan>,
    px: u32,
) -> Result<(Vec<u8>, u32, u32)> {
    let scene = sim.scene();
    let g = &scene.file.ground;
    let (vx, vy) = (g.size_m[0] / 2.0 + 0.6, g.size_m[1] / 2.0 + 0.6);
    let span = vx.max(vy);
    let (w, h) = (
        ((px as f32 * vx / span) as u32).max(16),
        ((px as f32 * vy / span) as u32).max(16),
    );
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
        root.fill(&WHITE).map_err(e)?;
        let mut chart = ChartBuilder::on(&root)
            .build_cartesian_2d(-vx..vx, -vy..vy)
            .map_err(e)?;
        draw_scene(&mut chart, scene)?;
        if let Some(scan) = scan {
            let o = (scan.origin_w[0], scan.origin_w[1]);
            for (p, hit) in scan.points_w.iter().zip(&scan.hit) {
                let c = if *hit {
                    RED.mix(0.8)
                } else {
                    RGBColor(150, 150, 150).mix(0.5)
                };
                chart
                    .draw_series(std::iter::once(PathElement::new(vec![o, (p[0], p[1])], c)))
                    .map_err(e)?;
            }
        }
        let pose = sim.car(0).pose2();
        let v = sim.vehicle();
        let r = v.wheels.iter().map(|w| w.radius_m).fold(0.0, f32::max);
        let (hl, hw) = (v.wheelbase_m / 2.0 + r, v.front_track_m / 2.0 + r / 2.0);
        let (c, sn) = (pose.yaw_rad.cos(), pose.yaw_rad.sin());
        let at = |dx: f32, dy: f32| (pose.x_m + dx * c - dy * sn, pose.y_m + dx * sn + dy * c);
        let body = vec![at(-hl, -hw), at(hl, -hw), at(hl, hw), at(-hl, hw)];
        chart
            .draw_series(std::iter::once(Polygon::new(body, BLUE.filled())))
            .map_err(e)?;
        // The nose, so the heading reads at a glance.
        chart
            .draw_series(std::iter::once(Polygon::new(
                vec![at(hl, -hw), at(hl + hw, 0.0), at(hl, hw)],
                BLACK.filled(),
            )))
            .map_err(e)?;
        root.present().map_err(e)?;
    }
    Ok((buf, w, h))
}

/// Top view of `scene` with the evaluated `paths` (start: circle, collision: cross).
pub fn trajectory(path: &Path, scene: &Scene, paths: &[Path2], title: &str) -> Result<()> {
    let g = &scene.file.ground;
    let (hx, hy) = (g.size_m[0] / 2.0, g.size_m[1] / 2.0);
    // Boundary walls stand just outside the ground (0.5 m thick in AutoVRL's maps).
    let (vx, vy) = (hx + 0.6, hy + 0.6);
    let span = hx.max(hy);
    let size = ((820.0 * hx / span) as u32 + 80, (820.0 * hy / span) as u32 + 110);
    render_png(path, size, |root| {
        let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(-vx..vx, -vy..vy)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x, m")
            .y_desc("y, m")
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(e)?;
        draw_scene(&mut chart, scene)?;
        let palette = [BLUE, MAGENTA, CYAN, RGBColor(255, 140, 0), BLACK];
        for (k, p) in paths.iter().enumerate() {
            let c = palette[k % palette.len()];
            chart
                .draw_series(LineSeries::new(p.xy.iter().copied(), c.stroke_width(2)))
                .map_err(e)?
                .label(format!(
                    "{}{}",
                    p.label.clone().unwrap_or_else(|| format!("episode {}", k + 1)),
                    if p.collided { " (collision)" } else { "" }
                ))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
            if let Some(&s) = p.xy.first() {
                chart
                    .draw_series(std::iter::once(Circle::new(s, 5, c.filled())))
                    .map_err(e)?;
            }
            if p.collided
                && let Some(&end) = p.xy.last()
            {
                chart
                    .draw_series(std::iter::once(Cross::new(end, 8, RED.stroke_width(3))))
                    .map_err(e)?;
            }
        }
        if !paths.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .draw()
                .map_err(e)?;
        }
        Ok(())
    })
}

/// 250000 -> "250k", 1500000 -> "1.5M".
fn steps_label(v: f64) -> String {
    let a = v.abs();
    if a >= 1e6 {
        format!("{}M", trim(v / 1e6))
    } else if a >= 1e3 {
        format!("{}k", trim(v / 1e3))
    } else {
        format!("{v:.0}")
    }
}

fn trim(x: f64) -> String {
    let s = format!("{x:.1}");
    s.strip_suffix(".0").map(str::to_string).unwrap_or(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_labels_are_short() {
        let got: Vec<_> = [0.0, 500.0, 20_000.0, 250_000.0, 1_500_000.0, 2e6]
            .map(steps_label)
            .into();
        assert_eq!(got, ["0", "500", "20k", "250k", "1.5M", "2M"]);
    }

    #[test]
    fn hull_of_a_square_with_inner_points() {
        let h = hull(vec![
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.5),
            (1.0, 1.0),
            (0.0, 1.0),
            (0.2, 0.7),
        ]);
        assert_eq!(h.len(), 4);
        for c in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            assert!(h.contains(&c), "{c:?} missing from {h:?}");
        }
    }

    #[test]
    fn csv_curve_skips_rows_without_a_mean() {
        let csv = "step,episodes,mean_return,policy_loss\n100,0,,0.1\n200,2,-3.5,0.2\n";
        assert_eq!(curve_of_csv(csv), vec![(200.0, -3.5)]);
    }
}
