//! A sim-backed ROS 2 robot (`agvrl-drive --serve-sim ENV`): publishes the simulated car's
//! LaserScan, Imu, Odometry (and NavSatFix, and its camera's depth as a 32FC1 Image when the
//! env's car carries a camera) and applies the AckermannDriveStamped commands it
//! receives, so the whole drive loop runs over real DDS. Each tick advances the simulator by
//! exactly one control period; the task's evaluation counts laps and collisions on this side
//! (a car's drive loop knows no map). `/tf` carries odom to base_link, `/tf_static` (latched)
//! the LiDAR's and camera's mounts.
//!
//! In a race ([`SimRobot::race`], `--serve-sim racing-duel`) car 0 is the served car and the
//! others are driven in-process by policies or classical racers; every car's topics and frames are under its own
//! namespace (`/car0/scan`, `/car1/scan`, `car1/base_link`), each car's odom frame hangs off
//! `map`, and a new race starts on the tick after the served car's race ends.

use super::config::Ros2Config;
use super::mapping;
use super::msg;
use super::ros2::{
    DRIVE_TYPE, IMAGE_TYPE, IMU_TYPE, NAVSAT_TYPE, ODOM_TYPE, Publisher, SCAN_TYPE, Subscription, TF_TYPE, node,
    publisher, subscribe,
};
use super::wire::{Outgoing, Wire, WireFaults, WireStats};
use crate::DeployError;
use crate::record::transform;
use agvrl_envs::api::{Control, MultiEnv, SensorFrame, TerminationCause, Vehicle};
use agvrl_envs::task::Task;
use agvrl_envs::{CarInput, EnvConfig, RaceEnv, make_race, make_sim_car, make_task};
use agvrl_rl::Policy;
use ros2_client::Node;
use ros2_client::dds::rustdds::mio1::{Events, Interest, Poll, Token};
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How the robot keeps time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// One control period per received command, as fast as commands come (tests, benches).
    Lockstep,
    /// One control period per wall-clock period, holding the newest command (zero after
    /// `COMMAND_TIMEOUT_S` without one, as a motor controller does).
    Realtime,
}

/// Without a command for this long a real-time robot stops, seconds.
pub const COMMAND_TIMEOUT_S: f64 = 0.5;

/// Faults to inject, by robot tick (ticks count control periods since reset).
#[derive(Clone, Debug, PartialEq)]
pub struct Faults {
    /// From this tick on, no scans are published.
    pub mute_scan_from: u64,
    /// On these ticks, scan rays `nan_rays` read NaN.
    pub nan_ticks: Range<u64>,
    /// Which rays.
    pub nan_rays: Range<usize>,
    /// The robot's drive reader joins only after this many ticks (a car whose motor node
    /// starts after its sensors); real-time pace only.
    pub drive_reader_from: u64,
    /// Camera images go out on every this many ticks (2: a 15 Hz camera on a 30 Hz car).
    pub image_every: u64,
    /// Faults on the wire (real-time pace only).
    pub wire: WireFaults,
}

impl Default for Faults {
    fn default() -> Self {
        Self {
            mute_scan_from: u64::MAX,
            nan_ticks: 0..0,
            nan_rays: 0..0,
            drive_reader_from: 0,
            image_every: 1,
            wire: WireFaults::default(),
        }
    }
}

/// What the robot has seen so far.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RobotStats {
    /// Control periods simulated.
    pub ticks: u64,
    /// Simulated time, seconds.
    pub stamp_s: f64,
    /// Commands received.
    pub commands: u64,
    /// The newest command, as applied.
    pub last_command: Control,
    /// Completed laps (racing).
    pub laps: u32,
    /// Fastest lap, seconds.
    pub best_lap_s: Option<f64>,
    /// Ticks on which the task saw a termination (collision, too close, flipped, out).
    pub terminations: u64,
    /// The first termination and its tick.
    pub first_termination: Option<(u64, TerminationCause)>,
    /// In a race: races finished (each ends when the served car's does).
    pub races: u32,
    /// Races the served car led when they ended.
    pub wins: u32,
    /// Contacts of the served car with other cars, and those its front caused.
    pub car_contacts: u32,
    /// See `car_contacts`.
    pub at_fault: u32,
    /// Passes the served car made (docs/racing.md, "Race figures").
    pub passes: u32,
}

/// A handle to stop a running robot and read its stats from another thread.
#[derive(Clone, Default)]
pub struct RobotHandle {
    stop: Arc<AtomicBool>,
    stats: Arc<Mutex<RobotStats>>,
}

impl RobotHandle {
    /// Ask `run` to return.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// A copy of the stats.
    pub fn stats(&self) -> RobotStats {
        // A thread that panicked holding the lock left whole counters: read them anyway.
        self.stats
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone()
    }
}

/// What the robot simulates.
enum World {
    /// One car and its task.
    Alone {
        vehicle: agvrl_envs::SimCar,
        task: Box<dyn Task>,
    },
    /// A race: car 0 served, the others driven in-process.
    Race(Box<Race>),
}

/// What drives an opponent car of a served race.
pub enum Opponent {
    /// A policy, deterministic actions through the car's own task.
    Policy(Box<Policy>),
    /// A classical racer (`agvrl_envs::drivers`), its controls applied as they are.
    Racer(Box<dyn agvrl_envs::drivers::Driver>),
}

/// An opponent's input for one period, owned.
enum Given {
    Action(Vec<f32>),
    Control(Control),
}

/// A race behind the robot.
struct Race {
    env: RaceEnv,
    /// One per car from car 1 on.
    opponents: Vec<Opponent>,
    obs: Vec<Vec<f32>>,
    /// Simulated time of the races before this one, seconds: stamps keep rising over restarts.
    clock_s: f64,
    /// The served car's laps in earlier races.
    laps_before: u32,
    /// Its contacts, faults and passes in earlier races.
    before: (u32, u32, u32),
}

impl World {
    fn control_period_s(&self) -> f64 {
        match self {
            World::Alone { vehicle, .. } => vehicle.control_period_s(),
            World::Race(r) => r.env.dt_s(),
        }
    }

    fn sim(&self) -> &agvrl_sim::Sim {
        match self {
            World::Alone { vehicle, .. } => vehicle.sim(),
            World::Race(r) => r.env.sim(),
        }
    }

    /// Simulated time since the robot started, seconds, at a frame stamped `stamp_s`.
    fn clock_s(&self, stamp_s: f64) -> f64 {
        match self {
            World::Alone { .. } => stamp_s,
            World::Race(r) => r.clock_s + stamp_s,
        }
    }

    /// Whether car `i`'s sensors run (a crashed opponent's are off until the next race).
    fn running(&self, i: usize) -> bool {
        match self {
            World::Alone { .. } => true,
            World::Race(r) => i == 0 || !r.env.done(i),
        }
    }
}

/// One car's sensor topics, and the prefix of its frame names.
struct CarTopics {
    /// "" for a car alone, "car1/" in a race.
    prefix: String,
    /// Its topic names and base frame (`frame_id`).
    topics: super::config::Topics,
    scan: Publisher<msg::LaserScan>,
    imu: Option<Publisher<msg::Imu>>,
    odom: Option<Publisher<msg::Odometry>>,
    navsat: Option<Publisher<msg::NavSatFix>>,
    image: Option<Publisher<msg::Image>>,
}

/// The simulated car (or race) behind ROS 2 topics.
pub struct SimRobot {
    cfg: Ros2Config,
    world: World,
    node: Node,
    /// Added to simulated time in the published stamps (wall-clock epoch time in real time).
    stamp_offset_s: f64,
    cars: Vec<CarTopics>,
    tf: Publisher<msg::TFMessage>,
    tf_static: Publisher<msg::TFMessage>,
    drive: Option<Subscription<msg::AckermannDriveStamped>>,
    poll: Poll,
    events: Events,
    /// Each car's newest sensor set.
    frames: Vec<SensorFrame>,
    faults: Faults,
    wire: Wire,
    handle: RobotHandle,
    bad_messages: u64,
    /// Sensor messages not sent because a writer would have blocked.
    blocked_messages: u64,
}

impl SimRobot {
    /// The env `env`'s vehicle and task, reset with `seed`, behind the topics of `cfg` (its
    /// `node_name` gets a `_sim` suffix). Sensor topics are published with the sensor QoS
    /// made reliable, which a best-effort or a reliable reader both accept.
    pub fn new(
        env: &str,
        env_cfg: &EnvConfig,
        cfg: Ros2Config,
        seed: u64,
        faults: Faults,
    ) -> Result<Self, DeployError> {
        cfg.validate().map_err(|e| DeployError::Config(e.message))?;
        let mut vehicle = make_sim_car(env, env_cfg)?;
        let mut task = make_task(env, env_cfg, vehicle.steering_limit_rad())?;
        let frame = vehicle.reset(seed)?;
        task.reset(&frame, vehicle.map());
        Self::serve(World::Alone { vehicle, task }, vec![frame], cfg, faults)
    }

    /// A race of `env_cfg.race.cars` cars (`racing-duel`'s settings) whose car 0 is served
    /// behind `cfg`'s topics under namespace `car0` while `opponents` drive the others
    /// in-process, one per car from car 1 on. Races are
    /// held out and seeded from `seed`; a race ends when the served car's episode does (a
    /// crash, or `env_cfg.max_steps`), and the next starts on the grid at the next tick.
    pub fn race(
        env_cfg: &EnvConfig,
        cfg: Ros2Config,
        seed: u64,
        faults: Faults,
        opponents: Vec<Opponent>,
    ) -> Result<Self, DeployError> {
        cfg.validate().map_err(|e| DeployError::Config(e.message))?;
        let env_cfg = EnvConfig {
            held_out: true,
            ..env_cfg.clone()
        };
        let mut env = make_race("racing-duel", &env_cfg)?;
        let n = env.n_agents();
        if n < 2 {
            return Err(DeployError::Config(
                "a served race needs at least 2 cars (the served car and an opponent)".into(),
            ));
        }
        if opponents.len() != n - 1 {
            return Err(DeployError::Config(format!(
                "{} opponents for {} opponent cars: give one each",
                opponents.len(),
                n - 1
            )));
        }
        for o in &opponents {
            if let Opponent::Policy(p) = o {
                p.check_spaces(&env.observation_space(), &env.action_space())
                    .map_err(DeployError::Mismatch)?;
            }
        }
        let obs = env.reset(Some(seed))?;
        let frames = (0..n).map(|i| env.frame_of(i).clone()).collect();
        let mut race = Race {
            env,
            opponents,
            obs,
            clock_s: 0.0,
            laps_before: 0,
            before: (0, 0, 0),
        };
        race.reset_racers();
        Self::serve(World::Race(Box::new(race)), frames, cfg, faults)
    }

    fn serve(world: World, frames: Vec<SensorFrame>, cfg: Ros2Config, faults: Faults) -> Result<Self, DeployError> {
        let mut cfg = cfg;
        // The robot serves its own car: an explicit max_speed_mps is honoured as set.
        let _ = cfg.drive.for_trained_top_speed(world.sim().vehicle().top_speed_mps());
        let mut node = node(&cfg, &format!("{}_sim", cfg.node_name))?;
        let q = super::config::TopicQos {
            reliability: super::config::Reliability::Reliable,
            ..cfg.qos.sensors
        };
        fn opt<M: serde::Serialize>(
            node: &mut Node,
            name: &str,
            ty: (&str, &str),
            q: super::config::TopicQos,
        ) -> Result<Option<Publisher<M>>, DeployError> {
            if name.is_empty() {
                Ok(None)
            } else {
                publisher(node, name, ty, q).map(Some)
            }
        }
        let race = matches!(world, World::Race(_));
        let mut cars = Vec::with_capacity(frames.len());
        for (i, frame) in frames.iter().enumerate() {
            let (t, prefix) = match race {
                true => (cfg.topics.namespaced(&format!("car{i}")), format!("car{i}/")),
                false => (cfg.topics.clone(), String::new()),
            };
            let image_topic = if frame.image.is_some() { t.image.as_str() } else { "" };
            cars.push(CarTopics {
                scan: publisher(&mut node, &t.scan, SCAN_TYPE, q)?,
                imu: opt(&mut node, &t.imu, IMU_TYPE, q)?,
                odom: opt(&mut node, &t.odom, ODOM_TYPE, q)?,
                navsat: opt(&mut node, &t.navsat, NAVSAT_TYPE, q)?,
                image: opt(&mut node, image_topic, IMAGE_TYPE, q)?,
                topics: t,
                prefix,
            });
        }
        let tf = publisher(&mut node, "/tf", TF_TYPE, q)?;
        let tf_static = super::ros2::latched_publisher(&mut node, "/tf_static", TF_TYPE)?;
        if race {
            cfg.topics = cfg.topics.namespaced("car0");
        }
        let poll = Poll::new().map_err(|e| DeployError::Vehicle(format!("poll: {e}")))?;
        let drive = if faults.drive_reader_from == 0 {
            drive_reader(&mut node, &cfg, &poll)?
        } else {
            None
        };
        let wire = Wire::new(faults.wire.clone(), world.control_period_s());
        Ok(Self {
            cfg,
            world,
            node,
            stamp_offset_s: 0.0,
            cars,
            tf,
            tf_static,
            drive,
            poll,
            events: Events::with_capacity(8),
            frames,
            faults,
            wire,
            handle: RobotHandle::default(),
            bad_messages: 0,
            blocked_messages: 0,
        })
    }

    /// A handle for another thread.
    pub fn handle(&self) -> RobotHandle {
        self.handle.clone()
    }

    /// What the wire did so far.
    pub fn wire_stats(&self) -> WireStats {
        self.wire.stats()
    }

    /// Sensor messages not sent so far because a writer would have blocked.
    pub fn blocked_messages(&self) -> u64 {
        self.blocked_messages
    }

    /// Commands that failed to decode so far.
    pub fn bad_messages(&self) -> u64 {
        self.bad_messages
    }

    /// Hand the current sensor sets to the wire (see [`Wire`]; other cars' go out at once),
    /// each car's odom to base_link to `/tf`, then send what is due.
    fn publish(&mut self) -> Result<(), DeployError> {
        let period = self.world.control_period_s();
        let clock_s = self.world.clock_s(self.frames[0].stamp_s);
        let tick = (clock_s / period).round() as u64;
        let stamp_s = clock_s + self.stamp_offset_s;
        let now = Instant::now();
        let mut tf = Vec::new();
        for i in 0..self.frames.len() {
            if !self.world.running(i) {
                continue;
            }
            let served = i == 0;
            let at = stamp_s
                + if served {
                    self.wire.faults().clock_offset_s(tick)
                } else {
                    0.0
                };
            for m in self.messages(i, tick, at, period) {
                if let Outgoing::Odom(o) = &m {
                    tf.push(odom_tf(o, stamp_s));
                }
                if served {
                    self.wire.send(tick, now, m);
                } else {
                    self.put(i, m)?;
                }
            }
        }
        // The sensor sets first: the drive waits on them, nothing waits on tf.
        self.flush(now)?;
        if !tf.is_empty() {
            put_or_count(
                self.tf.publish(msg::TFMessage { transforms: tf }),
                "/tf",
                &mut self.blocked_messages,
            )?;
        }
        Ok(())
    }

    /// Car `i`'s sensor messages at `tick`, stamped `stamp_s` (faults act on the served car).
    fn messages(&self, i: usize, tick: u64, stamp_s: f64, period_s: f64) -> Vec<Outgoing> {
        let (f, c) = (&self.frames[i], &self.cars[i]);
        let served = i == 0;
        let frame = |name: &str| format!("{}{name}", c.prefix);
        let mut out = Vec::with_capacity(5);
        if let Some(s) = &f.scan
            && (!served || tick < self.faults.mute_scan_from)
        {
            let mut m = mapping::scan_msg(s, stamp_s, &frame("laser"), period_s as f32);
            if served && self.faults.nan_ticks.contains(&tick) {
                for i in self.faults.nan_rays.clone() {
                    if let Some(r) = m.ranges.get_mut(i) {
                        *r = f32::NAN;
                    }
                }
            }
            out.push(Outgoing::Scan(m));
        }
        if let (Some(_), Some(i)) = (&c.imu, &f.imu) {
            out.push(Outgoing::Imu(mapping::imu_msg(i, stamp_s, &c.topics.frame_id)));
        }
        if let (Some(_), Some(i), Some(g)) = (&c.odom, &f.imu, &f.gps) {
            let mut m = mapping::odom_msg(g, i, stamp_s, &c.topics.frame_id);
            m.header.frame_id = frame("odom");
            out.push(Outgoing::Odom(Box::new(m)));
        }
        if let (Some(_), Some(geo)) = (&c.navsat, f.gps.as_ref().and_then(|g| g.geodetic)) {
            out.push(Outgoing::NavSat(mapping::navsat_msg(&geo, stamp_s, &frame("gps"))));
        }
        if let (Some(_), Some(img)) = (&c.image, &f.image)
            && tick.is_multiple_of(self.faults.image_every.max(1))
        {
            out.push(Outgoing::Image(mapping::depth_image_msg(
                img,
                stamp_s,
                &frame("camera"),
            )));
        }
        out
    }

    /// The mounts, latched on `/tf_static`: each car's LiDAR and camera on its base and, in a
    /// race, each car's odom frame on `map` (the simulator's odometry is its world pose).
    fn publish_static(&mut self) -> Result<(), DeployError> {
        let stamp_s = self.world.clock_s(self.frames[0].stamp_s) + self.stamp_offset_s;
        let model = self.world.sim().vehicle();
        let race = matches!(self.world, World::Race(_));
        let mut transforms = Vec::new();
        for c in &self.cars {
            let base = &c.topics.frame_id;
            transforms.push(transform(
                base,
                &format!("{}laser", c.prefix),
                stamp_s,
                &model.lidar_mount(),
            ));
            if let Some(cam) = model.camera_mount() {
                transforms.push(transform(base, &format!("{}camera", c.prefix), stamp_s, &cam));
            }
            if race {
                let at = agvrl_sim::msg::Pose3::default();
                transforms.push(transform("map", &format!("{}odom", c.prefix), stamp_s, &at));
            }
        }
        put_or_count(
            self.tf_static.publish(msg::TFMessage { transforms }),
            "/tf_static",
            &mut self.blocked_messages,
        )
    }

    /// Publish `m` on car `i`'s topic at once.
    fn put(&mut self, i: usize, m: Outgoing) -> Result<(), DeployError> {
        let (c, blocked) = (&self.cars[i], &mut self.blocked_messages);
        let t = &c.topics;
        match m {
            Outgoing::Scan(m) => put_or_count(c.scan.publish(m), &t.scan, blocked),
            Outgoing::Imu(m) => send(&c.imu, m, &t.imu, blocked),
            Outgoing::Odom(m) => send(&c.odom, *m, &t.odom, blocked),
            Outgoing::NavSat(m) => send(&c.navsat, m, &t.navsat, blocked),
            Outgoing::Image(m) => send(&c.image, m, &t.image, blocked),
        }
    }

    /// Send the served car's messages the wire releases by `now`.
    fn flush(&mut self, now: Instant) -> Result<(), DeployError> {
        for m in self.wire.due(now) {
            self.put(0, m)?;
        }
        Ok(())
    }

    fn commands(&mut self) -> Vec<Control> {
        let mut out = Vec::new();
        if let Some(d) = &self.drive {
            loop {
                match d.take() {
                    Ok(Some((m, _))) => out.push(mapping::control_of(&m.drive, &self.cfg.drive)),
                    Ok(None) => break,
                    Err(_) => self.bad_messages += 1,
                }
            }
        }
        out
    }

    /// One control period with `c` (the served car's), then publish the new sensor sets.
    fn step(&mut self, c: Control, received: bool) -> Result<(), DeployError> {
        let mut s = self.handle.stats();
        s.ticks += 1;
        s.last_command = c;
        s.commands += u64::from(received);
        let termination = match &mut self.world {
            World::Alone { vehicle, task } => {
                vehicle.actuate(c)?;
                self.frames[0] = vehicle.sense()?;
                let out = task.evaluate(&self.frames[0], vehicle.map());
                if let Some(r) = out.racing {
                    s.laps = r.laps;
                    s.best_lap_s = r.best_lap_s;
                }
                out.termination
            }
            World::Race(r) => r.step(c, &mut self.frames, &mut s)?,
        };
        if let Some(t) = termination {
            s.terminations += 1;
            s.first_termination.get_or_insert((s.ticks, t));
        }
        s.stamp_s = self.world.clock_s(self.frames[0].stamp_s);
        if let Ok(mut held) = self.handle.stats.lock() {
            *held = s;
        }
        self.publish()
    }

    /// Serve until `max_ticks` control periods have run (0: until stopped).
    pub fn run(&mut self, pace: Pace, max_ticks: u64) -> Result<(), DeployError> {
        if pace == Pace::Lockstep && self.faults.wire.any() {
            return Err(DeployError::Config(
                "faults on the wire need real-time pace (--realtime): lockstep waits for every message".into(),
            ));
        }
        let period = self.world.control_period_s();
        let done = |h: &RobotHandle| h.stop.load(Ordering::Relaxed) || (max_ticks > 0 && h.stats().ticks >= max_ticks);
        // In real time the stamps are the wall clock's, as a car's are (ROS tools read them as
        // dates); in lockstep they are simulated time.
        self.stamp_offset_s = match pace {
            Pace::Realtime => crate::run_loop::wall_clock_s() - self.world.clock_s(self.frames[0].stamp_s),
            Pace::Lockstep => 0.0,
        };
        self.publish_static()?;
        self.publish()?;
        match pace {
            Pace::Lockstep => {
                // Until a command comes, re-send the current set now and then for late joiners.
                let mut last_pub = Instant::now();
                while !done(&self.handle) {
                    let _ = self.poll.poll(&mut self.events, Some(Duration::from_millis(20)));
                    let cmds = self.commands();
                    if cmds.is_empty() && last_pub.elapsed() > Duration::from_millis(50) {
                        self.publish()?;
                        last_pub = Instant::now();
                    }
                    for c in cmds {
                        self.step(c, true)?;
                        last_pub = Instant::now();
                    }
                }
            }
            Pace::Realtime => {
                let t0 = Instant::now();
                let mut held = Control::default();
                let mut last_cmd = Instant::now();
                let mut k = 0u32;
                while !done(&self.handle) {
                    k += 1;
                    let deadline = t0 + Duration::from_secs_f64(period * k as f64);
                    // Wake for the wire's releases too, so delayed messages leave on time.
                    loop {
                        let now = Instant::now();
                        self.flush(now)?;
                        let Some(left) = deadline.checked_duration_since(now) else {
                            break;
                        };
                        let wake = self
                            .wire
                            .next_release()
                            .map_or(left, |r| left.min(r.saturating_duration_since(now)));
                        let _ = self.poll.poll(&mut self.events, Some(wake));
                    }
                    if self.drive.is_none() && u64::from(k) > self.faults.drive_reader_from {
                        self.drive = drive_reader(&mut self.node, &self.cfg, &self.poll)?;
                    }
                    let cmds = self.commands();
                    if let Some(c) = cmds.last() {
                        held = *c;
                        last_cmd = Instant::now();
                    } else if last_cmd.elapsed().as_secs_f64() > COMMAND_TIMEOUT_S {
                        held = Control::default();
                    }
                    self.step(held, !cmds.is_empty())?;
                }
            }
        }
        Ok(())
    }
}

/// `Ok` for a sent message or one a reader that is behind loses (counted in `blocked`, as a
/// car's sensor would drop it); an error otherwise.
fn put_or_count<M>(
    r: Result<(), ros2_client::WriteError<M>>,
    name: &str,
    blocked: &mut u64,
) -> Result<(), DeployError> {
    match r {
        Ok(()) => Ok(()),
        Err(ros2_client::WriteError::WouldBlock { .. }) => {
            *blocked += 1;
            Ok(())
        }
        Err(e) => Err(DeployError::Vehicle(format!("publishing {name}: {e}"))),
    }
}

/// Publish `m` on `p` when the topic is served (see [`put_or_count`]).
fn send<M: serde::Serialize>(p: &Option<Publisher<M>>, m: M, name: &str, blocked: &mut u64) -> Result<(), DeployError> {
    match p {
        Some(p) => put_or_count(p.publish(m), name, blocked),
        None => Ok(()),
    }
}

/// odom to base_link on `/tf`, from an Odometry message (its own frames), stamped `stamp_s`.
fn odom_tf(o: &msg::Odometry, stamp_s: f64) -> msg::TransformStamped {
    msg::TransformStamped {
        header: mapping::header(stamp_s, &o.header.frame_id),
        child_frame_id: o.child_frame_id.clone(),
        transform: mapping::odom_transform(o),
    }
}

impl Race {
    /// Start the classical racers on the race just reset.
    fn reset_racers(&mut self) {
        for (k, o) in self.opponents.iter_mut().enumerate() {
            if let Opponent::Racer(d) = o {
                d.reset(self.env.frame_of(k + 1), Some(self.env.map()));
            }
        }
    }

    /// One period: the served car with `c`, the others by their policies; the frames and the
    /// served car's stats follow, and a new race starts when the served car's ends. The served
    /// car's termination, if any.
    fn step(
        &mut self,
        c: Control,
        frames: &mut [SensorFrame],
        s: &mut RobotStats,
    ) -> Result<Option<TerminationCause>, DeployError> {
        let n = frames.len();
        // Each opponent's action (a policy's) or control (a racer's); a car out of the race waits.
        let mut given: Vec<Given> = Vec::with_capacity(n);
        for i in 1..n {
            let done = self.env.done(i);
            given.push(match &mut self.opponents[i - 1] {
                Opponent::Policy(_) if done => Given::Action(vec![0.0; 2]),
                Opponent::Policy(p) => Given::Action(
                    p.act(&self.obs[i], true)
                        .map_err(|e| DeployError::Vehicle(format!("car {i}'s policy: {e}")))?,
                ),
                Opponent::Racer(_) if done => Given::Control(Control::default()),
                Opponent::Racer(d) => Given::Control(d.control(self.env.frame_of(i), Some(self.env.map()))),
            });
        }
        let inputs: Vec<CarInput> = std::iter::once(CarInput::Control(c))
            .chain(given.iter().map(|g| match g {
                Given::Action(a) => CarInput::Action(a),
                Given::Control(c) => CarInput::Control(*c),
            }))
            .collect();
        let st = self.env.step_inputs(&inputs)?;
        for (i, a) in st.agents.iter().enumerate() {
            if let Some(a) = a {
                self.obs[i] = a.obs.clone();
            }
        }
        let me = st.agents[0].as_ref().ok_or(agvrl_envs::api::EnvError::Internal(
            "the served car runs until its race ends",
        ))?;
        let (race, racing) = (me.info.race.as_ref(), me.info.racing.as_ref());
        let laps = racing.map_or(0, |r| r.laps);
        s.laps = self.laps_before + laps;
        if let Some(b) = racing.and_then(|r| r.best_lap_s) {
            s.best_lap_s = Some(s.best_lap_s.map_or(b, |x| x.min(b)));
        }
        let (contacts, at_fault, passes) = race.map_or((0, 0, 0), |r| (r.contacts, r.at_fault, r.passes));
        s.car_contacts = self.before.0 + contacts;
        s.at_fault = self.before.1 + at_fault;
        s.passes = self.before.2 + passes;
        let termination = me.info.termination;
        if me.terminated || me.truncated {
            s.races += 1;
            s.wins += u32::from(race.is_some_and(|r| r.position == 1));
            self.laps_before = s.laps;
            self.before = (s.car_contacts, s.at_fault, s.passes);
            self.clock_s += self.env.sim().time_s() + self.env.dt_s();
            self.obs = self.env.reset(None)?;
            self.reset_racers();
        }
        for (i, f) in frames.iter_mut().enumerate() {
            if i == 0 || !self.env.done(i) {
                *f = self.env.frame_of(i).clone();
            }
        }
        Ok(termination)
    }
}

/// The robot's subscription to the drive topic, registered with `poll`.
fn drive_reader(
    node: &mut Node,
    cfg: &Ros2Config,
    poll: &Poll,
) -> Result<Option<Subscription<msg::AckermannDriveStamped>>, DeployError> {
    let mut drive = subscribe(node, &cfg.topics.drive, DRIVE_TYPE, cfg.qos.drive)?;
    if let Some(d) = drive.as_mut() {
        poll.registry()
            .register(d, Token(0), Interest::READABLE)
            .map_err(|e| DeployError::Vehicle(format!("poll: {e}")))?;
    }
    Ok(drive)
}
