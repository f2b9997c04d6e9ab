//! The path a driver follows: a closed polyline, resampled evenly, with the speed the car can
//! drive at each point (from its limits), read from a track's centre line or a raceline CSV.

use super::CarLimits;
use crate::api::Track;

/// Spacing of a resampled path, metres: fine against the car (0.33 m wheelbase) and the
/// lookahead, coarse enough that a window search stays short.
const SPACING_M: f64 = 0.1;
/// Half the span of the three points whose circumcircle gives the curvature, metres: long enough
/// that a hand-made or pixel-traced line's wiggles do not read as corners.
const CURVATURE_HALF_SPAN_M: f64 = 0.2;
/// Half the window of the moving average over the curvature, metres.
const CURVATURE_SMOOTHING_M: f64 = 0.2;

/// The header F1TENTH's raceline CSVs carry (f1tenth_racetracks' `*_raceline.csv`).
const F1TENTH_COLUMNS: [&str; 7] = ["s_m", "x_m", "y_m", "psi_rad", "kappa_radpm", "vx_mps", "ax_mps2"];

/// A closed path in racing order with a target speed at each point. The points are evenly spaced
/// (about 0.1 m) whatever the source's spacing, so the curvature stencil, the speed profile's
/// steps and a driver's search window mean the same distance everywhere.
#[derive(Clone, Debug, PartialEq)]
pub struct RacePath {
    points: Vec<[f64; 2]>,
    spacing_m: f64,
    curvature_1pm: Vec<f64>,
    speed_mps: Vec<f64>,
    /// The profile's scale, to rebuild it for a fitted path.
    speed_scale: f64,
}

impl RacePath {
    /// The closed path through `points` (racing order, the first not repeated at the end) with
    /// the fastest speed profile `limits` allow, times `speed_scale` (in (0, 1]). Errors name what
    /// is wrong in one line.
    ///
    /// The profile: at each point the top speed, the lateral limit `sqrt(a_lat / |kappa|)` and,
    /// where the path bends tighter than the steering can (`|kappa| > kappa_max`), the yaw rate
    /// of the tightest circle at the lateral limit, `sqrt(a_lat kappa_max) / |kappa|` (the car
    /// cannot hold such a corner; slower, it leaves it by less); then a forward pass with the
    /// drive's full-throttle acceleration and a backward pass with its deceleration, around the
    /// loop.
    pub fn new(points: &[[f32; 2]], limits: &CarLimits, speed_scale: f64) -> Result<Self, String> {
        if !(speed_scale.is_finite() && speed_scale > 0.0 && speed_scale <= 1.0) {
            return Err(format!(
                "speed_scale must be in (0, 1] (1 drives at the car's limits), got {speed_scale}"
            ));
        }
        limits.validate().map_err(|e| e.message)?;
        if let Some(i) = points.iter().position(|p| !(p[0].is_finite() && p[1].is_finite())) {
            return Err(format!("point {} is not finite: {:?}", i + 1, points[i]));
        }
        let pts: Vec<[f64; 2]> = points.iter().map(|p| [p[0] as f64, p[1] as f64]).collect();
        let points = resample(&pts)?;
        let n = points.len();
        let spacing_m = closed_length(&points) / n as f64;
        let curvature_1pm = curvature(&points, spacing_m);
        let speed_mps = profile(&curvature_1pm, spacing_m, limits)
            .into_iter()
            .map(|v| v * speed_scale)
            .collect();
        Ok(Self {
            points,
            spacing_m,
            curvature_1pm,
            speed_mps,
            speed_scale,
        })
    }

    /// The path fitted to `track` for a car of `limits`, and how many of its points moved. Each
    /// point further from the centre line than the track allows, its clearance at the nearest
    /// centre-line point less the car's half width less `margin_m` (at least 0), moves
    /// straight towards that centre-line point to that distance; the moved points make a new
    /// path as [`RacePath::new`] does (resampled, with its curvature and speed profile at this
    /// path's scale). A path that needs no move, or a track without clearances, gives the path
    /// unchanged.
    ///
    /// The clearance is the distance to the nearest wall on either side, so the wall the point
    /// moves towards is at least that far from the centre line.
    pub fn fit_to(&self, track: &Track, limits: &CarLimits, margin_m: f64) -> Result<(Self, usize), String> {
        let mut moved = 0;
        let mut points = Vec::with_capacity(self.points.len());
        for &p in &self.points {
            let s = track.centreline_s(p[0] as f32, p[1] as f32);
            let Some(clearance) = track.clearance_at_m(s) else {
                return Ok((self.clone(), 0));
            };
            let (c, _) = track.centreline_at(s);
            let c = [c[0] as f64, c[1] as f64];
            let v = [p[0] - c[0], p[1] - c[1]];
            let off = v[0].hypot(v[1]);
            let room = (clearance as f64 - limits.half_width_m - margin_m).max(0.0);
            if off > room {
                moved += 1;
                let k = room / off;
                points.push([(c[0] + k * v[0]) as f32, (c[1] + k * v[1]) as f32]);
            } else {
                points.push([p[0] as f32, p[1] as f32]);
            }
        }
        if moved == 0 {
            return Ok((self.clone(), 0));
        }
        Ok((Self::new(&points, limits, self.speed_scale)?, moved))
    }

    /// The centre line of `track` (the oval's closed form, or a map-file track's polyline),
    /// sampled every 0.1 m, with the profile of [`RacePath::new`].
    pub fn from_track(track: &Track, limits: &CarLimits, speed_scale: f64) -> Result<Self, String> {
        let lap_m = track.lap_length_m() as f64;
        if !(lap_m.is_finite() && lap_m > 3.0 * SPACING_M) {
            return Err(format!("the track's centre line is {lap_m} m long: no path"));
        }
        let n = (lap_m / SPACING_M).round() as usize;
        let points: Vec<[f32; 2]> = (0..n)
            .map(|k| track.centreline_at((k as f64 * lap_m / n as f64) as f32).0)
            .collect();
        Self::new(&points, limits, speed_scale)
    }

    /// The path of a raceline or centre-line CSV (see [`parse_raceline`]), with the profile of
    /// [`RacePath::new`].
    pub fn from_csv(text: &str, limits: &CarLimits, speed_scale: f64) -> Result<Self, String> {
        Self::new(&parse_raceline(text)?, limits, speed_scale)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the path has no points (never: a path has at least three).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The points, metres, in racing order; the last joins the first.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// Distance between consecutive points, metres.
    pub fn spacing_m(&self) -> f64 {
        self.spacing_m
    }

    /// Signed curvature at each point, 1/m (positive turning left), smoothed.
    pub fn curvatures_1pm(&self) -> &[f64] {
        &self.curvature_1pm
    }

    /// Target speed at each point, m/s.
    pub fn speeds_mps(&self) -> &[f64] {
        &self.speed_mps
    }

    /// Length of the closed path, metres.
    pub fn lap_length_m(&self) -> f64 {
        self.spacing_m * self.points.len() as f64
    }

    /// Time a lap takes at the profile's speeds (each segment at the mean of its ends), seconds.
    pub fn lap_time_s(&self) -> f64 {
        let n = self.len();
        (0..n)
            .map(|i| 2.0 * self.spacing_m / (self.speed_mps[i] + self.speed_mps[(i + 1) % n]))
            .sum()
    }

    /// Index of the point nearest to `p` among `len` points from `first` on (wrapping), and its
    /// squared distance, m^2.
    pub(crate) fn nearest_in(&self, p: [f64; 2], first: usize, len: usize) -> (usize, f64) {
        let n = self.len();
        (0..len.min(n))
            .map(|k| {
                let i = (first + k) % n;
                let q = self.points[i];
                (i, (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2))
            })
            .fold(
                (first % n, f64::INFINITY),
                |best, c| if c.1 < best.1 { c } else { best },
            )
    }
}

/// Parse a raceline: F1TENTH's raceline CSV (`s_m; x_m; y_m; psi_rad; kappa_radpm; vx_mps;
/// ax_mps2`, semicolon-separated, seven columns) or a centre line (`x, y[, ...]`,
/// comma-separated, the same number of columns on every line). Lines starting with `#` and blank
/// lines are skipped, as is a first line of column names. Gives the (x, y) points in metres,
/// without a last point that repeats the first; an error is one line naming the line and what it
/// expected.
pub fn parse_raceline(text: &str) -> Result<Vec<[f32; 2]>, String> {
    let mut points = Vec::new();
    // (semicolon format, number of columns) from the first data line.
    let mut shape: Option<(bool, usize)> = None;
    let mut header_allowed = true;
    for (idx, raw) in text.lines().enumerate() {
        let line_no = idx + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let semicolon = line.contains(';');
        let cols: Vec<&str> = line.split(if semicolon { ';' } else { ',' }).map(str::trim).collect();
        let numbers: Vec<Option<f64>> = cols.iter().map(|c| c.parse::<f64>().ok()).collect();
        if header_allowed && numbers.iter().all(Option::is_none) {
            // A line of column names.
            header_allowed = false;
            continue;
        }
        header_allowed = false;
        let names: Vec<String> = if semicolon {
            F1TENTH_COLUMNS.iter().map(|s| s.to_string()).collect()
        } else {
            (0..cols.len())
                .map(|i| match i {
                    0 => "x_m".to_string(),
                    1 => "y_m".to_string(),
                    _ => format!("column {}", i + 1),
                })
                .collect()
        };
        match shape {
            None if semicolon && cols.len() != F1TENTH_COLUMNS.len() => {
                return Err(format!(
                    "line {line_no}: expected F1TENTH's 7 semicolon-separated columns ({}), got {}",
                    F1TENTH_COLUMNS.join("; "),
                    cols.len()
                ));
            }
            None if !semicolon && cols.len() < 2 => {
                return Err(format!(
                    "line {line_no}: expected comma-separated x_m, y_m (more columns allowed), got '{line}'"
                ));
            }
            None => shape = Some((semicolon, cols.len())),
            Some((semi, n)) if semi != semicolon || n != cols.len() => {
                let (sep, what) = if semi {
                    ("semicolon", F1TENTH_COLUMNS.join("; "))
                } else {
                    ("comma", "x_m, y_m, ...".to_string())
                };
                return Err(format!(
                    "line {line_no}: expected {n} {sep}-separated columns ({what}) as on the first line, got '{line}'"
                ));
            }
            Some(_) => {}
        }
        for (i, (col, number)) in cols.iter().zip(&numbers).enumerate() {
            match number {
                None => {
                    return Err(format!("line {line_no}: {} is '{col}', expected a number", names[i]));
                }
                Some(v) if !v.is_finite() => {
                    return Err(format!("line {line_no}: {} is {v}, expected a finite number", names[i]));
                }
                Some(_) => {}
            }
        }
        let (xi, yi) = if semicolon { (1, 2) } else { (0, 1) };
        let (x, y) = (numbers[xi].unwrap_or_default(), numbers[yi].unwrap_or_default());
        if x.abs() > 1e6 || y.abs() > 1e6 {
            return Err(format!(
                "line {line_no}: ({x}, {y}) is over 1000 km from the origin, expected metres"
            ));
        }
        points.push([x as f32, y as f32]);
    }
    if points.len() > 3 && points.first() == points.last() {
        points.pop();
    }
    if points.is_empty() {
        return Err(format!(
            "no points: expected lines of x_m, y_m (comma-separated) or F1TENTH's {} (semicolon-separated)",
            F1TENTH_COLUMNS.join("; ")
        ));
    }
    if points.len() < 3 {
        return Err(format!("a closed path needs at least 3 points, got {}", points.len()));
    }
    Ok(points)
}

/// Length of the closed polyline through `pts`, metres.
fn closed_length(pts: &[[f64; 2]]) -> f64 {
    let n = pts.len();
    (0..n).map(|i| dist(pts[i], pts[(i + 1) % n])).sum()
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// The closed polyline through `pts` resampled at an even spacing of about [`SPACING_M`].
fn resample(pts: &[[f64; 2]]) -> Result<Vec<[f64; 2]>, String> {
    let len = closed_length(pts);
    if !(len.is_finite() && len > 3.0 * SPACING_M) {
        return Err(format!(
            "the closed path is {len:.3} m long: expected distinct points a lap apart"
        ));
    }
    let n = (len / SPACING_M).round() as usize;
    let step = len / n as f64;
    let mut out = Vec::with_capacity(n);
    let (mut seg, mut seg_start) = (0usize, 0.0f64);
    for k in 0..n {
        let s = k as f64 * step;
        // Walk to the segment holding s (zero-length segments are passed over).
        loop {
            let seg_len = dist(pts[seg], pts[(seg + 1) % pts.len()]);
            if s <= seg_start + seg_len || seg + 1 == pts.len() {
                let (a, b) = (pts[seg], pts[(seg + 1) % pts.len()]);
                let t = if seg_len > 0.0 {
                    ((s - seg_start) / seg_len).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                out.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
                break;
            }
            seg_start += seg_len;
            seg += 1;
        }
    }
    Ok(out)
}

/// Signed curvature at each point of the evenly spaced closed path `pts`, 1/m: the circle
/// through the points [`CURVATURE_HALF_SPAN_M`] behind and ahead, averaged over
/// [`CURVATURE_SMOOTHING_M`] each side. Exact on a circle.
fn curvature(pts: &[[f64; 2]], spacing_m: f64) -> Vec<f64> {
    let n = pts.len();
    let h = ((CURVATURE_HALF_SPAN_M / spacing_m).round() as usize).clamp(1, (n - 1) / 2);
    let raw: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b, c) = (pts[(i + n - h) % n], pts[i], pts[(i + h) % n]);
            let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            let d = dist(a, b) * dist(b, c) * dist(a, c);
            if d > 0.0 { 2.0 * cross / d } else { 0.0 }
        })
        .collect();
    let m = ((CURVATURE_SMOOTHING_M / spacing_m).round() as usize).min((n - 1) / 2);
    (0..n)
        .map(|i| (0..=2 * m).map(|k| raw[(i + n + k - m) % n]).sum::<f64>() / (2 * m + 1) as f64)
        .collect()
}

/// The fastest speed at each point of a closed path with curvature `kappa` and spacing
/// `spacing_m` that `limits` allow (see [`RacePath::new`]).
fn profile(kappa: &[f64], spacing_m: f64, limits: &CarLimits) -> Vec<f64> {
    let n = kappa.len();
    let a_lat = limits.lateral_accel_mps2;
    let k_max = limits.max_curvature_1pm();
    let mut v: Vec<f64> = kappa
        .iter()
        .map(|k| {
            let k = k.abs();
            let mut v = limits.top_speed_mps;
            if k > 0.0 {
                v = v.min((a_lat / k).sqrt());
            }
            if k > k_max {
                v = v.min((a_lat * k_max).sqrt() / k);
            }
            v
        })
        .collect();
    // What the tyres leave for the drive or the brake between points a and b at speed `v`,
    // cornering on the tighter of their curvatures.
    let along =
        |a: usize, b: usize, v: f64| limits.along_while_cornering_mps2(v * v * kappa[a].abs().max(kappa[b].abs()));
    // Two laps each way: a limit anywhere reaches every point it constrains within one lap.
    for step in 1..=2 * n {
        let (prev, i) = ((step - 1) % n, step % n);
        let accel = limits.accel_mps2(v[prev]).min(along(prev, i, v[prev]));
        let reach = (v[prev].powi(2) + 2.0 * accel * spacing_m).sqrt();
        v[i] = v[i].min(reach);
    }
    for step in (0..2 * n).rev() {
        let (i, next) = (step % n, (step + 1) % n);
        let decel = limits.decel_mps2(v[next]).min(along(i, next, v[next]));
        let reach = (v[next].powi(2) + 2.0 * decel * spacing_m).sqrt();
        v[i] = v[i].min(reach);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::tests::{circle, xtenth};

    /// An F1TENTH raceline of a circle of radius `r`, counter-clockwise, in the repository's
    /// format (two id lines, the column header, then `; `-separated rows).
    fn f1tenth_circle(r: f64, n: usize) -> String {
        let mut s = String::from(
            "# 17b4de0d-c737-4d0b-b937-32bd2ef0c95b\n# 603fd3987364b09f9aacb70d1ed12c268e24dd56\n\
             # s_m; x_m; y_m; psi_rad; kappa_radpm; vx_mps; ax_mps2\n",
        );
        for k in 0..n {
            let a = k as f64 * std::f64::consts::TAU / n as f64;
            s += &format!(
                "{:.7}; {:.7}; {:.7}; {:.7}; {:.7}; 8.0000000; 0.0000000\n",
                a * r,
                r * a.cos(),
                r * a.sin(),
                a,
                1.0 / r
            );
        }
        s
    }

    #[test]
    fn an_f1tenth_raceline_and_a_centre_line_csv_parse() {
        let pts = parse_raceline(&f1tenth_circle(3.0, 100)).unwrap();
        assert_eq!(pts.len(), 100);
        assert_eq!(pts[0], [3.0, 0.0]);
        assert!((pts[25][1] - 3.0).abs() < 1e-6, "{:?}", pts[25]);
        // The head of f1tenth_racetracks' Spielberg_raceline.csv, verbatim.
        let spielberg = "# 17b4de0d-c737-4d0b-b937-32bd2ef0c95b\n\
            # 603fd3987364b09f9aacb70d1ed12c268e24dd56\n\
            # s_m; x_m; y_m; psi_rad; kappa_radpm; vx_mps; ax_mps2\n\
            0.0000000; -0.0440806; -0.8491629; 1.8326155; 0.0000525; 8.0000000; 0.0000000\n\
            0.1999592; -0.2372250; -0.9009210; 1.8326266; 0.0000585; 8.0000000; 0.0000000\n\
            0.3999183; -0.4303688; -0.9526814; 1.8326389; 0.0000644; 8.0000000; 0.0000000\n";
        let pts = parse_raceline(spielberg).unwrap();
        let expected: [[f64; 2]; 3] = [
            [-0.0440806, -0.8491629],
            [-0.2372250, -0.9009210],
            [-0.4303688, -0.9526814],
        ];
        assert_eq!(pts.len(), 3);
        for (p, e) in pts.iter().zip(expected) {
            assert_eq!(*p, [e[0] as f32, e[1] as f32]);
        }
        // A centre line with a header line, F1TENTH's track widths, and the first point repeated.
        let centre = "x_m,y_m,w_tr_right_m,w_tr_left_m\n0,0,1,1\n1,0,1,1\n1,1,1,1\n0,0,1,1\n";
        assert_eq!(
            parse_raceline(centre).unwrap(),
            vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]
        );
        // The shipped bean's centre line.
        let bean = include_str!("../../../../assets/tracks/bean.csv");
        assert!(parse_raceline(bean).unwrap().len() > 600);
    }

    #[test]
    fn bad_raceline_csvs_give_one_clear_line_each() {
        let row = "0.0; 1.0; 2.0; 0.0; 0.0; 8.0; 0.0";
        let cases: Vec<(String, &str)> = vec![
            (String::new(), "no points: expected lines of x_m, y_m"),
            ("# only a comment\n\n".into(), "no points"),
            ("0, 0\n1, 0\n".into(), "at least 3 points, got 2"),
            ("0, 0\n1, 0\n1, x\n".into(), "line 3: y_m is 'x', expected a number"),
            (
                "0, 0\n1, 0\n1, NaN\n".into(),
                "line 3: y_m is NaN, expected a finite number",
            ),
            (
                "0, 0\n1, inf\n1, 1\n".into(),
                "line 2: y_m is inf, expected a finite number",
            ),
            (
                "0, 0, 5\n1, 0\n1, 1\n".into(),
                "line 2: expected 3 comma-separated columns",
            ),
            ("0\n1\n2\n".into(), "line 1: expected comma-separated x_m, y_m"),
            (
                format!(
                    "# s_m; x_m; y_m; psi_rad; kappa_radpm; vx_mps; ax_mps2\n{row}\n0.1; 1.1; 2.0; 0.0; 0.0; 8.0\n"
                ),
                "line 3: expected 7 semicolon-separated columns",
            ),
            (
                "0.0; 1.0; 2.0\n".into(),
                "line 1: expected F1TENTH's 7 semicolon-separated columns",
            ),
            (
                format!("{row}\n{row}\n0.2; 1.5; ; 0; 0; 8; 0\n"),
                "line 3: y_m is '', expected a number",
            ),
            (
                format!("{row}\n0, 0\n"),
                "line 2: expected 7 semicolon-separated columns",
            ),
            ("0, 0\n1e9, 0\n1, 1\n".into(), "line 2: (1000000000, 0) is over 1000 km"),
        ];
        for (text, expected) in cases {
            let e = parse_raceline(&text).expect_err(&text);
            assert!(e.contains(expected), "{text:?}: got '{e}', expected '{expected}'");
            assert!(!e.contains('\n'), "one line: {e:?}");
        }
        // Points that parse but make no lap.
        let e = RacePath::new(&[[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]], &xtenth(0.0), 1.0).unwrap_err();
        assert!(e.contains("0.000 m long"), "{e}");
    }

    /// A circle track of centre radius 3 m whose walls are 0.6 m either side.
    fn circle_track() -> Track {
        let track = crate::api::PathTrack::new(circle(3.0, 200)).with_clearance(vec![0.6; 200]);
        Track::Path(track.unwrap())
    }

    /// A raceline 0.05 m from the circle track's outer wall, and one 0.05 m from its inner wall,
    /// move in until every point leaves the car's half width and the margin to the wall.
    #[test]
    fn a_raceline_along_a_wall_is_pulled_in_to_leave_the_car_room() {
        let (limits, track, margin) = (xtenth(0.0), circle_track(), 0.2);
        for r in [3.55, 2.45] {
            let line = RacePath::new(&circle(r, 300), &limits, 1.0).unwrap();
            let (fitted, moved) = line.fit_to(&track, &limits, margin).unwrap();
            assert_eq!(moved, line.len(), "r {r}");
            for p in fitted.points() {
                let (x, y) = (p[0] as f32, p[1] as f32);
                let s = track.centreline_s(x, y);
                let room = track.clearance_at_m(s).unwrap() - track.lateral_offset_m(x, y).abs();
                assert!(
                    room as f64 >= limits.half_width_m + margin - 1e-3,
                    "r {r}: {p:?} leaves {room} m"
                );
            }
            // Pulled in as far as needed, not further: to 0.6 - 0.192 - 0.2 m off the centre line.
            let rho = fitted.points()[0][0].hypot(fitted.points()[0][1]);
            assert!(
                (rho - 3.0).abs() > 0.6 - limits.half_width_m - margin - 2e-3,
                "r {r}: {rho}"
            );
            // A wider path's profile was rebuilt for its new curvature.
            assert!((fitted.curvatures_1pm()[0] - 1.0 / rho).abs() < 0.01, "r {r}");
        }
    }

    /// A raceline that leaves the car room everywhere comes out unchanged, as does any raceline
    /// on a track whose clearance is unknown.
    #[test]
    fn a_raceline_inside_the_track_is_not_moved() {
        let (limits, margin) = (xtenth(0.0), 0.2);
        let line = RacePath::new(&circle(3.15, 300), &limits, 1.0).unwrap();
        let (fitted, moved) = line.fit_to(&circle_track(), &limits, margin).unwrap();
        assert_eq!((moved, &fitted), (0, &line));
        let unknown = Track::Path(crate::api::PathTrack::new(circle(3.0, 200)));
        let wide = RacePath::new(&circle(3.55, 300), &limits, 1.0).unwrap();
        assert_eq!(wide.fit_to(&unknown, &limits, margin).unwrap(), (wide.clone(), 0));
    }

    #[test]
    fn a_speed_scale_outside_zero_to_one_is_refused() {
        let pts = circle(2.0, 100);
        for bad in [0.0, -0.5, 1.5, f64::NAN, f64::INFINITY] {
            let e = RacePath::new(&pts, &xtenth(0.0), bad).unwrap_err();
            assert!(e.starts_with("speed_scale must be in (0, 1]"), "{bad}: {e}");
        }
        let half = RacePath::new(&pts, &xtenth(0.0), 0.5).unwrap();
        let full = RacePath::new(&pts, &xtenth(0.0), 1.0).unwrap();
        for (h, f) in half.speeds_mps().iter().zip(full.speeds_mps()) {
            assert!((h - 0.5 * f).abs() < 1e-12);
        }
    }

    #[test]
    fn a_circles_curvature_and_speed_are_its_closed_forms() {
        let mut limits = xtenth(0.0);
        // Low grip, so the lateral limit binds below the top speed on a 2 m circle; 0.5 m is
        // tighter than the steering's 0.88 m circle, where the yaw-rate limit binds.
        limits.lateral_accel_mps2 = 1.0;
        let k_max = limits.max_curvature_1pm();
        for (r, cw) in [(2.0, false), (4.0, true), (0.5, false)] {
            // A point every 0.1 m, as the shipped bean's centre line.
            let n = (std::f64::consts::TAU * r / 0.1).round() as usize;
            let mut pts = circle(r, n);
            if cw {
                pts.reverse();
            }
            let path = RacePath::new(&pts, &limits, 1.0).unwrap();
            let sign = if cw { -1.0 } else { 1.0 };
            // The resampled points lie on the source's chords, which sag inside the circle by
            // at most c^2 / (8 r) for the source's chords c; the curvature of points that far
            // off the circle over the 0.4 m stencil is 1/r within 1 %.
            let sag = (std::f64::consts::TAU * r / n as f64).powi(2) / (8.0 * r);
            for (i, k) in path.curvatures_1pm().iter().enumerate() {
                assert!((k - sign / r).abs() < 0.01 / r, "r {r}: kappa[{i}] = {k}");
                let p = path.points()[i];
                let off = p[0].hypot(p[1]) - r;
                assert!(off <= 1e-5 && off >= -sag - 1e-5, "point {i} off the circle by {off}");
            }
            // Lateral limit v = sqrt(a r), or the yaw-rate limit sqrt(a k_max) r, uniform around
            // the loop (below the top speed).
            let expected = (1.0 * r).sqrt().min(limits.top_speed_mps).min((1.0 * k_max).sqrt() * r);
            for v in path.speeds_mps() {
                assert!((v - expected).abs() < 0.01 * expected, "r {r}: v {v} vs {expected}");
            }
            let lap = path.lap_length_m();
            assert!((path.lap_length_m() - std::f64::consts::TAU * r).abs() < 0.01);
            assert!((path.lap_time_s() - lap / expected).abs() < 0.01 * path.lap_time_s());
        }
    }

    /// An 8 m square with corners of 1 m radius: the corners get the lateral limit (low grip, so
    /// it binds); the straights brake into them no harder than the drive's deceleration and
    /// accelerate out no harder than its full throttle, braking and driving only with the grip
    /// the cornering leaves, and come close to the top speed between.
    #[test]
    fn the_profile_brakes_into_corners_and_accelerates_out_within_the_drives_limits() {
        for (rc, a_lat, brake) in [(1.0, 1.0, 0.0), (1.0, 1.0, 2.0)] {
            let mut pts = Vec::new();
            let half = 4.0f64;
            for (sx, sy, a0) in [
                (1.0, 1.0, 0.0),
                (-1.0, 1.0, 90.0),
                (-1.0, -1.0, 180.0),
                (1.0, -1.0, 270.0),
            ] {
                let (cx, cy) = (sx * (half - rc), sy * (half - rc));
                for k in 0..=18 {
                    let a = (a0 + 5.0 * k as f64).to_radians();
                    pts.push([(cx + rc * a.cos()) as f32, (cy + rc * a.sin()) as f32]);
                }
            }
            let mut limits = xtenth(brake);
            limits.lateral_accel_mps2 = a_lat;
            let path = RacePath::new(&pts, &limits, 1.0).unwrap();
            let v = path.speeds_mps();
            let ds = path.spacing_m();
            let k_max = limits.max_curvature_1pm();
            let n = path.len();
            for i in 0..n {
                let k = path.curvatures_1pm()[i].abs();
                assert!(v[i] <= (a_lat / k).sqrt() + 1e-12, "point {i}: {} at kappa {k}", v[i]);
                if k > k_max {
                    let yaw_limit = (a_lat * k_max).sqrt() / k;
                    assert!(v[i] <= yaw_limit + 1e-12, "point {i}: {} over {yaw_limit}", v[i]);
                }
                let (a, b) = (v[i], v[(i + 1) % n]);
                let accel = (b * b - a * a) / (2.0 * ds);
                assert!(accel <= limits.accel_mps2(a) + 1e-9, "point {i}: +{accel} m/s^2");
                assert!(-accel <= limits.decel_mps2(b) + 1e-9, "point {i}: -{accel} m/s^2");
                // Braking or driving and cornering share one circle of grip (at the speed the
                // change starts from: the entry's when driving, the exit's when braking).
                let bend = k.max(path.curvatures_1pm()[(i + 1) % n].abs());
                let left = limits.along_while_cornering_mps2(if accel > 0.0 { a } else { b }.powi(2) * bend);
                assert!(
                    accel.abs() <= left + 1e-9,
                    "point {i}: {accel} m/s^2 where {left} is left"
                );
            }
            // The slowest point is the corner's limit at its radius (the curvature at the arc's
            // middle is 1/rc within the smoothing); the fastest is short of the top speed, which
            // the drive only approaches (its acceleration vanishes there), by a few per cent.
            let corner = (a_lat * rc).sqrt();
            let (lo, hi) = v.iter().fold((f64::MAX, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
            assert!(
                (lo - corner).abs() < 0.05 * corner,
                "rc {rc}: slowest {lo}, corner {corner}"
            );
            assert!(
                hi > 0.97 * limits.top_speed_mps && hi < limits.top_speed_mps,
                "rc {rc}: fastest {hi}"
            );
        }
        // A braking drive reaches the corner later, so it spends longer at speed.
        let mut pts = Vec::new();
        for (x, y) in [(4.0, 4.0), (-4.0, 4.0), (-4.0, -4.0), (4.0, -4.0)] {
            pts.push([x, y]);
        }
        let coast = RacePath::new(
            &pts,
            &CarLimits {
                lateral_accel_mps2: 1.0,
                ..xtenth(0.0)
            },
            1.0,
        )
        .unwrap();
        let braked = RacePath::new(
            &pts,
            &CarLimits {
                lateral_accel_mps2: 1.0,
                ..xtenth(2.0)
            },
            1.0,
        )
        .unwrap();
        assert!(braked.lap_time_s() < coast.lap_time_s());
    }

    #[test]
    fn the_ovals_path_is_its_centre_line_at_top_speed() {
        let oval = crate::api::OvalTrack {
            straight_m: 14.0,
            inner_radius_m: 3.0,
            outer_radius_m: 5.0,
        };
        let limits = xtenth(0.0);
        let path = RacePath::from_track(&Track::Oval(oval), &limits, 1.0).unwrap();
        assert!((path.lap_length_m() - oval.lap_length_m() as f64).abs() < 1e-3);
        assert!((path.spacing_m() - 0.1).abs() < 1e-3);
        // Radius 4 m at 0.8 g allows 5.6 m/s: the whole lap is at the top speed.
        for v in path.speeds_mps() {
            assert!((v - limits.top_speed_mps).abs() < 1e-9);
        }
        // Clockwise: negative curvature on the bends.
        let k = path.curvatures_1pm();
        assert!(k.iter().fold(0.0f64, |m, &x| m.min(x)) < -0.24);
        assert!(k.iter().all(|&x| x < 1e-6));
    }
}
