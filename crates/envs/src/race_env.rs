//! `RaceEnv`: several cars on one track in one world, each driven by its own racing task (the
//! single-car task's observation, action mapping, safety filter, reward and wall
//! termination), with race terms on top: progress along the centre line, and a penalty on the
//! car whose front touches another. A crashed car is parked where it stopped and stays an
//! obstacle until the race ends.

use crate::api::{
    BoxSpace, Control, EnvError, EpisodeSummary, Info, MapInfo, MultiEnv, MultiStep, RaceCarInfo, RaceSummary,
    RacingInfo, RewardTerms, SensorFrame, Step, Track, validate_action,
};
use crate::passer::{Passer, PasserSource};
use crate::race_figures::{CarAt, PassBook};
use crate::sim_vehicle::{Randomisation, map_of};
use crate::task::Task;
use agvrl_sim::{PlanarPose, SceneSource, Sim, SimConfig};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

/// Values per other car in [`RaceEnv::critic_obs_of`].
const CRITIC_VALUES_PER_CAR: usize = 4;

/// Race settings (`EnvConfig::race`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RaceSettings {
    /// Cars on the grid, 1 to 8 (one: the lone car that race lap times compare with).
    pub cars: usize,
    /// Reward per metre raced along the centre line.
    pub progress_per_m: f64,
    /// Reward on every step a car touches another with its front (a negative number).
    pub contact_penalty: f64,
    /// Reward per m/s of closing speed (along the track) when a contact the car caused begins
    /// (a negative number: the rear-end charge).
    pub rear_end_per_mps: f64,
    /// Reward per metre gained on each other running car while the gap lies within
    /// `position_behind_m` behind to `position_ahead_m` ahead (the gap clamped to that window,
    /// so pulling away further, or following at a steady gap, earns nothing).
    pub position_per_m: f64,
    /// See `position_per_m`, metres.
    pub position_behind_m: f64,
    /// See `position_per_m`, metres.
    pub position_ahead_m: f64,
    /// Distance between grid rows along the centre line, metres.
    pub grid_gap_m: f32,
    /// Lateral offset of the two grid columns from the centre line, metres, at most: where the
    /// track is too narrow for it (a slot must stand [`GRID_MARGIN_M`] beyond the racing rules'
    /// end limit from the walls, and at least [`GRID_MIN_CLEARANCE_M`]) the columns close in,
    /// down to single file.
    pub grid_offset_m: f32,
    /// Share of races that start with car 0 (the learner) [`Self::start_behind_m`] behind
    /// car 1 on the centre line, at a place along the lap drawn per race, the other cars a
    /// grid row apart ahead of car 1; the rest start from the grid. 0 to 1.
    pub start_behind_share: f64,
    /// How far car 0 starts behind car 1 in those races, metres (centre to centre).
    pub start_behind_m: f32,
    /// Give a learner's critic the other cars' state ([`RaceEnv::critic_obs_of`]) in
    /// `Info::critic_obs`, beside the observation the policy acts on (an asymmetric
    /// actor-critic: the policy still sees only what the car senses).
    pub critic_sees_opponents: bool,
    /// Training only: report, as each policy-driven car's corrected action, the passing advice
    /// ([`crate::pass_advice`]): a line that keeps this lateral gap, metres, between its body
    /// and a car it closes on, from a second before the bodies would overlap, or following
    /// where no such line fits; for PPO's correction term (`ppo.correction_coef`). The advice
    /// is worked out from both cars' places on the track and never applied. 0: off (and not
    /// written, so settings saved before it read and write the same).
    #[serde(skip_serializing_if = "is_off")]
    pub pass_advice_margin_m: f32,
    /// A passer ([`crate::passer`]) drives each policy-driven car's passes, in front of its
    /// safety filter, from the other car's place in the car's scan (`scan`) or in the
    /// simulator (`truth`). `off`: the policy drives every step (and not written, so settings
    /// saved before it read and write the same).
    #[serde(skip_serializing_if = "passer_off")]
    pub passer: PasserSource,
}

fn passer_off(v: &PasserSource) -> bool {
    *v == PasserSource::Off
}

fn is_off(v: &f32) -> bool {
    *v == 0.0
}

impl Default for RaceSettings {
    fn default() -> Self {
        Self {
            cars: 2,
            progress_per_m: 1.0,
            contact_penalty: -2.0,
            rear_end_per_mps: 0.0,
            position_per_m: 0.0,
            position_behind_m: 5.0,
            position_ahead_m: 10.0,
            grid_gap_m: 0.8,
            grid_offset_m: 0.3,
            start_behind_share: 0.0,
            start_behind_m: 2.0,
            critic_sees_opponents: false,
            pass_advice_margin_m: 0.0,
            passer: PasserSource::Off,
        }
    }
}

impl RaceSettings {
    /// Check the settings, naming what is wrong.
    pub fn validate(&self) -> Result<(), EnvError> {
        let bad = |m: String| Err(EnvError::Config(format!("race: {m}")));
        if !(1..=agvrl_sim::MAX_CARS).contains(&self.cars) {
            return bad(format!("cars must be 1 to {}, got {}", agvrl_sim::MAX_CARS, self.cars));
        }
        for (k, v) in [
            ("progress_per_m", self.progress_per_m),
            ("contact_penalty", self.contact_penalty),
            ("rear_end_per_mps", self.rear_end_per_mps),
            ("position_per_m", self.position_per_m),
        ] {
            if !v.is_finite() {
                return bad(format!("{k} must be finite, got {v}"));
            }
        }
        for (k, v) in [
            ("position_behind_m", self.position_behind_m),
            ("position_ahead_m", self.position_ahead_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{k} must be >= 0, got {v}"));
            }
        }
        if !(self.grid_gap_m >= 0.6 && self.grid_gap_m.is_finite()) {
            return bad(format!(
                "grid_gap_m must be at least 0.6 (a car's length), got {}",
                self.grid_gap_m
            ));
        }
        if !(self.pass_advice_margin_m >= 0.0 && self.pass_advice_margin_m.is_finite()) {
            return bad(format!(
                "pass_advice_margin_m must be >= 0, got {}",
                self.pass_advice_margin_m
            ));
        }
        if !(self.grid_offset_m >= 0.0 && self.grid_offset_m.is_finite()) {
            return bad(format!("grid_offset_m must be >= 0, got {}", self.grid_offset_m));
        }
        if !(0.0..=1.0).contains(&self.start_behind_share) {
            return bad(format!(
                "start_behind_share must be in [0, 1], got {}",
                self.start_behind_share
            ));
        }
        if self.start_behind_share > 0.0 && self.cars < 2 {
            return bad("start_behind_share needs a second car to start behind".into());
        }
        if !(self.start_behind_m >= 0.6 && self.start_behind_m.is_finite()) {
            return bad(format!(
                "start_behind_m must be at least 0.6 (a car's length), got {}",
                self.start_behind_m
            ));
        }
        Ok(())
    }
}

/// Clearance from a grid slot to the walls beyond the racing rules' end limit, metres.
pub const GRID_MARGIN_M: f32 = 0.15;
/// The least clearance from a grid slot to the walls, metres: half the car's width and a margin,
/// where only contact ends an episode.
pub const GRID_MIN_CLEARANCE_M: f32 = 0.35;

/// How long after a contact begins its time loss is counted, seconds.
const LOSS_WINDOW_S: f64 = 2.0;

/// What drives a car for one step of [`RaceEnv::step_inputs`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CarInput<'a> {
    /// An action in the action space, through the car's task (its mapping and safety filter),
    /// as [`MultiEnv::step`] takes.
    Action(&'a [f32]),
    /// A control applied as it is: a car driven from outside (`agvrl-drive --serve-sim`), whose
    /// own stack has already mapped and filtered it.
    Control(Control),
}

/// One car's race bookkeeping.
#[derive(Clone, Debug, Default)]
struct Racer {
    /// Arc length of the spawn, wrapped into (-lap/2, lap/2], metres.
    offset_m: f64,
    distance_m: f64,
    laps: u32,
    lap_start_s: Option<f64>,
    last_lap_s: Option<f64>,
    best_lap_s: Option<f64>,
    lap_times_s: Vec<f64>,
    contacts: u32,
    at_fault: u32,
    /// When its front last hit another car, seconds.
    last_fault_s: Option<f64>,
    time_lost_s: f64,
    /// (speed before, steps left) of the contact whose loss is counted now.
    loss: Option<(f64, u32)>,
    touching: Vec<usize>,
    crashed: bool,
    done: bool,
    ret: f64,
    len: u64,
}

/// How far down the track the training advice's line is pursued, metres.
const TRAINING_LOOKAHEAD_M: f32 = 0.6;

/// Several cars racing on one track.
pub struct RaceEnv {
    sim: Sim,
    map: MapInfo,
    track: Track,
    tasks: Vec<Box<dyn Task>>,
    settings: RaceSettings,
    randomisation: Randomisation,
    max_steps: u64,
    held_out: bool,
    rng: StdRng,
    frames: Vec<SensorFrame>,
    racers: Vec<Racer>,
    /// Encounters and passes of this race.
    book: PassBook,
    /// Each car's place at the start, 1 first.
    start_place: Vec<usize>,
    /// The grid, pole first.
    slots: Vec<PlanarPose>,
    /// Draw a new generated circuit for every race (see [`RaceEnv::with_new_layout_each_race`]).
    new_layout_each_race: bool,
    /// The racing rules' end limit, metres: the grid keeps clear of it.
    end_below_m: f32,
    /// Where the car's body ends behind and ahead of its base along x, metres: the contact
    /// point's place along the car says whose front hit.
    body_x_m: (f32, f32),
    /// Both cars' body, as the passing advice sees it.
    body: crate::pass_advice::Body,
    /// The car's limits, as the passing advice steers and throttles with them.
    limits: crate::drivers::CarLimits,
    /// Each car's passer, following the car ahead in its scan.
    passers: Vec<Passer>,
    steps: u64,
    ready: bool,
}

impl RaceEnv {
    /// A race of `settings.cars` cars on the track of `sim` (a scene with a track), each car
    /// driven by one of `tasks`.
    pub fn new(
        sim: SimConfig,
        tasks: Vec<Box<dyn Task>>,
        settings: RaceSettings,
        randomisation: Randomisation,
        max_steps: u64,
        held_out: bool,
        end_below_m: f32,
    ) -> Result<Self, EnvError> {
        settings.validate()?;
        if tasks.len() != settings.cars {
            return Err(EnvError::Internal("one task per car"));
        }
        let sim = Sim::with_cars(sim, settings.cars)?;
        let map = map_of(&sim);
        let track = map
            .track
            .clone()
            .ok_or_else(|| EnvError::Config("a race needs a track (the oval or a map file)".into()))?;
        let n = settings.cars;
        let clearance_m = (end_below_m + GRID_MARGIN_M).max(GRID_MIN_CLEARANCE_M);
        let slots = grid(&sim, &track, &settings, clearance_m);
        let model = sim.vehicle();
        let body_x_m = crate::passer::body_x_m(model);
        let passer = Passer::for_model(model);
        Ok(Self {
            sim,
            map,
            track,
            tasks,
            settings,
            randomisation,
            max_steps,
            held_out,
            rng: StdRng::seed_from_u64(0),
            frames: Vec::new(),
            racers: vec![Racer::default(); n],
            book: PassBook::new(n),
            start_place: (1..=n).collect(),
            slots,
            new_layout_each_race: false,
            end_below_m,
            body_x_m,
            body: passer.body(),
            limits: passer.limits(),
            passers: vec![passer; n],
            steps: 0,
            ready: false,
        })
    }

    /// Draw a new circuit for every race from the race's seed, when the track is a generated
    /// circuit (`layout_seed` on a racing env; in its half of the seed space, see
    /// [`crate::heldout`]).
    pub fn with_new_layout_each_race(mut self, on: bool) -> Self {
        self.new_layout_each_race = on;
        self
    }

    /// Rebuild the world on the circuit of `race_seed` when circuits change per race.
    fn relayout(&mut self, race_seed: u64) -> Result<(), EnvError> {
        let SceneSource::Circuit { settings, .. } = self.sim.config().scene.clone() else {
            return Ok(());
        };
        if !self.new_layout_each_race {
            return Ok(());
        }
        let cfg = SimConfig {
            scene: SceneSource::Circuit {
                seed: crate::heldout::layout_of_episode(race_seed),
                settings,
            },
            ..self.sim.config().clone()
        };
        self.sim = Sim::with_cars(cfg, self.racers.len())?;
        self.map = map_of(&self.sim);
        self.track = self
            .map
            .track
            .clone()
            .ok_or(EnvError::Internal("a generated circuit has a track"))?;
        let clearance_m = (self.end_below_m + GRID_MARGIN_M).max(GRID_MIN_CLEARANCE_M);
        self.slots = grid(&self.sim, &self.track, &self.settings, clearance_m);
        Ok(())
    }

    /// Car `i`'s last observation (after the last reset or step): opponents driven in-process
    /// act on it.
    pub fn observation_of(&self, i: usize) -> Vec<f32> {
        self.tasks[i].observe(&self.frames[i])
    }

    /// Length of [`Self::critic_obs_of`]: 4 values per other car with
    /// `critic_sees_opponents`, else 0.
    pub fn critic_obs_dim(&self) -> usize {
        if self.settings.critic_sees_opponents {
            CRITIC_VALUES_PER_CAR * (self.racers.len() - 1)
        } else {
            0
        }
    }

    /// What car `i` does not sense of the other cars, for a critic; per other car, in index
    /// order: the gap along the centre line (its distance raced minus car `i`'s, wrapped to
    /// half a lap, over 10 m, within +-3), its lateral offset from the centre line minus car
    /// `i`'s (metres, within +-3), its forward speed minus car `i`'s (over 2 m/s), and 1 while
    /// it races (0 once it crashed). Continuous across the lap line.
    pub fn critic_obs_of(&self, i: usize) -> Vec<f32> {
        let lap = self.track.lap_length_m() as f64;
        let lateral = |k: usize| {
            let p = self.sim.car(k).pose2();
            self.track.lateral_offset_m(p.x_m, p.y_m)
        };
        let speed = |k: usize| self.sim.car(k).forward_speed_mps();
        let mut out = Vec::with_capacity(self.critic_obs_dim());
        for j in (0..self.racers.len()).filter(|&j| j != i) {
            let gap = wrap(self.racers[j].distance_m - self.racers[i].distance_m, lap);
            out.extend([
                (gap / 10.0).clamp(-3.0, 3.0) as f32,
                (lateral(j) - lateral(i)).clamp(-3.0, 3.0),
                (speed(j) - speed(i)) / 2.0,
                if self.racers[j].crashed { 0.0 } else { 1.0 },
            ]);
        }
        out
    }

    /// Car `i`'s last sensor frame.
    pub fn frame_of(&self, i: usize) -> &SensorFrame {
        &self.frames[i]
    }

    /// Whether car `i`'s episode has ended (crashed or out of time).
    pub fn done(&self, i: usize) -> bool {
        self.racers[i].done
    }

    /// The simulator (read-only): viewers and plots.
    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    /// The track's map (what a scripted driver with the pose reads).
    pub fn map(&self) -> &MapInfo {
        &self.map
    }

    /// The track raced on.
    pub fn track(&self) -> &Track {
        &self.track
    }

    fn frame(&mut self, i: usize) -> SensorFrame {
        let sim = &mut self.sim;
        SensorFrame {
            stamp_s: sim.time_s(),
            scan: Some(sim.lidar_scan(i)),
            imu: Some(sim.car(i).imu()),
            gps: Some(sim.car(i).gps()),
            image: sim.car(i).camera_frame().map(|f| f.frame),
            contact: Some(!sim.car(i).contacts().is_empty()),
            applied: sim.car(i).control(),
        }
    }

    /// Arc length of car `i`, metres.
    fn arc_s(&self, i: usize) -> f64 {
        let p = self.sim.car(i).pose2();
        self.track.centreline_s(p.x_m, p.y_m) as f64
    }

    /// Where along the car (0 rear, 1 front) a world point lies.
    fn along(&self, i: usize, p: [f32; 3]) -> f32 {
        let pose = self.sim.car(i).pose2();
        let (s, c) = pose.yaw_rad.sin_cos();
        let x = (p[0] - pose.x_m) * c + (p[1] - pose.y_m) * s;
        let (rear, front) = self.body_x_m;
        (x - rear) / (front - rear).max(1e-3)
    }

    /// The control [`crate::pass_advice`] asks car `i` for instead of `control`, against the
    /// running car nearest ahead of it along the track; None when it asks nothing.
    fn pass_advice(&self, i: usize, control: Control, limit: f64) -> Option<Control> {
        let (pair, _) = self.pair_ahead(i, 0.0)?;
        let advice = crate::pass_advice::advise(&pair, &self.body, self.settings.pass_advice_margin_m)?;
        Some(
            self.plan()
                .apply(self.own_car(i), advice, control, limit, TRAINING_LOOKAHEAD_M),
        )
    }

    /// Car `i`'s passer's control instead of `control` (see [`crate::passer`]); None when it
    /// leaves the policy to drive.
    fn passer_control(&mut self, i: usize, control: Control, limit: f64) -> Option<Control> {
        let car = self.own_car(i);
        match self.settings.passer {
            PasserSource::Off => None,
            PasserSource::Truth => {
                let behind_m = self.body.length_m + crate::passer::HOLD_M;
                let Some(seen) = self.pair_ahead(i, -behind_m) else {
                    self.passers[i].reset();
                    return None;
                };
                self.passers[i].pass(&self.track, car, seen, control, limit)
            }
            PasserSource::Scan => {
                let (scan, now_s) = (self.frames[i].scan.as_ref(), self.sim.time_s());
                self.passers[i].control(&self.track, car, scan, now_s, control, limit)
            }
        }
    }

    /// Car `i`'s place and forward speed.
    fn own_car(&self, i: usize) -> crate::passer::OwnCar {
        crate::passer::OwnCar {
            pose: self.sim.car(i).pose2(),
            speed_mps: self.sim.car(i).forward_speed_mps(),
        }
    }

    /// What the passing advice and the passer plan a pass on.
    fn plan(&self) -> crate::passer::Plan<'_> {
        crate::passer::Plan {
            track: &self.track,
            limits: &self.limits,
            body: &self.body,
        }
    }

    /// Car `i` and the running car nearest ahead of it along the track (at most `-min_ahead_m`
    /// behind), from the simulator, with that car's drift across the track, m/s.
    fn pair_ahead(&self, i: usize, min_ahead_m: f32) -> Option<(crate::pass_advice::Pair, f32)> {
        let p = self.sim.car(i).pose2();
        let lap = self.track.lap_length_m();
        let s = self.track.centreline_s(p.x_m, p.y_m);
        let half_width_m = self.track.clearance_at_m(s)?;
        let (ahead_m, j) = (0..self.racers.len())
            .filter(|&j| j != i && !self.racers[j].crashed)
            .map(|j| {
                let q = self.sim.car(j).pose2();
                let d = (self.track.centreline_s(q.x_m, q.y_m) - s).rem_euclid(lap);
                (if d > 0.5 * lap { d - lap } else { d }, j)
            })
            .filter(|(d, _)| *d > min_ahead_m)
            .min_by(|a, b| a.0.total_cmp(&b.0))?;
        let q = self.sim.car(j).pose2();
        let other_speed_mps = self.sim.car(j).forward_speed_mps();
        let (_, [dx, dy]) = self.track.centreline_at(self.track.centreline_s(q.x_m, q.y_m));
        // Offsets grow to the right; a heading left of the track's shrinks them.
        let drift_mps = -other_speed_mps * (q.yaw_rad - dy.atan2(dx)).sin();
        let pair = crate::pass_advice::Pair {
            ahead_m,
            offset_m: self.track.offset_right_m(p.x_m, p.y_m),
            other_offset_m: self.track.offset_right_m(q.x_m, q.y_m),
            speed_mps: self.sim.car(i).forward_speed_mps(),
            other_speed_mps,
            half_width_m,
        };
        Some((pair, drift_mps))
    }

    fn positions(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.racers.len()).collect();
        order.sort_by(|&a, &b| {
            let (ra, rb) = (&self.racers[a], &self.racers[b]);
            ra.crashed
                .cmp(&rb.crashed)
                .then(rb.distance_m.total_cmp(&ra.distance_m))
                .then(a.cmp(&b))
        });
        order
    }

    fn summary(&self) -> RaceSummary {
        let r = &self.racers;
        RaceSummary {
            order: self.positions(),
            laps: r.iter().map(|c| c.laps).collect(),
            best_lap_s: r.iter().map(|c| c.best_lap_s).collect(),
            lap_times_s: r.iter().map(|c| c.lap_times_s.clone()).collect(),
            distance_m: r.iter().map(|c| c.distance_m).collect(),
            covered_m: r.iter().map(|c| c.distance_m - c.offset_m).collect(),
            start_place: self.start_place.clone(),
            encounters: self.book.encounters().to_vec(),
            passes: self.book.passes().to_vec(),
            contacts: r.iter().map(|c| c.contacts).collect(),
            at_fault: r.iter().map(|c| c.at_fault).collect(),
            time_lost_s: r.iter().map(|c| c.time_lost_s).collect(),
            crashed: r.iter().map(|c| c.crashed).collect(),
        }
    }
}

/// The grid slots, pole first: rows `grid_gap_m` apart behind the start line, columns
/// alternating left and right of the centre line, as far apart as the track allows.
fn grid(sim: &Sim, track: &Track, settings: &RaceSettings, clearance_m: f32) -> Vec<PlanarPose> {
    let slot = |k: usize, offset: f32| {
        let s = -(0.5 * settings.grid_gap_m + settings.grid_gap_m * k as f32);
        let ([x, y], [dx, dy]) = track.centreline_at(s.rem_euclid(track.lap_length_m()));
        let side = if k.is_multiple_of(2) { offset } else { -offset };
        PlanarPose {
            x_m: x - side * dy,
            y_m: y + side * dx,
            yaw_rad: dy.atan2(dx),
        }
    };
    let mut offset = settings.grid_offset_m;
    while offset > 0.0
        && !(0..settings.cars).all(|k| {
            let p = slot(k, offset);
            sim.free_at(p.x_m, p.y_m, clearance_m)
        })
    {
        offset = (offset - 0.05).max(0.0);
    }
    (0..settings.cars).map(|k| slot(k, offset)).collect()
}

impl RaceEnv {
    /// Add each car's position term (see [`RaceSettings::position_per_m`]) to its step:
    /// the ground gained this step on every other running car, the gap clamped to the window.
    fn position_terms(&mut self, before: &[f64], agents: &mut [Option<Step>]) {
        let (behind, ahead) = (self.settings.position_behind_m, self.settings.position_ahead_m);
        let clamp = |g: f64| g.clamp(-behind, ahead);
        let n = self.racers.len();
        for i in 0..n {
            let Some(st) = agents[i].as_mut() else {
                continue;
            };
            let gained: f64 = (0..n)
                .filter(|&j| j != i && !self.racers[j].crashed)
                .map(|j| {
                    let now = self.racers[i].distance_m - self.racers[j].distance_m;
                    clamp(now) - clamp(before[i] - before[j])
                })
                .sum();
            let p = self.settings.position_per_m * gained;
            st.info.reward_terms.position = p;
            st.reward += p;
            let r = &mut self.racers[i];
            r.ret += p;
            if let Some(e) = st.info.episode.as_mut() {
                e.ret = r.ret;
            }
        }
    }

    /// A start in a passing situation: car 1 on the centre line at a place drawn along the lap,
    /// car 0 [`RaceSettings::start_behind_m`] behind it, the other cars a grid row apart ahead
    /// of car 1. Gives the poses and the cars in order from the front.
    fn behind_start(&self, rng: &mut StdRng) -> (Vec<PlanarPose>, Vec<usize>) {
        let n = self.racers.len();
        let lap = self.track.lap_length_m();
        let s1 = rng.random_range(0.0..lap);
        let at = |s: f32| {
            let ([x, y], [dx, dy]) = self.track.centreline_at(s.rem_euclid(lap));
            PlanarPose {
                x_m: x,
                y_m: y,
                yaw_rad: dy.atan2(dx),
            }
        };
        let mut poses = vec![at(s1 - self.settings.start_behind_m), at(s1)];
        poses.extend((2..n).map(|k| at(s1 + self.settings.grid_gap_m * (k - 1) as f32)));
        let order = (0..n).rev().collect();
        (poses, order)
    }
}

/// `x` wrapped into (-lap/2, lap/2].
fn wrap(x: f64, lap: f64) -> f64 {
    let y = x.rem_euclid(lap);
    if y > lap / 2.0 { y - lap } else { y }
}

impl MultiEnv for RaceEnv {
    fn n_agents(&self) -> usize {
        self.racers.len()
    }

    fn observation_space(&self) -> BoxSpace {
        self.tasks[0].observation_space()
    }

    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(2, -1.0, 1.0)
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<Vec<Vec<f32>>, EnvError> {
        if let Some(s) = seed {
            self.rng = StdRng::seed_from_u64(s);
        }
        let episode_seed = crate::heldout::split(self.rng.random(), self.held_out);
        self.relayout(episode_seed)?;
        let mut rng = StdRng::seed_from_u64(episode_seed);
        let n = self.racers.len();
        let behind = self.settings.start_behind_share > 0.0 && rng.random_bool(self.settings.start_behind_share);
        let (poses, order) = if behind {
            self.behind_start(&mut rng)
        } else {
            // The grid order is drawn per race: slot k holds car order[k].
            let mut order: Vec<usize> = (0..n).collect();
            order.shuffle(&mut rng);
            let mut poses = vec![PlanarPose::default(); n];
            for (k, &car) in order.iter().enumerate() {
                poses[car] = self.slots[k];
            }
            (poses, order)
        };
        for (k, &car) in order.iter().enumerate() {
            self.start_place[car] = k + 1;
        }
        let nominal = self.sim.nominal_params();
        for i in 0..n {
            let p = self.randomisation.draw(nominal, &mut rng);
            self.sim.set_params_of(i, p);
        }
        self.sim.reset_cars(&poses)?;
        let lap = self.track.lap_length_m() as f64;
        self.frames.clear();
        self.racers = vec![Racer::default(); n];
        let mut obs = Vec::with_capacity(n);
        // Every car's place relative to car 0's, so gaps are right across the lap line.
        let first = wrap(self.arc_s(0), lap);
        let arc0 = self.arc_s(0);
        for i in 0..n {
            let frame = self.frame(i);
            self.tasks[i].needs().check(&frame)?;
            self.tasks[i].reset(&frame, Some(&self.map));
            obs.push(self.tasks[i].observe(&frame));
            self.frames.push(frame);
            let offset = first + wrap(self.arc_s(i) - arc0, lap);
            let r = &mut self.racers[i];
            r.offset_m = offset;
            r.distance_m = r.offset_m;
        }
        self.book = PassBook::new(n);
        self.passers.iter_mut().for_each(Passer::reset);
        self.steps = 0;
        self.ready = true;
        Ok(obs)
    }

    fn step(&mut self, actions: &[Vec<f32>]) -> Result<MultiStep, EnvError> {
        let inputs: Vec<CarInput> = actions.iter().map(|a| CarInput::Action(a)).collect();
        self.step_inputs(&inputs)
    }

    fn dt_s(&self) -> f64 {
        self.sim.config().settings.control_period_s
    }
}

impl RaceEnv {
    /// One step with each car driven by an action or by a control of its own (see
    /// [`CarInput`]); [`MultiEnv::step`] is every car by action.
    pub fn step_inputs(&mut self, inputs: &[CarInput<'_>]) -> Result<MultiStep, EnvError> {
        let n = self.racers.len();
        if inputs.len() != n {
            return Err(EnvError::Config(format!("{} actions for {n} agents", inputs.len())));
        }
        if !self.ready {
            return Err(EnvError::NeedsReset);
        }
        let space = self.action_space();
        let limit = self.sim.vehicle().spec.steering.max_rad;
        let mut controls = vec![Control::default(); n];
        let mut corrected = vec![None; n];
        for i in 0..n {
            if self.racers[i].done {
                continue;
            }
            let a = match inputs[i] {
                CarInput::Action(a) => a,
                CarInput::Control(c) => {
                    if !(c.throttle.is_finite() && c.steering_rad.is_finite()) {
                        return Err(EnvError::Config(format!("car {i}: control is not finite: {c:?}")));
                    }
                    controls[i] = Control {
                        throttle: c.throttle.clamp(-1.0, 1.0),
                        steering_rad: c.steering_rad.clamp(-limit, limit),
                    };
                    continue;
                }
            };
            validate_action(&space, a).map_err(|e| EnvError::InEnv {
                env: i,
                source: Box::new(e),
            })?;
            let mut a = a.to_vec();
            space.clamp(&mut a);
            if self.settings.passer != PasserSource::Off
                && let Some(proposed) = self.tasks[i].proposed(&a, limit)
                && let Some(c) = self.passer_control(i, proposed, limit)
                && let Some(b) = self.tasks[i].action_of(c, limit)
            {
                a = b;
                space.clamp(&mut a);
            }
            controls[i] = self.tasks[i].control(&a, limit, &self.frames[i]);
            corrected[i] = self.tasks[i].corrected_action();
            if corrected[i].is_none() && self.settings.pass_advice_margin_m > 0.0 {
                corrected[i] = self
                    .pass_advice(i, controls[i], limit)
                    .and_then(|c| self.tasks[i].action_of(c, limit));
            }
        }
        let speed_before: Vec<f64> = (0..n).map(|i| self.sim.car(i).forward_speed_mps() as f64).collect();
        let distance_before: Vec<f64> = self.racers.iter().map(|r| r.distance_m).collect();
        self.sim.step_cars(&controls)?;
        self.steps += 1;
        let dt = self.dt_s();
        let lap = self.track.lap_length_m() as f64;
        // Contacts between cars, each pair once, and whose front caused each.
        let mut fault = vec![false; n];
        let mut touching = vec![Vec::new(); n];
        for i in 0..n {
            for c in self.sim.car(i).car_contacts() {
                touching[i].push(c.other);
                if c.other > i {
                    let (fi, fj) = (self.along(i, c.point_w), self.along(c.other, c.point_w));
                    // The car whose front half holds the point, nearer its front than the
                    // other's (within a fifth of a car), hit; two fronts (head on), both did.
                    fault[i] |= fi >= fj - 0.2 && fi > 0.5;
                    fault[c.other] |= fj >= fi - 0.2 && fj > 0.5;
                }
            }
        }
        let mut agents: Vec<Option<Step>> = vec![None; n];
        let truncate = self.steps >= self.max_steps;
        for i in 0..n {
            if self.racers[i].done {
                continue;
            }
            let frame = self.frame(i);
            self.tasks[i].needs().check(&frame)?;
            let out = self.tasks[i].evaluate(&frame, Some(&self.map));
            let obs = self.tasks[i].observe(&frame);
            if !obs.iter().all(|v| v.is_finite()) {
                return Err(EnvError::Vehicle(format!("car {i}: observation is not finite")));
            }
            self.frames[i] = frame;
            let now = self.sim.time_s();
            let progress_m = out.racing.as_ref().map_or(0.0, |r| r.progress_laps * lap);
            let r = &mut self.racers[i];
            let before = r.distance_m;
            r.distance_m = r.offset_m + progress_m;
            // Laps count start line crossings; the first crossing starts the first lap.
            if before < 0.0 && r.distance_m >= 0.0 && r.lap_start_s.is_none() {
                r.lap_start_s = Some(now);
            }
            while r.distance_m >= (r.laps as f64 + 1.0) * lap {
                r.laps += 1;
                if let Some(t0) = r.lap_start_s {
                    let t = now - t0;
                    r.last_lap_s = Some(t);
                    r.lap_times_s.push(t);
                    r.best_lap_s = Some(r.best_lap_s.map_or(t, |b| b.min(t)));
                }
                r.lap_start_s = Some(now);
            }
            if fault[i] && !touching[i].is_empty() {
                r.last_fault_s = Some(now);
            }
            let mut rear_end = 0.0;
            for &j in &touching[i] {
                if !r.touching.contains(&j) {
                    r.contacts += 1;
                    r.at_fault += u32::from(fault[i]);
                    if fault[i] {
                        rear_end += self.settings.rear_end_per_mps * (speed_before[i] - speed_before[j]).max(0.0);
                    }
                    let window = (LOSS_WINDOW_S / dt).round() as u32;
                    let v0 = speed_before[i].max(r.loss.map_or(0.0, |l| l.0));
                    r.loss = Some((v0, window));
                }
            }
            r.touching = std::mem::take(&mut touching[i]);
            if let Some((v0, left)) = r.loss {
                if v0 > 0.1 {
                    let v = self.sim.car(i).forward_speed_mps() as f64;
                    r.time_lost_s += dt * (1.0 - v / v0).max(0.0);
                }
                r.loss = (left > 1).then_some((v0, left - 1));
            }
            let terminated = out.termination.is_some();
            let terms = RewardTerms {
                progress: self.settings.progress_per_m * (r.distance_m - before),
                car_contact: rear_end
                    + if fault[i] && !r.touching.is_empty() {
                        self.settings.contact_penalty
                    } else {
                        0.0
                    },
                ..out.terms
            };
            let reward = terms.total();
            r.ret += reward;
            r.len += 1;
            if terminated {
                r.crashed = true;
                self.sim.park(i);
            }
            let truncated = truncate && !terminated;
            let r = &mut self.racers[i];
            r.done = terminated || truncated;
            let info = Info {
                reward_terms: terms,
                termination: out.termination,
                racing: Some(RacingInfo {
                    laps: r.laps,
                    last_lap_s: r.last_lap_s,
                    best_lap_s: r.best_lap_s,
                    first_lap_s: r.lap_times_s.first().copied(),
                    progress_laps: r.distance_m / lap,
                }),
                corrected_action: corrected[i].take(),
                episode: r.done.then_some(EpisodeSummary { ret: r.ret, len: r.len }),
                ..Info::default()
            };
            agents[i] = Some(Step {
                obs,
                reward,
                terminated,
                truncated,
                info,
            });
        }
        if self.settings.position_per_m != 0.0 {
            self.position_terms(&distance_before, &mut agents);
        }
        let cars: Vec<CarAt> = self
            .racers
            .iter()
            .map(|r| CarAt {
                distance_m: r.distance_m,
                running: !r.crashed,
                last_fault_s: r.last_fault_s,
            })
            .collect();
        self.book.update(self.sim.time_s(), &cars);
        let order = self.positions();
        for (place, &i) in order.iter().enumerate() {
            if let Some(st) = agents[i].as_mut() {
                let r = &self.racers[i];
                st.info.race = Some(RaceCarInfo {
                    position: place + 1,
                    distance_m: r.distance_m,
                    contacts: r.contacts,
                    at_fault: r.at_fault,
                    encounters: self.book.encounters()[i],
                    passes: self.book.passes()[i],
                    time_lost_s: r.time_lost_s,
                    crashed: r.crashed,
                });
            }
        }
        let over = self.racers.iter().all(|r| r.done);
        if over {
            self.ready = false;
        }
        Ok(MultiStep {
            agents,
            summary: over.then(|| self.summary()),
        })
    }
}
