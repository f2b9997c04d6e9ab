//! The obstacle memory: odometry from the IMU, the scan points of the last seconds kept in the
//! odometry frame (one per cell, bucketed by place), and the points near the car in its own
//! frame (bucketed again for the path checks), against which the free length of an arc is
//! measured. The LiDAR does not see behind the car, so a reverse path is checked against what
//! the car saw on the way in.

use super::arcs::Fan;
use super::{SafetyFilterConfig, whole_scan_half_rad};
use crate::api::SensorFrame;
use std::collections::HashMap;

/// The most a car reverses along the way it came, metres (about what it drove in
/// `reverse_memory_s` at low speed; farther back, odometry drifts).
pub(super) const MAX_BACKABLE_M: f32 = 3.0;

/// Scan points farther than this from the LiDAR are not remembered, metres: within the memory's
/// time the car cannot reach them without scanning them again.
const REMEMBER_WITHIN_M: f32 = 3.0;
/// Remembered points are merged into cells this wide, metres (a point moves by at most half a
/// diagonal, under 3.6 cm: inside the margins).
pub(super) const CELL_M: f64 = 0.05;

/// Odometry and the obstacle points remembered along the way.
#[derive(Clone, Debug)]
pub(crate) struct ObstacleMemory {
    /// Rear-axle pose in the odometry frame: x, y, heading.
    pub(super) pose: [f64; 3],
    pub(super) last_stamp_s: Option<f64>,
    /// Distance driven over the last control period by odometry, metres.
    pub(super) last_ds: f32,
    /// How far the car may reverse: the distance it drove forward (less what it reversed since),
    /// at most `MAX_BACKABLE_M`. Reversing retraces ground the car has driven over; at a spawn
    /// nothing behind it is known.
    pub(super) backable_m: f32,
    /// Whether controls may reverse (else only `memory_s` of points is kept).
    reverses: bool,
    /// Obstacle points in the odometry frame, one per `CELL_M` cell, with the time the cell
    /// was last seen occupied (a wall seen in 45 scans is remembered once).
    pub(super) cells: CellMemory,
    /// Points near the car in its current frame, seen within `memory_s` (rebuilt every
    /// control; for the reverse lengths alone, all of them).
    pub(super) near: Vec<[f32; 2]>,
    /// Older remembered points near the car (only reverse paths are checked against them).
    near_old: Vec<[f32; 2]>,
    /// `near` and `near_old` bucketed by place, for the path checks (`near_old`'s only once a
    /// reverse path is checked this control: most controls check none).
    near_grid: PointGrid,
    near_old_grid: PointGrid,
    /// The reach of `near_old` while it is still to be gathered.
    old_pending: Option<f32>,
}

impl ObstacleMemory {
    /// An empty memory for a car whose controls may reverse (`reverses`: its old points are
    /// kept for reverse paths) or not.
    pub(crate) fn new(reverses: bool) -> Self {
        Self {
            pose: [0.0; 3],
            last_stamp_s: None,
            last_ds: 0.0,
            backable_m: 0.0,
            reverses,
            cells: CellMemory::default(),
            near: Vec::new(),
            near_old: Vec::new(),
            near_grid: PointGrid::default(),
            near_old_grid: PointGrid::default(),
            old_pending: None,
        }
    }

    /// Forget everything (a new episode): the odometry starts again at the origin.
    pub(crate) fn reset(&mut self) {
        self.pose = [0.0; 3];
        self.last_stamp_s = None;
        self.cells.clear();
        self.last_ds = 0.0;
        self.backable_m = 0.0;
    }

    /// Take in a frame as [`SafetyFilter::filter`](super::SafetyFilter::filter) does, under
    /// the settings `cfg`, and push to `out` how far the car could reverse from here along the
    /// arc of each steering in `deltas`, over `max_m` (the reverse check of a policy's control,
    /// up to `max_m`). `fan_half_rad` as in `filter`.
    pub(crate) fn reverse_free_fractions(
        &mut self,
        cfg: &SafetyFilterConfig,
        frame: &SensorFrame,
        deltas: &[f32],
        max_m: f32,
        fan_half_rad: Option<f32>,
        out: &mut Vec<f32>,
    ) {
        let fan_half_rad = fan_half_rad.unwrap_or_else(|| whole_scan_half_rad(frame));
        self.observe(cfg, frame);
        // Only reverse paths are checked here, against old and recent points alike.
        self.collect_near(cfg, cfg.reverse_reach(max_m), false);
        self.grid_old_points(cfg);
        out.extend(
            deltas
                .iter()
                .map(|&d| self.reverse_free_length(cfg, d, max_m, fan_half_rad) / max_m),
        );
    }

    /// Advance odometry to the frame and remember its near scan points; returns forward speed.
    pub(super) fn observe(&mut self, cfg: &SafetyFilterConfig, frame: &SensorFrame) -> f32 {
        let (v, w) = frame
            .imu
            .as_ref()
            .map(|i| (i.lin_vel_b[0], i.ang_vel_b[2]))
            .unwrap_or((0.0, 0.0));
        if let Some(t0) = self.last_stamp_s {
            let dt = (frame.stamp_s - t0).clamp(0.0, 0.5);
            // Midpoint heading: exact enough for one control period on an arc.
            let th = self.pose[2] + 0.5 * w * dt;
            self.last_ds = (v * dt).abs() as f32;
            self.backable_m = (self.backable_m + (v * dt) as f32).clamp(0.0, MAX_BACKABLE_M);
            self.pose[0] += v * dt * th.cos();
            self.pose[1] += v * dt * th.sin();
            self.pose[2] += w * dt;
        }
        self.last_stamp_s = Some(frame.stamp_s);
        let keep_s = if self.reverses {
            cfg.reverse_memory_s.max(cfg.memory_s)
        } else {
            cfg.memory_s
        };
        self.cells.forget_before(frame.stamp_s - keep_s as f64);
        if let Some(scan) = &frame.scan {
            let (s, c) = self.pose[2].sin_cos();
            for (i, &r) in scan.ranges.iter().enumerate() {
                let hit = scan.hit_at(i);
                if !hit || !r.is_finite() || r > REMEMBER_WITHIN_M {
                    continue;
                }
                let b = scan.bearing(i);
                let (px, py) = ((cfg.lidar_x_m + r * b.cos()) as f64, (r * b.sin()) as f64);
                let wx = self.pose[0] + c * px - s * py;
                let wy = self.pose[1] + s * px + c * py;
                let cell = ((wx / CELL_M).floor() as i32, (wy / CELL_M).floor() as i32);
                self.cells.insert(cell, frame.stamp_s);
            }
        }
        v as f32
    }

    /// Remembered points within `reach` metres of the rear axle, in the car's frame: those seen
    /// within `memory_s` in `near` and older ones in `near_old` (gathered once a reverse path is
    /// checked: most controls check none), or all in `near` if not `split_old`.
    pub(super) fn collect_near(&mut self, cfg: &SafetyFilterConfig, reach: f32, split_old: bool) {
        let recent_after = self.recent_after(cfg);
        let mut near = std::mem::take(&mut self.near);
        near.clear();
        self.push_points(reach, |seen| !split_old || seen >= recent_after, &mut near);
        self.near = near;
        self.near_grid.rebuild(&self.near);
        self.near_old.clear();
        if split_old {
            self.old_pending = Some(reach);
        } else {
            self.near_old_grid.rebuild(&[]);
            self.old_pending = None;
        }
    }

    /// Points seen before this are old (only reverse paths are checked against them).
    fn recent_after(&self, cfg: &SafetyFilterConfig) -> f64 {
        self.last_stamp_s.unwrap_or(0.0) - cfg.memory_s as f64
    }

    /// Push to `out` the remembered points within `reach` metres of the rear axle, in the car's
    /// frame, whose time last seen passes `keep`.
    fn push_points(&self, reach: f32, keep: impl Fn(f64) -> bool, out: &mut Vec<[f32; 2]>) {
        let (s, c) = self.pose[2].sin_cos();
        let (s, c) = (s as f32, c as f32);
        for cells in self.cells.around(self.pose[0], self.pose[1], reach as f64) {
            for &((i, j), seen) in cells {
                if !(self.cells.remembers(seen) && keep(seen)) {
                    continue;
                }
                // Relative to the car in f64, then f32: odometry may run far from its origin.
                let dx = ((i as f64 + 0.5) * CELL_M - self.pose[0]) as f32;
                let dy = ((j as f64 + 0.5) * CELL_M - self.pose[1]) as f32;
                let p = [c * dx + s * dy, -s * dx + c * dy];
                if p[0] * p[0] + p[1] * p[1] <= reach * reach {
                    out.push(p);
                }
            }
        }
    }

    /// Gather and bucket `near_old` for the reverse path checks of this control.
    pub(super) fn grid_old_points(&mut self, cfg: &SafetyFilterConfig) {
        if let Some(reach) = self.old_pending.take() {
            let recent_after = self.recent_after(cfg);
            let mut old = std::mem::take(&mut self.near_old);
            self.push_points(reach, |seen| seen < recent_after, &mut old);
            self.near_old = old;
            self.near_old_grid.rebuild(&self.near_old);
        }
    }

    /// How far the car reverses along the arc of steering `delta` before its body (with
    /// margin) touches any remembered point or the LiDAR comes within `reverse_clearance_m`
    /// of one in its fan, metres (up to `limit`, and never beyond the way the car came).
    pub(super) fn reverse_free_length(
        &self,
        cfg: &SafetyFilterConfig,
        delta: f32,
        limit: f32,
        fan_half_rad: f32,
    ) -> f32 {
        debug_assert!(
            self.old_pending.is_none(),
            "near_old is bucketed before a reverse check"
        );
        let fan = Fan::new(fan_half_rad, cfg.reverse_clearance_m);
        cfg.walk_arc(delta, limit.min(self.backable_m), -1.0, |pose| {
            let (lo, hi) = cfg.pose_box(pose, fan);
            [&self.near_grid, &self.near_old_grid]
                .iter()
                .all(|g| cfg.points_clear(g.within(lo, hi), pose, fan))
        })
    }

    /// How far along the arc of steering `delta` the car drives before its body (with margin)
    /// touches a point or the LiDAR comes within `clearance_m` of a point in its fan, metres
    /// (checked up to `limit`; `limit` itself when the path is clear).
    pub(super) fn free_length(&self, cfg: &SafetyFilterConfig, delta: f32, limit: f32, fan_half_rad: f32) -> f32 {
        let fan = Fan::new(fan_half_rad, cfg.clearance_m);
        cfg.walk_arc(delta, limit, 1.0, |pose| {
            let (lo, hi) = cfg.pose_box(pose, fan);
            cfg.points_clear(self.near_grid.within(lo, hi), pose, fan)
        })
    }
}

/// A remembered cell and the time it was last seen occupied.
pub(super) type SeenCell = ((i32, i32), f64);

/// The filter's remembered cells, bucketed by place: the points a path could reach are found
/// without visiting all of `reverse_memory_s` of scans along the way the car came, and old cells
/// are dropped in a sweep now and then rather than every control.
#[derive(Clone, Debug)]
pub(super) struct CellMemory {
    /// Each remembered cell's slot in its chunk.
    slot: HashMap<(i32, i32), u32>,
    /// The cells of each chunk (`CHUNK` cells a side), with the time each was last seen.
    chunks: HashMap<(i32, i32), Vec<SeenCell>>,
    /// Cells last seen before this are forgotten: skipped, and dropped by the next sweep.
    forget_before: f64,
    /// `forget_before` at the last sweep.
    swept_at: f64,
}

impl Default for CellMemory {
    fn default() -> Self {
        Self {
            slot: HashMap::new(),
            chunks: HashMap::new(),
            forget_before: f64::NEG_INFINITY,
            swept_at: f64::NEG_INFINITY,
        }
    }
}

impl CellMemory {
    /// Chunk side, cells.
    const CHUNK: i32 = 32;
    /// Seconds of forgetting between sweeps.
    const SWEEP_S: f64 = 1.0;

    fn chunk_of(cell: (i32, i32)) -> (i32, i32) {
        (cell.0.div_euclid(Self::CHUNK), cell.1.div_euclid(Self::CHUNK))
    }

    fn clear(&mut self) {
        self.slot.clear();
        self.chunks.clear();
        self.forget_before = f64::NEG_INFINITY;
        self.swept_at = f64::NEG_INFINITY;
    }

    /// Remember `cell` as seen at `t_s` (not before the last [`Self::forget_before`]).
    pub(super) fn insert(&mut self, cell: (i32, i32), t_s: f64) {
        let chunk = self.chunks.entry(Self::chunk_of(cell)).or_default();
        match self.slot.get(&cell) {
            Some(&k) => chunk[k as usize].1 = t_s,
            None => {
                self.slot.insert(cell, chunk.len() as u32);
                chunk.push((cell, t_s));
            }
        }
    }

    /// Forget the cells last seen before `t_s`. A time earlier than the last one first drops
    /// what the last one forgot, so a forgotten cell stays forgotten.
    fn forget_before(&mut self, t_s: f64) {
        if t_s < self.forget_before || t_s - self.swept_at >= Self::SWEEP_S {
            self.sweep();
        }
        self.forget_before = t_s;
    }

    /// Drop the forgotten cells.
    fn sweep(&mut self) {
        let after = self.forget_before;
        let slot = &mut self.slot;
        self.chunks.retain(|_, cells| {
            let before = cells.len();
            cells.retain(|&(cell, t)| {
                let keep = t >= after;
                if !keep {
                    slot.remove(&cell);
                }
                keep
            });
            if cells.len() < before {
                for (k, &(cell, _)) in cells.iter().enumerate() {
                    slot.insert(cell, k as u32);
                }
            }
            !cells.is_empty()
        });
        self.swept_at = after;
    }

    /// The chunks holding every remembered cell whose centre lies within `reach` metres of
    /// (`x`, `y`) in the odometry frame (and cells farther off; forgotten ones too: see
    /// [`Self::remembers`]).
    fn around(&self, x: f64, y: f64, reach: f64) -> impl Iterator<Item = &[SeenCell]> + '_ {
        // A cell's chunk is that of its centre; a cell's width of slack for rounding.
        let side = Self::CHUNK as f64 * CELL_M;
        let r = reach + CELL_M;
        let range = move |v: f64| (((v - r) / side).floor() as i32)..=(((v + r) / side).floor() as i32);
        range(x)
            .flat_map(move |ci| range(y).map(move |cj| (ci, cj)))
            .filter_map(|chunk| self.chunks.get(&chunk).map(Vec::as_slice))
    }

    /// Whether a cell last seen at `seen_s` is still remembered.
    fn remembers(&self, seen_s: f64) -> bool {
        seen_s >= self.forget_before
    }

    /// Every remembered cell and when it was last seen.
    #[cfg(test)]
    pub(super) fn cells(&self) -> impl Iterator<Item = SeenCell> + '_ {
        let after = self.forget_before;
        self.chunks
            .values()
            .flatten()
            .copied()
            .filter(move |&(_, t)| t >= after)
    }
}

/// Points bucketed into square cells (a CSR layout rebuilt every control), so that checking a
/// pose visits the points in the cells around it instead of every remembered point: a wall seen
/// for 1.5 s is hundreds of points, and a control checks tens of poses.
#[derive(Clone, Debug, Default)]
pub(super) struct PointGrid {
    /// The points, cell after cell (row-major: x index, then y index).
    pub(super) points: Vec<[f32; 2]>,
    /// Cell `c` holds `points[starts[c]..starts[c + 1]]`.
    starts: Vec<u32>,
    /// Workspaces of `rebuild`: each input point's cell, and each cell's next free slot.
    cell_of_point: Vec<u32>,
    cursor: Vec<u32>,
    min: [f32; 2],
    cell_m: f32,
    /// 1 / `cell_m`.
    per_m: f32,
    dims: [usize; 2],
}

impl PointGrid {
    /// Cell side, metres (at least: a grid is kept under `MAX_CELLS` cells).
    const CELL_M: f32 = 0.25;
    const MAX_CELLS: usize = 1 << 14;

    pub(super) fn rebuild(&mut self, pts: &[[f32; 2]]) {
        self.points.clear();
        self.starts.clear();
        self.dims = [0, 0];
        if pts.is_empty() {
            return;
        }
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        for p in pts {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        self.cell_m = Self::CELL_M.max(extent / (Self::MAX_CELLS as f32).sqrt());
        self.per_m = 1.0 / self.cell_m;
        self.min = lo;
        self.dims = [0, 1].map(|a| ((hi[a] - lo[a]) / self.cell_m) as usize + 1);
        let n = self.dims[0] * self.dims[1];
        self.starts.resize(n + 1, 0);
        self.cell_of_point.clear();
        for p in pts {
            let c = self.cell_of(p);
            self.cell_of_point.push(c as u32);
            self.starts[c + 1] += 1;
        }
        for c in 0..n {
            self.starts[c + 1] += self.starts[c];
        }
        self.points.resize(pts.len(), [0.0; 2]);
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.starts[..n]);
        for (p, c) in pts.iter().zip(&self.cell_of_point) {
            let slot = &mut self.cursor[*c as usize];
            self.points[*slot as usize] = *p;
            *slot += 1;
        }
    }

    /// The cell index of coordinate `v` along axis `a`, clamped to the grid (monotonic in `v`,
    /// so a range of coordinates maps to a range of cells; `as` saturates below 0 to 0).
    fn index(&self, v: f32, a: usize) -> usize {
        (((v - self.min[a]) * self.per_m) as usize).min(self.dims[a] - 1)
    }

    fn cell_of(&self, p: &[f32; 2]) -> usize {
        self.index(p[0], 0) * self.dims[1] + self.index(p[1], 1)
    }

    /// Every point in the cells that meet the box from `lo` to `hi` (so every point in it, and
    /// some more).
    pub(super) fn within(&self, lo: [f32; 2], hi: [f32; 2]) -> impl Iterator<Item = &[f32; 2]> {
        let span = |a: usize| {
            let (lo, hi) = (lo[a], hi[a]);
            let max = self.min[a] + self.dims[a] as f32 * self.cell_m;
            if self.dims[a] == 0 || hi < self.min[a] || lo > max {
                return (1, 0);
            }
            (self.index(lo, a), self.index(hi, a))
        };
        let (i0, i1) = span(0);
        let (j0, j1) = span(1);
        let empty = j0 > j1;
        (i0..=i1).flat_map(move |i| {
            let row = i * self.dims[1];
            let (s, e) = if empty {
                (0, 0)
            } else {
                (self.starts[row + j0] as usize, self.starts[row + j1 + 1] as usize)
            };
            self.points[s..e].iter()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::Control;
    use crate::task::safety::SafetyFilter;
    use crate::task::safety::arcs::PATH_STEP_M;
    use crate::task::safety::tests::{FAN, on, remembering, wall_frame};
    use proptest::prelude::*;

    #[test]
    fn an_arc_is_free_until_the_body_meets_a_point_on_it() {
        // A point on the rear axle's arc at full left lock (radius r = L / tan 0.36), a quarter
        // turn ahead. Seen from the car, a point an angle a ahead on that circle sits at
        // (r sin a, r (1 - cos a)): the body's front edge (0.415 m + 0.08 m margin) reaches it
        // at sin a = 0.495 / r, while it is still within the body's half width.
        let fan = std::f32::consts::FRAC_PI_4;
        let mut body_only = SafetyFilter::new(
            SafetyFilterConfig {
                clearance_m: 0.0,
                ..on().cfg
            },
            true,
        );
        let k = 0.36f32.tan() / 0.33;
        let r = 1.0 / k;
        body_only.memory.near = vec![[r, r]];
        body_only.memory.near_grid.rebuild(&body_only.memory.near);
        let free = body_only.free_length(0.36, 3.0, fan);
        let quarter = std::f32::consts::FRAC_PI_2 * r;
        let want = quarter - r * (0.495 / r).asin();
        assert!(
            free <= want && free > want - PATH_STEP_M - 1e-4,
            "free {free}, want {want}"
        );
        // The LiDAR's clearance stops the path earlier; the straight path passes the point by.
        let mut f = on();
        f.memory.near = body_only.memory.near.clone();
        f.memory.near_grid.rebuild(&f.memory.near);
        assert!(f.free_length(0.36, 3.0, fan) < free);
        assert_eq!(f.free_length(0.0, 3.0, fan), 3.0);
    }

    #[test]
    fn remembered_points_follow_the_odometry() {
        // One ray straight ahead sees a point 2 m off the LiDAR; after 1 s at 1 m/s (ten frames
        // with no hits) the point sits 1 m closer in the car's frame.
        let only_centre = |fr: &mut SensorFrame, hit_centre: bool| {
            let s = fr.scan.as_mut().unwrap();
            for (i, (r, h)) in s.ranges.iter_mut().zip(s.hit.iter_mut()).enumerate() {
                *h = hit_centre && i == 50;
                if !*h {
                    *r = 12.0;
                }
            }
        };
        let go = Control {
            throttle: 0.5,
            steering_rad: 0.0,
        };
        let mut f = on();
        let mut first = wall_frame(2.0, 0.0, 1.0);
        only_centre(&mut first, true);
        f.filter(&first, go, 0.36, FAN);
        for k in 1..=10 {
            let mut later = wall_frame(12.0, 0.1 * k as f64, 1.0);
            only_centre(&mut later, false);
            f.filter(&later, go, 0.36, FAN);
        }
        assert_eq!(f.memory.near.len(), 1);
        let [x, y] = f.memory.near[0];
        assert!((x - 1.16).abs() < 0.04 && y.abs() < 0.04, "({x}, {y})");
        // Forgotten after memory_s.
        let mut much_later = wall_frame(12.0, 3.0, 0.0);
        only_centre(&mut much_later, false);
        f.filter(&much_later, go, 0.36, FAN);
        assert!(f.memory.near.is_empty());
    }

    #[test]
    fn reverse_lengths_end_at_points_seen_behind_and_at_the_way_the_car_came() {
        let at_rest = |t: f64| {
            let mut fr = wall_frame(12.0, t, 0.0);
            fr.scan.as_mut().unwrap().hit.fill(false);
            fr
        };
        let lengths = |f: &mut SafetyFilter, fr: &SensorFrame| {
            let mut out = vec![];
            f.reverse_free_fractions(fr, &[0.36, 0.0, -0.36], 1.5, FAN, &mut out);
            out
        };
        // At a spawn nothing behind is known: no reverse arc is free.
        let mut f = on();
        assert_eq!(lengths(&mut f, &at_rest(0.0)), [0.0; 3]);
        // After 1 m forward with nothing seen, each arc is free for the 1 m driven.
        for k in 1..=10 {
            let mut fr = at_rest(0.1 * k as f64);
            fr.imu.as_mut().unwrap().lin_vel_b[0] = 1.0;
            lengths(&mut f, &fr);
        }
        for l in lengths(&mut f, &at_rest(1.1)) {
            assert!((l - 1.0 / 1.5).abs() < 1e-4, "{l}");
        }
        // A point seen 5 s ago 0.6 m behind the rear axle (its cell's centre 0.575 m): straight
        // back, the body's back (0.085 m) and margin (0.08 m) reach it after 0.41 m, so the
        // last clear pose is 0.40 m back.
        let mut f = remembering(-0.6, 0.0, 0.0, 5.0);
        let l = lengths(&mut f, &at_rest(5.0));
        assert!((l[1] - 0.40 / 1.5).abs() < 1e-4, "{l:?}");
        // Beyond reverse_memory_s it is forgotten.
        let mut f = remembering(-0.6, 0.0, 0.0, 10.5);
        assert_eq!(lengths(&mut f, &at_rest(10.5))[1], 1.0);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 400, max_global_rejects: 4000, ..ProptestConfig::default() })]

        /// Forgetting in sweeps keeps what forgetting at every call keeps, stamps running
        /// backwards included.
        #[test]
        fn the_memory_keeps_what_forgetting_every_control_keeps(
            ops in prop::collection::vec(
                prop_oneof![
                    ((-40i32..40, -40i32..40), 0.0f64..30.0).prop_map(|(c, t)| (Some(c), t)),
                    (0.0f64..30.0).prop_map(|t| (None, t)),
                ],
                1..300,
            ),
        ) {
            let mut memory = CellMemory::default();
            let mut model = HashMap::new();
            // A cell is seen at or after the last time forgetting was called with.
            let mut floor = 0.0;
            for (cell, t) in ops {
                match cell {
                    Some(c) => {
                        memory.insert(c, floor + t);
                        model.insert(c, floor + t);
                    }
                    None => {
                        memory.forget_before(t);
                        model.retain(|_, seen| *seen >= t);
                        floor = t;
                    }
                }
                let mut kept: Vec<_> = memory.cells().collect();
                kept.sort_by_key(|c| c.0);
                let mut want: Vec<_> = model.iter().map(|(&c, &t)| (c, t)).collect();
                want.sort_by_key(|c| c.0);
                prop_assert_eq!(kept, want);
            }
        }
    }
}
