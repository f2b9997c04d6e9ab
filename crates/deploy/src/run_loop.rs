//! The fixed-rate control loop and its watchdog.

use agvrl_envs::api::{Control, EnvError, RacingInfo, SensorFrame, TerminationCause, Vehicle};
use agvrl_envs::task::{Intervention, Task};
use agvrl_rl::Policy;
use std::time::{Duration, Instant};
use thiserror::Error;

/// Why the loop could not start or go on.
#[derive(Debug, Error)]
pub enum DeployError {
    /// The policy was trained for other observation or action spaces.
    #[error("the policy does not match this task")]
    Mismatch(#[source] agvrl_rl::RlError),
    /// The vehicle failed (not a stale reading: a broken connection, a DDS error).
    #[error("vehicle: {0}")]
    Vehicle(String),
    /// The simulated vehicle or the task failed.
    #[error("vehicle")]
    Env(#[from] EnvError),
    /// A bad setting (the car's TOML, a topic name).
    #[error("config: {0}")]
    Config(String),
    /// A bag could not be written or read.
    #[error("bag: {0}")]
    Bag(String),
    /// A file (the car's TOML) could not be read.
    #[error("{path}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

/// Loop settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveConfig {
    /// Control rate, Hz (30: AutoVRL's and the training period).
    pub rate_hz: f64,
    /// A frame older than this many control periods is stale.
    pub max_age_periods: f64,
    /// Hold the rate with the wall clock (hardware): ticks start on fixed deadlines and a
    /// frame's age is the wall clock now minus its stamp (stamps that look like dates must lie
    /// within `max_clock_skew_s` of the wall clock at start; smaller stamps are taken as a
    /// clock that started with the run, as a simulator's); off: run as fast as the vehicle
    /// allows and advance the loop's clock one period per tick (a simulated or lockstep
    /// vehicle keeps its own time).
    pub realtime: bool,
    /// Largest gap between the first frame's date stamp and the wall clock, seconds.
    pub max_clock_skew_s: f64,
}

/// Stamps above this many seconds are dates (after 2001-09-09), checked against the wall clock.
pub const DATE_STAMP_S: f64 = 1e9;

/// Seconds since the Unix epoch by the system clock.
pub fn wall_clock_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            max_age_periods: 2.0,
            realtime: false,
            max_clock_skew_s: 0.5,
        }
    }
}

/// Why a tick commanded a safe stop.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The newest frame is older than the limit, or stamped more than the limit ahead of the
    /// drive's clock (negative age).
    Stale {
        /// Its age, seconds.
        age_s: f64,
    },
    /// A reading holds NaN or infinity.
    NotFinite {
        /// Which sensor.
        sensor: &'static str,
    },
    /// A sensor the task needs is missing.
    Missing(String),
    /// The policy failed.
    Inference(String),
}

/// A vehicle's error: a hardware vehicle's message as it is, anything else with its source.
fn vehicle_err(e: EnvError) -> DeployError {
    match e {
        EnvError::Vehicle(m) => DeployError::Vehicle(m),
        other => DeployError::Env(other),
    }
}

/// What one tick did.
#[derive(Clone, Debug, PartialEq)]
pub struct Tick {
    /// Tick number since start.
    pub index: u64,
    /// The frame's time stamp, seconds.
    pub stamp_s: f64,
    /// The command sent.
    pub control: Control,
    /// Set when the watchdog or the policy forced a safe stop.
    pub event: Option<Event>,
    /// What the task's safety filter did to the policy's control.
    pub intervention: Intervention,
    /// Watchdog checks + observation + inference time, microseconds.
    pub infer_us: f64,
    /// Real time: how long after its deadline the tick started, seconds (0 in lockstep). A
    /// tick more than one period late is a late tick.
    pub late_s: f64,
    /// From the start of the tick to the command sent (sensing, inference, actuation),
    /// microseconds.
    pub tick_us: f64,
    /// The watchdog's clock on this tick (frames' time: the wall clock in real time, the
    /// loop's own clock in lockstep), seconds; a replay gives it back.
    pub now_s: f64,
    /// The wall clock when the frame was read, seconds since the epoch.
    pub sensed_wall_s: f64,
    /// What the task says about the frame (a car without a map has no laps).
    pub racing: Option<RacingInfo>,
    /// The task's termination verdict on the frame (collision, too close, ...); the loop
    /// drives on, a caller may stop.
    pub termination: Option<TerminationCause>,
    /// The observation the policy saw and the action it gave (None when the watchdog stopped
    /// the car before inference): what `agvrl-drive --trace` records.
    pub inference: Option<(Vec<f32>, Vec<f32>)>,
    /// The action the passer gave instead of the policy's, on a tick it drove a pass.
    pub passed: Option<Vec<f32>>,
}

/// A passer on the car of a drive ([`agvrl_envs::passer`]): it drives the passes, in front of
/// the task's safety filter, from the car's pose on the track, its speed and its scan.
pub struct DrivePasser {
    /// The passer.
    pub passer: agvrl_envs::passer::Passer,
    /// The track the car races on (its centre line and widths).
    pub track: agvrl_envs::api::Track,
    /// The LiDAR's mount on the car's base.
    pub lidar_b: agvrl_sim::msg::Pose3,
}

impl DrivePasser {
    /// The passer of a drive of env `env` with `cfg`, when its race settings turn one on
    /// (`race.passer = "scan"`): on the env's track (a map file's with `track`) as the
    /// simulator builds it, for the env's car. None when they turn none on.
    pub fn of_env(env: &str, cfg: &agvrl_envs::EnvConfig) -> Result<Option<Self>, DeployError> {
        use agvrl_envs::passer::{Passer, PasserSource};
        match cfg.race.as_ref().map(|r| r.passer).unwrap_or_default() {
            PasserSource::Off => Ok(None),
            PasserSource::Truth => Err(DeployError::Config(
                "race.passer = \"truth\" reads the simulator's places of the other cars, which a car's \
                 drive does not have: a drive's passer is \"scan\""
                    .into(),
            )),
            PasserSource::Scan => {
                let car = agvrl_envs::make_vehicle(env, cfg)?;
                let track = car.map().and_then(|m| m.track.clone()).ok_or_else(|| {
                    DeployError::Config(format!(
                        "race.passer = \"scan\" needs the track the car races on, and {env} has none: \
                         give the map (--track MAP.yaml)"
                    ))
                })?;
                let model = cfg.sim.vehicle_model().map_err(agvrl_envs::EnvError::from)?;
                Ok(Some(Self {
                    passer: Passer::for_model(&model),
                    track,
                    lidar_b: model.lidar_mount(),
                }))
            }
        }
    }
}

/// What picks the actions of a drive.
pub enum Brain {
    /// A trained policy, deterministic actions from the task's observation.
    Policy(Box<Policy>),
    /// A classical racer (pure pursuit, follow-the-gap): its control on the frame, as the
    /// action that maps to it, so the task's mapping and safety filter apply as to a policy's.
    Racer(Box<dyn agvrl_envs::drivers::Driver>, agvrl_envs::ActionMapping),
}

/// A policy driving a vehicle through a task's observation and action mapping.
pub struct DriveLoop<V, T> {
    vehicle: V,
    task: T,
    brain: Brain,
    cfg: DriveConfig,
    ticks: u64,
    clock_s: f64,
    start: Instant,
    /// Real time: the wall clock minus this is "now" on the frames' clock.
    wall_offset_s: f64,
    passer: Option<DrivePasser>,
}

impl<V: Vehicle, T: Task> DriveLoop<V, T> {
    /// Check the policy against the task and reset the vehicle.
    pub fn new(vehicle: V, task: T, policy: Policy, cfg: DriveConfig, seed: u64) -> Result<Self, DeployError> {
        let action_space = agvrl_envs::BoxSpace::uniform(2, -1.0, 1.0);
        policy
            .check_spaces(&task.observation_space(), &action_space)
            .map_err(DeployError::Mismatch)?;
        Self::with_brain(vehicle, task, Brain::Policy(Box::new(policy)), cfg, seed)
    }

    /// Reset the vehicle and drive it with `brain` (a racer starts its episode on the first
    /// frame).
    pub fn with_brain(
        mut vehicle: V,
        mut task: T,
        mut brain: Brain,
        cfg: DriveConfig,
        seed: u64,
    ) -> Result<Self, DeployError> {
        let frame = vehicle.reset(seed).map_err(vehicle_err)?;
        task.reset(&frame, vehicle.map());
        if let Brain::Racer(driver, _) = &mut brain {
            driver.reset(&frame, vehicle.map());
        }
        let clock_s = frame.stamp_s;
        let wall = wall_clock_s();
        let wall_offset_s = if frame.stamp_s > DATE_STAMP_S {
            let skew = wall - frame.stamp_s;
            if cfg.realtime && skew.abs() > cfg.max_clock_skew_s {
                return Err(DeployError::Vehicle(format!(
                    "the first sensor frame is stamped {skew:.3} s {} the wall clock (limit {} s): \
                     synchronise the car's clock with this computer's (chrony, NTP) or check that its \
                     sensors are live",
                    if skew > 0.0 { "behind" } else { "ahead of" },
                    cfg.max_clock_skew_s
                )));
            }
            0.0
        } else {
            wall - frame.stamp_s
        };
        Ok(Self {
            vehicle,
            task,
            brain,
            cfg,
            ticks: 0,
            clock_s,
            start: Instant::now(),
            wall_offset_s,
            passer: None,
        })
    }

    /// The drive with `passer` (when some) driving the car's passes.
    pub fn with_passer(mut self, passer: impl Into<Option<DrivePasser>>) -> Self {
        self.passer = passer.into();
        self
    }

    /// Whether a passer drives the car's passes.
    pub fn passing(&self) -> bool {
        self.passer.is_some()
    }

    /// The passer's action instead of `action` on `frame`, when it drives a pass.
    fn passer_action(&mut self, action: &[f32], frame: &SensorFrame) -> Option<Vec<f32>> {
        let p = self.passer.as_mut()?;
        let limit = self.vehicle.steering_limit_rad();
        let proposed = self.task.proposed(action, limit)?;
        let c = p
            .passer
            .control_on_frame(&p.track, frame, &p.lidar_b, proposed, limit)?;
        let mut a = self.task.action_of(c, limit)?;
        a.iter_mut().for_each(|v| *v = v.clamp(-1.0, 1.0));
        Some(a)
    }

    /// The vehicle.
    pub fn vehicle(&self) -> &V {
        &self.vehicle
    }

    /// The vehicle, mutably.
    pub fn vehicle_mut(&mut self) -> &mut V {
        &mut self.vehicle
    }

    fn check(&self, f: &SensorFrame, now_s: f64) -> Result<(), Event> {
        self.task.needs().check(f).map_err(|e| Event::Missing(e.to_string()))?;
        let age_s = now_s - f.stamp_s;
        // A frame from the future (a sensor clock stepped forward) has no age to judge: it
        // would look fresh for as long as the step, with the watchdog blind.
        let limit = self.cfg.max_age_periods / self.cfg.rate_hz + 1e-9;
        if age_s > limit || age_s < -limit {
            return Err(Event::Stale { age_s });
        }
        if let Some(s) = &f.scan
            && s.ranges.iter().any(|r| !r.is_finite())
        {
            return Err(Event::NotFinite { sensor: "scan" });
        }
        if let Some(i) = &f.imu
            && i.lin_vel_b
                .iter()
                .chain(&i.ang_vel_b)
                .chain(&i.lin_acc_b)
                .any(|v| !v.is_finite())
        {
            return Err(Event::NotFinite { sensor: "imu" });
        }
        if let Some(g) = &f.gps
            && g.position_m.iter().any(|v| !v.is_finite())
        {
            return Err(Event::NotFinite { sensor: "gps" });
        }
        Ok(())
    }

    /// One control period: sense, check, infer, actuate. The loop's clock advances by one
    /// period per tick (the vehicle's own time when it is simulated).
    pub fn tick(&mut self) -> Result<Tick, DeployError> {
        self.tick_at(None)
    }

    /// A tick whose watchdog reads `now_s` instead of the loop's clock (a replay's recorded
    /// clock).
    pub fn tick_at(&mut self, now_s: Option<f64>) -> Result<Tick, DeployError> {
        let period = 1.0 / self.cfg.rate_hz;
        let started = Instant::now();
        let late_s = if self.cfg.realtime {
            let deadline = self.start + Duration::from_secs_f64(period * self.ticks as f64);
            started.saturating_duration_since(deadline).as_secs_f64()
        } else {
            0.0
        };
        let frame = self.vehicle.sense().map_err(vehicle_err)?;
        let sensed_wall_s = wall_clock_s();
        // Timed from here: checks, observation and inference (not the vehicle's wait).
        let t0 = Instant::now();
        let now_s = now_s.unwrap_or(if self.cfg.realtime {
            wall_clock_s() - self.wall_offset_s
        } else {
            self.clock_s
        });
        let checked = self.check(&frame, now_s);
        let fresh = checked.is_ok();
        // The task takes the frame in before the policy sees it, as the env does: the memories
        // an observation reads (explored ground, the ground behind the car) include this frame.
        let t_eval = Instant::now();
        let outcome = fresh.then(|| self.task.evaluate(&frame, self.vehicle.map()));
        let eval_time = t_eval.elapsed();
        let mut intervention = Intervention::None;
        let mut passed = None;
        let (control, event, inference) = match checked {
            Err(ev) => (Control::default(), Some(ev), None),
            Ok(()) => {
                let obs = self.task.observe(&frame);
                let acted = match &mut self.brain {
                    Brain::Policy(p) => p.act(&obs, true).map_err(|e| e.to_string()),
                    Brain::Racer(driver, mapping) => {
                        let c = driver.control(&frame, self.vehicle.map());
                        let [a0, a1] = mapping.action(c, self.vehicle.steering_limit_rad());
                        Ok(vec![a0 as f32, a1 as f32])
                    }
                };
                match acted {
                    Ok(a) if a.iter().all(|v| v.is_finite()) => {
                        passed = self.passer_action(&a, &frame);
                        let driven = passed.as_deref().unwrap_or(&a);
                        let c = self.task.control(driven, self.vehicle.steering_limit_rad(), &frame);
                        intervention = self.task.intervention();
                        (c, None, Some((obs, a)))
                    }
                    Ok(a) => (
                        Control::default(),
                        Some(Event::Inference("non-finite action".into())),
                        Some((obs, a)),
                    ),
                    Err(e) => (Control::default(), Some(Event::Inference(e)), None),
                }
            }
        };
        let infer_us = t0.elapsed().saturating_sub(eval_time).as_secs_f64() * 1e6;
        self.vehicle.actuate(control).map_err(vehicle_err)?;
        let tick_us = started.elapsed().as_secs_f64() * 1e6;
        self.clock_s += period;
        self.ticks += 1;
        if self.cfg.realtime {
            // Absolute deadlines: sleep overshoot does not accumulate into drift.
            let deadline = self.start + Duration::from_secs_f64(period * self.ticks as f64);
            if let Some(rest) = deadline.checked_duration_since(Instant::now()) {
                std::thread::sleep(rest);
            }
        }
        Ok(Tick {
            index: self.ticks,
            stamp_s: frame.stamp_s,
            control,
            event,
            intervention,
            infer_us,
            late_s,
            tick_us,
            now_s,
            sensed_wall_s,
            racing: outcome.as_ref().and_then(|o| o.racing.clone()),
            termination: outcome.and_then(|o| o.termination),
            inference,
            passed,
        })
    }
}
