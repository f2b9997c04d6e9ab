//! A sim-backed ROS 2 robot (`agvrl-drive --serve-sim ENV`): publishes the simulated car's
//! LaserScan, Imu, Odometry (and NavSatFix, and its camera's depth as a 32FC1 Image when the
//! env's car carries a camera) and applies the AckermannDriveStamped commands it
//! receives, so the whole drive loop runs over real DDS. Each tick advances the simulator by
//! exactly one control period; the task's evaluation counts laps and collisions on this side
//! (a car's drive loop knows no map).

use super::config::Ros2Config;
use super::mapping;
use super::msg;
use super::ros2::{
    DRIVE_TYPE, IMAGE_TYPE, IMU_TYPE, NAVSAT_TYPE, ODOM_TYPE, Publisher, SCAN_TYPE, Subscription, node, publisher,
    subscribe,
};
use super::wire::{Outgoing, Wire, WireFaults, WireStats};
use crate::DeployError;
use agvrl_envs::api::{Control, SensorFrame, TerminationCause, Vehicle};
use agvrl_envs::task::Task;
use agvrl_envs::{EnvConfig, make_sim_car, make_task};
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

/// The simulated car behind ROS 2 topics.
pub struct SimRobot {
    cfg: Ros2Config,
    vehicle: agvrl_envs::SimCar,
    task: Box<dyn Task>,
    node: Node,
    /// Added to simulated time in the published stamps (wall-clock epoch time in real time).
    stamp_offset_s: f64,
    scan: Publisher<msg::LaserScan>,
    imu: Option<Publisher<msg::Imu>>,
    odom: Option<Publisher<msg::Odometry>>,
    navsat: Option<Publisher<msg::NavSatFix>>,
    image: Option<Publisher<msg::Image>>,
    drive: Option<Subscription<msg::AckermannDriveStamped>>,
    poll: Poll,
    events: Events,
    frame: SensorFrame,
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
        let mut cfg = cfg;
        // The robot serves its own car: an explicit max_speed_mps is honoured as set.
        let _ = cfg.drive.for_trained_top_speed(vehicle.sim().vehicle().top_speed_mps());
        let mut task = make_task(env, env_cfg, vehicle.steering_limit_rad())?;
        let frame = vehicle.reset(seed)?;
        task.reset(&frame, vehicle.map());
        let mut node = node(&cfg, &format!("{}_sim", cfg.node_name))?;
        let t = &cfg.topics;
        let q = super::config::TopicQos {
            reliability: super::config::Reliability::Reliable,
            ..cfg.qos.sensors
        };
        let scan = publisher(&mut node, &t.scan, SCAN_TYPE, q)?;
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
        let imu = opt(&mut node, &t.imu, IMU_TYPE, q)?;
        let odom = opt(&mut node, &t.odom, ODOM_TYPE, q)?;
        let navsat = opt(&mut node, &t.navsat, NAVSAT_TYPE, q)?;
        let image_topic = if frame.image.is_some() { t.image.as_str() } else { "" };
        let image = opt(&mut node, image_topic, IMAGE_TYPE, q)?;
        let poll = Poll::new().map_err(|e| DeployError::Vehicle(format!("poll: {e}")))?;
        let drive = if faults.drive_reader_from == 0 {
            drive_reader(&mut node, &cfg, &poll)?
        } else {
            None
        };
        let handle = RobotHandle::default();
        let wire = Wire::new(faults.wire.clone(), vehicle.control_period_s());
        Ok(Self {
            cfg,
            vehicle,
            task,
            node,
            stamp_offset_s: 0.0,
            scan,
            imu,
            odom,
            navsat,
            image,
            drive,
            poll,
            events: Events::with_capacity(8),
            frame,
            faults,
            wire,
            handle,
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

    /// Hand the current sensor set to the wire (see [`Wire`]), then send what is due.
    fn publish(&mut self) -> Result<(), DeployError> {
        let f = &self.frame;
        let tick = (f.stamp_s / self.vehicle.control_period_s()).round() as u64;
        let stamp_s = f.stamp_s + self.stamp_offset_s + self.wire.faults().clock_offset_s(tick);
        let now = Instant::now();
        let mut out = Vec::with_capacity(5);
        if let Some(s) = &f.scan
            && tick < self.faults.mute_scan_from
        {
            let mut m = mapping::scan_msg(s, stamp_s, "laser", self.vehicle.control_period_s() as f32);
            if self.faults.nan_ticks.contains(&tick) {
                for i in self.faults.nan_rays.clone() {
                    if let Some(r) = m.ranges.get_mut(i) {
                        *r = f32::NAN;
                    }
                }
            }
            out.push(Outgoing::Scan(m));
        }
        let t = &self.cfg.topics;
        if let (Some(_), Some(i)) = (&self.imu, &f.imu) {
            out.push(Outgoing::Imu(mapping::imu_msg(i, stamp_s, &t.frame_id)));
        }
        if let (Some(_), Some(i), Some(g)) = (&self.odom, &f.imu, &f.gps) {
            out.push(Outgoing::Odom(Box::new(mapping::odom_msg(g, i, stamp_s, &t.frame_id))));
        }
        if let (Some(_), Some(geo)) = (&self.navsat, f.gps.as_ref().and_then(|g| g.geodetic)) {
            out.push(Outgoing::NavSat(mapping::navsat_msg(&geo, stamp_s, "gps")));
        }
        if let (Some(_), Some(img)) = (&self.image, &f.image)
            && tick.is_multiple_of(self.faults.image_every.max(1))
        {
            out.push(Outgoing::Image(mapping::depth_image_msg(img, stamp_s, "camera")));
        }
        for m in out {
            self.wire.send(tick, now, m);
        }
        self.flush(now)
    }

    /// Send the messages the wire releases by `now`.
    fn flush(&mut self, now: Instant) -> Result<(), DeployError> {
        let t = &self.cfg.topics;
        let pub_err = |name: &str, e: String| DeployError::Vehicle(format!("publishing {name}: {e}"));
        for m in self.wire.due(now) {
            let sent = match m {
                Outgoing::Scan(m) => self
                    .scan
                    .publish(m)
                    .map_err(|e| (t.scan.as_str(), e.to_string(), blocked(&e))),
                Outgoing::Imu(m) => send(&self.imu, m, &t.imu),
                Outgoing::Odom(m) => send(&self.odom, *m, &t.odom),
                Outgoing::NavSat(m) => send(&self.navsat, m, &t.navsat),
                Outgoing::Image(m) => send(&self.image, m, &t.image),
            };
            match sent {
                Ok(()) => {}
                // A reader that is behind loses this message, as a car's sensor would drop it.
                Err((_, _, true)) => self.blocked_messages += 1,
                Err((name, e, false)) => return Err(pub_err(name, e)),
            }
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

    /// One control period with `c`, then publish the new sensor set.
    fn step(&mut self, c: Control, received: bool) -> Result<(), DeployError> {
        self.vehicle.actuate(c)?;
        self.frame = self.vehicle.sense()?;
        let out = self.task.evaluate(&self.frame, self.vehicle.map());
        if let Ok(mut s) = self.handle.stats.lock() {
            s.ticks += 1;
            s.stamp_s = self.frame.stamp_s;
            s.last_command = c;
            s.commands += u64::from(received);
            if let Some(r) = out.racing {
                s.laps = r.laps;
                s.best_lap_s = r.best_lap_s;
            }
            if let Some(t) = out.termination {
                s.terminations += 1;
                let tick = s.ticks;
                s.first_termination.get_or_insert((tick, t));
            }
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
        let period = self.vehicle.control_period_s();
        let done = |h: &RobotHandle| h.stop.load(Ordering::Relaxed) || (max_ticks > 0 && h.stats().ticks >= max_ticks);
        // In real time the stamps are the wall clock's, as a car's are (ROS tools read them as
        // dates); in lockstep they are simulated time.
        self.stamp_offset_s = match pace {
            Pace::Realtime => crate::run_loop::wall_clock_s() - self.frame.stamp_s,
            Pace::Lockstep => 0.0,
        };
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

/// Whether a write failed only because it would have blocked.
fn blocked<M>(e: &ros2_client::WriteError<M>) -> bool {
    matches!(e, ros2_client::WriteError::WouldBlock { .. })
}

/// Publish `m` on `p` when the topic is served: (topic, error, whether it would have blocked).
fn send<'a, M: serde::Serialize>(p: &Option<Publisher<M>>, m: M, name: &'a str) -> Result<(), (&'a str, String, bool)> {
    match p {
        Some(p) => p.publish(m).map_err(|e| (name, e.to_string(), blocked(&e))),
        None => Ok(()),
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
