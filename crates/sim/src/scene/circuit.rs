//! Seeded race circuits in the manner of F1TENTH's scaled Formula 1 tracks: a closed centre
//! line of straights and circular arcs (so every corner's radius is known exactly), one width a
//! circuit, and thin walls along both edges, as a [`MapTrack`] that the simulator builds like a
//! loaded map. A new circuit at every episode reset keeps a policy from learning one lap by
//! heart; [`write_map`] saves one as map_server files for the real stack or for a look.
//!
//! A circuit is drawn as a polygon (points round a noisy ellipse, some pulled inward for
//! chicanes, and on a share of narrow circuits a V-shaped spike whose tip is a hairpin), scaled
//! until the filleted lap has the drawn length, every corner rounded with a circular arc. A
//! draw that breaks a property (a corner tighter than allowed, two stretches of track closer
//! than a track width and the wall gap, half a metre by default, no straight to start on) is
//! redrawn from the same generator, so a seed always gives the same circuit. With the gap at
//! 0.2 m (`wall_gap_m`) two stretches' walls may stand back to back, and a hairpin may turn
//! round a thin tip, as in mapped halls.
//!
//! On a share of the sharp corners (`pocket_share`, none by default) the corridor also runs on
//! straight past the corner's entry and ends against a wall: a dead-end pocket, as where a
//! mapped hall runs on past a turn (f1tenth_gym's berlin has one). Driving on into the open
//! space ahead is then a mistake a policy must learn not to make.

use super::MapTrack;
use super::map_track::{MAX_PIXELS, MAX_SIDE_PX, WALL_HEIGHT_M};
use crate::{InvalidSetting, SimError};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};
use std::path::{Path, PathBuf};

/// Depth of a wall box, metres: a thin box on the far side of the edge, as map walls are.
const WALL_DEPTH_M: f64 = 0.1;
/// The widest arc one centre-line segment or one wall face spans, radians (5 degrees).
const MAX_ARC_STEP_RAD: f64 = 5.0 * PI / 180.0;
/// The longest centre-line segment, metres: consumers find the nearest point on segments, and
/// a fine line keeps the progress along it smooth.
const MAX_STEP_M: f64 = 1.0;
/// The width between narrow and wide circuits, metres (F1TENTH's tracks are 2.2 m wide).
const NARROW_WIDTH_M: f32 = 2.0;
/// The largest centre-line radius of a hairpin, metres (F1TENTH's are about 1 m).
const HAIRPIN_MAX_RADIUS_M: f64 = 1.5;
/// The range a hairpin's turn is drawn from, degrees. Past 170 degrees the legs run so nearly
/// parallel that they would have to be a track width apart all along.
const HAIRPIN_TURN_DEG: [f64; 2] = [150.0, 170.0];
/// The default gap between two stretches of track, beyond the width, metres: with 0.1 m walls
/// each side, 0.3 m of open ground stays between them (`CircuitSettings::wall_gap_m`).
const GAP_M: f64 = 0.5;
/// The least gap: the two stretches' walls back to back, one wall 0.2 m thick.
const MIN_GAP_M: f64 = 2.0 * WALL_DEPTH_M;
/// How far into the longest straight the lap starts, metres (at most half the straight).
const START_INTO_STRAIGHT_M: f64 = 3.0;
/// The shortest straight a lap may start on, metres: a car and a little room behind it.
const MIN_START_STRAIGHT_M: f64 = 2.0;
/// Polygon corners turning less than this are dropped, radians (3 degrees): a tiny arc would
/// leave a centre-line segment of millimetres.
const MIN_CORNER_RAD: f64 = 3.0 * PI / 180.0;
/// Polygon corners turning more than this are refused, radians (172 degrees): the track would
/// double back onto itself.
const MAX_CORNER_RAD: f64 = 172.0 * PI / 180.0;
/// The shortest straight between two arcs, metres (shorter ones are mostly given to an arc).
const MIN_LINE_M: f64 = 0.05;
/// Spacing of the points the self-clearance check compares, metres.
const CLEARANCE_STEP_M: f64 = 0.25;
/// Corners turning less than this get no pocket, radians (60 degrees).
const POCKET_MIN_TURN_RAD: f64 = 60.0 * PI / 180.0;
/// The range a pocket's depth past the corner's outer wall is drawn from, metres.
const POCKET_DEPTH_M: [f64; 2] = [1.0, 4.0];
/// Salt of the pockets' own generator: drawing them leaves the shape's draws as they were.
const POCKET_SALT: u64 = 0x706f_636b_6574;
/// Draws of one circuit's shape before giving up.
const MAX_TRIES: usize = 200;
/// The margin round the circuit in a written map image, metres.
const IMAGE_MARGIN_M: f64 = 1.0;

/// What circuits are drawn from: the `[circuit]` settings table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CircuitSettings {
    /// The range the lap length is drawn from, uniformly, once a circuit, metres (centre line).
    /// F1TENTH's scaled F1 circuits are 340 to 460 m.
    pub length_m: [f32; 2],
    /// The range of the track width, wall face to wall face, metres; one width a circuit.
    pub width_m: [f32; 2],
    /// The share of circuits whose width is drawn from `[width_m[0], 2.0]`; the rest draw from
    /// `[2.0, width_m[1]]`. F1TENTH's tracks are 2.2 m wide, so narrow circuits are the real
    /// ones; when `width_m` lies on one side of 2.0 m, both draw from `width_m`.
    pub narrow_share: f32,
    /// The smallest centre-line radius of any corner, metres. Every corner's radius is also at
    /// least half the width plus half `wall_gap_m`, so the inner wall never folds and the two
    /// legs of a hairpin stay a width and the gap apart.
    pub min_radius_m: f32,
    /// The share of circuits with at least one hairpin: a corner turning 150 to 170 degrees
    /// with a centre-line radius drawn in `[max(min_radius_m, (width + wall_gap_m) / 2), 1.5]`
    /// metres. Only circuits narrow enough for that lower bound to stay under 1.5 m (2.5 m
    /// with the default gap) can have one, so the share of all circuits is smaller.
    pub tight_share: f32,
    /// The share of corners turning at least 60 degrees that get a dead-end pocket: the
    /// corridor carried straight on past the corner's entry, one width wide, 1 to 4 m past the
    /// corner's outer wall, closed by a wall (see the module doc). A pocket that would come
    /// near another stretch of track or another pocket is left out.
    pub pocket_share: f32,
    /// Metres per pixel of a map image written by [`write_map`].
    pub resolution_m: f32,
    /// How far apart the walls of two stretches of track stay, beyond the width (centre lines
    /// at least the width plus this apart), metres, at least 0.2. 0.5 (the default) leaves
    /// 0.3 m of open ground between two 0.1 m walls; at 0.2 the walls may stand back to back,
    /// and with `min_radius_m` at most half the width plus 0.1 m a hairpin turns round a tip
    /// 0.1 m wide, as in mapped halls.
    #[serde(skip_serializing_if = "is_default_gap")]
    pub wall_gap_m: f32,
}

fn is_default_gap(g: &f32) -> bool {
    *g == GAP_M as f32
}

impl Default for CircuitSettings {
    /// Lap 50 to 500 m, width 1.5 to 3.5 m (40 % at most 2 m), radii from 1 m, hairpins on half
    /// of the circuits that can have them, 5 cm pixels: F1TENTH's tracks and some smaller and
    /// wider ones around them.
    fn default() -> Self {
        Self {
            length_m: [50.0, 500.0],
            width_m: [1.5, 3.5],
            narrow_share: 0.4,
            min_radius_m: 1.0,
            tight_share: 0.5,
            pocket_share: 0.0,
            resolution_m: 0.05,
            wall_gap_m: GAP_M as f32,
        }
    }
}

impl CircuitSettings {
    /// Check every key: ranges ordered and finite, shares in [0, 1], and a shortest lap room
    /// enough for the widest circuit's corners.
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let bad = |msg: String| Err(InvalidSetting::new("circuit", msg));
        let [l0, l1] = self.length_m;
        if !(l0.is_finite() && l1.is_finite() && (20.0..=2000.0).contains(&l0) && l0 <= l1 && l1 <= 2000.0) {
            return bad(format!(
                "circuit length_m must be an ordered range within [20, 2000] metres, got {:?}",
                self.length_m
            ));
        }
        let [w0, w1] = self.width_m;
        if !(w0.is_finite() && w1.is_finite() && (0.5..=10.0).contains(&w0) && w0 <= w1 && w1 <= 10.0) {
            return bad(format!(
                "circuit width_m must be an ordered range within [0.5, 10] metres, got {:?}",
                self.width_m
            ));
        }
        for (key, v) in [
            ("narrow_share", self.narrow_share),
            ("tight_share", self.tight_share),
            ("pocket_share", self.pocket_share),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return bad(format!("circuit {key} must be in [0, 1], got {v}"));
            }
        }
        if !(self.min_radius_m.is_finite() && self.min_radius_m > 0.0 && self.min_radius_m <= 20.0) {
            return bad(format!(
                "circuit min_radius_m must be in (0, 20] metres, got {}",
                self.min_radius_m
            ));
        }
        let g = self.wall_gap_m;
        if !(g.is_finite() && (MIN_GAP_M as f32..=5.0).contains(&g)) {
            return bad(format!(
                "circuit wall_gap_m must be in [{MIN_GAP_M}, 5] metres (two walls back to back at \
                 least), got {g}"
            ));
        }
        // The widest circuit's tightest corner: a lap must hold a handful of them.
        let r = self.min_radius_m.max(0.5 * (w1 + g));
        if l0 < 20.0 * r {
            return bad(format!(
                "circuit length_m[0] must be at least 20 times the tightest corner's radius \
                 (max(min_radius_m, (width_m[1] + wall_gap_m) / 2) = {r} m), got {l0}"
            ));
        }
        if !(self.resolution_m.is_finite() && (0.01..=0.5).contains(&self.resolution_m)) {
            return bad(format!(
                "circuit resolution_m must be in [0.01, 0.5] metres per pixel, got {}",
                self.resolution_m
            ));
        }
        Ok(())
    }

    /// CRC-32 of the seed and the settings' bytes: which circuit a [`MapTrack`] is.
    fn crc32(&self, seed: u64) -> String {
        let mut crc = crc32fast::Hasher::new();
        crc.update(&seed.to_le_bytes());
        for v in [self.length_m, self.width_m].into_iter().flatten().chain([
            self.narrow_share,
            self.min_radius_m,
            self.tight_share,
            self.resolution_m,
        ]) {
            crc.update(&v.to_le_bytes());
        }
        // Only when set: circuits without pockets or with the default gap keep the names they
        // always had.
        if self.pocket_share > 0.0 {
            crc.update(&self.pocket_share.to_le_bytes());
        }
        if !is_default_gap(&self.wall_gap_m) {
            crc.update(&self.wall_gap_m.to_le_bytes());
        }
        format!("{:08x}", crc.finalize())
    }
}

/// What a generated circuit was drawn as: for logs, and for [`write_map`]'s track width.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CircuitInfo {
    /// The seed it was generated from.
    pub seed: u64,
    /// Lap length of the sampled centre line, metres (what [`MapTrack::lap_length_m`] gives).
    pub length_m: f32,
    /// Track width, wall face to wall face, metres.
    pub width_m: f32,
    /// The smallest centre-line radius of any corner, metres.
    pub min_radius_m: f32,
    /// Whether the lap runs clockwise seen from above (z up).
    pub clockwise: bool,
    /// The dead-end pockets' floors, each a rectangle's corners in order: open ground beside
    /// the track band, walled round (see [`CircuitSettings::pocket_share`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub pockets: Vec<[[f32; 2]; 4]>,
}

/// The per-circuit draws: kept over the redraws of its shape, so that rejection does not bend
/// their distributions.
struct Plan {
    length_m: f64,
    width_m: f64,
    /// The smallest radius any corner may take, metres.
    min_radius_m: f64,
    /// Least distance between two stretches' walls, beyond the width, metres.
    gap_m: f64,
    clockwise: bool,
    hairpin: bool,
}

/// A piece of the centre line, in racing order.
#[derive(Clone, Copy, Debug)]
enum Piece {
    Line {
        from: [f64; 2],
        to: [f64; 2],
    },
    /// An arc round `centre` from the angle `start_rad`, turning `turn_rad` (positive to the
    /// left, counter-clockwise).
    Arc {
        centre: [f64; 2],
        radius_m: f64,
        start_rad: f64,
        turn_rad: f64,
    },
}

impl Piece {
    fn length_m(&self) -> f64 {
        match *self {
            Self::Line { from, to } => dist(from, to),
            Self::Arc { radius_m, turn_rad, .. } => radius_m * turn_rad.abs(),
        }
    }

    /// The point at fraction `u` of the piece, offset `left_m` to the left of the racing line.
    fn at(&self, u: f64, left_m: f64) -> [f64; 2] {
        match *self {
            Self::Line { from, to } => {
                let d = unit(sub(to, from));
                let p = add(from, scale(sub(to, from), u));
                add(p, scale([-d[1], d[0]], left_m))
            }
            Self::Arc {
                centre,
                radius_m,
                start_rad,
                turn_rad,
            } => {
                let a = start_rad + u * turn_rad;
                // The centre is on the left of a left turn: the left edge is the inner one.
                let rho = radius_m - turn_rad.signum() * left_m;
                [centre[0] + rho * a.cos(), centre[1] + rho * a.sin()]
            }
        }
    }

    /// Segments of the sampled centre line: at most `MAX_STEP_M` long, at most
    /// `MAX_ARC_STEP_RAD` of arc.
    fn n_steps(&self) -> usize {
        let by_len = (self.length_m() / MAX_STEP_M - 1e-9).ceil();
        let by_angle = match *self {
            Self::Line { .. } => 1.0,
            Self::Arc { turn_rad, .. } => (turn_rad.abs() / MAX_ARC_STEP_RAD - 1e-9).ceil(),
        };
        by_len.max(by_angle).max(1.0) as usize
    }

    fn shifted(self, by: [f64; 2]) -> Self {
        match self {
            Self::Line { from, to } => Self::Line {
                from: add(from, by),
                to: add(to, by),
            },
            Self::Arc {
                centre,
                radius_m,
                start_rad,
                turn_rad,
            } => Self::Arc {
                centre: add(centre, by),
                radius_m,
                start_rad,
                turn_rad,
            },
        }
    }

    /// The wall boxes along the edge `left_m` to the left of the line (negative: the right),
    /// each on the side away from the track: a straight is one face; an arc is split into
    /// faces of at most `MAX_ARC_STEP_RAD`, inscribed in the edge on the inside of the bend and
    /// circumscribed on the outside, so no face stands in the track. Each face is the part
    /// of it `clip` keeps (given its two ends), if any.
    fn walls(
        &self,
        left_m: f64,
        clip: impl Fn([f64; 2], [f64; 2]) -> Option<([f64; 2], [f64; 2])>,
        out: &mut Vec<[f32; 5]>,
    ) {
        let corners: Vec<[f64; 2]> = match *self {
            Self::Line { .. } => vec![self.at(0.0, left_m), self.at(1.0, left_m)],
            Self::Arc {
                centre,
                radius_m,
                start_rad,
                turn_rad,
            } => {
                let n = (turn_rad.abs() / MAX_ARC_STEP_RAD - 1e-9).ceil().max(1.0) as usize;
                let step = turn_rad / n as f64;
                let rho = radius_m - turn_rad.signum() * left_m;
                let rho = if rho < radius_m { rho } else { rho / (0.5 * step).cos() };
                (0..=n)
                    .map(|k| {
                        let a = start_rad + k as f64 * step;
                        [centre[0] + rho * a.cos(), centre[1] + rho * a.sin()]
                    })
                    .collect()
            }
        };
        for ab in corners.windows(2) {
            if let Some((a, b)) = clip(ab[0], ab[1]) {
                // Away from the track: left of the face for the left wall, right for the right.
                wall_face(a, b, left_m > 0.0, out);
            }
        }
    }
}

/// A wall box whose face runs from `a` to `b`, `WALL_DEPTH_M` deep on the face's left or right.
fn wall_face(a: [f64; 2], b: [f64; 2], on_left: bool, out: &mut Vec<[f32; 5]>) {
    let len = dist(a, b);
    if len < 1e-9 {
        return;
    }
    let d = scale(sub(b, a), 1.0 / len);
    let away = scale([-d[1], d[0]], if on_left { 1.0 } else { -1.0 });
    let c = add(scale(add(a, b), 0.5), scale(away, 0.5 * WALL_DEPTH_M));
    out.push([
        c[0] as f32,
        c[1] as f32,
        // A millimetre longer at each end: no ray slips between two faces at a corner.
        (0.5 * len + 1e-3) as f32,
        (0.5 * WALL_DEPTH_M) as f32,
        d[1].atan2(d[0]) as f32,
    ]);
}

/// A dead-end pocket at a corner: the corridor carried straight on from where the corner's arc
/// starts, `length_m` long, closed at its end. In its own frame x runs along the entry's
/// heading and y towards the corner's inside; the floor is `[0, length_m] x [-w/2, w/2]`.
#[derive(Clone, Copy, Debug)]
struct Pocket {
    /// The index of the corner's arc among the pieces.
    piece: usize,
    /// The arc's start on the centre line, and the heading there.
    at: [f64; 2],
    dir: [f64; 2],
    /// +1 for a left corner, -1 for a right one.
    side: f64,
    half_width_m: f64,
    length_m: f64,
    /// Where the corner's outer wall crosses the pocket's inner side, along x: the inner wall
    /// starts there.
    inner_from_m: f64,
}

impl Pocket {
    /// A point of the pocket's frame in the plane.
    fn world(&self, x: f64, y: f64) -> [f64; 2] {
        let left = [-self.dir[1], self.dir[0]];
        add(self.at, add(scale(self.dir, x), scale(left, self.side * y)))
    }

    /// A point of the plane in the pocket's frame.
    fn local(&self, p: [f64; 2]) -> [f64; 2] {
        let q = sub(p, self.at);
        let left = [-self.dir[1], self.dir[0]];
        [
            q[0] * self.dir[0] + q[1] * self.dir[1],
            self.side * (q[0] * left[0] + q[1] * left[1]),
        ]
    }

    /// The part of the corner's outer wall face `a`-`b` off the floor: the outer wall runs
    /// onto the floor from the mouth and leaves it across the inner side, nowhere else.
    fn clip(&self, a: [f64; 2], b: [f64; 2]) -> Option<([f64; 2], [f64; 2])> {
        let h = self.half_width_m;
        let on = |p: [f64; 2]| {
            let [x, y] = self.local(p);
            x > -1e-3 && y < h
        };
        // Where the face crosses the inner side, when it leaves the floor that way.
        let across = |inside: [f64; 2], outside: [f64; 2]| {
            let (yi, yo) = (self.local(inside)[1], self.local(outside)[1]);
            (yo >= h).then(|| add(inside, scale(sub(outside, inside), (h - yi) / (yo - yi))))
        };
        match (on(a), on(b)) {
            (true, true) => None,
            (false, false) => Some((a, b)),
            (true, false) => Some((across(a, b).unwrap_or(a), b)),
            (false, true) => Some((a, across(b, a).unwrap_or(b))),
        }
    }

    /// The floor's corners, in order round it.
    fn floor(&self) -> [[f32; 2]; 4] {
        let (l, h) = (self.length_m, self.half_width_m);
        [(0.0, -h), (l, -h), (l, h), (0.0, h)].map(|(x, y)| self.world(x, y).map(|v| v as f32))
    }

    /// Its three walls: the outer side on from the entry's outer wall, the end, and the inner
    /// side from where it meets the corner's outer wall. Every box stands off the floor but
    /// the inner side's, which stands on it: off it lies the corner's own track.
    fn walls(&self, out: &mut Vec<[f32; 5]>) {
        let (l, h, d) = (self.length_m, self.half_width_m, WALL_DEPTH_M);
        // Each face runs along +x or +y of the frame with its box on the frame's right; a right
        // corner's frame is mirrored, which puts that on the plane's left.
        let away = self.side < 0.0;
        wall_face(self.world(0.0, -h), self.world(l, -h), away, out);
        wall_face(self.world(l, -h - d), self.world(l, h), away, out);
        wall_face(self.world(self.inner_from_m, h), self.world(l + d, h), away, out);
    }
}

/// The pockets of a circuit (see [`CircuitSettings::pocket_share`]): on each corner turning
/// at least `POCKET_MIN_TURN_RAD` whose outer wall crosses the pocket's inner side on the arc,
/// with chance `share`, unless its new floor or walls would come within a wall's depth and a
/// sampling step of another stretch's track band or of an earlier pocket.
fn pockets(pieces: &[Piece], width_m: f64, gap_m: f64, share: f64, seed: u64) -> Vec<Pocket> {
    let mut rng = StdRng::seed_from_u64(seed);
    let h = 0.5 * width_m;
    let pts = sampled(pieces, CLEARANCE_STEP_M);
    let lap: f64 = pieces.iter().map(Piece::length_m).sum();
    let mut s0 = 0.0;
    let mut out: Vec<(Pocket, Vec<[f64; 2]>)> = Vec::new();
    for (i, p) in pieces.iter().enumerate() {
        let s_start = s0;
        s0 += p.length_m();
        // Both draws on every piece: whether one corner gets a pocket never moves another's.
        let (chance, depth) = (
            rng.random::<f64>(),
            uniform(&mut rng, POCKET_DEPTH_M[0], POCKET_DEPTH_M[1]),
        );
        let Piece::Arc {
            radius_m: r,
            turn_rad,
            start_rad,
            ..
        } = *p
        else {
            continue;
        };
        // The outer wall (radius r + h round the centre, which sits r to the inside) crosses
        // the line y = h at the angle `cross` into the corner.
        let cross = ((r - h) / (r + h)).acos();
        if chance >= share || turn_rad.abs() < POCKET_MIN_TURN_RAD.max(cross + MAX_ARC_STEP_RAD) {
            continue;
        }
        let a = p.at(0.0, 0.0);
        // x^2 + (h - r)^2 = (r + h)^2 on the outer wall's circle.
        let inner_from_m = (2.0 * r * width_m).sqrt();
        let pocket = Pocket {
            piece: i,
            at: a,
            // The tangent where the arc starts, turning the arc's way.
            dir: scale([-start_rad.sin(), start_rad.cos()], turn_rad.signum()),
            side: turn_rad.signum(),
            half_width_m: h,
            length_m: inner_from_m + depth,
            inner_from_m,
        };
        // The new ground: the floor and its walls, beyond the corner's outer wall.
        let step = CLEARANCE_STEP_M;
        let (nx, ny) = (
            ((pocket.length_m + 0.1) / step).ceil() as usize,
            ((width_m + 0.2) / step).ceil() as usize,
        );
        let centre = [0.0, r];
        let new: Vec<[f64; 2]> = (0..=nx)
            .flat_map(|ix| (0..=ny).map(move |iy| [ix as f64 * step, -h - 0.1 + iy as f64 * step]))
            .filter(|q| dist(*q, centre) > r + h)
            .map(|[x, y]| pocket.world(x, y))
            .collect();
        // Stretches other than the corner and the way into it, whose band a wall and a step
        // beyond the pocket's floor may not reach.
        let reach = h + WALL_DEPTH_M + step;
        let (from, to) = (s_start - 2.0 * (width_m + gap_m), s0);
        let near_corner = |s: f64| (s - from).rem_euclid(lap) <= to - from;
        let around = pocket.length_m + width_m + reach;
        let others: Vec<[f64; 2]> = pts
            .iter()
            .filter(|&&(c, s)| !near_corner(s) && dist(c, a) < around)
            .map(|&(c, _)| c)
            .collect();
        let crowded = new.iter().any(|q| {
            others.iter().any(|c| dist(*c, *q) < reach)
                || out
                    .iter()
                    .any(|(_, other)| other.iter().any(|o| dist(*o, *q) < 2.0 * WALL_DEPTH_M + step))
        });
        if !crowded {
            out.push((pocket, new));
        }
    }
    out.into_iter().map(|(k, _)| k).collect()
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn scale(a: [f64; 2], k: f64) -> [f64; 2] {
    [a[0] * k, a[1] * k]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn unit(a: [f64; 2]) -> [f64; 2] {
    let n = a[0].hypot(a[1]);
    if n > 0.0 { scale(a, 1.0 / n) } else { [1.0, 0.0] }
}

/// Uniform in `[lo, hi)`, or `lo` when the range is empty (a degenerate settings range).
fn uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    if hi > lo { rng.random_range(lo..hi) } else { lo }
}

/// The signed turn from direction `a` to direction `b`, radians in (-pi, pi], left positive.
fn turn_between(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] * b[1] - a[1] * b[0]).atan2(a[0] * b[0] + a[1] * b[1])
}

/// Why a draw was refused.
type Reject = &'static str;

impl MapTrack {
    /// A seeded race circuit drawn from `settings` (see the module doc), with what it was
    /// drawn as. The same seed and settings give the same circuit, bit for bit. The lap starts
    /// a few metres into its longest straight, so a car spawned at the first point heading to
    /// the second stands clear of the walls.
    ///
    /// Errors when the settings are invalid, or when no draw of the circuit's shape met the
    /// properties within a bounded number of tries (settings at the edge of the possible).
    pub fn generated(seed: u64, settings: &CircuitSettings) -> Result<(MapTrack, CircuitInfo), SimError> {
        let name = format!("circuit-{seed}");
        let invalid = |msg: String| SimError::Invalid {
            context: name.clone(),
            msg,
        };
        settings.validate().map_err(|e| invalid(e.message))?;
        let s = settings;
        let mut rng = StdRng::seed_from_u64(seed);
        let length_m = uniform(&mut rng, s.length_m[0] as f64, s.length_m[1] as f64);
        let split = NARROW_WIDTH_M.clamp(s.width_m[0], s.width_m[1]);
        let narrow = rng.random::<f32>() < s.narrow_share;
        let width_m = match narrow && split > s.width_m[0] || split >= s.width_m[1] {
            true => uniform(&mut rng, s.width_m[0] as f64, split as f64),
            false => uniform(&mut rng, split as f64, s.width_m[1] as f64),
        };
        let gap_m = s.wall_gap_m as f64;
        let min_radius_m = (s.min_radius_m as f64).max(0.5 * (width_m + gap_m));
        let clockwise = rng.random_bool(0.5);
        let tight = rng.random::<f32>() < s.tight_share;
        let plan = Plan {
            length_m,
            width_m,
            min_radius_m,
            gap_m,
            clockwise,
            hairpin: tight && min_radius_m <= HAIRPIN_MAX_RADIUS_M,
        };
        let mut last = "";
        for _ in 0..MAX_TRIES {
            let pieces = match draw_shape(&mut rng, &plan) {
                Ok(p) => p,
                Err(why) => {
                    last = why;
                    continue;
                }
            };
            let (pieces, centreline) = start_and_centre(pieces);
            let pockets = match s.pocket_share > 0.0 {
                true => pockets(&pieces, width_m, gap_m, s.pocket_share as f64, seed ^ POCKET_SALT),
                false => Vec::new(),
            };
            let mut walls = Vec::with_capacity(4 * centreline.len());
            for (i, p) in pieces.iter().enumerate() {
                let pocket = pockets.iter().find(|k| k.piece == i);
                for left_m in [0.5 * width_m, -0.5 * width_m] {
                    let outer = pocket.filter(|k| k.side * left_m < 0.0);
                    p.walls(left_m, |a, b| outer.map_or(Some((a, b)), |k| k.clip(a, b)), &mut walls);
                }
            }
            for k in &pockets {
                k.walls(&mut walls);
            }
            let min_radius = pieces
                .iter()
                .filter_map(|p| match *p {
                    Piece::Arc { radius_m, .. } => Some(radius_m),
                    Piece::Line { .. } => None,
                })
                .fold(f64::INFINITY, f64::min);
            let track = MapTrack {
                name: name.clone(),
                crc32: s.crc32(seed),
                resolution_m: s.resolution_m,
                wall_height_m: WALL_HEIGHT_M,
                walls,
                centreline: centreline.iter().map(|p| [p[0] as f32, p[1] as f32]).collect(),
                centreline_source: "generated".into(),
            };
            track.validate().map_err(&invalid)?;
            let info = CircuitInfo {
                seed,
                length_m: track.lap_length_m(),
                width_m: width_m as f32,
                min_radius_m: min_radius as f32,
                clockwise,
                pockets: pockets.iter().map(Pocket::floor).collect(),
            };
            return Ok((track, info));
        }
        Err(invalid(format!(
            "no draw of a {length_m:.0} m circuit {width_m:.2} m wide{} met the circuit's properties in \
             {MAX_TRIES} tries (the last: {last}); widen circuit length_m or narrow width_m",
            if plan.hairpin { " with a hairpin" } else { "" }
        )))
    }
}

/// A corner of the circuit's polygon.
#[derive(Clone, Copy, Debug)]
struct Corner {
    at: [f64; 2],
    /// The radius its arc takes where the edges leave room, metres.
    radius_m: f64,
    /// A hairpin's tip or foot: dropping it would change the hairpin's turn.
    keep: bool,
}

/// One draw of the circuit's shape: the centre line as pieces in racing order, or why the draw
/// fails a property.
fn draw_shape(rng: &mut StdRng, plan: &Plan) -> Result<Vec<Piece>, Reject> {
    let (len, r_min) = (plan.length_m, plan.min_radius_m);
    // Corners: more on a longer lap (a real circuit has a dozen or two); a hairpin's spike
    // brings three.
    let n_lo = 4 + (len / 70.0) as usize;
    let n_hi = (6 + (len / 30.0) as usize).min(24) - if plan.hairpin { 2 } else { 0 };
    let n = rng.random_range(n_lo..=n_hi.max(n_lo));
    let aspect = rng.random_range(0.45..1.0);
    let (sin_spin, cos_spin) = rng.random_range(0.0..TAU).sin_cos();
    // Radii are log-uniform: tight corners as often as open ones.
    let r_max = (1.5 * r_min).max(0.05 * len);
    let corner = |rng: &mut StdRng, at: [f64; 2]| Corner {
        at,
        radius_m: rng.random_range(r_min.ln()..r_max.ln()).exp(),
        keep: false,
    };
    let mut poly: Vec<Corner> = Vec::with_capacity(n + 3);
    let mut pulled = false;
    for k in 0..n {
        let a = TAU * (k as f64 + rng.random_range(-0.35..0.35)) / n as f64;
        let mut rho = rng.random_range(0.75..1.25);
        // Pulled towards the middle: a concave bend between two convex ones (a chicane), never
        // two in a row (a cavity).
        pulled = !pulled && rng.random_bool(0.3);
        if pulled {
            rho *= rng.random_range(0.35..0.7);
        }
        let (x, y) = (rho * a.cos(), aspect * rho * a.sin());
        poly.push(corner(rng, [cos_spin * x - sin_spin * y, sin_spin * x + cos_spin * y]));
    }
    let edge = |poly: &[Corner], i: usize| dist(poly[i].at, poly[(i + 1) % poly.len()].at);
    let perimeter = |poly: &[Corner]| (0..poly.len()).map(|i| edge(poly, i)).sum::<f64>();
    let grow = |poly: &mut [Corner], k: f64| poly.iter_mut().for_each(|c| c.at = scale(c.at, k));
    if plan.hairpin {
        // A V-shaped spike on one edge, its tip the hairpin: legs `leg` long at `apex` to each
        // other, long enough for the tip's arc and the arcs where they leave the edge. The
        // sharper the turn, the longer the legs its arc needs: on a short lap the turn is held
        // to what legs of a fifth of the lap can carry (150 degrees at least).
        let tip_radius = uniform(rng, r_min, HAIRPIN_MAX_RADIUS_M);
        let [lo, hi] = HAIRPIN_TURN_DEG.map(f64::to_radians);
        let t_foot_max = r_min * (0.25 * (2.0 * PI - lo)).tan();
        let hi = hi.min(2.0 * ((0.2 * len / 1.15 - t_foot_max) / tip_radius).atan());
        let turn = uniform(rng, lo, hi);
        let apex = PI - turn;
        let t_tip = tip_radius * (0.5 * turn).tan();
        let t_foot = r_min * (0.25 * (PI + apex)).tan();
        let leg = (t_tip + t_foot) * rng.random_range(1.15..1.6) + rng.random_range(0.0..0.03 * len);
        let (half_base, height) = (leg * (0.5 * apex).sin(), leg * (0.5 * apex).cos());
        let inward = rng.random_bool(0.5);
        let place = rng.random_range(0.3..0.7);
        let k = (len - 2.0 * (leg - half_base)) / perimeter(&poly);
        grow(&mut poly, k);
        // The longest edge: the most room for the spike's feet.
        let j = (0..n)
            .max_by(|&a, &b| edge(&poly, a).total_cmp(&edge(&poly, b)))
            .unwrap_or(0);
        let (a, b) = (poly[j].at, poly[(j + 1) % n].at);
        let d = unit(sub(b, a));
        let mid = add(a, scale(sub(b, a), place));
        // The polygon runs counter-clockwise here: outward is to the right.
        let side = if inward { [-d[1], d[0]] } else { [d[1], -d[0]] };
        let mut spike = [
            corner(rng, sub(mid, scale(d, half_base))),
            corner(rng, add(mid, scale(side, height))),
            corner(rng, add(mid, scale(d, half_base))),
        ];
        spike[1].radius_m = tip_radius;
        spike.iter_mut().for_each(|c| c.keep = true);
        poly.splice(j + 1..j + 1, spike);
    } else {
        let k = len / perimeter(&poly);
        grow(&mut poly, k);
    }
    if plan.clockwise {
        poly.reverse();
    }
    // Scale until the filleted lap has the drawn length (the fillets shorten it by about the
    // same whatever the scale), dropping corners that hardly turn or crowd another.
    for _ in 0..8 + poly.len() {
        if poly.len() < 4 {
            return Err("fewer than four corners");
        }
        let turns = corner_turns(&poly);
        if let Some(i) = (0..poly.len()).find(|&i| turns[i].abs() < MIN_CORNER_RAD && !poly[i].keep) {
            poly.remove(i);
            continue;
        }
        let pieces = match fillet(&poly, r_min) {
            Ok(p) => p,
            Err(Some(i)) => {
                poly.remove(i);
                continue;
            }
            Err(None) => return Err("a hairpin crowded by another corner"),
        };
        let lap: f64 = pieces.iter().map(Piece::length_m).sum();
        if (lap - len).abs() < 2e-3 * len {
            let longest = pieces
                .iter()
                .filter(|p| matches!(p, Piece::Line { .. }))
                .map(Piece::length_m)
                .fold(0.0, f64::max);
            if longest < MIN_START_STRAIGHT_M {
                return Err("no straight to start on");
            }
            if !clear_of_itself(&pieces, plan.width_m, plan.gap_m) {
                return Err("two stretches of track closer than the width and the gap");
            }
            return Ok(pieces);
        }
        let k = 1.0 + (len - lap) / perimeter(&poly);
        if k <= 0.0 {
            return Err("the corners alone are longer than the lap");
        }
        grow(&mut poly, k);
    }
    Err("the lap length did not settle")
}

/// The signed turn at each corner of a closed polygon, radians, left positive.
fn corner_turns(poly: &[Corner]) -> Vec<f64> {
    let m = poly.len();
    (0..m)
        .map(|i| {
            let (prev, at, next) = (poly[(i + m - 1) % m].at, poly[i].at, poly[(i + 1) % m].at);
            turn_between(sub(at, prev), sub(next, at))
        })
        .collect()
}

/// Round every corner of the closed polygon with a circular arc: the corner's radius where the
/// neighbouring edges leave room, less where they do not, never less than `r_min`. The tangent
/// length of a corner turning `phi` with radius `r` is `r tan(phi / 2)`, and two corners share
/// an edge. Where a corner doubles back or two corners crowd an edge even at `r_min`, the
/// error names a corner to drop (None when both are a hairpin's).
fn fillet(poly: &[Corner], r_min: f64) -> Result<Vec<Piece>, Option<usize>> {
    let m = poly.len();
    let turns = corner_turns(poly);
    if let Some(i) = (0..m).find(|&i| turns[i].abs() > MAX_CORNER_RAD) {
        return Err((!poly[i].keep).then_some(i));
    }
    // Edge i runs from corner i to corner i + 1.
    let edge: Vec<f64> = (0..m).map(|i| dist(poly[i].at, poly[(i + 1) % m].at)).collect();
    let dir: Vec<[f64; 2]> = (0..m).map(|i| unit(sub(poly[(i + 1) % m].at, poly[i].at))).collect();
    let k: Vec<f64> = turns.iter().map(|t| (0.5 * t.abs()).tan()).collect();
    let t_min: Vec<f64> = k.iter().map(|k| r_min * k).collect();
    if let Some(i) = (0..m).find(|&i| t_min[i] + t_min[(i + 1) % m] > edge[i]) {
        // The gentler corner goes, unless it is a hairpin's.
        let j = (i + 1) % m;
        let (soft, hard) = if turns[i].abs() < turns[j].abs() {
            (i, j)
        } else {
            (j, i)
        };
        return Err([soft, hard].into_iter().find(|&c| !poly[c].keep));
    }
    let mut t: Vec<f64> = (0..m)
        .map(|i| {
            let prev = (i + m - 1) % m;
            (poly[i].radius_m * k[i])
                .min(edge[prev] - t_min[prev])
                .min(edge[i] - t_min[(i + 1) % m])
                .max(t_min[i])
        })
        .collect();
    // Where two corners still want more of an edge than it has, each gives up a share of what
    // it holds above its smallest arc; shrinking never overfills another edge.
    for i in 0..m {
        let j = (i + 1) % m;
        let over = t[i] + t[j] - edge[i];
        if over > 0.0 {
            let (si, sj) = (t[i] - t_min[i], t[j] - t_min[j]);
            let slack = (si + sj).max(1e-12);
            t[i] -= over * si / slack;
            t[j] -= over * sj / slack;
        }
    }
    // A line of a few centimetres would leave a centre-line segment too short to carry a
    // heading: a neighbouring arc takes it when the edge behind that arc has room.
    let line = |t: &[f64], e: usize| edge[e] - t[e] - t[(e + 1) % m];
    for i in 0..m {
        let (prev, next) = ((i + m - 1) % m, (i + 1) % m);
        let short = line(&t, i);
        if short > 0.0 && short < MIN_LINE_M {
            if line(&t, prev) >= short + MIN_LINE_M {
                t[i] += short;
            } else if line(&t, next) >= short + MIN_LINE_M {
                t[next] += short;
            }
        }
    }
    let mut pieces = Vec::with_capacity(2 * m);
    for i in 0..m {
        let (prev, next) = ((i + m - 1) % m, (i + 1) % m);
        let v = poly[i].at;
        let start = sub(v, scale(dir[prev], t[i]));
        let r = t[i] / k[i];
        let left = [-dir[prev][1], dir[prev][0]];
        let centre = add(start, scale(left, r * turns[i].signum()));
        pieces.push(Piece::Arc {
            centre,
            radius_m: r,
            start_rad: (start[1] - centre[1]).atan2(start[0] - centre[0]),
            turn_rad: turns[i],
        });
        if line(&t, i) > 1e-9 {
            pieces.push(Piece::Line {
                from: add(v, scale(dir[i], t[i])),
                to: sub(poly[next].at, scale(dir[i], t[next])),
            });
        }
    }
    Ok(pieces)
}

/// Whether every two points of the line more than pi (w + gap) apart along the lap (the shorter
/// way round) are at least w + gap apart in the plane: no two stretches of track touch or come
/// closer than the gap between their walls. Points `CLEARANCE_STEP_M` apart are compared with
/// both bounds moved by the step, so the check holds for the continuous line, not only for the
/// points.
fn clear_of_itself(pieces: &[Piece], width_m: f64, gap_m: f64) -> bool {
    let step = CLEARANCE_STEP_M;
    let gap = width_m + gap_m;
    let (near, along) = (gap + step, PI * gap - step);
    let pts = sampled(pieces, step);
    let lap: f64 = pieces.iter().map(Piece::length_m).sum();
    // Points bucketed in cells `near` a side: a close pair lies in neighbouring cells.
    let cell = |p: [f64; 2]| ((p[0] / near).floor() as i64, (p[1] / near).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    for (i, (p, _)) in pts.iter().enumerate() {
        grid.entry(cell(*p)).or_default().push(i);
    }
    pts.iter().enumerate().all(|(i, &(p, s))| {
        let (cx, cy) = cell(p);
        (-1..=1).all(|dx| {
            (-1..=1).all(|dy| {
                grid.get(&(cx + dx, cy + dy)).is_none_or(|v| {
                    v.iter().all(|&j| {
                        let d_s = (pts[j].1 - s).abs();
                        j <= i || d_s.min(lap - d_s) <= along || dist(pts[j].0, p) >= near
                    })
                })
            })
        })
    })
}

/// Points of the centre line at most `step` apart, each with its distance along the lap.
fn sampled(pieces: &[Piece], step: f64) -> Vec<([f64; 2], f64)> {
    let mut pts = Vec::new();
    let mut s0 = 0.0;
    for p in pieces {
        let l = p.length_m();
        let n = (l / step).ceil().max(1.0) as usize;
        pts.extend((0..n).map(|k| (p.at(k as f64 / n as f64, 0.0), s0 + l * k as f64 / n as f64)));
        s0 += l;
    }
    pts
}

/// The pieces rotated so that the lap starts `START_INTO_STRAIGHT_M` into its longest
/// straight (at most half way), shifted so the circuit's bounding box is centred on the
/// origin (the ground a scene lays is centred there), and the sampled centre line.
fn start_and_centre(pieces: Vec<Piece>) -> (Vec<Piece>, Vec<[f64; 2]>) {
    let (i, l) = pieces
        .iter()
        .enumerate()
        .filter(|(_, p)| matches!(p, Piece::Line { .. }))
        .map(|(i, p)| (i, p.length_m()))
        .fold((0, -1.0), |best, c| if c.1 > best.1 { c } else { best });
    let mut ordered = Vec::with_capacity(pieces.len() + 1);
    if let Piece::Line { from, to } = pieces[i] {
        let start = pieces[i].at(START_INTO_STRAIGHT_M.min(0.5 * l) / l, 0.0);
        ordered.push(Piece::Line { from: start, to });
        ordered.extend_from_slice(&pieces[i + 1..]);
        ordered.extend_from_slice(&pieces[..i]);
        ordered.push(Piece::Line { from, to: start });
    }
    let sample = |pieces: &[Piece]| -> Vec<[f64; 2]> {
        let mut pts = Vec::new();
        for p in pieces {
            let n = p.n_steps();
            pts.extend((0..n).map(|k| p.at(k as f64 / n as f64, 0.0)));
        }
        pts
    };
    let pts = sample(&ordered);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &pts {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let by = scale(add(lo, hi), -0.5);
    let ordered: Vec<Piece> = ordered.into_iter().map(|p| p.shifted(by)).collect();
    let pts = sample(&ordered);
    (ordered, pts)
}

/// Write `track` as ROS map_server files in `dir` and return the YAML's path: `NAME.yaml`
/// (trinary, 0.65 / 0.196 thresholds), `NAME.png` (8-bit grey: 254 on the track band between
/// the walls, 0 elsewhere, with a metre's margin round the circuit) and `NAME.csv` (the centre
/// line in F1TENTH's TUM format, `x, y, w/2, w/2` a line). Each file is written under a
/// temporary name and renamed into place, the YAML last: a reader never finds half a map.
/// [`MapTrack::load`] gives the circuit back, its walls traced from the image.
pub fn write_map(track: &MapTrack, info: &CircuitInfo, dir: &Path) -> Result<PathBuf, SimError> {
    let invalid = |msg: String| SimError::Invalid {
        context: format!("map of {}", track.name),
        msg,
    };
    track.validate().map_err(invalid)?;
    let res = track.resolution_m as f64;
    let half_w = 0.5 * info.width_m as f64;
    let line: Vec<[f64; 2]> = track.centreline.iter().map(|p| [p[0] as f64, p[1] as f64]).collect();
    let pockets: Vec<[[f64; 2]; 4]> = info.pockets.iter().map(|q| q.map(|p| p.map(f64::from))).collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &line {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a] - half_w - IMAGE_MARGIN_M);
            hi[a] = hi[a].max(p[a] + half_w + IMAGE_MARGIN_M);
        }
    }
    for p in pockets.iter().flatten() {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a] - IMAGE_MARGIN_M);
            hi[a] = hi[a].max(p[a] + IMAGE_MARGIN_M);
        }
    }
    // The origin on the pixel grid of the world, so that two maps of one circuit line up.
    let origin = [(lo[0] / res).floor() * res, (lo[1] / res).floor() * res];
    let (w, h) = (
        ((hi[0] - origin[0]) / res).ceil() as u64,
        ((hi[1] - origin[1]) / res).ceil() as u64,
    );
    if w > MAX_SIDE_PX as u64 || h > MAX_SIDE_PX as u64 || w * h > MAX_PIXELS {
        return Err(invalid(format!(
            "the image would be {w} x {h} pixels, more than a map loads ({MAX_SIDE_PX} a side, \
             {MAX_PIXELS} in all): raise circuit resolution_m"
        )));
    }
    let (w, h) = (w as usize, h as usize);
    // Free where a pixel's centre lies within half the width of the centre line, or on a
    // pocket's floor: each segment's capsule and each floor paints the pixels of its box.
    let mut px = vec![0u8; w * h];
    let mut paint = |lo: [f64; 2], hi: [f64; 2], inside: &dyn Fn([f64; 2]) -> bool| {
        let c0 = ((lo[0] - origin[0]) / res).floor().max(0.0) as usize;
        let c1 = (((hi[0] - origin[0]) / res).ceil() as usize).min(w);
        let r0 = ((lo[1] - origin[1]) / res).floor().max(0.0) as usize;
        let r1 = (((hi[1] - origin[1]) / res).ceil() as usize).min(h);
        for r in r0..r1 {
            let y = origin[1] + (r as f64 + 0.5) * res;
            for c in c0..c1 {
                if inside([origin[0] + (c as f64 + 0.5) * res, y]) {
                    // Image rows run from the top.
                    px[(h - 1 - r) * w + c] = 254;
                }
            }
        }
    };
    for i in 0..line.len() {
        let (a, b) = (line[i], line[(i + 1) % line.len()]);
        let ab = sub(b, a);
        let len2 = (ab[0] * ab[0] + ab[1] * ab[1]).max(1e-18);
        let near = |p: [f64; 2]| {
            let ap = sub(p, a);
            let u = ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0);
            dist(p, add(a, scale(ab, u))) <= half_w
        };
        let lo = [a[0].min(b[0]) - half_w, a[1].min(b[1]) - half_w];
        let hi = [a[0].max(b[0]) + half_w, a[1].max(b[1]) + half_w];
        paint(lo, hi, &near);
    }
    for q in &pockets {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in q {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        // Inside its four sides: on the same side of each.
        let on_floor = |p: [f64; 2]| {
            let s: [f64; 4] = std::array::from_fn(|k| {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
            });
            s.iter().all(|v| *v >= 0.0) || s.iter().all(|v| *v <= 0.0)
        };
        paint(lo, hi, &on_floor);
    }
    let img = image::GrayImage::from_raw(w as u32, h as u32, px)
        .ok_or_else(|| invalid("the image buffer does not match its size".into()))?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| invalid(format!("cannot encode the image: {e}")))?;
    let mut csv = String::from("# x_m, y_m, w_tr_right_m, w_tr_left_m\n");
    for p in &track.centreline {
        // f32's shortest form reads back to the same f32.
        csv += &format!("{}, {}, {half_w}, {half_w}\n", p[0], p[1]);
    }
    let yaml = format!(
        "image: {name}.png\nresolution: {res}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n\
         free_thresh: 0.196\nmode: trinary\n",
        origin[0],
        origin[1],
        name = track.name
    );
    let path = |ext: &str| dir.join(format!("{}.{ext}", track.name));
    write_atomic(&path("png"), png.get_ref())?;
    write_atomic(&path("csv"), csv.as_bytes())?;
    write_atomic(&path("yaml"), yaml.as_bytes())?;
    Ok(path("yaml"))
}

/// [`crate::write_atomic`], its error naming `path`.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SimError> {
    crate::write_atomic(path, bytes).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(length_m: f64, width_m: f64, clockwise: bool, hairpin: bool) -> Plan {
        Plan {
            length_m,
            width_m,
            min_radius_m: (0.5 * (width_m + GAP_M)).max(1.0),
            gap_m: GAP_M,
            clockwise,
            hairpin,
        }
    }

    /// A stadium: two straights `gap_m` apart joined by half circles, counter-clockwise.
    fn stadium(straight_m: f64, gap_m: f64) -> Vec<Piece> {
        let r = 0.5 * gap_m;
        vec![
            Piece::Line {
                from: [0.0, -r],
                to: [straight_m, -r],
            },
            Piece::Arc {
                centre: [straight_m, 0.0],
                radius_m: r,
                start_rad: -0.5 * PI,
                turn_rad: PI,
            },
            Piece::Line {
                from: [straight_m, r],
                to: [0.0, r],
            },
            Piece::Arc {
                centre: [0.0, 0.0],
                radius_m: r,
                start_rad: 0.5 * PI,
                turn_rad: PI,
            },
        ]
    }

    /// Each piece of a drawn shape starts where the one before it ends, heading the same way:
    /// the arcs are true fillets, and the lap is the drawn length.
    #[test]
    fn pieces_join_end_to_start_without_a_kink() {
        let mut rng = StdRng::seed_from_u64(5);
        let mut drawn = 0;
        for k in 0..60 {
            let p = plan(50.0 + 7.5 * k as f64, 1.5 + 0.03 * k as f64, k % 2 == 0, k % 3 == 0);
            let Ok(pieces) = draw_shape(&mut rng, &p) else { continue };
            drawn += 1;
            let heading = |q: &Piece, u: f64| {
                let (a, b) = (q.at(u - 1e-7, 0.0), q.at(u + 1e-7, 0.0));
                (b[1] - a[1]).atan2(b[0] - a[0])
            };
            for (i, a) in pieces.iter().enumerate() {
                let b = &pieces[(i + 1) % pieces.len()];
                assert!(dist(a.at(1.0, 0.0), b.at(0.0, 0.0)) < 1e-9, "{a:?} then {b:?}");
                let kink = turn_between(
                    [heading(a, 1.0).cos(), heading(a, 1.0).sin()],
                    [heading(b, 0.0).cos(), heading(b, 0.0).sin()],
                );
                assert!(kink.abs() < 1e-5, "a kink of {kink} rad between {a:?} and {b:?}");
            }
            let lap: f64 = pieces.iter().map(Piece::length_m).sum();
            assert!((lap / p.length_m - 1.0).abs() < 2e-3);
        }
        assert!(drawn > 50, "only {drawn} of 60 draws met the properties");
    }

    /// Asked for a hairpin, every drawn shape has an arc turning 150 to 170 degrees with a
    /// radius between the floor and 1.5 m.
    #[test]
    fn a_hairpin_draw_always_holds_a_hairpin() {
        let mut rng = StdRng::seed_from_u64(9);
        for k in 0..40 {
            let p = plan(50.0 + 11.0 * k as f64, 1.5 + 0.025 * k as f64, k % 2 == 1, true);
            let Ok(pieces) = draw_shape(&mut rng, &p) else { continue };
            let found = pieces.iter().any(|q| match *q {
                Piece::Arc { radius_m, turn_rad, .. } => {
                    (150.0..=170.0).contains(&turn_rad.abs().to_degrees())
                        && (p.min_radius_m..=HAIRPIN_MAX_RADIUS_M).contains(&radius_m)
                }
                Piece::Line { .. } => false,
            });
            assert!(found, "draw {k}: no hairpin");
        }
    }

    /// The self-clearance check refuses two straights closer than the width and the gap (and
    /// than the step it samples at, on the safe side) and passes them farther apart.
    #[test]
    fn the_self_clearance_check_refuses_stretches_too_close() {
        let w = 2.0;
        assert!(clear_of_itself(
            &stadium(20.0, w + GAP_M + 2.0 * CLEARANCE_STEP_M),
            w,
            GAP_M
        ));
        assert!(!clear_of_itself(&stadium(20.0, w + GAP_M - 0.05), w, GAP_M));
        // Straights exactly a width and the gap apart meet the property, but the check's step
        // margin refuses them: it errs on the safe side.
        assert!(!clear_of_itself(&stadium(20.0, w + GAP_M), w, GAP_M));
    }
}
