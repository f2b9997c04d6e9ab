//! Race track geometry as the racing task reads it: progress along the centre line and the
//! lateral offset, for the oval (closed form) and for a map-file track (a closed polyline).
//! Plain numbers: the simulator's scene describes the walls, and `SimVehicle` hands the task
//! this from it.

use serde::{Deserialize, Serialize};

/// An oval (stadium) race track: straights along y joined by semicircles centred at
/// (0, +-straight/2). Plain geometry for progress along the centre line.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OvalTrack {
    /// Length of each straight, metres.
    pub straight_m: f32,
    /// Radius of the inner wall's lane-side face, metres.
    pub inner_radius_m: f32,
    /// Radius of the outer wall's lane-side face, metres.
    pub outer_radius_m: f32,
}

impl OvalTrack {
    /// Radius of the centre line, metres.
    pub fn centre_radius_m(&self) -> f32 {
        0.5 * (self.inner_radius_m + self.outer_radius_m)
    }

    /// Length of the centre line, metres.
    pub fn lap_length_m(&self) -> f32 {
        2.0 * self.straight_m + 2.0 * std::f32::consts::PI * self.centre_radius_m()
    }

    /// Arc length (metres, in [0, lap)) of the centre-line point nearest to (x, y), measured
    /// clockwise seen from above (AutoVRL's direction) from the top end of the +x straight
    /// (x = R, y = +straight/2).
    pub fn centreline_s(&self, x: f32, y: f32) -> f32 {
        use std::f32::consts::PI;
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        if y.abs() <= h {
            if x >= 0.0 {
                h - y
            } else {
                self.straight_m + PI * r + (y + h)
            }
        } else if y < -h {
            let a = (-(y + h)).atan2(x).clamp(0.0, PI);
            self.straight_m + a * r
        } else {
            let a = (y - h).atan2(-x).clamp(0.0, PI);
            2.0 * self.straight_m + PI * r + a * r
        }
    }

    /// The centre-line point at arc length `s` and the racing direction there (unit x, y).
    pub fn centreline_at(&self, s: f32) -> ([f32; 2], [f32; 2]) {
        use std::f32::consts::PI;
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        let s = s.rem_euclid(self.lap_length_m());
        let arc = PI * r;
        if s < self.straight_m {
            ([r, h - s], [0.0, -1.0])
        } else if s < self.straight_m + arc {
            let a = (s - self.straight_m) / r;
            ([r * a.cos(), -h - r * a.sin()], [-a.sin(), -a.cos()])
        } else if s < 2.0 * self.straight_m + arc {
            ([-r, -h + (s - self.straight_m - arc)], [0.0, 1.0])
        } else {
            let a = (s - 2.0 * self.straight_m - arc) / r;
            ([-r * a.cos(), h + r * a.sin()], [a.sin(), a.cos()])
        }
    }

    /// Signed distance from the centre line, metres (positive towards the outer wall).
    pub fn lateral_offset_m(&self, x: f32, y: f32) -> f32 {
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        if y.abs() <= h {
            x.abs() - r
        } else {
            let cy = if y > 0.0 { h } else { -h };
            (x * x + (y - cy).powi(2)).sqrt() - r
        }
    }
}

/// A closed centre line as a polyline (a map-file track), in racing order.
#[derive(Clone, Debug, PartialEq)]
pub struct PathTrack {
    points: Vec<[f32; 2]>,
    /// Arc length at each point; the last entry is the lap.
    cum_s: Vec<f32>,
    /// Distance from each point to the nearest wall, metres, when known.
    clearance_m: Option<Vec<f32>>,
    /// A circle (centre x, y, radius) holding each run of [`CHUNK`] segments, so a search
    /// skips the runs that cannot hold the nearest point.
    chunks: Vec<[f32; 3]>,
}

/// Segments per bounding circle of [`PathTrack`]'s search.
const CHUNK: usize = 8;

impl PathTrack {
    /// The closed polyline through `points` (at least 3, not repeating the first at the end).
    pub fn new(points: Vec<[f32; 2]>) -> Self {
        let n = points.len();
        let mut cum_s = Vec::with_capacity(n + 1);
        let mut s = 0.0f32;
        cum_s.push(0.0);
        for i in 0..n {
            let (a, b) = (points[i], points[(i + 1) % n]);
            s += ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            cum_s.push(s);
        }
        let chunks = (0..n.div_ceil(CHUNK))
            .map(|c| {
                // The run's segments' end points: its own and the next run's first.
                let ends = || (c * CHUNK..=((c + 1) * CHUNK).min(n)).map(|i| points[i % n]);
                let (lo, hi) = ends().fold(([f32::MAX; 2], [f32::MIN; 2]), |(lo, hi), p| {
                    ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
                });
                let (cx, cy) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
                let r = ends()
                    .map(|p| ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt())
                    .fold(0.0, f32::max);
                [cx, cy, r]
            })
            .collect();
        Self {
            points,
            cum_s,
            clearance_m: None,
            chunks,
        }
    }

    /// The track with the distance from each centre-line point to the nearest wall, metres (one
    /// per point, in order; a list of another length is an error).
    pub fn with_clearance(mut self, clearance_m: Vec<f32>) -> Result<Self, String> {
        if clearance_m.len() != self.points.len() {
            return Err(format!(
                "{} clearances for {} centre-line points",
                clearance_m.len(),
                self.points.len()
            ));
        }
        self.clearance_m = Some(clearance_m);
        Ok(self)
    }

    /// The centre-line points, metres, in racing order.
    pub fn points(&self) -> &[[f32; 2]] {
        &self.points
    }

    /// Distance from each centre-line point to the nearest wall, metres, when known.
    pub fn clearances_m(&self) -> Option<&[f32]> {
        self.clearance_m.as_deref()
    }

    /// Distance from the centre-line point at arc length `s` to the nearest wall, metres
    /// (linear between the points), when known.
    pub fn clearance_at_m(&self, s: f32) -> Option<f32> {
        let c = self.clearance_m.as_ref()?;
        let n = self.points.len();
        let s = s.rem_euclid(self.lap_length_m());
        let i = self.cum_s[1..].partition_point(|&v| v <= s).min(n - 1);
        let len = self.cum_s[i + 1] - self.cum_s[i];
        let t = if len > 0.0 {
            ((s - self.cum_s[i]) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        Some(c[i] + t * (c[(i + 1) % n] - c[i]))
    }

    /// Length of the centre line, metres.
    pub fn lap_length_m(&self) -> f32 {
        self.cum_s[self.points.len()]
    }

    /// The segment nearest to (x, y): (index, fraction along it, signed distance; positive on
    /// the right of the racing direction).
    fn nearest(&self, x: f32, y: f32) -> (usize, f32, f32) {
        self.nearest_in(0, self.points.len() - 1, x, y)
    }

    /// [`Self::nearest`] among segments `first..=last` (indices, wrapping past the last): the
    /// first in that order at the least distance, as visiting every segment finds it. Runs of
    /// segments whose bounding circle lies farther than a nearest segment's distance are
    /// skipped: that distance bounds the least one, so they cannot hold it.
    fn nearest_in(&self, first: usize, last: usize, x: f32, y: f32) -> (usize, f32, f32) {
        let n = self.points.len();
        // The pieces of runs in range: (first segment, unwrapped; one past the last).
        let pieces = || {
            let mut j = first;
            std::iter::from_fn(move || {
                (j <= last).then(|| {
                    let i = j % n;
                    let end = (j + ((i / CHUNK + 1) * CHUNK).min(n) - i).min(last + 1);
                    let piece = (j, end);
                    j = end;
                    piece
                })
            })
        };
        // The least distance to the segments of the run holding segment j: at least this.
        let below = |j: usize| {
            let [cx, cy, r] = self.chunks[(j % n) / CHUNK];
            ((x - cx) * (x - cx) + (y - cy) * (y - cy)).sqrt() - r
        };
        // A bound on the least distance: the nearest segment of the piece whose circle is
        // nearest. A piece farther than that cannot hold the nearest segment.
        let (j, end) = pieces()
            .min_by(|a, b| below(a.0).total_cmp(&below(b.0)))
            .expect("a segment in range");
        let i0 = j % n;
        let bound = (i0..i0 + end - j)
            .map(|i| self.to_segment(i, x, y).1)
            .fold(f32::INFINITY, f32::min);
        // Beyond rounding.
        let reach = bound.sqrt() + 1e-3;
        let mut best = (0, 0.0, f32::INFINITY, 0.0f32);
        for (j, end) in pieces() {
            if below(j) > reach {
                continue;
            }
            let i0 = j % n;
            for i in i0..i0 + end - j {
                let (t, d2, side) = self.to_segment(i, x, y);
                if d2 < best.2 {
                    best = (i, t, d2, side);
                }
            }
        }
        let d = best.2.sqrt();
        (best.0, best.1, if best.3 > 0.0 { -d } else { d })
    }

    /// From (x, y) to segment `i`: where along it the nearest point lies (0 to 1), the distance
    /// squared, and a side (the cross product of the direction and the offset: negative on the
    /// left).
    fn to_segment(&self, i: usize, x: f32, y: f32) -> (f32, f32, f32) {
        let n = self.points.len();
        let (a, b) = (self.points[i], self.points[(i + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((x - a[0]) * dx + (y - a[1]) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (px, py) = (a[0] + t * dx - x, a[1] + t * dy - y);
        (t, px * px + py * py, dx * (y - a[1]) - dy * (x - a[0]))
    }

    /// Arc length (metres, in [0, lap)) of the centre-line point nearest to (x, y), from the
    /// first point.
    pub fn centreline_s(&self, x: f32, y: f32) -> f32 {
        let (i, t, _) = self.nearest(x, y);
        let s = self.cum_s[i] + t * (self.cum_s[i + 1] - self.cum_s[i]);
        s.rem_euclid(self.lap_length_m())
    }

    /// [`Self::centreline_s`] and [`Self::lateral_offset_m`] of (x, y) from one search.
    pub fn place(&self, x: f32, y: f32) -> (f32, f32) {
        self.place_of(self.nearest(x, y))
    }

    /// [`Self::place`] searching only the centre line within `window_m` of arc length `near_s`:
    /// the place of a point the car sees from there, in the part of the track it is on.
    pub fn place_near(&self, x: f32, y: f32, near_s: f32, window_m: f32) -> (f32, f32) {
        let n = self.points.len();
        let lap = self.lap_length_m();
        if 2.0 * window_m >= lap {
            return self.place(x, y);
        }
        let from_s = (near_s - window_m).rem_euclid(lap);
        let first = self.cum_s[1..].partition_point(|&c| c <= from_s).min(n - 1);
        // The segment holding the window's far end, wrapping past the last.
        let to_s = from_s + 2.0 * window_m;
        let (lap_from, to_s) = if to_s < lap { (0, to_s) } else { (n, to_s - lap) };
        let last = (lap_from + self.cum_s[1..].partition_point(|&c| c < to_s).min(n - 1)).max(first);
        self.place_of(self.nearest_in(first, last, x, y))
    }

    fn place_of(&self, (i, t, d): (usize, f32, f32)) -> (f32, f32) {
        let s = self.cum_s[i] + t * (self.cum_s[i + 1] - self.cum_s[i]);
        (s.rem_euclid(self.lap_length_m()), d)
    }

    /// The centre-line point at arc length `s` and the racing direction there (unit x, y).
    pub fn centreline_at(&self, s: f32) -> ([f32; 2], [f32; 2]) {
        let n = self.points.len();
        let s = s.rem_euclid(self.lap_length_m());
        let i = self.cum_s[1..].partition_point(|&c| c <= s).min(n - 1);
        let (a, b) = (self.points[i], self.points[(i + 1) % n]);
        let len = self.cum_s[i + 1] - self.cum_s[i];
        let t = if len > 0.0 { (s - self.cum_s[i]) / len } else { 0.0 };
        let d = if len > 0.0 {
            [(b[0] - a[0]) / len, (b[1] - a[1]) / len]
        } else {
            [1.0, 0.0]
        };
        ([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])], d)
    }

    /// Distance from the centre line, metres, positive on the right of the racing direction.
    pub fn lateral_offset_m(&self, x: f32, y: f32) -> f32 {
        self.nearest(x, y).2
    }
}

/// A race track: the oval, or a centre line from a map file.
#[derive(Clone, Debug, PartialEq)]
pub enum Track {
    /// The oval (closed form).
    Oval(OvalTrack),
    /// A map-file track's centre line.
    Path(PathTrack),
}

impl Track {
    /// Length of the centre line, metres.
    pub fn lap_length_m(&self) -> f32 {
        match self {
            Self::Oval(t) => t.lap_length_m(),
            Self::Path(t) => t.lap_length_m(),
        }
    }

    /// Arc length of the centre-line point nearest to (x, y), metres in [0, lap).
    pub fn centreline_s(&self, x: f32, y: f32) -> f32 {
        match self {
            Self::Oval(t) => t.centreline_s(x, y),
            Self::Path(t) => t.centreline_s(x, y),
        }
    }

    /// The centre-line point at arc length `s` and the racing direction there.
    pub fn centreline_at(&self, s: f32) -> ([f32; 2], [f32; 2]) {
        match self {
            Self::Oval(t) => t.centreline_at(s),
            Self::Path(t) => t.centreline_at(s),
        }
    }

    /// Signed distance from the centre line, metres (the oval: positive outwards; a centre
    /// line: positive on the right of the racing direction).
    pub fn lateral_offset_m(&self, x: f32, y: f32) -> f32 {
        match self {
            Self::Oval(t) => t.lateral_offset_m(x, y),
            Self::Path(t) => t.lateral_offset_m(x, y),
        }
    }

    /// Signed distance from the centre line, metres, positive on the right of the racing
    /// direction on every track (the oval is raced clockwise: its right is inwards).
    pub fn offset_right_m(&self, x: f32, y: f32) -> f32 {
        match self {
            Self::Oval(t) => -t.lateral_offset_m(x, y),
            Self::Path(t) => t.lateral_offset_m(x, y),
        }
    }

    /// [`Self::centreline_s`] and [`Self::offset_right_m`] of (x, y), a map-file track's from
    /// one search of its centre line.
    pub fn place_m(&self, x: f32, y: f32) -> (f32, f32) {
        match self {
            Self::Oval(t) => (t.centreline_s(x, y), -t.lateral_offset_m(x, y)),
            Self::Path(t) => t.place(x, y),
        }
    }

    /// [`Self::place_m`] searching a map-file track's centre line only within `window_m` of
    /// arc length `near_s` ([`PathTrack::place_near`]).
    pub fn place_near_m(&self, x: f32, y: f32, near_s: f32, window_m: f32) -> (f32, f32) {
        match self {
            Self::Oval(_) => self.place_m(x, y),
            Self::Path(t) => t.place_near(x, y, near_s, window_m),
        }
    }

    /// Distance from the centre-line point at arc length `s` to the nearest wall, metres: the
    /// oval's half lane, `(outer - inner radius) / 2`; a centre line's where the map measured it
    /// (`SimVehicle` does), else None.
    pub fn clearance_at_m(&self, s: f32) -> Option<f32> {
        match self {
            Self::Oval(t) => Some(0.5 * (t.outer_radius_m - t.inner_radius_m)),
            Self::Path(t) => t.clearance_at_m(s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One search gives what the two separate ones give, on the oval and on a centre line, at
    /// points inside, on and outside the track.
    #[test]
    fn a_place_is_its_arc_length_and_right_hand_offset() {
        let oval = Track::Oval(OvalTrack {
            straight_m: 4.0,
            inner_radius_m: 1.5,
            outer_radius_m: 3.5,
        });
        let path = Track::Path(PathTrack::new(vec![
            [0.0, 0.0],
            [6.0, 0.0],
            [8.0, 3.0],
            [5.0, 6.0],
            [-1.0, 4.0],
        ]));
        for track in [oval, path] {
            for i in 0..21 {
                for j in 0..21 {
                    let (x, y) = (-4.0 + 0.6 * i as f32, -5.0 + 0.6 * j as f32);
                    let (s, o) = track.place_m(x, y);
                    assert!((s - track.centreline_s(x, y)).abs() < 1e-4, "{track:?} ({x}, {y})");
                    assert!((o - track.offset_right_m(x, y)).abs() < 1e-4, "{track:?} ({x}, {y})");
                }
            }
        }
    }

    /// Searched near a place, a point within the window gets the place a full search gives;
    /// the window wraps past the centre line's first point.
    #[test]
    fn a_place_searched_near_the_car_is_the_same_within_its_window() {
        let points: Vec<[f32; 2]> = (0..200)
            .map(|k| {
                let a = std::f32::consts::TAU * k as f32 / 200.0;
                [20.0 * a.cos(), 12.0 * a.sin()]
            })
            .collect();
        let track = Track::Path(PathTrack::new(points));
        let lap = track.lap_length_m();
        for k in 0..400 {
            let s = lap * k as f32 / 400.0;
            for (ahead, off) in [(0.0, 0.0), (3.0, 1.2), (7.5, -1.5), (-2.0, 0.7)] {
                let ([px, py], [dx, dy]) = track.centreline_at(s + ahead);
                let (x, y) = (px + off * dy, py - off * dx);
                let (ws, wo) = track.place_near_m(x, y, s, 12.0);
                let (fs, fo) = track.place_m(x, y);
                let ds = (ws - fs).abs();
                assert!(
                    ds.min(lap - ds) < 1e-3 && (wo - fo).abs() < 1e-4,
                    "s {s} +{ahead}: {ws} {wo} / {fs} {fo}"
                );
            }
        }
    }

    /// The search that skips runs of segments gives what visiting every segment gives, bit for
    /// bit, on wobbly closed lines of 3 to 300 points (a run and a part run, many runs), at
    /// points on, near and far from the line, over the whole line and over windows of it that
    /// wrap past its first point.
    #[test]
    fn skipping_far_runs_of_segments_finds_the_nearest_segment_of_all() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for n in [3, 15, 16, 17, 40, 300] {
            let points: Vec<[f32; 2]> = (0..n)
                .map(|k| {
                    let a = std::f32::consts::TAU * k as f32 / n as f32;
                    let r = 10.0 + rng.random_range(-2.0..2.0f32);
                    [r * a.cos(), 0.6 * r * a.sin()]
                })
                .collect();
            let track = PathTrack::new(points.clone());
            for k in 0..4000 {
                let (x, y) = (rng.random_range(-16.0..16.0f32), rng.random_range(-12.0..12.0f32));
                // The whole line, then windows of 1 to n + 1 segments from anywhere.
                let (first, len) = if k % 2 == 0 {
                    (0, n)
                } else {
                    (rng.random_range(0..n), rng.random_range(1..=n + 1))
                };
                // Every segment, in order: the first strictly nearest.
                let mut best = (0, 0.0f32, f32::INFINITY, 0.0f32);
                for i in (first..first + len).map(|j| j % n) {
                    let (a, b) = (points[i], points[(i + 1) % n]);
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let t = (((x - a[0]) * dx + (y - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                    let (px, py) = (a[0] + t * dx - x, a[1] + t * dy - y);
                    let d2 = px * px + py * py;
                    if d2 < best.2 {
                        best = (i, t, d2, dx * (y - a[1]) - dy * (x - a[0]));
                    }
                }
                let d = best.2.sqrt();
                let want = (best.0, best.1, if best.3 > 0.0 { -d } else { d });
                let got = track.nearest_in(first, first + len - 1, x, y);
                assert_eq!(got, want, "{n} points, segments {first} + {len}, ({x}, {y})");
            }
        }
    }
}
