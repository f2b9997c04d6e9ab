//! Race tracks from ROS map_server map files, the format F1TENTH shares its tracks in: a YAML
//! naming a PGM or PNG occupancy image, its resolution and origin. Walls stand where free pixels
//! meet occupied or unknown ones: each boundary of the free space, simplified to straight faces
//! within half a pixel, becomes a chain of thin static boxes (few shapes for a scan to walk, and
//! smooth faces for contact, where pixel squares would leave a staircase). The centre line comes
//! from a CSV beside the YAML, or is traced through the free space. The loaded track is plain
//! data ([`MapTrack`]) that travels inside configs and policy files, so a policy drives the
//! track it was trained on without the files.

use crate::SimError;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Wall height of a map-file track, metres (the oval's).
pub const WALL_HEIGHT_M: f32 = 0.75;
/// Step of a traced centre line, metres.
const TRACE_STEP_M: f64 = 0.1;
/// The widest track a trace looks across, metres (each side).
const TRACE_REACH_M: f64 = 10.0;
/// How far a wall face may stray from the middles of the pixel edges it stands for, pixels
/// (a map's own accuracy): a curve of 3 m radius at 5 cm a pixel then takes a face every metre.
pub const SIMPLIFY_PX: f64 = 1.0;
/// The largest image accepted, pixels a side and in all (F1TENTH's maps are a few thousand a
/// side; the clearance field takes 8 bytes a pixel).
pub(crate) const MAX_SIDE_PX: u32 = 8_192;
pub(crate) const MAX_PIXELS: u64 = 16 << 20;

/// The map_server YAML. Unknown keys are an error: a misspelt threshold would otherwise leave
/// its default in force without a word.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapYaml {
    image: String,
    resolution: f64,
    origin: [f64; 3],
    occupied_thresh: f64,
    free_thresh: f64,
    #[serde(default)]
    negate: u8,
    #[serde(default)]
    mode: Option<String>,
}

/// A race track loaded from a map file: what the simulator builds and the racing task measures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapTrack {
    /// The YAML's file name without `.yaml`.
    pub name: String,
    /// CRC-32 (hex) of the YAML, image and centre-line bytes: which files these were.
    pub crc32: String,
    /// Metres per pixel of the image.
    pub resolution_m: f32,
    /// Wall height, metres.
    pub wall_height_m: f32,
    /// Wall boxes in the world: centre x, centre y, half extent x, half extent y (metres), yaw
    /// (rad).
    pub walls: Vec<[f32; 5]>,
    /// The closed centre line in racing order, metres; the first point is the start.
    pub centreline: Vec<[f32; 2]>,
    /// `csv` (from the file beside the YAML) or `traced` (through the free space).
    pub centreline_source: String,
}

/// The occupancy image in the map frame: row 0 is the bottom row.
pub(crate) struct Grid {
    w: usize,
    h: usize,
    res: f64,
    origin: [f64; 3],
    /// 0 free, 1 unknown, 2 occupied.
    cells: Vec<u8>,
}

impl Grid {
    fn at(&self, c: usize, r: usize) -> u8 {
        self.cells[r * self.w + c]
    }

    /// The cell holding world point `p` (None outside the image).
    fn cell_of(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let (s, c) = self.origin[2].sin_cos();
        let (dx, dy) = (p[0] - self.origin[0], p[1] - self.origin[1]);
        let (lx, ly) = (c * dx + s * dy, -s * dx + c * dy);
        let (ci, ri) = ((lx / self.res).floor(), (ly / self.res).floor());
        (ci >= 0.0 && ri >= 0.0 && ci < self.w as f64 && ri < self.h as f64).then_some((ci as usize, ri as usize))
    }

    fn free(&self, p: [f64; 2]) -> bool {
        self.cell_of(p).is_some_and(|(c, r)| self.at(c, r) == 0)
    }

    /// World point of map-frame point (x, y).
    fn world(&self, x: f64, y: f64) -> [f64; 2] {
        let (s, c) = self.origin[2].sin_cos();
        [self.origin[0] + c * x - s * y, self.origin[1] + s * x + c * y]
    }

    /// The boundaries of the free space as closed loops of pixel corners (column, row from the
    /// bottom), free space on the left: every edge between a free cell and one that is not
    /// (occupied, unknown, or outside the image), chained.
    fn boundary_loops(&self) -> Vec<Vec<(i64, i64)>> {
        let (w, h) = (self.w as i64, self.h as i64);
        let free = |c: i64, r: i64| c >= 0 && r >= 0 && c < w && r < h && self.at(c as usize, r as usize) == 0;
        let mut out_edges: std::collections::HashMap<(i64, i64), Vec<(i64, i64)>> = Default::default();
        for r in 0..h {
            for c in 0..w {
                if !free(c, r) {
                    continue;
                }
                let mut edge = |a: (i64, i64), b: (i64, i64)| out_edges.entry(a).or_default().push(b);
                if !free(c, r - 1) {
                    edge((c, r), (c + 1, r));
                }
                if !free(c + 1, r) {
                    edge((c + 1, r), (c + 1, r + 1));
                }
                if !free(c, r + 1) {
                    edge((c + 1, r + 1), (c, r + 1));
                }
                if !free(c - 1, r) {
                    edge((c, r + 1), (c, r));
                }
            }
        }
        let mut starts: Vec<(i64, i64)> = out_edges.keys().copied().collect();
        starts.sort_unstable();
        let mut loops = Vec::new();
        for s in starts {
            while out_edges.get(&s).is_some_and(|v| !v.is_empty()) {
                let mut ring = vec![s];
                let (mut at, mut dir) = (s, (0i64, 0i64));
                while let Some(v) = out_edges.get_mut(&at).filter(|v| !v.is_empty()) {
                    // At a corner two free cells share (a saddle), keep the turn to the left: each
                    // loop then bounds one free region.
                    let k = if v.len() > 1 {
                        let left = (-dir.1, dir.0);
                        v.iter().position(|b| (b.0 - at.0, b.1 - at.1) == left).unwrap_or(0)
                    } else {
                        0
                    };
                    let b = v.swap_remove(k);
                    dir = (b.0 - at.0, b.1 - at.1);
                    at = b;
                    if at == s {
                        break;
                    }
                    ring.push(at);
                }
                loops.push(ring);
            }
        }
        loops
    }

    /// The walls: each boundary loop simplified (Douglas-Peucker, `SIMPLIFY_PX`) into straight
    /// faces, each face a box one pixel deep on the side away from the free space. World
    /// boxes: centre x, centre y, half length, half depth, yaw.
    fn wall_boxes(&self) -> Vec<[f32; 5]> {
        let mut out = Vec::new();
        for ring in self.boundary_loops() {
            // The middles of the pixel edges: a staircase's corners stray half a pixel from the
            // line it draws, its edges' middles a quarter.
            let pts: Vec<[f64; 2]> = (0..ring.len())
                .map(|k| {
                    let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
                    self.world(0.5 * (a.0 + b.0) as f64 * self.res, 0.5 * (a.1 + b.1) as f64 * self.res)
                })
                .collect();
            let keep = simplify_loop(&pts, SIMPLIFY_PX * self.res);
            let corners = refit(&pts, &keep, 2.0 * SIMPLIFY_PX * self.res);
            let depth = self.res;
            for k in 0..corners.len() {
                let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = (dx * dx + dy * dy).sqrt();
                if len < 1e-9 {
                    continue;
                }
                // Free space lies on the left: the box on the right, its face on the segment.
                let n = [dy / len, -dx / len];
                out.push([
                    (0.5 * (a[0] + b[0]) + 0.5 * depth * n[0]) as f32,
                    (0.5 * (a[1] + b[1]) + 0.5 * depth * n[1]) as f32,
                    // A millimetre longer at each end: no ray slips between two faces at a corner.
                    (0.5 * len + 1e-3) as f32,
                    (0.5 * depth) as f32,
                    dy.atan2(dx) as f32,
                ]);
            }
        }
        out
    }

    /// Squared distance (pixels^2) from each free cell's centre to the nearest cell that is not
    /// free: Felzenszwalb and Huttenlocher's exact transform, by columns then rows.
    fn clearance_sq(&self) -> Vec<f64> {
        let (w, h) = (self.w, self.h);
        let big = ((w + h) * (w + h)) as f64;
        let mut f: Vec<f64> = self.cells.iter().map(|&v| if v == 0 { big } else { 0.0 }).collect();
        let mut line = Vec::new();
        for c in 0..w {
            line.clear();
            line.extend((0..h).map(|r| f[r * w + c]));
            for (r, v) in edt_1d(&line).into_iter().enumerate() {
                f[r * w + c] = v;
            }
        }
        for r in 0..h {
            let out = edt_1d(&f[r * w..(r + 1) * w]);
            f[r * w..(r + 1) * w].copy_from_slice(&out);
        }
        f
    }

    /// The point of the free span across `q` (along the normal of heading `h`) farthest from
    /// the walls: on the track's medial line (None when `q` is not free or a side stays open
    /// within reach).
    fn centre_across(&self, q: [f64; 2], h: f64, clear: &[f64]) -> Option<[f64; 2]> {
        if !self.free(q) {
            return None;
        }
        let n = [-h.sin(), h.cos()];
        let step = 0.5 * self.res;
        let reach = |sign: f64| {
            let mut d = 0.0;
            while d < TRACE_REACH_M {
                d += step;
                if !self.free([q[0] + sign * n[0] * d, q[1] + sign * n[1] * d]) {
                    return Some(d);
                }
            }
            None
        };
        let (l, r) = (reach(1.0)?, reach(-1.0)?);
        // The widest clearance along the span; a plateau counts by its middle.
        let (mut best, mut lo, mut hi) = (-1.0, 0.0, 0.0);
        let mut d = -r + step;
        while d < l {
            let p = [q[0] + n[0] * d, q[1] + n[1] * d];
            if let Some((c, rr)) = self.cell_of(p) {
                let v = clear[rr * self.w + c];
                if v > best {
                    (best, lo, hi) = (v, d, d);
                } else if v == best {
                    hi = d;
                }
            }
            d += step;
        }
        let m = if best < 0.0 { 0.5 * (l - r) } else { 0.5 * (lo + hi) };
        Some([q[0] + n[0] * m, q[1] + n[1] * m])
    }

    /// Distance to the nearest cell that is not free at world point `p`, metres, interpolated
    /// between cell centres (0 outside the image).
    fn clearance_at(&self, clear: &[f64], p: [f64; 2]) -> f64 {
        let (s, c) = self.origin[2].sin_cos();
        let (dx, dy) = (p[0] - self.origin[0], p[1] - self.origin[1]);
        let (u, v) = ((c * dx + s * dy) / self.res - 0.5, (-s * dx + c * dy) / self.res - 0.5);
        let (c0, r0) = (u.floor(), v.floor());
        let (fu, fv) = (u - c0, v - r0);
        let at = |ci: f64, ri: f64| {
            if ci < 0.0 || ri < 0.0 || ci >= self.w as f64 || ri >= self.h as f64 {
                0.0
            } else {
                clear[ri as usize * self.w + ci as usize].sqrt()
            }
        };
        let d = (1.0 - fu) * (1.0 - fv) * at(c0, r0)
            + fu * (1.0 - fv) * at(c0 + 1.0, r0)
            + (1.0 - fu) * fv * at(c0, r0 + 1.0)
            + fu * fv * at(c0 + 1.0, r0 + 1.0);
        d * self.res
    }

    /// Trace the centre line from `start` heading `yaw`: from the centre of the span across the
    /// start, step along the ridge of the clearance (the point of widest clearance on an arc
    /// ahead), until the trace comes back to where it began.
    fn trace(&self, start: [f64; 2], yaw: f64) -> Result<Vec<[f64; 2]>, String> {
        let clear = self.clearance_sq();
        let p0 = self.centre_across(start, yaw, &clear).ok_or_else(|| {
            format!(
                "({}, {}) is not in free space between walls: a traced centre line starts there",
                start[0], start[1]
            )
        })?;
        let step = TRACE_STEP_M.max(2.0 * self.res);
        let side_m = self.w.max(self.h) as f64 * self.res;
        let max_steps = (8.0 * side_m / step) as usize + 100;
        let (mut p, mut h, mut travelled) = (p0, yaw, 0.0);
        let mut pts = vec![p0];
        for _ in 0..max_steps {
            // Up to 60 degrees either way, the straighter of equal clearances first.
            let mut best = (0.0, h, p);
            for k in [0i32].into_iter().chain((1..=30).flat_map(|k| [k, -k])) {
                let a = h + (2.0 * k as f64).to_radians();
                let q = [p[0] + step * a.cos(), p[1] + step * a.sin()];
                let v = self.clearance_at(&clear, q);
                if v > best.0 + 1e-9 {
                    best = (v, a, q);
                }
            }
            if best.0 <= 0.0 {
                return Err(format!("the trace lost the free space near ({:.2}, {:.2})", p[0], p[1]));
            }
            (h, p) = (best.1, best.2);
            travelled += step;
            let back = ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2)).sqrt();
            if travelled > 20.0 * step && back < 1.5 * step {
                return Ok(smooth(&pts));
            }
            pts.push(p);
        }
        Err(format!(
            "the trace did not come back to its start after {travelled:.0} m (not a closed track?)"
        ))
    }
}

/// Indices of the corners of the closed polyline `pts` that Douglas-Peucker keeps at `tol`
/// (collinear runs of pixel edges become one face; a staircase within `tol` becomes a slope).
fn simplify_loop(pts: &[[f64; 2]], tol: f64) -> Vec<usize> {
    let n = pts.len();
    if n < 4 {
        return (0..n).collect();
    }
    let d2 = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    // Split the loop at its first point and the point farthest from it.
    let far = (1..n)
        .max_by(|&i, &j| d2(pts[0], pts[i]).total_cmp(&d2(pts[0], pts[j])))
        .unwrap_or(n / 2);
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    let mut stack = vec![(0, far), (far, n)];
    while let Some((i, j)) = stack.pop() {
        let (a, b) = (pts[i], pts[j % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = (dx * dx + dy * dy).sqrt().max(1e-12);
        let mut worst = (0.0, i);
        for (k, p) in pts.iter().enumerate().take(j).skip(i + 1) {
            let d = ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len;
            if d > worst.0 {
                worst = (d, k);
            }
        }
        if worst.0 > tol {
            keep[worst.1] = true;
            stack.push((i, worst.1));
            stack.push((worst.1, j));
        }
    }
    (0..n).filter(|&k| keep[k]).collect()
}

/// Corners of the faces of a simplified loop: each face is the line fitted (least squares,
/// perpendicular) to the points between its two kept ends, those ends left out (either may
/// belong to the next face round a corner); a corner is where two neighbouring lines meet,
/// unless that lies more than `max_shift` from the kept point.
fn refit(pts: &[[f64; 2]], keep: &[usize], max_shift: f64) -> Vec<[f64; 2]> {
    let (n, m) = (pts.len(), keep.len());
    if m < 3 {
        return keep.iter().map(|&k| pts[k]).collect();
    }
    // Each face's line: a point on it and its unit direction.
    let lines: Vec<([f64; 2], [f64; 2])> = (0..m)
        .map(|k| {
            let (i, j) = (keep[k], if k + 1 < m { keep[k + 1] } else { keep[0] + n });
            let inner: Vec<[f64; 2]> = (i + 1..j).map(|q| pts[q % n]).collect();
            let set = if inner.len() >= 2 {
                inner
            } else {
                vec![pts[i], pts[j % n]]
            };
            let c = set.iter().fold([0.0; 2], |s, p| [s[0] + p[0], s[1] + p[1]]);
            let c = [c[0] / set.len() as f64, c[1] / set.len() as f64];
            let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
            for p in &set {
                let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
                sxx += dx * dx;
                sxy += dx * dy;
                syy += dy * dy;
            }
            let a = 0.5 * (2.0 * sxy).atan2(sxx - syy);
            let mut d = [a.cos(), a.sin()];
            // Point it the way the loop runs.
            let (ex, ey) = (pts[j % n][0] - pts[i][0], pts[j % n][1] - pts[i][1]);
            if d[0] * ex + d[1] * ey < 0.0 {
                d = [-d[0], -d[1]];
            }
            (c, d)
        })
        .collect();
    (0..m)
        .map(|k| {
            let (p1, d1) = lines[(k + m - 1) % m];
            let (p2, d2) = lines[k];
            let cross = d1[0] * d2[1] - d1[1] * d2[0];
            let kept = pts[keep[k]];
            if cross.abs() < 1e-3 {
                // Nearly parallel: the kept point, onto the face that starts there.
                let t = (kept[0] - p2[0]) * d2[0] + (kept[1] - p2[1]) * d2[1];
                return [p2[0] + t * d2[0], p2[1] + t * d2[1]];
            }
            let t = ((p2[0] - p1[0]) * d2[1] - (p2[1] - p1[1]) * d2[0]) / cross;
            let x = [p1[0] + t * d1[0], p1[1] + t * d1[1]];
            // Lines meeting at a sharp angle can cross far out: such a corner stays put.
            if (x[0] - kept[0]).hypot(x[1] - kept[1]) > max_shift {
                kept
            } else {
                x
            }
        })
        .collect()
}

/// The exact 1D squared distance transform of `f` (Felzenszwalb and Huttenlocher 2012).
fn edt_1d(f: &[f64]) -> Vec<f64> {
    let n = f.len();
    let (mut v, mut z) = (vec![0usize; n], vec![0.0f64; n + 1]);
    let mut k = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    let parabola = |q: usize, p: usize| ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
    for q in 1..n {
        // z[0] is minus infinity: k stays >= 0.
        let mut s = parabola(q, v[k]);
        while s <= z[k] {
            k -= 1;
            s = parabola(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    let mut out = vec![0.0; n];
    k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let d = q as f64 - v[k] as f64;
        *o = d * d + f[v[k]];
    }
    out
}

/// A closed polyline averaged over 5 neighbours: the trace's one-pixel jitter out.
fn smooth(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let n = pts.len() as isize;
    (0..n)
        .map(|i| {
            let mut s = [0.0; 2];
            for k in -2..=2 {
                let q = pts[(i + k).rem_euclid(n) as usize];
                s[0] += q[0] / 5.0;
                s[1] += q[1] / 5.0;
            }
            s
        })
        .collect()
}

fn read(path: &Path) -> Result<Vec<u8>, SimError> {
    std::fs::read(path).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// The centre-line CSV beside `yaml`: `NAME.csv`, or F1TENTH's `TRACK_centerline.csv` beside
/// `TRACK_map.yaml`.
fn centreline_path(yaml: &Path) -> Option<PathBuf> {
    let stem = yaml.file_stem()?.to_str()?;
    let dir = yaml.parent().unwrap_or(Path::new(""));
    let f1tenth = format!("{}_centerline.csv", stem.strip_suffix("_map").unwrap_or(stem));
    [format!("{stem}.csv"), f1tenth]
        .into_iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file())
}

/// Parse a centre-line CSV: `x, y` in metres a line (more columns ignored), `#` comments and a
/// header line allowed.
pub(crate) fn parse_centreline(text: &str) -> Result<Vec<[f64; 2]>, String> {
    let mut pts = Vec::new();
    let mut seen_row = false;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut cols = line.split([',', ';', ' ', '\t']).filter(|c| !c.is_empty());
        let xy = (cols.next(), cols.next());
        let parsed = match xy {
            (Some(x), Some(y)) => x.trim().parse::<f64>().ok().zip(y.trim().parse::<f64>().ok()),
            _ => None,
        };
        match parsed {
            Some((x, y)) if x.is_finite() && y.is_finite() => pts.push([x, y]),
            // The first line may name the columns.
            None if !seen_row => {}
            _ => return Err(format!("line {}: expected x, y in metres, got '{line}'", i + 1)),
        }
        seen_row = true;
    }
    if pts.len() > 3 && pts.first() == pts.last() {
        pts.pop();
    }
    if pts.len() < 3 {
        return Err(format!(
            "a closed centre line needs at least 3 points, got {}",
            pts.len()
        ));
    }
    Ok(pts)
}

/// Decode the image of a map: 8- or 16-bit grey, RGB or RGBA PGM/PNG, as grey levels 0-255
/// (the mean of the colour channels, as map_server takes it), top row first.
fn decode_image(bytes: &[u8], path: &Path) -> Result<(usize, usize, Vec<u8>), SimError> {
    let bad = |msg: String| SimError::Invalid {
        context: path.display().to_string(),
        msg,
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    if reader.format().is_none() {
        return Err(bad("not a PGM or PNG image".into()));
    }
    // The decoder refuses what its limits forbid before it allocates the pixels.
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SIDE_PX);
    limits.max_image_height = Some(MAX_SIDE_PX);
    limits.max_alloc = Some(256 << 20);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| bad(format!("bad image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w < 2 || h < 2 {
        return Err(bad(format!("the image is {w} x {h} pixels: too small for a track")));
    }
    if (w * h) as u64 > MAX_PIXELS {
        return Err(bad(format!("the image is {w} x {h} pixels: over {MAX_PIXELS} in all")));
    }
    let rgb = img.to_rgb8();
    let grey = rgb
        .pixels()
        .map(|p| ((p[0] as u16 + p[1] as u16 + p[2] as u16) / 3) as u8)
        .collect();
    Ok((w, h, grey))
}

impl MapTrack {
    /// Load the map YAML at `yaml`, its image and its centre line (the CSV beside it, or traced
    /// from the map frame's origin heading +x, f1tenth_gym's default start pose).
    pub fn load(yaml: &Path) -> Result<Self, SimError> {
        let invalid = |msg: String| SimError::Invalid {
            context: yaml.display().to_string(),
            msg,
        };
        let yaml_bytes = read(yaml)?;
        let text = std::str::from_utf8(&yaml_bytes).map_err(|_| invalid("not UTF-8 text".into()))?;
        let m: MapYaml = serde_yaml_ng::from_str(text).map_err(|e| invalid(format!("bad map YAML: {e}")))?;
        if !(m.resolution.is_finite() && m.resolution > 0.0 && m.resolution <= 1.0) {
            return Err(invalid(format!(
                "resolution must be in (0, 1] metres per pixel, got {}",
                m.resolution
            )));
        }
        if m.origin.iter().any(|v| !v.is_finite() || v.abs() > 1e5) {
            return Err(invalid(format!(
                "origin must be finite metres and radians, got {:?}",
                m.origin
            )));
        }
        if !(0.0..=1.0).contains(&m.free_thresh)
            || !(0.0..=1.0).contains(&m.occupied_thresh)
            || m.free_thresh >= m.occupied_thresh
        {
            return Err(invalid(format!(
                "thresholds need 0 <= free_thresh < occupied_thresh <= 1, got free_thresh {} and occupied_thresh {}",
                m.free_thresh, m.occupied_thresh
            )));
        }
        if m.negate > 1 {
            return Err(invalid(format!("negate must be 0 or 1, got {}", m.negate)));
        }
        match m.mode.as_deref() {
            None | Some("trinary") | Some("scale") => {}
            Some(other) => {
                return Err(invalid(format!(
                    "mode '{other}' is not supported here: trinary or scale"
                )));
            }
        }
        let dir = yaml.parent().unwrap_or(Path::new(""));
        let image_path = dir.join(&m.image);
        let image_bytes = read(&image_path)?;
        let (w, h, grey) = decode_image(&image_bytes, &image_path)?;
        let cells = (0..h)
            .flat_map(|r| {
                // Row 0 of the grid is the image's bottom row.
                let row = &grey[(h - 1 - r) * w..(h - r) * w];
                row.iter().map(|&v| {
                    let v = v as f64 / 255.0;
                    let p = if m.negate == 1 { v } else { 1.0 - v };
                    if p > m.occupied_thresh {
                        2
                    } else if p < m.free_thresh {
                        0
                    } else {
                        1
                    }
                })
            })
            .collect();
        let grid = Grid {
            w,
            h,
            res: m.resolution,
            origin: m.origin,
            cells,
        };
        let mut crc = crc32fast::Hasher::new();
        crc.update(&yaml_bytes);
        crc.update(&image_bytes);
        let (centreline, source) = match centreline_path(yaml) {
            Some(csv) => {
                let bytes = read(&csv)?;
                crc.update(&bytes);
                let text = String::from_utf8_lossy(&bytes);
                let pts = parse_centreline(&text).map_err(|msg| SimError::Invalid {
                    context: csv.display().to_string(),
                    msg,
                })?;
                if let Some((i, p)) = pts.iter().enumerate().find(|(_, p)| !grid.free(**p)) {
                    return Err(SimError::Invalid {
                        context: csv.display().to_string(),
                        msg: format!(
                            "point {} ({}, {}) is not in the map's free space (outside the image, \
                             on a wall or unknown)",
                            i + 1,
                            p[0],
                            p[1]
                        ),
                    });
                }
                (pts, "csv")
            }
            None => {
                let pts = grid.trace([0.0, 0.0], 0.0).map_err(|e| {
                    invalid(format!(
                        "no centre-line CSV beside it, and {e}; give the centre line as NAME.csv \
                         (x, y in metres, one point a line)"
                    ))
                })?;
                (pts, "traced")
            }
        };
        let walls = grid.wall_boxes();
        if walls.is_empty() {
            return Err(invalid("the image has no free pixels: no track".into()));
        }
        let name = yaml.file_stem().and_then(|s| s.to_str()).unwrap_or("map").to_string();
        let track = Self {
            name,
            crc32: format!("{:08x}", crc.finalize()),
            resolution_m: m.resolution as f32,
            wall_height_m: WALL_HEIGHT_M,
            walls,
            centreline: centreline.iter().map(|p| [p[0] as f32, p[1] as f32]).collect(),
            centreline_source: source.into(),
        };
        let lap_m = track.lap_length_m();
        if lap_m < 2.0 {
            return Err(invalid(format!("the centre line is {lap_m:.2} m long: no track")));
        }
        Ok(track)
    }

    /// Length of the centre line, metres.
    pub fn lap_length_m(&self) -> f32 {
        let n = self.centreline.len();
        (0..n)
            .map(|i| {
                let (a, b) = (self.centreline[i], self.centreline[(i + 1) % n]);
                ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
            })
            .sum()
    }

    /// Check what a hand-edited or damaged config could carry.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite() && x.abs() < 1e5);
        if self.walls.is_empty() || self.walls.iter().any(|w| !(finite(w) && w[2] > 0.0 && w[3] > 0.0)) {
            return Err("walls must be boxes with finite centres and positive half extents".into());
        }
        if self.centreline.len() < 3 || self.centreline.iter().any(|p| !finite(p)) {
            return Err("the centre line needs at least 3 finite points".into());
        }
        if self.lap_length_m().is_nan() || self.lap_length_m() < 2.0 {
            return Err("the centre line is shorter than 2 m".into());
        }
        if !(self.wall_height_m.is_finite() && self.wall_height_m > 0.0 && self.resolution_m > 0.0) {
            return Err("wall_height_m and resolution_m must be positive".into());
        }
        Ok(())
    }
}
