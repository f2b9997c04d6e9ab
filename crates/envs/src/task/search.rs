//! Search / exploration (the paper's R_search): drive fast, keep a clearance band, avoid
//! obstacles. Reports coverage of the free map and the distance travelled.

use super::explored::ExploredMemory;
use super::reward::{self, SafeShaping, SearchReward};
use super::safety::ObstacleMemory;
use super::{CommonConfig, Intervention, Outcome, SafetyFilter, ScanHistory, Task, min_range_ahead_m, terminate};
use crate::api::{BoxSpace, Control, MapInfo, SearchInfo, SensorFrame, SensorNeeds};
use serde::{Deserialize, Serialize};

/// Search settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SearchConfig {
    /// Shared settings.
    #[serde(flatten)]
    pub common: CommonConfig,
    /// Reward form.
    pub reward: SearchReward,
    /// Constants of the `safe` form.
    pub safe: SafeShaping,
    /// AutoVRL's outdoor-50 extra -50 when T < 0.1.
    pub slow_penalty: bool,
    /// The episode ends when the minimum range falls below this, metres (AutoVRL: 0.6).
    pub terminate_below_m: f32,
    /// r_m, the range the reward and the termination use, is the minimum over the rays within
    /// half this of straight ahead, degrees; 0: every ray. AutoVRL's LiDAR is 90 degrees wide,
    /// so 90 keeps its r_m for a wider LiDAR whose side rays only feed the observation.
    pub clearance_fov_deg: f32,
    /// A free cell counts as covered once the vehicle came this close, metres.
    pub coverage_radius_m: f32,
    /// A subject counts as found once it covers this many camera pixels...
    pub found_min_pixels: usize,
    /// ...no farther than this, metres (the stand-in for a detector's range).
    pub found_range_m: f32,
}

impl Default for SearchConfig {
    fn default() -> Self {
        Self {
            common: CommonConfig::default(),
            reward: SearchReward::AutovrlCode,
            safe: SafeShaping::default(),
            slow_penalty: false,
            terminate_below_m: 0.6,
            clearance_fov_deg: 0.0,
            coverage_radius_m: 2.0,
            found_min_pixels: 30,
            found_range_m: 8.0,
        }
    }
}

/// The search task.
pub struct Search {
    cfg: SearchConfig,
    steering_limit: f64,
    grid: CoverageGrid,
    covered: Vec<bool>,
    n_covered: usize,
    distance_m: f64,
    last_xy: Option<[f64; 2]>,
    start_s: f64,
    /// When the last newly covered cell was reached, seconds (the `stale` charge).
    last_new_cell_s: f64,
    found: Vec<(u32, f64)>,
    n_subjects: usize,
    filter: SafetyFilter,
    correction: Option<Vec<f32>>,
    interventions: u64,
    /// Steered, braked and reversed controls, and back-outs begun, since reset.
    by_kind: [u64; 4],
    clearance_m: f64,
    explored: Option<ExploredMemory>,
    /// With `observation.rear`: the obstacle memory the reverse lengths are checked against
    /// (kept as the safety filter keeps its own, under `safety_filter`'s geometry), and the
    /// reverse lengths of the last frame.
    rear: Option<(ObstacleMemory, Vec<f32>)>,
    past: ScanHistory,
}

/// The free cells of a map that coverage counts, indexed by position.
#[derive(Default)]
pub struct CoverageGrid {
    origin: [f32; 2],
    cell: f32,
    nx: i32,
    ny: i32,
    index: Vec<i32>,
    n_free: usize,
}

impl CoverageGrid {
    /// The grid of `map`'s free cells; cell k is the k-th in map order that lies on the map.
    pub fn new(map: &MapInfo) -> Self {
        let cell = map.cell_m.max(1e-3);
        let origin = [-map.half_extent_m[0], -map.half_extent_m[1]];
        let nx = (2.0 * map.half_extent_m[0] / cell).ceil() as i32;
        let ny = (2.0 * map.half_extent_m[1] / cell).ceil() as i32;
        let mut index = vec![-1; (nx * ny).max(0) as usize];
        let mut n_free = 0;
        for c in &map.free_cells {
            let i = ((c[0] - origin[0]) / cell).floor() as i32;
            let j = ((c[1] - origin[1]) / cell).floor() as i32;
            if (0..nx).contains(&i) && (0..ny).contains(&j) {
                index[(i * ny + j) as usize] = n_free as i32;
                n_free += 1;
            }
        }
        Self {
            origin,
            cell,
            nx,
            ny,
            index,
            n_free,
        }
    }

    /// Number of free cells.
    pub fn len(&self) -> usize {
        self.n_free
    }

    /// Whether the map has no free cell.
    pub fn is_empty(&self) -> bool {
        self.n_free == 0
    }

    /// Call `f` with every free cell whose centre lies within `r` of (x, y).
    pub fn for_each_within(&self, x: f32, y: f32, r: f32, mut f: impl FnMut(usize)) {
        let (i0, i1) = (
            ((x - r - self.origin[0]) / self.cell).floor() as i32,
            ((x + r - self.origin[0]) / self.cell).ceil() as i32,
        );
        let (j0, j1) = (
            ((y - r - self.origin[1]) / self.cell).floor() as i32,
            ((y + r - self.origin[1]) / self.cell).ceil() as i32,
        );
        for i in i0.max(0)..i1.min(self.nx) {
            for j in j0.max(0)..j1.min(self.ny) {
                let k = self.index[(i * self.ny + j) as usize];
                if k < 0 {
                    continue;
                }
                let cx = self.origin[0] + (i as f32 + 0.5) * self.cell;
                let cy = self.origin[1] + (j as f32 + 0.5) * self.cell;
                if (cx - x).powi(2) + (cy - y).powi(2) <= r * r {
                    f(k as usize);
                }
            }
        }
    }
}

impl Search {
    /// A search task.
    pub fn new(cfg: SearchConfig, steering_limit_rad: f64) -> Self {
        Self {
            cfg,
            steering_limit: steering_limit_rad,
            grid: CoverageGrid::default(),
            covered: vec![],
            n_covered: 0,
            distance_m: 0.0,
            last_xy: None,
            start_s: 0.0,
            last_new_cell_s: 0.0,
            found: vec![],
            n_subjects: 0,
            filter: SafetyFilter::new(
                cfg.common.safety_filter,
                cfg.common.action_mapping == crate::task::ActionMapping::ScaledReverse,
            ),
            correction: None,
            interventions: 0,
            by_kind: [0; 4],
            clearance_m: f64::INFINITY,
            explored: (!cfg.common.observation.explored.is_empty())
                .then(|| ExploredMemory::new(cfg.common.observation.explored)),
            rear: (!cfg.common.observation.rear.is_empty()).then(|| (ObstacleMemory::new(true), vec![])),
            past: ScanHistory::new(cfg.common.observation.past_scans),
        }
    }

    /// Take in a frame for the reverse lengths (`observation.rear`).
    fn look_behind(&mut self, frame: &SensorFrame) {
        let rear_cfg = self.cfg.common.observation.rear;
        let fan = (self.cfg.clearance_fov_deg > 0.0).then(|| 0.5 * self.cfg.clearance_fov_deg.to_radians());
        let filter_cfg = &self.cfg.common.safety_filter;
        if let Some((memory, lengths)) = &mut self.rear {
            lengths.clear();
            let deltas = rear_cfg.steerings(self.steering_limit);
            memory.reverse_free_fractions(filter_cfg, frame, &deltas, rear_cfg.max_m, fan, lengths);
        }
    }

    /// Mark subjects that cover enough near pixels of the frame's segmentation as found.
    fn look(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        let (Some(img), Some(m)) = (&frame.image, map) else {
            return;
        };
        for &id in &m.subjects {
            if self.found.iter().any(|(f, _)| *f == id) {
                continue;
            }
            let n = img
                .segmentation
                .iter()
                .zip(&img.depth_m)
                .filter(|(s, z)| **s == id + 1 && **z <= self.cfg.found_range_m)
                .count();
            if n >= self.cfg.found_min_pixels {
                self.found.push((id, frame.stamp_s - self.start_s));
            }
        }
    }

    fn cover(&mut self, x: f32, y: f32) {
        let (covered, n_covered) = (&mut self.covered, &mut self.n_covered);
        self.grid.for_each_within(x, y, self.cfg.coverage_radius_m, |k| {
            if !covered[k] {
                covered[k] = true;
                *n_covered += 1;
            }
        });
    }

    fn info(&self) -> SearchInfo {
        let coverage = if !self.grid.is_empty() {
            self.n_covered as f64 / self.grid.len() as f64
        } else {
            0.0
        };
        SearchInfo {
            coverage,
            distance_m: self.distance_m,
            subjects_found: self.found.len(),
            subjects_total: self.n_subjects,
            find_times_s: self.found.iter().map(|(_, t)| *t).collect(),
            filter_interventions: self.interventions,
            filter_steered: self.by_kind[0],
            filter_braked: self.by_kind[1],
            filter_reversed: self.by_kind[2],
            filter_backouts: self.by_kind[3],
            clearance_m: self.clearance_m,
        }
    }
}

impl Task for Search {
    fn needs(&self) -> SensorNeeds {
        self.cfg.common.needs()
    }

    fn observation_space(&self) -> BoxSpace {
        self.cfg.common.space()
    }

    fn control(&mut self, action: &[f32], steering_limit_rad: f64, frame: &SensorFrame) -> Control {
        let proposed = self.cfg.common.control(action, steering_limit_rad);
        let fan = (self.cfg.clearance_fov_deg > 0.0).then(|| 0.5 * self.cfg.clearance_fov_deg.to_radians());
        let before = self.filter.last_intervention();
        let (c, correction) = self.filter.apply(frame, proposed, steering_limit_rad, fan);
        self.correction = correction.map(|k| self.cfg.common.action_of(k, steering_limit_rad));
        let now = self.filter.last_intervention();
        if now != Intervention::None {
            self.interventions += 1;
        }
        match now {
            Intervention::None => {}
            Intervention::Steered => self.by_kind[0] += 1,
            Intervention::Braked => self.by_kind[1] += 1,
            Intervention::Reversed => {
                self.by_kind[2] += 1;
                self.by_kind[3] += (before != Intervention::Reversed) as u64;
            }
        }
        c
    }

    fn intervention(&self) -> Intervention {
        self.filter.last_intervention()
    }

    fn corrected_action(&self) -> Option<Vec<f32>> {
        self.correction.clone()
    }

    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) {
        self.filter.reset();
        self.correction = None;
        self.interventions = 0;
        self.by_kind = [0; 4];
        self.clearance_m = min_range_ahead_m(frame, self.cfg.clearance_fov_deg);
        if let Some(m) = &mut self.explored {
            m.clear();
            m.visit(frame);
        }
        if let Some((memory, _)) = &mut self.rear {
            memory.reset();
        }
        self.look_behind(frame);
        self.past.reset(frame);
        self.grid = map.map(CoverageGrid::new).unwrap_or_default();
        self.start_s = frame.stamp_s;
        self.last_new_cell_s = frame.stamp_s;
        self.found.clear();
        self.n_subjects = map.map(|m| m.subjects.len()).unwrap_or(0);
        self.look(frame, map);
        self.covered = vec![false; self.grid.len()];
        self.n_covered = 0;
        self.distance_m = 0.0;
        self.last_xy = frame.gps.as_ref().map(|g| [g.position_m[0], g.position_m[1]]);
        if let Some([x, y]) = self.last_xy {
            self.cover(x as f32, y as f32);
        }
    }

    fn observe(&self, frame: &SensorFrame) -> Vec<f32> {
        self.cfg.common.observation.observe(
            frame,
            self.steering_limit,
            self.explored.as_ref(),
            self.rear.as_ref().map(|(_, l)| l.as_slice()),
            Some(&self.past),
        )
    }

    fn evaluate(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Outcome {
        let d = min_range_ahead_m(frame, self.cfg.clearance_fov_deg);
        self.clearance_m = d;
        let c = frame.applied;
        let covered_before = self.n_covered;
        if let Some(g) = &frame.gps {
            let xy = [g.position_m[0], g.position_m[1]];
            if let Some(p) = self.last_xy {
                self.distance_m += ((xy[0] - p[0]).powi(2) + (xy[1] - p[1]).powi(2)).sqrt();
            }
            self.last_xy = Some(xy);
            self.cover(xy[0] as f32, xy[1] as f32);
        }
        if let Some(m) = &mut self.explored {
            m.visit(frame);
        }
        self.look_behind(frame);
        self.past.push(frame);
        let new_cells = self.n_covered - covered_before;
        let mut terms = reward::search(
            self.cfg.reward,
            &self.cfg.safe,
            d,
            // A back-out's reverse throttle earns nothing.
            c.throttle.max(0.0),
            c.steering_rad,
            self.cfg.slow_penalty,
            new_cells,
        );
        let forward = frame.imu.as_ref().map_or(f64::INFINITY, |i| i.lin_vel_b[0]);
        reward::weight_proximity_by_speed(&mut terms, &self.cfg.safe, forward);
        if self.cfg.reward == SearchReward::Safe && self.filter.last_intervention() != Intervention::None {
            terms.filter = self.cfg.safe.filter;
        }
        if new_cells > 0 {
            self.last_new_cell_s = frame.stamp_s;
        } else if self.cfg.reward == SearchReward::Safe
            && frame.stamp_s - self.last_new_cell_s > self.cfg.safe.stale_after_s
        {
            terms.stale = self.cfg.safe.stale;
        }
        let termination = terminate(
            &mut terms,
            frame,
            map,
            d,
            self.cfg.terminate_below_m,
            self.cfg.reward.collision_penalty(&self.cfg.safe),
        );
        self.look(frame, map);
        Outcome {
            terms,
            termination,
            truncate: false,
            racing: None,
            search: Some(self.info()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::TerminationCause;
    use agvrl_sim::msg::LaserScan;

    /// A 270 degree scan (one ray per degree) reading 5 m except `near` m at `bearing_deg`.
    fn frame(bearing_deg: i32, near: f32) -> SensorFrame {
        let ranges: Vec<f32> = (-135..=135)
            .map(|a| if a == bearing_deg { near } else { 5.0 })
            .collect();
        SensorFrame {
            scan: Some(LaserScan {
                angle_min: -135f32.to_radians(),
                angle_increment: 1f32.to_radians(),
                range_min: 0.05,
                range_max: 12.0,
                hit: vec![true; ranges.len()],
                ranges,
                ..LaserScan::default()
            }),
            ..SensorFrame::default()
        }
    }

    #[test]
    fn clearance_fov_judges_only_the_rays_ahead() {
        let narrow = SearchConfig {
            clearance_fov_deg: 90.0,
            reward: SearchReward::Safe,
            ..SearchConfig::default()
        };
        let whole = SearchConfig {
            clearance_fov_deg: 0.0,
            ..narrow
        };
        let ended = |cfg: SearchConfig, f: &SensorFrame| {
            let mut s = Search::new(cfg, 0.36);
            s.reset(f, None);
            s.evaluate(f, None)
        };
        // An obstacle 0.4 m away at 80 degrees (beside the car): outside AutoVRL's 90 degree
        // fan, so only the whole-scan rule ends the episode.
        let side = frame(80, 0.4);
        assert_eq!(ended(whole, &side).termination, Some(TerminationCause::TooClose));
        let o = ended(narrow, &side);
        assert_eq!(o.termination, None);
        assert_eq!(o.terms.proximity, 0.0, "r_m is 5 m ahead");
        // At 30 degrees it is ahead: both end it.
        assert_eq!(
            ended(narrow, &frame(30, 0.4)).termination,
            Some(TerminationCause::TooClose)
        );
        // 45 degrees is the fan's edge, still inside.
        assert_eq!(
            ended(narrow, &frame(45, 0.5)).termination,
            Some(TerminationCause::TooClose)
        );
        assert_eq!(ended(narrow, &frame(47, 0.5)).termination, None);
    }

    #[test]
    fn stale_is_charged_only_after_stale_after_s_without_a_new_cell() {
        let cfg = SearchConfig {
            reward: SearchReward::Safe,
            safe: SafeShaping {
                stale: -0.3,
                stale_after_s: 1.0,
                ..SafeShaping::default()
            },
            ..SearchConfig::default()
        };
        // Free cells every 0.5 m along y = 0, x from 0 to 20 m; coverage reaches 2 m.
        let map = MapInfo {
            half_extent_m: [30.0, 30.0],
            free_cells: (0..=40).map(|k| [k as f32 * 0.5, 0.0]).collect(),
            cell_m: 0.5,
            ..MapInfo::default()
        };
        let at = |x: f64, t: f64| SensorFrame {
            stamp_s: t,
            gps: Some(agvrl_sim::msg::GpsReading {
                position_m: [x, 0.0, 0.0],
                orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
                ..Default::default()
            }),
            ..frame(0, 5.0)
        };
        let mut s = Search::new(cfg, 0.36);
        s.reset(&at(0.0, 0.0), Some(&map));
        // Standing still: free for 1 s, then charged every step.
        let charged: Vec<f64> = (1..=20)
            .map(|k| s.evaluate(&at(0.0, k as f64 * 0.1), Some(&map)).terms.stale)
            .collect();
        assert!(charged[..10].iter().all(|&c| c == 0.0), "{charged:?}");
        assert!(charged[10..].iter().all(|&c| c == -0.3), "{charged:?}");
        // New ground clears it at once; the clock starts again.
        let o = s.evaluate(&at(3.0, 2.1), Some(&map));
        assert!(o.terms.coverage > 0.0);
        assert_eq!(o.terms.stale, 0.0);
        assert_eq!(s.evaluate(&at(3.0, 3.0), Some(&map)).terms.stale, 0.0);
        assert_eq!(s.evaluate(&at(3.0, 3.2), Some(&map)).terms.stale, -0.3);
        // Off by default.
        let mut free = Search::new(
            SearchConfig {
                reward: SearchReward::Safe,
                ..SearchConfig::default()
            },
            0.36,
        );
        free.reset(&at(0.0, 0.0), Some(&map));
        assert_eq!(free.evaluate(&at(0.0, 50.0), Some(&map)).terms.stale, 0.0);
    }
}
