//! `agvrl eval --planner map|frontier`: coverage references for the search envs, driving the
//! same car, with the same settings, safety filter and held-out episodes as the policy they are
//! compared with.
//!
//! - `map`: knows the map and its exact pose (what no policy gets). Every few controls it runs
//!   Dijkstra over a 0.25 m grid of the positions `INFLATE_M` clear of every obstacle, heads for
//!   the cell with the most uncovered ground within the coverage radius per metre of cost (path
//!   length, a fixed cost, and the turn towards it), and follows that path by pure pursuit at
//!   full throttle.
//! - `frontier`: a frontier explorer (explore_lite's kind, for coverage) that knows no map: the
//!   same grid, but a position is open unless a LiDAR return (placed by the pose fix) lies
//!   within `FRONTIER_INFLATE_M` of it (unknown ground counts as open, and a path through it is replanned
//!   once the LiDAR sees what is there); its targets are frontier cells of a 0.5 m coverage grid
//!   over the arena's bounds (not yet within the coverage radius, not seen occupied, next to a
//!   covered cell), scored as the map planner scores its targets.

use crate::episode::{Observer, SimEnv, observe};
use agvrl_envs::api::MapInfo;
use agvrl_envs::task::CoverageGrid;
use agvrl_envs::task::search::SearchConfig;
use agvrl_envs::{Step, Vehicle};
use anyhow::{Context, Result};
use std::cell::RefCell;
use std::collections::BinaryHeap;

// Tuned on validation episodes (seed base 1,000,000) of the 20 m scenes, not on docs/search.md's.
const PLAN_CELL_M: f32 = 0.25;
const INFLATE_M: f32 = 0.4;
/// The frontier explorer's clearance from LiDAR returns, metres: its paths cross ground it has
/// not seen yet, so they keep farther off what it has seen (0.4 / 0.55 / 0.7 / 0.85 / 1.0 m
/// ended 10 / 7 / 1 / 2 / 0 of 60 validation episodes on urban-20, built-in and procedural,
/// covering 0.506 / 0.509 / 0.567 / 0.582 / 0.547).
const FRONTIER_INFLATE_M: f32 = 0.85;
const REPLAN_EVERY: u64 = 5;
const LOOKAHEAD_M: f32 = 0.8;
/// Targets are searched within this path length first (then anywhere), metres.
const HORIZON_M: f32 = 15.0;
/// A target's cost: path metres + `FIXED_COST_M` + `TURN_COST_M` per radian of turn towards it.
const FIXED_COST_M: f32 = 3.0;
const TURN_COST_M: f32 = 1.5;
/// Targets with fewer uncovered cells around them are not worth the trip.
const MIN_GAIN: usize = 3;
/// A car that moved less than `STUCK_M` in `STUCK_STEPS` controls gives up its target.
const STUCK_M: f32 = 0.3;
const STUCK_STEPS: u64 = 45;

/// What a planner knows of the world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Knowledge {
    /// The map and the exact pose.
    Map,
    /// What the LiDAR has returned so far, placed by the pose fix (a frontier explorer).
    Frontier,
}

/// The grid of open positions, the ground each one covers, and what is covered so far.
struct Planner {
    knowledge: Knowledge,
    origin: [f32; 2],
    nx: i32,
    ny: i32,
    open: Vec<bool>,
    /// For each planning cell, the coverage cells within the coverage radius of its centre.
    sees: Vec<Vec<u32>>,
    cover: CoverageGrid,
    cover_m: f32,
    covered: Vec<bool>,
    /// Targets given up after the car got stuck on the way.
    banned: Vec<bool>,
    /// Frontier: coverage cells a LiDAR return fell in.
    occupied: Vec<bool>,
    /// Frontier: the coverage cell under each planning cell's centre.
    cover_of: Vec<i32>,
}

impl Planner {
    fn new(sim: &agvrl_sim::Sim, map: &MapInfo, knowledge: Knowledge) -> Self {
        let half = map.half_extent_m;
        let cover = match knowledge {
            Knowledge::Map => CoverageGrid::new(map),
            // Every cell of the arena: which ones are free is what the explorer finds out.
            Knowledge::Frontier => {
                let c = map.cell_m.max(1e-3);
                let (nx, ny) = ((2.0 * half[0] / c).ceil() as i32, (2.0 * half[1] / c).ceil() as i32);
                let free_cells = (0..nx)
                    .flat_map(|i| {
                        (0..ny).map(move |j| [-half[0] + (i as f32 + 0.5) * c, -half[1] + (j as f32 + 0.5) * c])
                    })
                    .collect();
                CoverageGrid::new(&MapInfo {
                    free_cells,
                    ..map.clone()
                })
            }
        };
        let cover_m = SearchConfig::default().coverage_radius_m;
        let origin = [-half[0], -half[1]];
        let nx = (2.0 * half[0] / PLAN_CELL_M) as i32;
        let ny = (2.0 * half[1] / PLAN_CELL_M) as i32;
        let mut open = vec![false; (nx * ny) as usize];
        let mut sees = vec![Vec::new(); (nx * ny) as usize];
        for i in 0..nx {
            for j in 0..ny {
                let (x, y) = Self::centre(origin, i, j);
                let k = (i * ny + j) as usize;
                open[k] = knowledge == Knowledge::Frontier || sim.free_at(x, y, INFLATE_M);
                if open[k] {
                    cover.for_each_within(x, y, cover_m, |c| sees[k].push(c as u32));
                }
            }
        }
        let mut cover_of = Vec::new();
        if knowledge == Knowledge::Frontier {
            cover_of = (0..nx * ny)
                .map(|k| {
                    let (x, y) = Self::centre(origin, k / ny, k % ny);
                    let mut at = -1;
                    cover.for_each_within(x, y, 0.5 * map.cell_m, |c| at = c as i32);
                    at
                })
                .collect();
        }
        Self {
            knowledge,
            occupied: vec![false; cover.len()],
            cover_of,
            origin,
            nx,
            ny,
            open,
            covered: vec![false; cover.len()],
            sees,
            cover,
            cover_m,
            banned: vec![false; (nx * ny) as usize],
        }
    }

    fn centre(origin: [f32; 2], i: i32, j: i32) -> (f32, f32) {
        (
            origin[0] + (i as f32 + 0.5) * PLAN_CELL_M,
            origin[1] + (j as f32 + 0.5) * PLAN_CELL_M,
        )
    }

    fn cell_of(&self, x: f32, y: f32) -> (i32, i32) {
        (
            (((x - self.origin[0]) / PLAN_CELL_M).floor() as i32).clamp(0, self.nx - 1),
            (((y - self.origin[1]) / PLAN_CELL_M).floor() as i32).clamp(0, self.ny - 1),
        )
    }

    fn visit(&mut self, x: f32, y: f32) {
        let covered = &mut self.covered;
        self.cover.for_each_within(x, y, self.cover_m, |c| covered[c] = true);
    }

    /// Frontier: a LiDAR return at (x, y) closes the positions within `FRONTIER_INFLATE_M` of it and
    /// marks its coverage cell occupied.
    fn hit(&mut self, x: f32, y: f32) {
        let occupied = &mut self.occupied;
        self.cover.for_each_within(x, y, 0.3, |c| occupied[c] = true);
        let (ci, cj) = self.cell_of(x, y);
        let r = (FRONTIER_INFLATE_M / PLAN_CELL_M).ceil() as i32 + 1;
        for i in (ci - r).max(0)..=(ci + r).min(self.nx - 1) {
            for j in (cj - r).max(0)..=(cj + r).min(self.ny - 1) {
                let (px, py) = Self::centre(self.origin, i, j);
                if (px - x).hypot(py - y) < FRONTIER_INFLATE_M {
                    self.open[(i * self.ny + j) as usize] = false;
                }
            }
        }
    }

    /// Frontier: whether planning cell `k` lies on a frontier cell (free as far as the LiDAR
    /// knows, not yet covered, next to a covered cell).
    fn on_frontier(&self, k: usize) -> bool {
        let c = self.cover_of[k];
        if c < 0 || self.covered[c as usize] || self.occupied[c as usize] {
            return false;
        }
        let (x, y) = Self::centre(self.origin, k as i32 / self.ny, k as i32 % self.ny);
        let mut next_to_covered = false;
        self.cover
            .for_each_within(x, y, 0.75, |n| next_to_covered |= self.covered[n]);
        next_to_covered
    }

    /// The path (cell centres, from the car) to the best target, if any.
    fn plan(&self, x: f32, y: f32, yaw: f32) -> Option<Vec<(f32, f32)>> {
        self.plan_within(x, y, yaw, HORIZON_M)
            .or_else(|| self.plan_within(x, y, yaw, f32::INFINITY))
    }

    /// As `plan`, among the targets within `horizon_m` of path.
    fn plan_within(&self, x: f32, y: f32, yaw: f32, horizon_m: f32) -> Option<Vec<(f32, f32)>> {
        let n = (self.nx * self.ny) as usize;
        let mut dist = vec![f32::INFINITY; n];
        let mut parent = vec![usize::MAX; n];
        // Start from the nearest open cell (the car may stand inside the inflated margin).
        let (ci, cj) = self.cell_of(x, y);
        let mut start = None;
        'search: for r in 0..8 {
            for i in ci - r..=ci + r {
                for j in cj - r..=cj + r {
                    if (0..self.nx).contains(&i) && (0..self.ny).contains(&j) && self.open[(i * self.ny + j) as usize] {
                        start = Some((i * self.ny + j) as usize);
                        break 'search;
                    }
                }
            }
        }
        let start = start?;
        dist[start] = 0.0;
        let mut heap = BinaryHeap::new();
        heap.push((std::cmp::Reverse(0u32), start));
        while let Some((std::cmp::Reverse(d), k)) = heap.pop() {
            let d = d as f32 / 1000.0;
            if d > dist[k] {
                continue;
            }
            let (i, j) = (k as i32 / self.ny, k as i32 % self.ny);
            for (di, dj) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)] {
                let (a, b) = (i + di, j + dj);
                if !(0..self.nx).contains(&a) || !(0..self.ny).contains(&b) {
                    continue;
                }
                let m = (a * self.ny + b) as usize;
                if !self.open[m] {
                    continue;
                }
                let nd = d + PLAN_CELL_M * if di != 0 && dj != 0 { 1.414 } else { 1.0 };
                if nd < dist[m] && nd <= horizon_m {
                    dist[m] = nd;
                    parent[m] = k;
                    heap.push((std::cmp::Reverse((nd * 1000.0) as u32), m));
                }
            }
        }
        let mut best = None;
        let mut best_score = 0.0;
        for (k, d) in dist.iter().enumerate() {
            if !d.is_finite() || self.banned[k] {
                continue;
            }
            if self.knowledge == Knowledge::Frontier && !self.on_frontier(k) {
                continue;
            }
            let gain = self.sees[k]
                .iter()
                .filter(|&&c| !self.covered[c as usize] && !self.occupied[c as usize])
                .count();
            if gain < MIN_GAIN {
                continue;
            }
            let (tx, ty) = Self::centre(self.origin, k as i32 / self.ny, k as i32 % self.ny);
            let bearing = (ty - y).atan2(tx - x) - yaw;
            let turn = bearing.sin().atan2(bearing.cos()).abs();
            // A target behind the car costs about a half circle of the turning radius.
            let score = gain as f32 / (d + FIXED_COST_M + TURN_COST_M * turn);
            if score > best_score {
                best_score = score;
                best = Some(k);
            }
        }
        let mut k = best?;
        let mut path = Vec::new();
        while k != usize::MAX {
            path.push(Self::centre(self.origin, k as i32 / self.ny, k as i32 % self.ny));
            k = parent[k];
        }
        path.reverse();
        Some(path)
    }
}

/// The planner driving one episode.
pub struct CoveragePlanner {
    grid: Planner,
    wheelbase_m: f32,
    steering_limit_rad: f32,
    path: Vec<(f32, f32)>,
    /// The step and place where the car last moved `STUCK_M`.
    moved: (u64, f32, f32),
    step: u64,
}

impl CoveragePlanner {
    /// A planner for the episode `env` has just been reset to.
    pub fn new(env: &SimEnv, knowledge: Knowledge) -> Result<Self> {
        let car = env.inner().vehicle();
        let map = car.map().context("the planner needs a map: a search env")?;
        let sim = car.sim();
        let p = sim.car(0).pose2();
        Ok(Self {
            grid: Planner::new(sim, map, knowledge),
            wheelbase_m: sim.vehicle().wheelbase_m,
            steering_limit_rad: car.steering_limit_rad() as f32,
            path: Vec::new(),
            moved: (0, p.x_m, p.y_m),
            step: 0,
        })
    }

    /// The action for the state `env` is in.
    pub fn act(&mut self, env: &SimEnv) -> Vec<f32> {
        let sim = env.inner().vehicle().sim();
        let p = sim.car(0).pose2();
        self.grid.visit(p.x_m, p.y_m);
        if self.grid.knowledge == Knowledge::Frontier
            && let Some(scan) = env.inner().last_frame().and_then(|f| f.scan.as_ref())
        {
            let l = sim.car(0).lidar_pose();
            let yaw = l.yaw_rad();
            for (i, (r, hit)) in scan.ranges.iter().zip(&scan.hit).enumerate() {
                if *hit && r.is_finite() {
                    let b = yaw + scan.angle_min + i as f32 * scan.angle_increment;
                    self.grid
                        .hit(l.position_m[0] + r * b.cos(), l.position_m[1] + r * b.sin());
                }
            }
        }
        if (p.x_m - self.moved.1).hypot(p.y_m - self.moved.2) > STUCK_M {
            self.moved = (self.step, p.x_m, p.y_m);
        } else if self.step - self.moved.0 > STUCK_STEPS {
            if let Some(&(tx, ty)) = self.path.last() {
                let (i, j) = self.grid.cell_of(tx, ty);
                self.grid.banned[(i * self.grid.ny + j) as usize] = true;
            }
            self.path.clear();
            self.moved = (self.step, p.x_m, p.y_m);
        }
        if self.step.is_multiple_of(REPLAN_EVERY) || self.path.len() < 2 {
            self.path = self.grid.plan(p.x_m, p.y_m, p.yaw_rad).unwrap_or_default();
        }
        self.step += 1;
        // Drop the points already passed, then aim at the first one a lookahead away.
        while self.path.len() > 1 && (self.path[0].0 - p.x_m).hypot(self.path[0].1 - p.y_m) < 0.4 {
            self.path.remove(0);
        }
        let aim = self
            .path
            .iter()
            .find(|q| (q.0 - p.x_m).hypot(q.1 - p.y_m) >= LOOKAHEAD_M)
            .or(self.path.last())
            .copied();
        match aim {
            Some((ax, ay)) => {
                let alpha = (ay - p.y_m).atan2(ax - p.x_m) - p.yaw_rad;
                let alpha = alpha.sin().atan2(alpha.cos());
                let ld = (ax - p.x_m).hypot(ay - p.y_m).max(0.3);
                let delta = (2.0 * self.wheelbase_m * alpha.sin() / ld).atan();
                vec![1.0, (delta / self.steering_limit_rad).clamp(-1.0, 1.0)]
            }
            None => vec![1.0, 0.0],
        }
    }
}

/// Drive one episode of `env` with the planner, reporting every step (as `episode::drive`).
pub fn drive(
    env: &mut SimEnv,
    knowledge: Knowledge,
    seed: u64,
    episode: usize,
    obs: &mut Observer<'_>,
) -> Result<(f64, Step)> {
    let planner: RefCell<Option<CoveragePlanner>> = RefCell::new(None);
    let next = RefCell::new(vec![0.0f32; 2]);
    agvrl_rl::eval::run_episode(
        env,
        seed,
        |_| Ok::<_, anyhow::Error>(next.borrow().clone()),
        |env, k, st| {
            observe(env, obs, episode, k, st, None)?;
            let mut p = planner.borrow_mut();
            if k == 0 {
                *p = Some(CoveragePlanner::new(env, knowledge)?);
            }
            if let Some(p) = p.as_mut() {
                *next.borrow_mut() = p.act(env);
            }
            Ok(())
        },
    )
}
