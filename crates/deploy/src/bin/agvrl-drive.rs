//! agvrl-drive: run a trained policy on a vehicle at a fixed rate, with a watchdog.
//!
//! `agvrl-drive --policy assets/policies/racing-oval-ppo.agvrl` drives the simulated car with
//! the shipped policy (with the settings embedded in it); `--vehicle ros2 --config
//! car.toml` drives a ROS 2 car; `--serve-sim racing-oval` is the simulated car behind ROS 2
//! topics. Each tick prints one `key=value` line, the run ends with a summary line.

use agvrl_deploy::hardware::config::DriveMapping;
use agvrl_deploy::hardware::frames::Subscribed;
use agvrl_deploy::record::{self, BagCar, DriveBag, Recorded};
use agvrl_deploy::stats::{cpu_time_s, quantile, rss_mb};
use agvrl_deploy::{DriveConfig, DriveLoop, DrivePasser};
use agvrl_envs::api::Vehicle;
use agvrl_envs::task::{Intervention, Task};
use agvrl_envs::{EnvConfig, make_task, make_vehicle};
use agvrl_rl::Policy;
use agvrl_run::PolicySettings;
use anyhow::{Context, Result, bail};
use clap::Parser;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// `println!` that never panics: a closed stdout (`agvrl-drive ... | head`) must not stop the
/// control loop; the lines are lost, the drive goes on.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($t)*);
    }};
}

/// `--vehicle`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum VehicleKind {
    /// The simulated car of the env.
    Sim,
    /// A car behind ROS 2 topics.
    Ros2,
}

#[derive(Parser)]
#[command(
    name = "agvrl-drive",
    version,
    about = "Drive a trained agvrl policy on the simulator or a ROS 2 car at a fixed rate, with a watchdog; or serve the simulated car over ROS 2."
)]
struct Args {
    /// A run directory from `agvrl train` (its policy.agvrl and config.toml).
    #[arg(long, conflicts_with = "policy")]
    run: Option<PathBuf>,
    /// A policy file, driven with the settings embedded in it (`agvrl policy FILE` prints
    /// them; files written before settings were embedded: FILE.toml beside it, or the
    /// config.toml of the run directory holding it).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Drive a classical racer instead of a policy: `pure-pursuit` (along --raceline, else the
    /// track's centre line; needs the pose: the simulator's, or the car's odometry topic) or
    /// `follow-the-gap` (the LiDAR alone). The env is --env (default racing-oval) with --track.
    #[arg(long, value_name = "KIND", conflicts_with_all = ["run", "policy", "check_trace", "replay"])]
    racer: Option<String>,
    /// The racer's speed: a scale of pure pursuit's speed profile or of follow-the-gap's top
    /// speed, in (0, 1].
    #[arg(long, default_value_t = 1.0, requires = "racer")]
    speed_scale: f64,
    /// Pure pursuit's path: F1TENTH's raceline CSV or an x, y CSV, in the map frame of the pose.
    #[arg(long, value_name = "FILE.csv", requires = "racer")]
    raceline: Option<PathBuf>,
    /// Override one of the policy's settings (a racer's: of the env's defaults), KEY=VALUE as
    /// `agvrl train --set` (`--set env_config.safety_filter.clearance_m=0.9`).
    #[arg(long, value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Race on the track of a ROS map file (its YAML): `--set env_config.track=PATH`; with
    /// --serve-sim, the simulated car drives it.
    #[arg(long, value_name = "MAP.yaml")]
    track: Option<PathBuf>,
    /// Environment id whose task to run (default: the policy's; racing-oval for --serve-sim
    /// without a policy).
    #[arg(long)]
    env: Option<String>,
    /// Which vehicle: the simulated car, or a ROS 2 car (needs --config, or uses the default
    /// topics).
    #[arg(long, value_enum, default_value_t = VehicleKind::Sim)]
    vehicle: VehicleKind,
    /// The car's TOML: topics, QoS, scan mapping, command scaling (see car.example.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override the config's DDS domain id.
    #[arg(long)]
    domain_id: Option<u16>,
    /// Serve the simulated car of env ENV over ROS 2 instead of driving. `racing-duel`: a race
    /// whose car 0 is served under namespace car0 (`/car0/scan`, `/car0/drive`; every car's
    /// sensors under its own) while --opponent policies or racers drive the others in-process.
    #[arg(long, value_name = "ENV", conflicts_with = "vehicle")]
    serve_sim: Option<String>,
    /// --serve-sim racing-duel: what drives the opponents (repeat for one per opponent): a
    /// policy file, or a classical racer `pure-pursuit` or `follow-the-gap`, optionally
    /// `@SCALE` of its speed (`pure-pursuit@0.75`). The race runs on --policy's env settings,
    /// else the first policy opponent's, else racing-duel's defaults (its track unless --track).
    #[arg(long = "opponent", value_name = "FILE|KIND[@SCALE]", requires = "serve_sim")]
    opponents: Vec<String>,
    /// --serve-sim racing-duel: cars on the grid, the served one included (default: one per
    /// opponent policy plus the served car).
    #[arg(long, requires = "serve_sim")]
    cars: Option<usize>,
    /// --vehicle ros2 (and --replay of its bag): the car's topics under this namespace (`car0`:
    /// `/car0/scan`, `/car0/drive`), as a served race names its cars.
    #[arg(long, value_name = "NS", conflicts_with = "serve_sim")]
    namespace: Option<String>,
    /// --serve-sim --realtime: faults on the wire, comma-separated KEY=VALUE (loss, delay_ms,
    /// jitter_ms, duplicate, reorder, outage=FROM+TICKS, mute=SENSOR@TICK,
    /// clock_step=SECONDS@TICK, seed); see docs/reliability.md.
    #[arg(long, value_name = "SPEC", requires = "serve_sim")]
    faults: Option<agvrl_deploy::hardware::WireFaults>,
    /// Control rate, Hz.
    #[arg(long, default_value_t = 30.0)]
    rate_hz: f64,
    /// Ticks to run (0: until interrupted).
    #[arg(long, default_value_t = 900)]
    steps: u64,
    /// Hold the rate with the wall clock (a car); without it a ROS 2 vehicle runs lockstep
    /// with `--serve-sim` (which must then also run without --realtime).
    #[arg(long)]
    realtime: bool,
    /// Seed of the vehicle's reset.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print only the summary line.
    #[arg(long)]
    quiet: bool,
    /// Record every tick's observation and action to FILE (JSON lines: tick, obs, action),
    /// to check another build or machine against with --check-trace.
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
    /// Drive nothing: run the policy on the observations of a --trace file and compare its
    /// actions with the recorded ones (exit status 1 beyond --tolerance).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["trace", "serve_sim"])]
    check_trace: Option<PathBuf>,
    /// Record the drive as a rosbag2 bag in directory DIR (MCAP; see docs/deploy.md):
    /// sensor messages, commands, transforms, the URDF and per tick the policy's observation,
    /// action and the safety filter's and watchdog's doings.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["check_trace", "serve_sim"])]
    record: Option<PathBuf>,
    /// Rebuild DIR/metadata.yaml of a bag from its MCAP file (a recording killed before it
    /// wrote one), then exit.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["record", "check_trace", "serve_sim"])]
    reindex: Option<PathBuf>,
    /// Print every message of bag DIR as a JSON line (topic, type, log_ns, msg), then exit.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["record", "reindex", "check_trace", "serve_sim"])]
    dump: Option<PathBuf>,
    /// Drive nothing: feed bag DIR (of --record) to the policy open loop, tick by tick as
    /// recorded (the car's TOML of --config names its topics), at the recorded pace.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["record", "reindex", "dump", "check_trace", "serve_sim"])]
    replay: Option<PathBuf>,
    /// --replay as fast as possible.
    #[arg(long, requires = "replay")]
    fast: bool,
    /// --replay: compare the actions and commands with the recorded ones (exit status 1 beyond
    /// --tolerance, or when a tick's watchdog event differs).
    #[arg(long, requires = "replay")]
    check: bool,
    /// Largest action difference --check-trace and --replay --check accept.
    #[arg(long, default_value_t = 1e-4)]
    tolerance: f32,
}

/// One line of a --trace file.
#[derive(serde::Serialize, Deserialize)]
struct TraceRow {
    tick: u64,
    obs: Vec<f32>,
    action: Vec<f32>,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {}", agvrl_run::error_line(e.as_ref()));
        std::process::exit(1);
    }
}

/// The policy's settings, env id and env settings from --run / --policy (agvrl-run's one
/// resolver), --set and --env. Without a policy (`--serve-sim` alone) the env is --env or
/// racing-oval.
fn policy_and_env(a: &Args) -> Result<(Option<PolicySettings>, String, EnvConfig)> {
    let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
    if a.run.is_none() && a.policy.is_none() {
        if let Some(s) = a.set.first().filter(|_| a.racer.is_none()) {
            bail!("--set {s}: there is no policy whose settings it could override");
        }
        // A racer drives the env's defaults, with --track and --set env_config.KEY=VALUE.
        let env = a.env.clone().unwrap_or_else(|| "racing-oval".to_string());
        let run = agvrl_run::RunConfig::from_toml_with(&format!("env = \"{env}\"\n"), "--racer", &sets)?;
        return Ok((None, env, run.env_config));
    }
    let src = PolicySettings::resolve(a.run.as_deref(), a.policy.as_deref(), &sets)?;
    let (env, cfg) = (src.env_id(a.env.as_deref())?, src.drive_env_config());
    Ok((Some(src), env, cfg))
}

#[cfg(feature = "ros2")]
fn ros2_config(a: &Args) -> Result<agvrl_deploy::hardware::Ros2Config> {
    let mut c = match &a.config {
        Some(p) => agvrl_deploy::hardware::Ros2Config::load(p)?,
        None => agvrl_deploy::hardware::Ros2Config::default(),
    };
    if let Some(d) = a.domain_id {
        c.domain_id = d;
        c.validate().map_err(|e| anyhow::anyhow!("--domain-id: {e}"))?;
    }
    if let Some(ns) = &a.namespace {
        c.topics = c.topics.namespaced(ns);
    }
    Ok(c)
}

fn run() -> Result<()> {
    let a = Args::parse();
    if !(a.rate_hz > 0.0 && a.rate_hz.is_finite()) {
        bail!("--rate-hz must be positive");
    }
    if let Some(dir) = &a.dump {
        return dump(dir);
    }
    if let Some(dir) = &a.reindex {
        let (s, damage) = agvrl_deploy::bag::reindex(dir)?;
        if let Some(d) = damage {
            eprintln!("warning: {d}");
        }
        out!("reindexed {} messages={}", dir.display(), s.messages());
        return Ok(());
    }
    if let Some(id) = a
        .serve_sim
        .as_deref()
        .filter(|id| agvrl_envs::MULTI_ENV_IDS.contains(id))
    {
        return serve_race(&a, id);
    }
    if !a.opponents.is_empty() || a.cars.is_some() {
        bail!(
            "--opponent and --cars set up a served race: --serve-sim {}",
            agvrl_envs::MULTI_ENV_IDS.join(" | ")
        );
    }
    let (src, env, env_cfg) = policy_and_env(&a)?;
    if let Some(sim_env) = &a.serve_sim {
        return serve_sim(&a, sim_env, &env_cfg);
    }
    if let Some(kind) = &a.racer {
        return drive_racer(&a, kind, &env, &env_cfg);
    }
    let Some(mut src) = src else {
        bail!("give --run DIR or --policy FILE (e.g. assets/policies/racing-oval-ppo.agvrl), or --racer KIND");
    };
    let mut policy = src.load_policy()?;
    if let Some(trace) = &a.check_trace {
        return check_trace(&mut policy, trace, a.tolerance);
    }
    if let Some(dir) = &a.replay {
        return replay(&a, dir, &env, &env_cfg, policy);
    }
    let drive = DriveConfig {
        rate_hz: a.rate_hz,
        realtime: a.realtime,
        ..DriveConfig::default()
    };
    match a.vehicle {
        VehicleKind::Sim => {
            let passer = DrivePasser::of_env(&env, &env_cfg)?;
            let mut vehicle = make_vehicle(&env, &env_cfg)?;
            let task = make_task(&env, &env_cfg, vehicle.steering_limit_rad())?;
            let Some(dir) = &a.record else {
                let lp = DriveLoop::new(vehicle, task, policy, drive, a.seed)?.with_passer(passer);
                return drive_loop(&a, lp, None);
            };
            // The sensors the bag holds: those of the first frame (the loop resets again, to
            // the same state).
            let bag = Arc::new(sim_bag(dir, Some(&src.policy), &env, &env_cfg, &mut vehicle, a.seed)?);
            let v = Recorded::new(vehicle, bag.clone(), true);
            let lp = DriveLoop::new(v, task, policy, drive, a.seed)?.with_passer(passer);
            drive_loop(&a, lp, Some(bag))
        }
        VehicleKind::Ros2 => drive_ros2(&a, &src, &env, &env_cfg, policy, drive),
    }
}

/// `--racer KIND`: a classical racer drives the simulated car or a ROS 2 car through the env's
/// task (its action mapping and safety filter), with the watchdog of a policy's drive.
fn drive_racer(a: &Args, kind: &str, env: &str, env_cfg: &EnvConfig) -> Result<()> {
    use agvrl_envs::drivers::{RacerKind, make_racer};
    let kind = RacerKind::of(kind)?;
    if !(a.speed_scale.is_finite() && a.speed_scale > 0.0 && a.speed_scale <= 1.0) {
        bail!("--speed-scale must be in (0, 1], got {}", a.speed_scale);
    }
    let raceline = match &a.raceline {
        Some(p) => Some(std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?),
        // A real car has no map: pure pursuit there follows the track's centre line.
        None if kind == RacerKind::PurePursuit && a.vehicle == VehicleKind::Ros2 => {
            let Some(t) = &env_cfg.track else {
                bail!("pure pursuit on a ROS 2 car follows --raceline FILE or the centre line of --track MAP.yaml");
            };
            let t = t.load()?;
            Some(t.centreline.iter().map(|p| format!("{}, {}\n", p[0], p[1])).collect())
        }
        None => None,
    };
    let driver = make_racer(kind, env_cfg, a.speed_scale, raceline.as_deref())
        .map_err(|e| anyhow::anyhow!("--racer {}: {e}", kind.name()))?;
    let brain = agvrl_deploy::run_loop::Brain::Racer(driver, env_cfg.action_mapping);
    let drive = DriveConfig {
        rate_hz: a.rate_hz,
        realtime: a.realtime,
        ..DriveConfig::default()
    };
    match a.vehicle {
        VehicleKind::Sim => {
            let passer = DrivePasser::of_env(env, env_cfg)?;
            let mut vehicle = make_vehicle(env, env_cfg)?;
            let task = make_task(env, env_cfg, vehicle.steering_limit_rad())?;
            let Some(dir) = &a.record else {
                let lp = DriveLoop::with_brain(vehicle, task, brain, drive, a.seed)?.with_passer(passer);
                return drive_loop(a, lp, None);
            };
            let bag = Arc::new(sim_bag(dir, None, env, env_cfg, &mut vehicle, a.seed)?);
            let v = Recorded::new(vehicle, bag.clone(), true);
            let lp = DriveLoop::with_brain(v, task, brain, drive, a.seed)?.with_passer(passer);
            drive_loop(a, lp, Some(bag))
        }
        VehicleKind::Ros2 => racer_ros2(a, env, env_cfg, brain, drive),
    }
}

/// The bag of a drive of the simulated car `vehicle` (`policy`: the policy file, None for a
/// racer): the sensors of its first frame (the loop resets again, to the same state), the
/// drive commands within the simulated car's own limits, in simulated time.
fn sim_bag(
    dir: &Path,
    policy: Option<&Path>,
    env: &str,
    env_cfg: &EnvConfig,
    vehicle: &mut Box<dyn Vehicle>,
    seed: u64,
) -> Result<DriveBag> {
    let sensors = Subscribed::of_frame(&vehicle.reset(seed)?);
    let model = env_cfg.sim.vehicle_model()?;
    let mut mapping = DriveMapping {
        steering_limit_rad: model.spec.steering.max_rad,
        ..DriveMapping::default()
    };
    mapping.for_trained_top_speed(model.top_speed_mps());
    let topics = agvrl_deploy::hardware::config::Topics::default();
    let car = BagCar {
        topics: &topics,
        sensors,
        drive: mapping,
        sim_time: true,
    };
    Ok(record::for_policy(dir, policy, env, env_cfg, car)?)
}

#[cfg(feature = "ros2")]
fn racer_ros2(
    a: &Args,
    env: &str,
    env_cfg: &EnvConfig,
    brain: agvrl_deploy::run_loop::Brain,
    drive: DriveConfig,
) -> Result<()> {
    let mut cfg = ros2_config(a)?;
    cfg.check_lidar(&env_cfg.sim.lidar)?;
    cfg.drive
        .for_trained_top_speed(env_cfg.sim.vehicle_model()?.top_speed_mps());
    let task = make_task(env, env_cfg, cfg.drive.steering_limit_rad)?;
    ros2_car(a, cfg, task, None, (None, env, env_cfg), brain, drive)
}

/// Drive the ROS 2 car of `cfg` (with `camera`) with `brain` through `task`, recording into
/// `--record DIR` when given (the bag names `policy`, the file, or none for a racer).
#[cfg(feature = "ros2")]
fn ros2_car(
    a: &Args,
    cfg: agvrl_deploy::hardware::Ros2Config,
    task: Box<dyn Task>,
    camera: Option<agvrl_sim::sensors::CameraConfig>,
    (policy, env, env_cfg): (Option<&Path>, &str, &EnvConfig),
    brain: agvrl_deploy::run_loop::Brain,
    drive: DriveConfig,
) -> Result<()> {
    let passer = DrivePasser::of_env(env, env_cfg)?;
    let bag = match &a.record {
        Some(dir) => {
            let car = BagCar {
                topics: &cfg.topics,
                sensors: Subscribed::of_topics(&cfg.topics, camera.is_some()),
                drive: cfg.drive,
                sim_time: false,
            };
            Some(Arc::new(record::for_policy(dir, policy, env, env_cfg, car)?))
        }
        None => None,
    };
    let mut vehicle = agvrl_deploy::hardware::Ros2Vehicle::new(cfg, !a.realtime, camera)?;
    match bag {
        Some(bag) => {
            vehicle.record_into(bag.clone());
            let v = Recorded::new(vehicle, bag.clone(), false);
            let lp = DriveLoop::with_brain(v, task, brain, drive, a.seed)?.with_passer(passer);
            drive_loop(a, lp, Some(bag))
        }
        None => {
            let lp = DriveLoop::with_brain(vehicle, task, brain, drive, a.seed)?.with_passer(passer);
            drive_loop(a, lp, None)
        }
    }
}

#[cfg(not(feature = "ros2"))]
fn racer_ros2(_: &Args, _: &str, _: &EnvConfig, _: agvrl_deploy::run_loop::Brain, _: DriveConfig) -> Result<()> {
    bail!("this agvrl-drive was built without ROS 2 (feature ros2)")
}

#[cfg(feature = "ros2")]
fn drive_ros2(
    a: &Args,
    src: &PolicySettings,
    env: &str,
    env_cfg: &EnvConfig,
    policy: Policy,
    drive: DriveConfig,
) -> Result<()> {
    let mut cfg = ros2_config(a)?;
    cfg.check_lidar(&env_cfg.sim.lidar)?;
    // Full throttle is the trained car's top speed unless the car's TOML says otherwise.
    let top = env_cfg.sim.vehicle_model()?.top_speed_mps();
    if let Some(w) = cfg.drive.for_trained_top_speed(top) {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "full throttle commands {:.2} m/s (trained top speed {top:.2} m/s)",
        cfg.drive.full_throttle_mps()
    );
    let task = make_task(env, env_cfg, cfg.drive.steering_limit_rad)?;
    let camera = if task.needs().image {
        let c = env_cfg.sim.camera.clone();
        Some(c.ok_or_else(|| anyhow::anyhow!("the policy sees a camera image, but its env has no camera"))?)
    } else {
        None
    };
    // What DriveLoop::new checks for a policy.
    policy
        .check_spaces(&task.observation_space(), &agvrl_envs::BoxSpace::uniform(2, -1.0, 1.0))
        .map_err(agvrl_deploy::DeployError::Mismatch)?;
    let brain = agvrl_deploy::run_loop::Brain::Policy(Box::new(policy));
    ros2_car(a, cfg, task, camera, (Some(&src.policy), env, env_cfg), brain, drive)
}

#[cfg(not(feature = "ros2"))]
fn drive_ros2(_: &Args, _: &PolicySettings, _: &str, _: &EnvConfig, _: Policy, _: DriveConfig) -> Result<()> {
    bail!("--vehicle ros2: this agvrl-drive was built without the `ros2` feature")
}

/// `--replay DIR [--fast] [--check]`.
fn replay(a: &Args, dir: &Path, env: &str, env_cfg: &EnvConfig, policy: Policy) -> Result<()> {
    use agvrl_deploy::hardware::Ros2Config;
    let mut cfg = a.config.as_deref().map(Ros2Config::load).transpose()?;
    // A drive of a served race's car: its topics under its namespace, as it drove.
    if let Some(ns) = &a.namespace {
        let mut c = cfg.unwrap_or_else(|| {
            let mut c = Ros2Config::default();
            c.scan = c.scan.with_rays_of(&env_cfg.sim.lidar);
            c
        });
        c.topics = c.topics.namespaced(ns);
        cfg = Some(c);
    }
    let mut r = agvrl_deploy::replay::Replayer::open(dir, cfg, env, env_cfg, policy, a.rate_hz, a.seed)?;
    if let Some(d) = &r.vehicle().damage {
        eprintln!("warning: {d}; replaying the intact part");
    }
    for j in r.vehicle().clock_jumps.iter().take(5) {
        eprintln!("warning: {}: {j}", dir.display());
    }
    let recorded = r.vehicle().recorded();
    if !recorded {
        if a.check {
            bail!(
                "{}: no /agvrl/tick, so no recorded commands to check against (a car log of another stack replays \
                 without --check: the watchdog's events and the policy's commands)",
                dir.display()
            );
        }
        eprintln!(
            "{}: no /agvrl/tick: ticking at {} Hz on the log clock, as a live car would have read it",
            dir.display(),
            a.rate_hz
        );
    }
    let (t0, clock0) = (Instant::now(), r.vehicle().ticks()[0].clock_s);
    let (mut ticks, mut events) = (0, 0);
    loop {
        if !a.fast
            && let Some(clock) = r.vehicle().next_clock_s()
        {
            let due = Duration::from_secs_f64((clock - clock0).max(0.0));
            if let Some(rest) = due.checked_sub(t0.elapsed()) {
                std::thread::sleep(rest);
            }
        }
        let Some((rec, t)) = r.step()? else { break };
        ticks += 1;
        events += u64::from(t.event.is_some());
        if !a.quiet {
            let ev = t.event.as_ref().map(|e| format!(" event={e:?}")).unwrap_or_default();
            let was = if recorded {
                format!(
                    " recorded_throttle={:.3} recorded_steering_rad={:.3}",
                    rec.throttle, rec.steering_rad
                )
            } else {
                String::new()
            };
            out!(
                "tick={} clock_s={:.3} throttle={:.3} steering_rad={:.3}{was}{ev}",
                t.index,
                rec.clock_s,
                t.control.throttle,
                t.control.steering_rad
            );
        }
    }
    let d = &r.diff;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    out!(
        "replay ticks={ticks} events={events} events_differ={} action_diff_max={:e} action_diff_p99={:e} control_diff_max={:e} \
         control_diff_p99={:e} bad_messages={} wall_s={:.2}",
        d.events,
        max(&d.action),
        quantile(&d.action, 0.99),
        max(&d.control),
        quantile(&d.control, 0.99),
        r.vehicle().bad_messages(),
        t0.elapsed().as_secs_f64()
    );
    if a.check && (d.events > 0 || d.worst() > a.tolerance as f64) {
        bail!(
            "the replay differs from the recording: {} ticks' watchdog events, largest difference {:e} \
             (tolerance {:e})",
            d.events,
            d.worst(),
            a.tolerance
        );
    }
    Ok(())
}

/// `--dump DIR`: every intact message as a JSON line; damage is a warning on stderr.
fn dump(dir: &Path) -> Result<()> {
    use std::io::Write;
    let (msgs, damage) = agvrl_deploy::bag::read_messages(dir)?;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let (mut unknown, mut bad) = (0u64, 0u64);
    for (i, m) in msgs.iter().enumerate() {
        let row = match agvrl_deploy::record::decode_json(m) {
            Ok(v) => serde_json::json!({"topic": m.topic, "type": m.ty, "log_ns": m.log_ns, "msg": v}),
            // Kept as a row: a topic of another schema, or a message that does not decode.
            Err(e) => {
                if e.starts_with("no decoder") {
                    unknown += 1;
                } else {
                    bad += 1;
                    eprintln!(
                        "warning: {}: message {i} ({} on {}, log time {} ns): {e}",
                        dir.display(),
                        m.ty,
                        m.topic,
                        m.log_ns
                    );
                }
                serde_json::json!({"topic": m.topic, "type": m.ty, "log_ns": m.log_ns, "msg": null, "bytes": m.data.len(), "error": e})
            }
        };
        // A closed stdout (`| head`) ends the dump quietly.
        if writeln!(out, "{row}").is_err() {
            return Ok(());
        }
    }
    let _ = out.flush();
    if unknown > 0 {
        eprintln!(
            "warning: {unknown} messages of types without a decoder here (\"msg\": null, their size in \"bytes\")"
        );
    }
    if let Some(d) = damage {
        eprintln!("warning: {d}");
    }
    if bad > 0 {
        bail!("{}: {bad} messages did not decode (rows with \"error\")", dir.display());
    }
    Ok(())
}

fn drive_loop<V: Vehicle, T: Task>(a: &Args, mut lp: DriveLoop<V, T>, bag: Option<Arc<DriveBag>>) -> Result<()> {
    let passing = lp.passing();
    let (cpu0, t0) = (cpu_time_s(), Instant::now());
    let (mut k, mut events, mut terminations, mut filtered) = (0u64, 0u64, 0u64, 0u64);
    let mut passed = 0u64;
    // Constant memory however long the car drives.
    let mut infer_us = agvrl_deploy::stats::Latencies::default();
    let (mut late, mut tick_us, period_s) = (0u64, agvrl_deploy::stats::Latencies::default(), 1.0 / a.rate_hz);
    let mut racing = None;
    let mut stops = agvrl_deploy::stats::Stops::default();
    let mut trace = a.trace.as_deref().map(TraceWriter::create).transpose()?;
    while a.steps == 0 || k < a.steps {
        let t = lp.tick()?;
        if let Some(b) = &bag {
            b.tick(&t);
        }
        late += u64::from(t.late_s > period_s);
        stops.add(&t);
        tick_us.add(t.tick_us);
        if let (Some(w), Some((obs, action))) = (trace.as_mut(), &t.inference) {
            w.row(t.index, obs, action)?;
        }
        k += 1;
        events += u64::from(t.event.is_some());
        terminations += u64::from(t.termination.is_some());
        filtered += u64::from(t.intervention != Intervention::None);
        passed += u64::from(t.passed.is_some());
        infer_us.add(t.infer_us);
        if t.racing.is_some() {
            racing = t.racing.clone();
        }
        if !a.quiet {
            let ev = t.event.as_ref().map(|e| format!(" event={e:?}")).unwrap_or_default();
            let term = t.termination.map(|c| format!(" termination={c:?}")).unwrap_or_default();
            let filter = match t.intervention {
                Intervention::None => "",
                Intervention::Steered => " filter=steered",
                Intervention::Braked => " filter=braked",
                Intervention::Reversed => " filter=reversed",
            };
            let laps = t
                .racing
                .as_ref()
                .map(|r| format!(" laps={}", r.laps))
                .unwrap_or_default();
            let pass = if t.passed.is_some() { " passer=1" } else { "" };
            out!(
                "tick={} stamp_s={:.3} throttle={:.3} steering_rad={:.3} infer_us={:.1}{laps}{pass}{filter}{ev}{term}",
                t.index,
                t.stamp_s,
                t.control.throttle,
                t.control.steering_rad,
                t.infer_us
            );
        }
    }
    let wall_s = t0.elapsed().as_secs_f64();
    if let Some(w) = trace {
        w.finish()?;
    }
    drop(lp);
    let bagged = match bag.map(Arc::try_unwrap) {
        Some(Ok(b)) => {
            let s = b.finish()?;
            format!(" bag_messages={}", s.messages())
        }
        Some(Err(_)) => bail!("the bag is still in use"),
        None => String::new(),
    };
    let cpu = match (cpu0, cpu_time_s()) {
        (Some(c0), Some(c1)) if wall_s > 0.0 => format!("{:.1}", 100.0 * (c1 - c0) / wall_s),
        _ => "na".into(),
    };
    let rss = rss_mb().map_or("na".into(), |r| format!("{r:.1}"));
    let laps = racing.as_ref().map_or(String::new(), |r| {
        format!(
            " laps={} best_lap_s={}",
            r.laps,
            r.best_lap_s.map_or("na".into(), |b| format!("{b:.2}"))
        )
    });
    let passer = if passing {
        format!(" passer_ticks={passed}")
    } else {
        String::new()
    };
    out!(
        "summary ticks={k} events={events} terminations={terminations} filter_interventions={filtered}{passer}{laps} infer_us_p50={:.1} infer_us_p99={:.1} late_ticks={late} tick_us_p99={:.1} tick_us_max={:.1} wall_s={wall_s:.2} cpu_pct={cpu} rss_mb={rss}{}{bagged}",
        infer_us.quantile(0.5),
        infer_us.quantile(0.99),
        tick_us.quantile(0.99),
        tick_us.max(),
        stops.summary()
    );
    Ok(())
}

/// A --trace file, written beside its name and renamed when the run ends, so a file under
/// that name is always whole.
struct TraceWriter {
    part: PathBuf,
    path: PathBuf,
    out: std::io::BufWriter<std::fs::File>,
}

impl TraceWriter {
    fn create(path: &Path) -> Result<Self> {
        let mut part = path.as_os_str().to_owned();
        part.push(".part");
        let part = PathBuf::from(part);
        let f = std::fs::File::create(&part).with_context(|| format!("creating {}", part.display()))?;
        Ok(Self {
            part,
            path: path.to_path_buf(),
            out: std::io::BufWriter::new(f),
        })
    }

    fn row(&mut self, tick: u64, obs: &[f32], action: &[f32]) -> Result<()> {
        use std::io::Write;
        let row = TraceRow {
            tick,
            obs: obs.to_vec(),
            action: action.to_vec(),
        };
        serde_json::to_writer(&mut self.out, &row)?;
        self.out.write_all(b"\n")?;
        Ok(())
    }

    fn finish(self) -> Result<()> {
        let f = self.out.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&self.part, &self.path).with_context(|| format!("writing {}", self.path.display()))?;
        Ok(())
    }
}

/// Re-run the policy on a trace's observations; print the largest action difference.
fn check_trace(policy: &mut Policy, path: &Path, tolerance: f32) -> Result<()> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let (mut rows, mut max_diff, mut worst_tick) = (0u64, 0f32, 0u64);
    for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let r: TraceRow =
            serde_json::from_str(line).with_context(|| format!("{}:{}: not a trace row", path.display(), i + 1))?;
        let a = policy
            .act(&r.obs, true)
            .with_context(|| format!("{}:{}: tick {}", path.display(), i + 1, r.tick))?;
        if a.len() != r.action.len() {
            bail!(
                "{}:{}: the policy gives {} actions, the trace {}",
                path.display(),
                i + 1,
                a.len(),
                r.action.len()
            );
        }
        for (x, y) in a.iter().zip(&r.action) {
            let d = (x - y).abs();
            if d.is_nan() || d > max_diff {
                max_diff = if d.is_nan() { f32::INFINITY } else { d };
                worst_tick = r.tick;
            }
        }
        rows += 1;
    }
    if rows == 0 {
        bail!("{}: no trace rows", path.display());
    }
    out!("trace rows={rows} max_action_diff={max_diff:e} worst_tick={worst_tick} tolerance={tolerance:e}");
    if max_diff > tolerance {
        bail!("actions differ from the trace by {max_diff:e} (tick {worst_tick}), over the tolerance {tolerance:e}");
    }
    Ok(())
}

#[cfg(feature = "ros2")]
fn serve_sim(a: &Args, env: &str, env_cfg: &EnvConfig) -> Result<()> {
    use agvrl_deploy::hardware::SimRobot;
    let robot = SimRobot::new(env, env_cfg, ros2_config(a)?, a.seed, faults(a))?;
    eprintln!("serving {env} over ROS 2; Ctrl-C stops");
    serve(a, robot, false)
}

/// `--serve-sim racing-duel --opponent FILE|KIND ...`: car 0 served, the opponents in-process.
#[cfg(feature = "ros2")]
fn serve_race(a: &Args, id: &str) -> Result<()> {
    use agvrl_deploy::hardware::{Opponent, SimRobot};
    use agvrl_envs::drivers::{RacerKind, make_racer, parse_racer};
    if a.opponents.is_empty() {
        bail!(
            "--serve-sim {id}: give the opponents with --opponent FILE or --opponent KIND[@SCALE] (repeat for one each)"
        );
    }
    let cars = a.cars.unwrap_or(a.opponents.len() + 1);
    if !(2..=agvrl_sim::MAX_CARS).contains(&cars) {
        bail!(
            "--cars must be 2 to {} (the served car and its opponents)",
            agvrl_sim::MAX_CARS
        );
    }
    if a.opponents.len() > 1 && a.opponents.len() != cars - 1 {
        bail!(
            "{} opponents for {} opponent cars: give one for all, or one each",
            a.opponents.len(),
            cars - 1
        );
    }
    // A racer's name (a bad scale included) is a racer; anything else a policy file.
    let racer = |o: &str| -> Result<Option<(RacerKind, f64)>> {
        let kind = o.split_once('@').map_or(o, |(k, _)| k);
        match RacerKind::of(kind) {
            Ok(_) => Ok(Some(parse_racer(o).map_err(|e| match e {
                agvrl_envs::EnvError::Config(m) => anyhow::anyhow!("--opponent {m}"),
                e => e.into(),
            })?)),
            Err(_) => Ok(None),
        }
    };
    let racers = a.opponents.iter().map(|o| racer(o)).collect::<Result<Vec<_>>>()?;
    // The race's settings: --policy's if given (the served stack's), else the first policy
    // opponent's, else racing-duel's own.
    let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
    let first_policy = a
        .opponents
        .iter()
        .zip(&racers)
        .find(|(_, r)| r.is_none())
        .map(|(o, _)| Path::new(o));
    let mut env_cfg = match a.policy.as_deref().or(first_policy) {
        Some(p) => PolicySettings::resolve(None, Some(p), &sets)?.eval_env_config(),
        None => agvrl_run::RunConfig::from_toml_with(&format!("env = \"{id}\"\n"), "--opponent", &sets)?.env_config,
    };
    env_cfg.race = Some(agvrl_envs::RaceSettings {
        cars,
        ..env_cfg.race.unwrap_or_default()
    });
    let mut opponents = Vec::new();
    for k in 0..cars - 1 {
        let o = if a.opponents.len() == 1 { 0 } else { k };
        opponents.push(match racers[o] {
            Some((kind, scale)) => Opponent::Racer(
                make_racer(kind, &env_cfg, scale, None)
                    .map_err(|e| anyhow::anyhow!("--opponent {}: {e}", a.opponents[o]))?,
            ),
            None => Opponent::Policy(Box::new(
                PolicySettings::resolve(None, Some(Path::new(&a.opponents[o])), &[])?.load_policy()?,
            )),
        });
    }
    let robot = SimRobot::race(&env_cfg, ros2_config(a)?, a.seed, faults(a), opponents)?;
    eprintln!("serving car 0 of a {cars}-car race over ROS 2 under /car0; Ctrl-C stops");
    serve(a, robot, true)
}

#[cfg(feature = "ros2")]
fn faults(a: &Args) -> agvrl_deploy::hardware::Faults {
    agvrl_deploy::hardware::Faults {
        wire: a.faults.clone().unwrap_or_default(),
        ..Default::default()
    }
}

/// Run a served robot for --steps ticks and print its summary line.
#[cfg(feature = "ros2")]
fn serve(a: &Args, mut robot: agvrl_deploy::hardware::SimRobot, race: bool) -> Result<()> {
    use agvrl_deploy::hardware::Pace;
    let h = robot.handle();
    let pace = if a.realtime { Pace::Realtime } else { Pace::Lockstep };
    robot.run(pace, a.steps)?;
    let (s, w) = (h.stats(), robot.wire_stats());
    let race = match race {
        true => format!(
            " races={} wins={} car_contacts={} at_fault={} passes={}",
            s.races, s.wins, s.car_contacts, s.at_fault, s.passes
        ),
        false => String::new(),
    };
    out!(
        "summary ticks={} stamp_s={:.3} commands={} laps={} best_lap_s={} terminations={}{race} wire_offered={} wire_sent={} wire_lost={} wire_withheld={} wire_duplicated={} wire_held_back={}",
        s.ticks,
        s.stamp_s,
        s.commands,
        s.laps,
        s.best_lap_s.map_or("na".into(), |b| format!("{b:.2}")),
        s.terminations,
        w.offered,
        w.sent,
        w.lost,
        w.withheld,
        w.duplicated,
        w.held_back
    );
    Ok(())
}

#[cfg(not(feature = "ros2"))]
fn serve_sim(_: &Args, _: &str, _: &EnvConfig) -> Result<()> {
    bail!("--serve-sim: this agvrl-drive was built without the `ros2` feature")
}

#[cfg(not(feature = "ros2"))]
fn serve_race(_: &Args, _: &str) -> Result<()> {
    bail!("--serve-sim: this agvrl-drive was built without the `ros2` feature")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_cli_is_consistent_and_a_bad_vehicle_lists_the_valid_ones() {
        Args::command().debug_assert();
        let e = Args::try_parse_from(["agvrl-drive", "--vehicle", "car"])
            .err()
            .map(|e| e.to_string());
        let e = e.unwrap_or_default();
        assert!(e.contains("sim") && e.contains("ros2"), "{e}");
        let a = Args::try_parse_from(["agvrl-drive"]).unwrap();
        assert_eq!(a.vehicle, VehicleKind::Sim);
    }
}
