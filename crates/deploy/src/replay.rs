//! `agvrl-drive --replay DIR`: a recorded bag fed back through the `Vehicle` seam, open loop.
//! Each tick's frame is made, by the code a ROS 2 car's frames go through
//! ([`FrameBuilder`]), of the sensor messages logged up to the time that tick read its frame
//! (`/agvrl/tick`'s `sensed_s`; a car log without ticks: a tick grid on its log clock), and the
//! watchdog reads the recorded clock, so the same binary on the same data gives the same
//! commands; the commands go nowhere. [`Replayer`] drives it for the CLI, Python and the tests.

use crate::bag::{self, BagMessage};
use crate::hardware::config::Ros2Config;
use crate::hardware::frames::{FrameBuilder, Subscribed};
use crate::hardware::{mapping, msg};
use crate::{DeployError, DriveConfig, DriveLoop, Tick};
use agvrl_envs::EnvConfig;
use agvrl_envs::api::{Control, EnvError, SensorFrame, Vehicle};
use agvrl_envs::task::Task;
use agvrl_rl::Policy;
use agvrl_sim::sensors::CameraConfig;
use std::path::Path;

/// A bag as a vehicle.
pub struct Replay {
    frames: FrameBuilder,
    /// Sensor messages in log order: (log time, topic kind, payload).
    msgs: Vec<(u64, Kind, Vec<u8>)>,
    next_msg: usize,
    ticks: Vec<msg::Tick>,
    /// When each tick read its frame, on the log clock, ns.
    sensed_ns: Vec<u64>,
    /// Whether the ticks are the bag's own (`/agvrl/tick`) rather than made for a bag of
    /// another stack.
    recorded: bool,
    period_s: f64,
    /// Ticks sensed so far.
    k: usize,
    applied: Control,
    /// Messages that did not decode (skipped).
    bad: u64,
    /// Where the bag stopped being readable, if it did.
    pub damage: Option<String>,
    /// Log-clock jumps in file order (backwards, or forwards by over a second): replayed in
    /// log-time order, as they were received, but worth a look.
    pub clock_jumps: Vec<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Scan,
    Imu,
    Odom,
    NavSat,
    Image,
}

impl Replay {
    /// Open bag `dir` with the car's settings `cfg` (its topic names and mappings) and the
    /// policy's camera. A bag without `/agvrl/tick` (a car log of another stack) is replayed as
    /// a live car at `rate_hz` would have read it: the first tick when every subscribed sensor
    /// has spoken (a live car's first complete frame), then one a period until the last sensor
    /// message, each reading what was logged (received) by then.
    pub fn open(dir: &Path, cfg: Ros2Config, camera: Option<CameraConfig>, rate_hz: f64) -> Result<Self, DeployError> {
        let (all, damage) = bag::read_messages(dir)?;
        let t = &cfg.topics;
        let kind = |m: &BagMessage| -> Option<Kind> {
            let n = m.topic.as_str();
            [
                (&t.scan, Kind::Scan),
                (&t.imu, Kind::Imu),
                (&t.odom, Kind::Odom),
                (&t.navsat, Kind::NavSat),
                (&t.image, Kind::Image),
            ]
            .into_iter()
            .find(|(name, _)| !name.is_empty() && *name == n)
            .map(|(_, k)| k)
        };
        let mut ticks = Vec::new();
        let mut msgs = Vec::new();
        let mut bad = 0;
        let mut clock_jumps = Vec::new();
        for w in all.windows(2) {
            let (a, b) = (w[0].log_ns, w[1].log_ns);
            if b + 1_000_000 < a || b > a + 1_000_000_000 {
                clock_jumps.push(format!(
                    "the log clock jumps {:+.3} s from {} to {} ({})",
                    (b as f64 - a as f64) * 1e-9,
                    w[0].topic,
                    w[1].topic,
                    if b < a { "backwards" } else { "forwards" }
                ));
            }
        }
        for m in all {
            if m.topic == crate::record::TICK_TOPIC {
                match bag::decode::<msg::Tick>(&m.data) {
                    Ok(t) => ticks.push(t),
                    Err(_) => bad += 1,
                }
            } else if let Some(k) = kind(&m) {
                msgs.push((m.log_ns, k, m.data));
            }
        }
        // Stable: messages logged at the same time keep their file order.
        msgs.sort_by_key(|(log, _, _)| *log);
        ticks.sort_by_key(|t| t.tick);
        let frames = FrameBuilder::new(cfg, camera);
        let recorded = !ticks.is_empty();
        let sensed_ns = if recorded {
            ticks.iter().map(|t| bag::ns(t.sensed_s)).collect()
        } else {
            let grid = tick_grid(dir, &msgs, frames.subscribed(), rate_hz)?;
            ticks = grid
                .iter()
                .enumerate()
                .map(|(k, &ns)| msg::Tick {
                    tick: k as u64,
                    clock_s: ns as f64 * 1e-9,
                    sensed_s: ns as f64 * 1e-9,
                    ..msg::Tick::default()
                })
                .collect();
            grid
        };
        Ok(Self {
            frames,
            msgs,
            next_msg: 0,
            ticks,
            sensed_ns,
            recorded,
            period_s: 1.0 / rate_hz,
            k: 0,
            applied: Control::default(),
            bad,
            damage,
            clock_jumps,
        })
    }

    /// The recorded ticks (for a bag of another stack, the ticks made for it: clocks only).
    pub fn ticks(&self) -> &[msg::Tick] {
        &self.ticks
    }

    /// Whether the ticks are the bag's own, with the commands to check a replay against.
    pub fn recorded(&self) -> bool {
        self.recorded
    }

    /// Messages that did not decode so far (skipped, as a live car skips them).
    pub fn bad_messages(&self) -> u64 {
        self.bad + self.frames.bad_images()
    }

    /// The recorded watchdog clock of the next tick (None past the last one).
    pub fn next_clock_s(&self) -> Option<f64> {
        self.ticks.get(self.k).map(|t| t.clock_s)
    }

    /// Feed the messages logged at or before `until` (ns).
    fn feed(&mut self, until: u64) {
        while let Some((log, kind, data)) = self.msgs.get(self.next_msg) {
            if *log > until {
                break;
            }
            let ok = match kind {
                Kind::Scan => bag::decode(data).map(|m| self.frames.scan(m)),
                Kind::Imu => bag::decode(data).map(|m| self.frames.imu(m)),
                Kind::Odom => bag::decode(data).map(|m| self.frames.odom(m)),
                Kind::NavSat => bag::decode(data).map(|m| self.frames.navsat(m)),
                Kind::Image => bag::decode::<msg::Image>(data).map(|m| self.frames.image(&m)),
            };
            self.bad += u64::from(ok.is_err());
            self.next_msg += 1;
        }
    }
}

/// Tick times for a bag without ticks: from the first log time by which every subscribed
/// sensor has a message to the last sensor message, one a period (ns, exact).
fn tick_grid(dir: &Path, msgs: &[(u64, Kind, Vec<u8>)], on: Subscribed, rate_hz: f64) -> Result<Vec<u64>, DeployError> {
    let wanted = [
        (on.scan, Kind::Scan, "scan"),
        (on.imu, Kind::Imu, "imu"),
        (on.odom, Kind::Odom, "odom"),
        (on.navsat, Kind::NavSat, "navsat"),
        (on.image, Kind::Image, "image"),
    ];
    let mut start = 0;
    for (_, kind, name) in wanted.iter().filter(|w| w.0) {
        let first = msgs.iter().find(|m| m.1 == *kind).map(|m| m.0).ok_or_else(|| {
            DeployError::Bag(format!(
                "{}: no /agvrl/tick (not a bag of agvrl), and no message on the topic of `topics.{name}`: a live car \
                 would never start (name the car's topics with --config, or leave the topic empty)",
                dir.display()
            ))
        })?;
        start = start.max(first);
    }
    let end = msgs.last().map_or(start, |m| m.0);
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(DeployError::Config(format!("rate {rate_hz} Hz")));
    }
    let period_ns = 1e9 / rate_hz;
    Ok((0..)
        .map(|k: u64| start + (k as f64 * period_ns).round() as u64)
        .take_while(|&t| t <= end)
        .collect())
}

impl Vehicle for Replay {
    /// The frame of the first tick.
    fn reset(&mut self, _seed: u64) -> Result<SensorFrame, EnvError> {
        self.k = 0;
        self.next_msg = 0;
        self.frames = FrameBuilder::new(self.frames.cfg().clone(), self.frames.camera().cloned());
        self.applied = Control::default();
        self.feed(self.sensed_ns[0]);
        Ok(self.frames.frame(self.applied))
    }

    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        self.applied = mapping::clip(control, &self.frames.cfg().drive);
        Ok(())
    }

    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        let Some(&sensed) = self.sensed_ns.get(self.k) else {
            return Err(EnvError::Vehicle("the bag has no more ticks".into()));
        };
        self.k += 1;
        self.feed(sensed);
        Ok(self.frames.frame(self.applied))
    }

    fn control_period_s(&self) -> f64 {
        self.period_s
    }

    fn steering_limit_rad(&self) -> f64 {
        self.frames.cfg().drive.steering_limit_rad
    }
}

/// A bag driven by a policy through [`DriveLoop`], tick by tick, each replayed tick beside the
/// recorded one.
pub struct Replayer {
    lp: DriveLoop<Replay, Box<dyn Task>>,
    next: usize,
    /// The differences so far.
    pub diff: ReplayDiff,
}

/// How far replayed ticks are from the recorded ones.
#[derive(Clone, Debug, Default)]
pub struct ReplayDiff {
    /// Per tick with an action both times: the largest |difference| of an action element.
    pub action: Vec<f64>,
    /// Per tick: the largest |difference| of throttle or steering sent.
    pub control: Vec<f64>,
    /// Ticks whose watchdog event (or whether the policy acted) differs.
    pub events: u64,
}

impl ReplayDiff {
    fn add(&mut self, rec: &msg::Tick, t: &Tick) {
        let action = t.inference.as_ref().map_or(&[][..], |(_, a)| a.as_slice());
        if action.len() == rec.action.len() {
            let d = action
                .iter()
                .zip(&rec.action)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            self.action.push(d as f64);
        } else {
            self.events += 1;
        }
        self.control.push(
            (t.control.throttle - rec.throttle)
                .abs()
                .max((t.control.steering_rad - rec.steering_rad).abs()),
        );
        let recorded_event = !rec.event.is_empty();
        self.events += u64::from(t.event.is_some() != recorded_event);
    }

    /// The largest action or control difference.
    pub fn worst(&self) -> f64 {
        self.action.iter().chain(&self.control).copied().fold(0.0, f64::max)
    }
}

impl Replayer {
    /// Replay bag `dir` with the policy of env `env` (settings `env_cfg`). `cfg` is the car's
    /// TOML (its topics and mappings); without one, the scans are taken to have the policy's
    /// own rays (a bag of `agvrl-drive` or `agvrl eval`).
    pub fn open(
        dir: &Path,
        cfg: Option<Ros2Config>,
        env: &str,
        env_cfg: &EnvConfig,
        policy: Policy,
        rate_hz: f64,
        seed: u64,
    ) -> Result<Self, DeployError> {
        let lidar = &env_cfg.sim.lidar;
        let mut cfg = cfg.unwrap_or_else(|| {
            let mut c = Ros2Config::default();
            c.scan = c.scan.with_rays_of(lidar);
            c
        });
        cfg.check_lidar(lidar)?;
        let model = env_cfg
            .sim
            .vehicle_model()
            .map_err(|e| DeployError::Config(format!("the env's vehicle: {e}")))?;
        let _ = cfg.drive.for_trained_top_speed(model.top_speed_mps());
        let task = agvrl_envs::make_task(env, env_cfg, cfg.drive.steering_limit_rad)?;
        let camera = if task.needs().image {
            env_cfg.sim.camera.clone()
        } else {
            None
        };
        let vehicle = Replay::open(dir, cfg, camera, rate_hz)?;
        let drive = DriveConfig {
            rate_hz,
            realtime: false,
            ..DriveConfig::default()
        };
        // A drive's passer is in its settings; it replays as it drove.
        let passer = crate::run_loop::DrivePasser::of_env(env, env_cfg)?;
        let lp = DriveLoop::new(vehicle, task, policy, drive, seed)?.with_passer(passer);
        Ok(Self {
            lp,
            next: 0,
            diff: ReplayDiff::default(),
        })
    }

    /// The bag as read (its damage, bad messages).
    pub fn vehicle(&self) -> &Replay {
        self.lp.vehicle()
    }

    /// Replay the next recorded tick (its watchdog reads the recorded clock): the recorded tick
    /// and the replayed one; `None` after the last.
    pub fn step(&mut self) -> Result<Option<(msg::Tick, Tick)>, DeployError> {
        let Some(rec) = self.lp.vehicle().ticks().get(self.next).cloned() else {
            return Ok(None);
        };
        let t = self.lp.tick_at(Some(rec.clock_s))?;
        if self.lp.vehicle().recorded() {
            self.diff.add(&rec, &t);
        }
        self.next += 1;
        Ok(Some((rec, t)))
    }
}
