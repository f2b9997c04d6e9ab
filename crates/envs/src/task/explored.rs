//! A memory of the ground the car has explored, read from the GPS / pose fix only (no map), so
//! the same code runs on the car: a memoryless policy cannot tell new ground from old and
//! sweeps the same loop again and again. The observation gets, for each sector around the car
//! and each ring of distances, the fraction of its cells the car has not yet come near, and
//! optionally the fraction it has seen free (a LiDAR ray crossed it) but not yet come near: the
//! frontier, which, unlike unexplored ground, never lies behind a wall.

use crate::api::SensorFrame;
use serde::{Deserialize, Serialize};

/// Cells per side of the memory grid (a power of two): positions wrap around every
/// `GRID * cell_m` metres, far beyond what one query reads, so the memory needs no map bounds.
const GRID: i32 = 256;

/// The explored-ground part of the observation (`[env_config.observation.explored]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExploredObs {
    /// Sectors around the car (0: off). Sector k is centred `k * 360 / sectors` degrees left of
    /// straight ahead.
    pub sectors: usize,
    /// Ring boundaries, metres: ring k spans `radii_m[k]` to `radii_m[k + 1]` from the car.
    pub radii_m: [f32; 3],
    /// A cell is explored once the car came this close to its centre, metres (the coverage
    /// radius).
    pub visited_m: f32,
    /// Cell size, metres.
    pub cell_m: f32,
    /// Also append the frontier fractions (seen free, not yet visited) after the unexplored
    /// ones; needs the LiDAR scan.
    pub frontier: bool,
    /// When > 0, also append how long the car has gone without coming near a cell it had not
    /// visited, over this many seconds (capped at 1), last: a car parked on swept ground sees
    /// the time pass, where the rest of its observation stands still. 0: off.
    pub stale_s: f32,
    /// When > 0, also append where the nearest frontier cell (seen free, not yet visited) within
    /// this many metres lies: (1 + cos) / 2 and (1 + sin) / 2 of its bearing from straight ahead,
    /// and its distance over `goal_m` (0.5, 0.5, 1 when there is none), before the stale time.
    /// Needs the LiDAR scan. The rings end at `radii_m[2]`; a car whose rings are all swept
    /// learns from this where new ground lies. 0: off.
    pub goal_m: f32,
}

impl Default for ExploredObs {
    fn default() -> Self {
        Self {
            sectors: 0,
            radii_m: [2.0, 4.0, 8.0],
            visited_m: 2.0,
            cell_m: 0.5,
            frontier: false,
            stale_s: 0.0,
            goal_m: 0.0,
        }
    }
}

impl ExploredObs {
    /// Values appended: one per sector and ring (twice with the frontier), three for the nearest
    /// frontier cell, and the stale time, each in [0, 1].
    pub fn len(&self) -> usize {
        if self.sectors == 0 {
            return 0;
        }
        self.sectors * (self.radii_m.len() - 1) * (1 + self.frontier as usize)
            + 3 * (self.goal_m > 0.0) as usize
            + (self.stale_s > 0.0) as usize
    }

    /// Whether it is off.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The parts appended, in order, with their widths (none when off).
    pub fn layout(&self) -> Vec<(&'static str, usize)> {
        if self.is_empty() {
            return vec![];
        }
        vec![
            ("explored", self.sectors * (self.radii_m.len() - 1)),
            (
                "explored.frontier",
                self.sectors * (self.radii_m.len() - 1) * self.frontier as usize,
            ),
            ("explored.goal", 3 * (self.goal_m > 0.0) as usize),
            ("explored.stale", (self.stale_s > 0.0) as usize),
        ]
    }

    /// An error for settings that cannot work.
    pub fn validate(&self) -> Result<(), agvrl_sim::InvalidSetting> {
        if self.is_empty() {
            return Ok(());
        }
        let r = self.radii_m;
        let ok = self.sectors <= 64
            && self.cell_m.is_finite()
            && self.cell_m >= 0.05
            && self.visited_m.is_finite()
            && self.visited_m >= 0.0
            && r.iter().all(|x| x.is_finite())
            && r[0] >= 0.0
            && r[0] < r[1]
            && r[1] < r[2]
            && r[2].max(self.visited_m) < 0.25 * GRID as f32 * self.cell_m
            && self.stale_s.is_finite()
            && self.stale_s >= 0.0
            && self.goal_m.is_finite()
            && self.goal_m >= 0.0
            && self.goal_m < 0.25 * GRID as f32 * self.cell_m;
        if ok {
            Ok(())
        } else {
            Err(agvrl_sim::InvalidSetting::new(
                "observation.explored",
                format!(
                    "observation.explored needs sectors <= 64, cell_m >= 0.05, 0 <= radii_m[0] < radii_m[1] < \
                     radii_m[2], radii_m[2], visited_m, goal_m < {} cells and stale_s, goal_m >= 0; got {self:?}",
                    GRID / 4
                ),
            ))
        }
    }
}

/// A cell the car came near.
const VISITED: u8 = 1;
/// A cell a LiDAR ray crossed before its hit.
const SEEN: u8 = 2;
/// Rays mark free cells out to this range at most, metres.
const SEE_WITHIN_M: f32 = 10.0;
/// A scan is marked only once the car has turned this far since the last marked one, radians,
/// or moved half a cell: marking costs about 40 us a scan, and a scan from nearly the same pose
/// marks nearly the same cells.
const SEE_TURN_RAD: f64 = 0.1;

/// The memory behind `ExploredObs` for one episode.
#[derive(Clone, Debug)]
pub struct ExploredMemory {
    cfg: ExploredObs,
    /// `VISITED | SEEN` bits per cell.
    visited: Vec<u8>,
    /// Cells within the rings, relative to the car's cell: offset, bearing (rad), ring.
    stencil: Vec<(i32, i32, f32, usize)>,
    /// Cells within `goal_m` of the car's cell, nearest first.
    goal_stencil: Vec<(i32, i32)>,
    /// When `visit` last marked a cell visited for the first time, seconds.
    last_new_s: Option<f64>,
    /// The pose (x, y, yaw) of the last scan marked.
    last_seen: Option<(f64, f64, f64)>,
}

impl ExploredMemory {
    /// An empty memory (the settings were validated).
    pub fn new(cfg: ExploredObs) -> Self {
        let c = cfg.cell_m;
        let reach = (cfg.radii_m[2] / c).ceil() as i32 + 1;
        let mut stencil = Vec::new();
        for di in -reach..=reach {
            for dj in -reach..=reach {
                let (x, y) = (di as f32 * c, dj as f32 * c);
                let d = x.hypot(y);
                if let Some(ring) = (0..2).find(|&k| d >= cfg.radii_m[k] && d < cfg.radii_m[k + 1]) {
                    stencil.push((di, dj, y.atan2(x), ring));
                }
            }
        }
        let reach = (cfg.goal_m / c).ceil() as i32;
        let mut goal_stencil: Vec<(i32, i32)> = (-reach..=reach)
            .flat_map(|di| (-reach..=reach).map(move |dj| (di, dj)))
            .filter(|&(di, dj)| ((di * di + dj * dj) as f32).sqrt() * c <= cfg.goal_m)
            .collect();
        goal_stencil.sort_by_key(|&(di, dj)| (di * di + dj * dj, di, dj));
        Self {
            cfg,
            visited: vec![0; (GRID * GRID) as usize],
            stencil,
            goal_stencil,
            last_new_s: None,
            last_seen: None,
        }
    }

    fn index(i: i32, j: i32) -> usize {
        ((i & (GRID - 1)) * GRID + (j & (GRID - 1))) as usize
    }

    fn cell_of(&self, v: f64) -> i32 {
        (v / self.cfg.cell_m as f64).round() as i32
    }

    /// Forget everything (a new episode).
    pub fn clear(&mut self) {
        self.visited.fill(0);
        self.last_new_s = None;
        self.last_seen = None;
    }

    /// The memory's indices of the cells within `visited_m` of (x, y).
    fn near(cfg: &ExploredObs, x: f64, y: f64) -> impl Iterator<Item = usize> + use<> {
        let c = cfg.cell_m as f64;
        let r = cfg.visited_m as f64;
        let cell = move |v: f64| (v / c).round() as i32;
        let (i0, i1) = (cell(x - r), cell(x + r));
        let (j0, j1) = (cell(y - r), cell(y + r));
        (i0..=i1)
            .flat_map(move |i| (j0..=j1).map(move |j| (i, j)))
            .filter(move |&(i, j)| (i as f64 * c - x).powi(2) + (j as f64 * c - y).powi(2) <= r * r)
            .map(|(i, j)| Self::index(i, j))
    }

    /// Mark the cells within `visited_m` of the frame's position.
    pub fn visit(&mut self, frame: &SensorFrame) {
        let Some(g) = &frame.gps else { return };
        let (x, y) = (g.position_m[0], g.position_m[1]);
        let mut new = false;
        for k in Self::near(&self.cfg, x, y) {
            new |= self.visited[k] & VISITED == 0;
            self.visited[k] |= VISITED;
        }
        if new || self.last_new_s.is_none() {
            self.last_new_s = Some(frame.stamp_s);
        }
        if self.cfg.frontier || self.cfg.goal_m > 0.0 {
            self.see(frame);
        }
    }

    /// Mark the cells the scan's rays crossed before their hits (from the pose fix: the LiDAR
    /// sits near the base link; a cell is half a metre).
    fn see(&mut self, frame: &SensorFrame) {
        let (Some(g), Some(scan)) = (&frame.gps, &frame.scan) else {
            return;
        };
        let c = self.cfg.cell_m as f64;
        let (x, y, yaw) = (g.position_m[0], g.position_m[1], g.rpy_rad[2]);
        if let Some((lx, ly, lyaw)) = self.last_seen {
            let turned = (yaw - lyaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            if (x - lx).hypot(y - ly) < 0.5 * c && turned.abs() < SEE_TURN_RAD {
                return;
            }
        }
        self.last_seen = Some((x, y, yaw));
        let step = 0.5 * self.cfg.cell_m;
        for (k, &r) in scan.ranges.iter().enumerate() {
            if !r.is_finite() {
                continue;
            }
            let hit = scan.hit_at(k);
            // Stop short of the cell holding the hit.
            let end = if hit { r - self.cfg.cell_m } else { r }.min(SEE_WITHIN_M);
            let b = yaw + scan.bearing(k) as f64;
            let (sb, cb) = b.sin_cos();
            let mut d = step;
            while d <= end {
                let (px, py) = (x + cb * d as f64, y + sb * d as f64);
                self.visited[Self::index((px / c).round() as i32, (py / c).round() as i32)] |= SEEN;
                d += step;
            }
        }
    }

    /// Append the unexplored fraction of every (ring, sector), ring-major, then the frontier
    /// fractions if on. The frame's own position counts as visited whether or not `visit` saw
    /// it yet, so the unexplored part does not depend on whether the task evaluated the frame
    /// before observing it (the env does, the drive loop does not); the frontier reads the
    /// scans `visit` took in, so on the car it lags one frame behind the env's.
    pub fn append(&self, frame: &SensorFrame, out: &mut Vec<f32>) {
        let n = self.cfg.sectors;
        let Some(g) = frame.gps.as_ref().filter(|_| n > 0) else {
            out.extend(std::iter::repeat_n(0.0, self.cfg.len()));
            return;
        };
        let (x, y) = (g.position_m[0], g.position_m[1]);
        let (ci, cj) = (self.cell_of(x), self.cell_of(y));
        // The car's offset from its cell's centre, for the cells it stands near now.
        let c = self.cfg.cell_m as f64;
        let (ox, oy) = ((x - ci as f64 * c) as f32, (y - cj as f64 * c) as f32);
        let r2 = self.cfg.visited_m * self.cfg.visited_m;
        let yaw = g.rpy_rad[2] as f32;
        let width = std::f32::consts::TAU / n as f32;
        let n_open = self.cfg.sectors * (self.cfg.radii_m.len() - 1);
        let mut total = [0u32; 128];
        let mut open = [0u32; 256];
        for &(di, dj, bearing, ring) in &self.stencil {
            let rel = wrap_tau(bearing - yaw + 0.5 * width);
            let k = ring * n + ((rel / width) as usize).min(n - 1);
            total[k] += 1;
            let (dx, dy) = (di as f32 * self.cfg.cell_m - ox, dj as f32 * self.cfg.cell_m - oy);
            let here = dx * dx + dy * dy <= r2;
            let state = self.visited[Self::index(ci + di, cj + dj)];
            let unvisited = !here && state & VISITED == 0;
            open[k] += u32::from(unvisited);
            open[n_open + k] += u32::from(unvisited && state & SEEN != 0);
        }
        let fractions = n_open * (1 + self.cfg.frontier as usize);
        out.extend((0..fractions).map(|k| open[k] as f32 / total[k % n_open].max(1) as f32));
        if self.cfg.goal_m > 0.0 {
            // The nearest cell seen free and not visited, nor within reach from where the car
            // stands (the stencil is sorted from the car's cell centre: off by half a cell at most).
            let goal = self.goal_stencil.iter().find_map(|&(di, dj)| {
                let (dx, dy) = (di as f32 * self.cfg.cell_m - ox, dj as f32 * self.cfg.cell_m - oy);
                let state = self.visited[Self::index(ci + di, cj + dj)];
                (state & SEEN != 0 && state & VISITED == 0 && dx * dx + dy * dy > r2).then_some((dx, dy))
            });
            match goal {
                Some((dx, dy)) => {
                    let (s, c) = (dy.atan2(dx) - yaw).sin_cos();
                    let d = dx.hypot(dy) / self.cfg.goal_m;
                    out.extend([0.5 * (1.0 + c), 0.5 * (1.0 + s), d.min(1.0)]);
                }
                None => out.extend([0.5, 0.5, 1.0]),
            }
        }
        if self.cfg.stale_s > 0.0 {
            // New ground under the car now is no wait, whether or not `visit` took it in yet.
            let fresh = Self::near(&self.cfg, x, y).any(|k| self.visited[k] & VISITED == 0);
            let waited = match self.last_new_s {
                Some(t) if !fresh => (frame.stamp_s - t).max(0.0) as f32,
                _ => 0.0,
            };
            out.push((waited / self.cfg.stale_s).min(1.0));
        }
    }
}

/// `x.rem_euclid(TAU)`, without the libm call for `x` within one turn of [0, TAU) (a yaw in
/// [-pi, pi] keeps it there): one exact subtraction gives the same bits.
fn wrap_tau(x: f32) -> f32 {
    use std::f32::consts::TAU;
    if (0.0..TAU).contains(&x) {
        x
    } else if x > -TAU && x < 0.0 {
        x + TAU
    } else if (TAU..2.0 * TAU).contains(&x) {
        x - TAU
    } else {
        x.rem_euclid(TAU)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agvrl_sim::msg::GpsReading;

    fn at(x: f64, y: f64, yaw: f64) -> SensorFrame {
        SensorFrame {
            gps: Some(GpsReading {
                position_m: [x, y, 0.0],
                rpy_rad: [0.0, 0.0, yaw],
                ..GpsReading::default()
            }),
            ..SensorFrame::default()
        }
    }

    fn read(m: &ExploredMemory, f: &SensorFrame) -> Vec<f32> {
        let mut v = vec![];
        m.append(f, &mut v);
        v
    }

    fn cfg() -> ExploredObs {
        ExploredObs {
            sectors: 4,
            ..ExploredObs::default()
        }
    }

    #[test]
    fn a_fresh_memory_reads_all_unexplored_and_the_rings_start_beyond_the_visited_disk() {
        let mut m = ExploredMemory::new(cfg());
        let f = at(3.0, -7.0, 0.4);
        m.visit(&f);
        // The car marked a 2 m disk; the inner ring starts at 2 m, so nearly nothing of it is
        // explored yet (cells on the 2 m circle may be).
        let v = read(&m, &f);
        assert_eq!(v.len(), 8);
        for x in &v[..4] {
            assert!(*x > 0.85 && *x <= 1.0, "{v:?}");
        }
        for x in &v[4..] {
            assert_eq!(*x, 1.0, "{v:?}");
        }
    }

    #[test]
    fn driving_ahead_explores_the_sector_behind_and_leaves_the_one_ahead_open() {
        let mut m = ExploredMemory::new(cfg());
        // Drive 6 m along +x, heading +x, then look from the end of the track.
        for k in 0..=60 {
            m.visit(&at(k as f64 * 0.1, 0.0, 0.0));
        }
        let v = read(&m, &at(6.0, 0.0, 0.0));
        // Sectors: 0 ahead, 1 left, 2 behind, 3 right.
        // Cells on the 2 m circle count as visited from where the car stands.
        assert!(v[0] > 0.95, "ahead is new ground: {v:?}");
        assert!(v[2] < 0.1, "the ring behind (2-4 m) was driven through: {v:?}");
        // Left and right mirror each other up to the cells on the sector edges (diagonals).
        assert!(v[1] > 0.3 && (v[1] - v[3]).abs() < 0.1, "{v:?}");
        assert!(
            v[6] < 0.7 && v[4] == 1.0,
            "outer ring: behind partly explored, ahead not: {v:?}"
        );
        // Turned around (heading -x), the explored sector is now sector 0.
        let w = read(&m, &at(6.0, 0.0, std::f64::consts::PI));
        assert!(w[0] < 0.1 && w[2] > 0.95 && w[6] == 1.0 && w[4] < 0.7, "{w:?}");
    }

    #[test]
    fn the_reading_is_the_same_before_and_after_the_frame_is_visited() {
        let mut m = ExploredMemory::new(cfg());
        for k in 0..30 {
            m.visit(&at(k as f64 * 0.13, k as f64 * 0.07, 0.5));
        }
        let f = at(4.33, 2.21, 0.5);
        let before = read(&m, &f);
        m.visit(&f);
        assert_eq!(before, read(&m, &f));
    }

    #[test]
    fn the_frontier_is_ground_the_lidar_saw_free_and_never_ground_behind_a_hit() {
        use agvrl_sim::msg::LaserScan;
        let m_cfg = ExploredObs {
            frontier: true,
            ..cfg()
        };
        // A 90 degree fan ahead (+x): free to 12 m except a wall 5 m ahead within 10 degrees.
        let ranges: Vec<f32> = (-45..=45)
            .map(|a: i32| if a.abs() <= 10 { 5.0 } else { 12.0 })
            .collect();
        let mut f = at(0.0, 0.0, 0.0);
        f.scan = Some(LaserScan {
            angle_min: -45f32.to_radians(),
            angle_increment: 1f32.to_radians(),
            range_max: 12.0,
            hit: ranges.iter().map(|r| *r < 12.0).collect(),
            ranges,
            ..LaserScan::default()
        });
        let mut m = ExploredMemory::new(m_cfg);
        m.visit(&f);
        let v = read(&m, &f);
        assert_eq!(v.len(), 16);
        let (unexplored, frontier) = v.split_at(8);
        // Everything beyond 2 m is unexplored; the frontier lies ahead only.
        assert!(unexplored[4..].iter().all(|x| *x == 1.0), "{v:?}");
        assert!(frontier[0] > 0.5 && frontier[4] > 0.3, "ahead, both rings: {v:?}");
        for k in [1, 3, 5, 7] {
            assert!(
                frontier[k] < 0.1,
                "sector {}: the fan's 45 degree edge at most: {v:?}",
                k % 4
            );
        }
        assert_eq!((frontier[2], frontier[6]), (0.0, 0.0), "behind: unseen {v:?}");
        // Seen: ground before the wall and the open fan; unseen: the wall's cell, its shadow,
        // the ground beside the car and beyond the 10 m the rays mark.
        let seen = |x: f64, y: f64| m.visited[ExploredMemory::index(m.cell_of(x), m.cell_of(y))] & SEEN != 0;
        assert!(seen(3.0, 0.0) && seen(4.0, 0.3) && seen(8.0, 4.0));
        assert!(!seen(5.0, 0.0) && !seen(7.0, 0.0) && !seen(9.0, 0.5));
        assert!(!seen(0.0, 5.0) && !seen(-3.0, 0.0) && !seen(11.0, 0.0));
        // Visiting the frontier turns it into explored ground.
        for k in 0..=40 {
            m.visit(&at(k as f64 * 0.1, 0.0, 0.0));
        }
        let after = read(&m, &at(4.0, 0.0, std::f64::consts::PI));
        assert!(after[8] < frontier[0], "{after:?}");
    }

    #[test]
    fn the_goal_points_at_the_nearest_ground_seen_free_and_not_yet_visited() {
        use agvrl_sim::msg::LaserScan;
        let goal = ExploredObs { goal_m: 10.0, ..cfg() };
        assert_eq!(goal.len(), cfg().len() + 3);
        let tail = |m: &ExploredMemory, f: &SensorFrame| read(m, f)[8..].to_vec();
        // Nothing seen yet: no goal.
        let mut m = ExploredMemory::new(goal);
        m.visit(&at(0.0, 0.0, 0.0));
        assert_eq!(tail(&m, &at(0.0, 0.0, 0.0)), vec![0.5, 0.5, 1.0]);
        // A 20 degree fan ahead (+x), free to 12 m.
        let mut f = at(0.0, 0.0, 0.0);
        f.scan = Some(LaserScan {
            angle_min: -10f32.to_radians(),
            angle_increment: 1f32.to_radians(),
            range_max: 12.0,
            hit: vec![false; 21],
            ranges: vec![12.0; 21],
            ..LaserScan::default()
        });
        m.visit(&f);
        // Ahead, just beyond the 2 m the car has swept: a cell beside the axis, 2.06 m away at
        // 14 degrees (the one on the axis lies on the 2 m circle, so counts as reached).
        let v = tail(&m, &f);
        assert!(v[0] > 0.98 && (v[1] - 0.5).abs() < 0.13, "{v:?}");
        assert!(v[2] > 0.2 && v[2] < 0.25, "{v:?}");
        // Facing +y, the same ground lies to the right.
        let v = tail(&m, &at(0.0, 0.0, std::f64::consts::FRAC_PI_2));
        assert!((v[0] - 0.5).abs() < 0.13 && v[1] < 0.02, "{v:?}");
        // Having driven 4 m along the fan, the nearest unvisited ground is 2 m further on.
        for k in 0..=40 {
            m.visit(&at(k as f64 * 0.1, 0.0, 0.0));
        }
        let v = tail(&m, &at(4.0, 0.0, 0.0));
        assert!(v[0] > 0.98 && v[2] > 0.2 && v[2] < 0.25, "{v:?}");
        // Beyond goal_m there is none.
        let mut near = ExploredMemory::new(ExploredObs { goal_m: 2.0, ..goal });
        near.visit(&f);
        assert_eq!(tail(&near, &f), vec![0.5, 0.5, 1.0]);
        assert!(ExploredObs { goal_m: -1.0, ..cfg() }.validate().is_err());
        assert!(ExploredObs { goal_m: 100.0, ..cfg() }.validate().is_err());
    }

    #[test]
    fn a_scan_is_marked_again_only_once_the_car_has_moved_half_a_cell_or_turned() {
        use agvrl_sim::msg::LaserScan;
        let mut m = ExploredMemory::new(ExploredObs {
            frontier: true,
            ..cfg()
        });
        // One ray at `bearing` from the car's heading, free to 6 m.
        let ray = |x: f64, yaw: f64, bearing: f32| SensorFrame {
            scan: Some(LaserScan {
                angle_min: bearing,
                angle_increment: 0.1,
                range_max: 6.0,
                hit: vec![false],
                ranges: vec![6.0],
                ..LaserScan::default()
            }),
            ..at(x, 0.0, yaw)
        };
        let seen = |m: &ExploredMemory, x: f64, y: f64| {
            m.visited[ExploredMemory::index(m.cell_of(x), m.cell_of(y))] & SEEN != 0
        };
        let left = std::f32::consts::FRAC_PI_2;
        m.visit(&ray(0.0, 0.0, 0.0));
        assert!(seen(&m, 5.0, 0.0) && !seen(&m, 0.0, 5.0));
        // Turned 0.05 rad, or moved 0.2 m, from the marked pose: this scan (to the left) is not
        // marked.
        m.visit(&ray(0.0, 0.05, left));
        m.visit(&ray(0.2, 0.0, left));
        assert!(!seen(&m, 0.0, 5.0) && !seen(&m, 0.2, 5.0));
        // Turned 0.1 rad: marked.
        m.visit(&ray(0.0, 0.1, left));
        assert!(seen(&m, -0.5, 5.0));
        // Moved half a cell from there: marked.
        m.visit(&ray(0.0, 0.1, 0.0));
        assert!(!seen(&m, 5.0, 0.5));
        m.visit(&ray(0.25, 0.1, 0.0));
        assert!(seen(&m, 5.0, 0.5));
        // A new episode marks its first scan.
        m.clear();
        m.visit(&ray(0.0, 0.0, left));
        assert!(seen(&m, 0.0, 5.0) && !seen(&m, 5.0, 0.0));
    }

    #[test]
    fn wrap_tau_is_rem_euclid_over_the_range_it_is_used_on() {
        let tau = std::f32::consts::TAU;
        for k in -4000..=4000 {
            let x = k as f32 * 0.0019 - 0.3 * tau + (k as f32).sin() * 1e-3;
            for x in [x, x - tau, x + tau, x + 9.0 * tau, 0.0, tau, -tau, 2.0 * tau, -0.0] {
                assert_eq!(wrap_tau(x).to_bits(), x.rem_euclid(tau).to_bits(), "{x}");
            }
        }
    }

    #[test]
    fn clear_forgets_and_far_positions_do_not_alias_within_a_query() {
        let mut m = ExploredMemory::new(cfg());
        let f = at(0.0, 0.0, 0.0);
        for k in 0..50 {
            m.visit(&at(k as f64 * 0.1, 0.0, 0.0));
        }
        assert!(read(&m, &f).iter().any(|x| *x < 1.0));
        m.clear();
        m.visit(&f);
        // 100 m away the grid has not wrapped onto the visited cells (period 128 m).
        let far = at(100.0, 0.0, 0.0);
        assert_eq!(read(&m, &far), read(&ExploredMemory::new(cfg()), &far));
        assert!(
            ExploredObs {
                radii_m: [3.0, 2.0, 8.0],
                ..cfg()
            }
            .validate()
            .is_err()
        );
        assert!(cfg().validate().is_ok());
    }

    #[test]
    fn the_stale_time_grows_on_swept_ground_and_drops_to_zero_on_new_ground() {
        let stale = ExploredObs { stale_s: 2.0, ..cfg() };
        assert_eq!(stale.len(), cfg().len() + 1);
        let mut m = ExploredMemory::new(stale);
        let at_t = |x: f64, t: f64| SensorFrame {
            stamp_s: t,
            ..at(x, 0.0, 0.0)
        };
        let last = |m: &ExploredMemory, f: &SensorFrame| *read(m, f).last().unwrap();
        m.visit(&at_t(0.0, 10.0));
        // Standing still: the wait grows with the clock, over stale_s, capped at 1.
        for (t, want) in [(10.0, 0.0), (10.5, 0.25), (11.0, 0.5), (12.0, 1.0), (30.0, 1.0)] {
            let f = at_t(0.0, t);
            m.visit(&f);
            assert_eq!(last(&m, &f), want, "t = {t}");
        }
        // 0.4 m on uncovers cells at the disk's edge; back where it stood, nothing.
        m.visit(&at_t(0.4, 31.0));
        assert_eq!(last(&m, &at_t(0.4, 31.0)), 0.0);
        m.visit(&at_t(0.0, 31.5));
        assert_eq!(last(&m, &at_t(0.0, 31.5)), 0.25);
        // New ground reads 0 whether or not it was visited yet (the car's order, the env's).
        let f = at_t(3.0, 32.0);
        let before = read(&m, &f);
        assert_eq!(*before.last().unwrap(), 0.0);
        m.visit(&f);
        assert_eq!(before, read(&m, &f));
        assert_eq!(last(&m, &at_t(3.0, 33.0)), 0.5);
        // A new episode starts its clock at its first frame.
        m.clear();
        m.visit(&at_t(0.0, 100.0));
        assert_eq!(last(&m, &at_t(0.0, 100.5)), 0.25);
        assert!(ExploredObs { stale_s: -1.0, ..cfg() }.validate().is_err());
        assert!(
            ExploredObs {
                stale_s: f32::NAN,
                ..cfg()
            }
            .validate()
            .is_err()
        );
    }
}
