//! ROS 2 over DDS on loopback: the sim-backed robot in a thread, the drive loop here.

use crate::{kv, replay_check, scratch, shipped_policy};
use agvrl_deploy::hardware::config::{InvalidRay, Reliability};
use agvrl_deploy::hardware::{Faults, Pace, RobotHandle, Ros2Config, Ros2Vehicle, SimRobot};
use agvrl_deploy::{DeployError, DriveConfig, DriveLoop, Event};
use agvrl_envs::api::Control;
use agvrl_envs::{EnvConfig, make_task};
use agvrl_rl::Policy;
use ros2_client::QosProfile;
use std::sync::atomic::{AtomicU16, Ordering};

/// A DDS domain of its own for each test: tests in this process step through domains from
/// one base (drawn once, so two tests never meet), and the base differs between processes.
fn domain() -> u16 {
    static BASE: std::sync::OnceLock<u16> = std::sync::OnceLock::new();
    static NEXT: AtomicU16 = AtomicU16::new(0);
    let base = *BASE.get_or_init(|| {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .subsec_nanos();
        ((nanos ^ std::process::id().wrapping_mul(2_654_435_761)) % 150) as u16
    });
    1 + ((base + 7 * NEXT.fetch_add(1, Ordering::Relaxed)) % 230)
}

fn ros_cfg(invalid: InvalidRay) -> Ros2Config {
    let mut c = Ros2Config {
        domain_id: domain(),
        startup_timeout_s: 30.0,
        fresh_timeout_s: 0.2,
        ..Ros2Config::default()
    };
    c.qos.sensors.reliability = Reliability::Reliable;
    c.scan.invalid = invalid;
    c
}

type Loop = DriveLoop<Ros2Vehicle, Box<dyn agvrl_envs::task::Task>>;

/// Run `f` on the start of a drive loop (shipped policy, ROS 2 vehicle, both sides at
/// `pace`) against a robot with `faults`; the robot stops afterwards.
/// Held by the tests that time the car against the wall clock or render every frame, so
/// that on two cores they do not starve each other.
static HEAVY: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn heavy() -> std::sync::MutexGuard<'static, ()> {
    HEAVY.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn with_robot_at<R>(
    pace: Pace,
    cfg: Ros2Config,
    faults: Faults,
    f: impl FnOnce(Result<Loop, DeployError>, &RobotHandle) -> R,
) -> R {
    let policy = Policy::load(&shipped_policy("racing-oval-ppo")).unwrap();
    let _serial = (pace == Pace::Realtime).then(heavy);
    with_policy_robot_at(policy, &EnvConfig::default(), None, pace, cfg, faults, f)
}

/// As `with_robot_at`, with `policy` on env settings `env_cfg` (and the policy camera).
fn with_policy_robot_at<R>(
    policy: Policy,
    env_cfg: &EnvConfig,
    camera: Option<agvrl_sim::sensors::CameraConfig>,
    pace: Pace,
    cfg: Ros2Config,
    faults: Faults,
    f: impl FnOnce(Result<Loop, DeployError>, &RobotHandle) -> R,
) -> R {
    let mut robot = SimRobot::new("racing-oval", env_cfg, cfg.clone(), 0, faults).unwrap();
    let h = robot.handle();
    let th = std::thread::spawn(move || robot.run(pace, 0));
    let realtime = pace == Pace::Realtime;
    let v = Ros2Vehicle::new(cfg.clone(), !realtime, camera).unwrap();
    let task = make_task("racing-oval", env_cfg, cfg.drive.steering_limit_rad).unwrap();
    let drive = DriveConfig {
        realtime,
        ..DriveConfig::default()
    };
    let r = f(DriveLoop::new(v, task, policy, drive, 0), &h);
    h.stop();
    th.join().unwrap().unwrap();
    r
}

/// Run `f` on a lockstep drive loop against a robot with `faults`.
fn with_robot<R>(cfg: Ros2Config, faults: Faults, f: impl FnOnce(&mut Loop, &RobotHandle) -> R) -> R {
    with_robot_at(Pace::Lockstep, cfg, faults, |lp, h| f(&mut lp.unwrap(), h))
}

#[test]
fn the_shipped_policy_laps_the_oval_over_dds_without_collision() {
    let ticks = 1200; // 40 s of simulated time; a lap takes about 31 s
    let stats = with_robot(ros_cfg(InvalidRay::Stop), Faults::default(), |lp, h| {
        for k in 0..ticks {
            let t = lp.tick().unwrap();
            assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
        }
        // The robot applies the last command once it arrives.
        let t0 = std::time::Instant::now();
        while h.stats().commands < ticks && t0.elapsed().as_secs() < 10 {
            std::thread::yield_now();
        }
        h.stats()
    });
    assert_eq!(stats.commands, ticks, "every command arrived once: {stats:?}");
    assert_eq!(stats.ticks, ticks, "one control period per command: {stats:?}");
    assert!(stats.laps >= 1, "no full lap: {stats:?}");
    assert_eq!(stats.terminations, 0, "collision or too close: {stats:?}");
}

#[test]
fn a_drive_reader_of_another_type_is_no_reader_and_startup_names_it() {
    #[derive(serde::Deserialize)]
    struct Twist {
        _linear: [f64; 3],
        _angular: [f64; 3],
    }
    let e = refusal_with_only_this_drive_reader::<Twist>(("geometry_msgs", "Twist"), QosProfile::default());
    assert!(e.contains("geometry_msgs::msg::dds_::Twist_"), "{e}");
    assert!(e.contains("ackermann_msgs::msg::dds_::AckermannDriveStamped_"), "{e}");
}

#[test]
fn an_ackermann_reader_asking_more_than_the_writer_offers_is_no_reader() {
    // Transient-local durability: the volatile drive writer can never match it.
    let q = QosProfile::default().durability(ros2_client::qos::Durability::TransientLocal);
    let e = refusal_with_only_this_drive_reader::<agvrl_deploy::hardware::msg::AckermannDriveStamped>(
        ("ackermann_msgs", "AckermannDriveStamped"),
        q,
    );
    assert!(e.contains("incompatible QoS: Durability"), "{e}");
}

/// Startup's error when the car's only reader on the drive topic has type `ty` and QoS `q`.
fn refusal_with_only_this_drive_reader<M: serde::de::DeserializeOwned + 'static>(
    ty: (&str, &str),
    q: QosProfile,
) -> String {
    use ros2_client::{Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions};
    let mut cfg = ros_cfg(InvalidRay::Stop);
    cfg.startup_timeout_s = 3.0;
    // A car with sensors but no drive reader of its own.
    let faults = Faults {
        drive_reader_from: u64::MAX,
        ..Faults::default()
    };
    let ctx = Context::with_options(ContextOptions::new().domain_id(cfg.domain_id)).unwrap();
    let mut node = ctx
        .new_node(
            NodeName::new("/", "other_car").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let topic = node
        .create_topic(
            &Name::parse(&cfg.topics.drive).unwrap(),
            MessageTypeName::new(ty.0, ty.1),
            &q,
        )
        .unwrap();
    let _reader = node.create_subscription::<M>(&topic, Some(q)).unwrap();
    with_robot_at(Pace::Realtime, cfg, faults, |lp, _| match lp {
        Ok(_) => panic!("started with nobody able to read the commands"),
        Err(e) => e.to_string(),
    })
}

#[test]
fn muted_scans_stop_the_car_over_dds_within_two_periods() {
    let faults = Faults {
        mute_scan_from: 30,
        ..Faults::default()
    };
    with_robot(ros_cfg(InvalidRay::Stop), faults, |lp, h| {
        let mut first_stop = None;
        for k in 0..40u64 {
            let t = lp.tick().unwrap();
            match &t.event {
                None => assert!(k < 32, "tick {k} drove on a scan {} periods old", k - 29),
                Some(Event::Stale { .. }) => {
                    assert!(k >= 30, "tick {k} stopped while scans were fresh");
                    first_stop.get_or_insert(k);
                    assert_eq!(t.control, Control::default());
                }
                Some(e) => panic!("tick {k}: unexpected event {e:?}"),
            }
        }
        // The last scan is the tick-29 one: two periods later it is too old.
        assert_eq!(first_stop, Some(32));
        let t0 = std::time::Instant::now();
        while h.stats().commands < 40 && t0.elapsed().as_secs() < 10 {
            std::thread::yield_now();
        }
        let s = h.stats();
        assert_eq!(s.commands, 40);
        assert_eq!(s.last_command, Control::default(), "the robot got zero throttle");
    });
}

#[test]
fn nan_ranges_over_dds_never_reach_the_policy() {
    let faults = Faults {
        nan_ticks: 5..8,
        nan_rays: 10..13,
        ..Faults::default()
    };
    // One scan ray per policy ray: a NaN ray has nothing valid to fall back on -> stop.
    with_robot(ros_cfg(InvalidRay::Stop), faults.clone(), |lp, _| {
        for k in 0..12u64 {
            let t = lp.tick().unwrap();
            if (5..8).contains(&k) {
                assert_eq!(t.event, Some(Event::NotFinite { sensor: "scan" }), "tick {k}");
                assert_eq!(t.control, Control::default());
            } else {
                assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
            }
        }
    });
    // Mapped to "no return" instead: the loop drives on, with finite observations only.
    with_robot(ros_cfg(InvalidRay::RangeMax), faults, |lp, _| {
        for k in 0..12u64 {
            let t = lp.tick().unwrap();
            assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
        }
    });
}

/// `agvrl-drive --serve-sim racing-oval` and `agvrl-drive --vehicle ros2 ARGS` with
/// `policy` for `ticks` lockstep ticks on a domain of their own (sensors reliable, as the
/// library tests' `ros_cfg`): (drive ok, drive stdout + stderr, robot stdout). A robot still
/// waiting 30 s after the drive ended is killed, so a lost command fails instead of hanging.
fn serve_and_drive(policy: &std::path::Path, ticks: u64, args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let dir = scratch("car");
    let car = dir.path().join("car.toml");
    std::fs::write(&car, "[qos.sensors]\nreliability = \"reliable\"\ndepth = 1\n").unwrap();
    let (d, n) = (domain().to_string(), ticks.to_string());
    let bin = env!("CARGO_BIN_EXE_agvrl-drive");
    let mut robot = std::process::Command::new(bin)
        .arg("--policy")
        .arg(policy)
        .args([
            "--serve-sim",
            "racing-oval",
            "--steps",
            &n,
            "--domain-id",
            &d,
            "--config",
        ])
        .arg(&car)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let drive = std::process::Command::new(bin)
        .arg("--policy")
        .arg(policy)
        .args([
            "--vehicle",
            "ros2",
            "--steps",
            &n,
            "--domain-id",
            &d,
            "--quiet",
            "--config",
        ])
        .arg(&car)
        .args(args)
        .output()
        .unwrap();
    let t0 = std::time::Instant::now();
    while robot.try_wait().unwrap().is_none() && t0.elapsed().as_secs() < 30 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let hung = robot.try_wait().unwrap().is_none();
    let _ = robot.kill();
    let robot = robot.wait_with_output().unwrap();
    let out = format!(
        "{}{}",
        String::from_utf8_lossy(&drive.stdout),
        String::from_utf8_lossy(&drive.stderr)
    );
    (
        drive.status.success(),
        out,
        format!(
            "{}{}",
            if hung {
                "robot killed, still waiting 30 s after the drive ended\n"
            } else {
                ""
            },
            String::from_utf8_lossy(&robot.stdout)
        ),
    )
}

/// The camera-only policy over DDS, both sides the `agvrl-drive` binary: the robot
/// publishes its camera's depth as a 32FC1 Image, the drive decodes it to the policy's
/// frame; a lap, no collision, no watchdog event.
#[test]
fn the_camera_policy_laps_the_oval_over_dds_from_depth_images() {
    // 40 s; a lap takes about 31 s.
    let _serial = heavy();
    let (ok, out, rout) = serve_and_drive(&shipped_policy("racing-oval-camera"), 1200, &[]);
    assert!(ok, "{out}");
    assert!(out.contains("summary ticks=1200 events=0 terminations=0 "), "{out}");
    assert!(
        rout.contains("summary ticks=1200 ") && rout.contains(" commands=1200 "),
        "{rout}"
    );
    assert!(rout.contains(" terminations=0") && !rout.contains(" laps=0 "), "{rout}");
}

/// A drive over DDS recorded on the drive's side replays bit for bit: the same frames
/// (every message as received, each tick's own), the same watchdog clock, the same actions.
#[test]
fn a_ros2_drive_replays_from_its_bag_to_the_same_bits() {
    let dir = scratch("ros2bag");
    let bag = dir.path().join("car");
    let policy = shipped_policy("racing-oval-camera");
    let (ok, out, _) = serve_and_drive(&policy, 300, &["--record".as_ref(), bag.as_os_str()]);
    assert!(ok, "{out}");
    let (ok, out, err) = replay_check(&policy, &bag);
    assert!(ok, "{out}{err}");
    assert_eq!(kv(&out, "ticks"), 300.0, "{out}");
    assert_eq!(kv(&out, "action_diff_max"), 0.0, "{out}");
}

/// A subscription on `name` of ROS type `ty` in `domain`, keeping everything received
/// (latched: transient local, as `/tf_static` is offered).
fn listen<M: serde::de::DeserializeOwned + 'static>(
    node: &mut ros2_client::Node,
    name: &str,
    ty: (&str, &str),
    latched: bool,
) -> ros2_client::Subscription<M> {
    use ros2_client::qos::{Durability, History, WhenFull};
    let q = ros2_client::QosProfile::subscription_default()
        .durability(if latched {
            Durability::TransientLocal
        } else {
            Durability::Volatile
        })
        .history(History::KeepLast { depth: 5000 })
        .reliability_reliable(WhenFull::DEFAULT);
    let n = ros2_client::Name::parse(name).unwrap();
    let t = node
        .create_topic(&n, ros2_client::MessageTypeName::new(ty.0, ty.1), &q)
        .unwrap();
    node.create_subscription(&t, Some(q)).unwrap()
}

/// Every message waiting on `s` (none may fail to decode).
fn take_all<M: serde::de::DeserializeOwned + 'static>(s: &ros2_client::Subscription<M>) -> Vec<M> {
    let mut out = vec![];
    while let Some((m, _)) = s.take().unwrap() {
        out.push(m);
    }
    out
}

/// A race of `cars` on the oval, rows `grid_gap_m` apart, each race 1,000 ticks.
fn served_race(cars: usize, grid_gap_m: f32) -> EnvConfig {
    EnvConfig {
        race: Some(agvrl_envs::RaceSettings {
            cars,
            grid_gap_m,
            ..Default::default()
        }),
        max_steps: 1000,
        ..EnvConfig::default()
    }
}

/// A node of its own on `cfg`'s domain, as a team's tools would run (its context beside it).
fn listener_node(cfg: &Ros2Config, name: &str) -> (ros2_client::Context, ros2_client::Node) {
    let ctx = ros2_client::Context::with_options(ros2_client::ContextOptions::new().domain_id(cfg.domain_id)).unwrap();
    let node = ctx
        .new_node(
            ros2_client::NodeName::new("/", name).unwrap(),
            ros2_client::NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    (ctx, node)
}

/// Car 0 of a served race driven over DDS by the shipped oval policy for `ticks` ticks, none
/// with a watchdog event; then the robot gets (within 10 s) every command and is stopped.
fn drive_car0(cfg: &Ros2Config, env_cfg: &EnvConfig, ticks: u64, h: &RobotHandle) {
    let car0 = Ros2Config {
        topics: cfg.topics.namespaced("car0"),
        ..cfg.clone()
    };
    let v = Ros2Vehicle::new(car0, true, None).unwrap();
    let task = make_task("racing-oval", env_cfg, cfg.drive.steering_limit_rad).unwrap();
    let policy = Policy::load(&shipped_policy("racing-oval-ppo")).unwrap();
    let mut lp = DriveLoop::new(v, task, policy, DriveConfig::default(), 0).unwrap();
    for k in 0..ticks {
        let t = lp.tick().unwrap();
        assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
    }
    drop(lp);
    let t0 = std::time::Instant::now();
    while h.stats().commands < ticks && t0.elapsed().as_secs() < 10 {
        std::thread::yield_now();
    }
    h.stop();
}

/// A race served over DDS (`SimRobot::race`): car 0 driven by the shipped policy through
/// `/car0/...`, car 1 by the same policy in-process. The served car gets one period per
/// command and laps; car 1's sensors are on `/car1/...` in its own frames; `/tf` moves both
/// cars and `/tf_static` hangs each car's odom frame on `map` and its LiDAR on its base.
#[test]
fn a_served_race_drives_car0_over_dds_and_names_every_car_apart() {
    use agvrl_deploy::hardware::msg;
    let ticks = 1200; // 40 s; a lap of the oval takes about 31 s
    let policy = || Policy::load(&shipped_policy("racing-oval-ppo")).unwrap();
    let mut cfg = ros_cfg(InvalidRay::Stop);
    // Writers that keep every set: lockstep outruns this listener, whose lost samples are
    // then resent rather than overwritten.
    cfg.qos.sensors.depth = 4096;
    // Rows 2 m apart: this policy, trained alone, rams a car 0.8 m ahead. A race is
    // 1,000 ticks (a lap and a bit), so the second starts on the grid mid-drive.
    let env_cfg = served_race(2, 2.0);
    let (_ctx, mut node) = listener_node(&cfg, "race_listener");
    let scan1 = listen::<msg::LaserScan>(&mut node, "/car1/scan", ("sensor_msgs", "LaserScan"), false);
    let tf = listen::<msg::TFMessage>(&mut node, "/tf", ("tf2_msgs", "TFMessage"), false);
    let tf_static = listen::<msg::TFMessage>(&mut node, "/tf_static", ("tf2_msgs", "TFMessage"), true);
    let opponents = vec![agvrl_deploy::hardware::Opponent::Policy(Box::new(policy()))];
    let mut robot = SimRobot::race(&env_cfg, cfg.clone(), 0, Faults::default(), opponents).unwrap();
    let h = robot.handle();
    let th = std::thread::spawn(move || {
        robot.run(Pace::Lockstep, 0).unwrap();
        robot.blocked_messages()
    });
    // A reader of its own, as a team's tools would be: it takes what comes as it comes.
    let listening = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let on = listening.clone();
    let listener = std::thread::spawn(move || {
        let (mut scans, mut moves, mut mounts) = (vec![], vec![], vec![]);
        let mut quiet = std::time::Instant::now();
        // Until stopped, then until nothing more comes for a second.
        while on.load(Ordering::Relaxed) || quiet.elapsed().as_secs() < 1 {
            let n = scans.len() + moves.len();
            scans.extend(take_all(&scan1));
            moves.extend(take_all(&tf));
            mounts.extend(take_all(&tf_static));
            if scans.len() + moves.len() > n {
                quiet = std::time::Instant::now();
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        (scans, moves, mounts)
    });
    drive_car0(&cfg, &env_cfg, ticks, &h);
    let blocked = th.join().unwrap();
    let stats = h.stats();
    listening.store(false, Ordering::Relaxed);
    let (scans, moves, mounts) = listener.join().unwrap();
    assert_eq!(blocked, 0, "sensor messages dropped by the robot");
    assert_eq!(stats.commands, ticks, "every command arrived once: {stats:?}");
    assert_eq!(stats.ticks, ticks, "one control period per command: {stats:?}");
    assert!(stats.laps >= 1, "the served car did not lap: {stats:?}");
    assert_eq!(
        (stats.races, stats.terminations, stats.car_contacts),
        (1, 0, 0),
        "{stats:?}"
    );
    assert!(scans.len() > 1000, "{} scans of car 1", scans.len());
    assert!(scans.iter().all(|m| m.header.frame_id == "car1/laser"));
    let stamps: Vec<f64> = scans.iter().map(|m| m.header.stamp.as_secs()).collect();
    assert!(
        stamps.windows(2).all(|w| w[1] >= w[0]),
        "stamps go on rising over the new race"
    );
    let xs = |child: &str| -> Vec<f64> {
        moves
            .iter()
            .flat_map(|m| &m.transforms)
            .filter(|t| t.child_frame_id == child)
            .map(|t| {
                assert_eq!(t.header.frame_id, child.replace("base_link", "odom"));
                t.transform.translation.x
            })
            .collect()
    };
    for car in ["car0/base_link", "car1/base_link"] {
        let x = xs(car);
        let span =
            x.iter().copied().fold(f64::NEG_INFINITY, f64::max) - x.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(
            x.len() > 100 && span > 2.0,
            "{car}: {} transforms over {span} m",
            x.len()
        );
    }
    let mounts: Vec<(String, String)> = mounts
        .iter()
        .flat_map(|m| &m.transforms)
        .map(|t| (t.header.frame_id.clone(), t.child_frame_id.clone()))
        .collect();
    for i in 0..2 {
        let pair = |a: String, b: String| (a, b);
        assert!(
            mounts.contains(&pair("map".into(), format!("car{i}/odom"))),
            "{mounts:?}"
        );
        assert!(
            mounts.contains(&pair(format!("car{i}/base_link"), format!("car{i}/laser"))),
            "{mounts:?}"
        );
    }
}

/// A served race against classical racers: car 0 driven over DDS by the shipped policy,
/// pure pursuit and follow-the-gap (each at 0.75 of its speed) drive cars 1 and 2
/// in-process, and each racer's own odometry on `/carN/odom` shows it driving.
#[test]
fn a_served_race_runs_classical_racers_as_opponents() {
    use agvrl_deploy::hardware::{Opponent, msg};
    use agvrl_envs::drivers::{RacerKind, make_racer};
    let ticks = 300; // 10 s: a racer at 0.75 of 1.79 m/s covers up to 13 m
    let mut cfg = ros_cfg(InvalidRay::Stop);
    cfg.qos.sensors.depth = 4096;
    // Rows 3 m apart: closer, follow-the-gap meets pure pursuit in the first turn.
    let env_cfg = served_race(3, 3.0);
    let (_ctx, mut node) = listener_node(&cfg, "racers_listener");
    let odom: Vec<_> = (1..3)
        .map(|i| listen::<msg::Odometry>(&mut node, &format!("/car{i}/odom"), ("nav_msgs", "Odometry"), false))
        .collect();
    let opponents = [RacerKind::PurePursuit, RacerKind::FollowTheGap]
        .into_iter()
        .map(|k| Opponent::Racer(make_racer(k, &env_cfg, 0.75, None).unwrap()))
        .collect();
    let mut robot = SimRobot::race(&env_cfg, cfg.clone(), 0, Faults::default(), opponents).unwrap();
    let h = robot.handle();
    let th = std::thread::spawn(move || robot.run(Pace::Lockstep, 0).unwrap());
    let listening = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let on = listening.clone();
    let listener = std::thread::spawn(move || {
        let mut seen: Vec<Vec<msg::Odometry>> = vec![vec![], vec![]];
        let mut quiet = std::time::Instant::now();
        while on.load(Ordering::Relaxed) || quiet.elapsed().as_secs() < 1 {
            let n: usize = seen.iter().map(Vec::len).sum();
            for (s, o) in seen.iter_mut().zip(&odom) {
                s.extend(take_all(o));
            }
            if seen.iter().map(Vec::len).sum::<usize>() > n {
                quiet = std::time::Instant::now();
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
        seen
    });
    drive_car0(&cfg, &env_cfg, ticks, &h);
    th.join().unwrap();
    listening.store(false, Ordering::Relaxed);
    let seen = listener.join().unwrap();
    let stats = h.stats();
    assert_eq!(stats.commands, ticks, "{stats:?}");
    assert_eq!((stats.terminations, stats.car_contacts), (0, 0), "{stats:?}");
    for (k, s) in seen.iter().enumerate() {
        let p = |m: &msg::Odometry| (m.pose.pose.position.x, m.pose.pose.position.y);
        let path: f64 = s
            .windows(2)
            .map(|w| (p(&w[1]).0 - p(&w[0]).0).hypot(p(&w[1]).1 - p(&w[0]).1))
            .sum();
        assert!(
            s.len() > 200 && path > 6.0,
            "car {}: {} odometry messages, {path:.1} m driven",
            k + 1,
            s.len()
        );
    }
}

/// A served race on the sweepers: car 0, driven over DDS by pure pursuit at full speed along
/// the centre line, starts 2 m behind pure pursuit at half speed. With the drive's passer
/// (`race.passer = "scan"`, from the car's odometry and scan) it passes once without a contact;
/// without it, the same racer runs into the car ahead.
#[test]
fn a_drives_passer_takes_its_car_round_a_slower_one_over_dds() {
    use agvrl_deploy::DrivePasser;
    use agvrl_deploy::hardware::Opponent;
    use agvrl_deploy::run_loop::Brain;
    use agvrl_envs::drivers::{RacerKind, make_racer};
    use agvrl_envs::passer::PasserSource;
    let ticks = 420; // 14 s, within one race of 450 ticks
    let run = |passer: PasserSource| {
        let cfg = ros_cfg(InvalidRay::Stop);
        let sweepers = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/sweepers.yaml");
        let env_cfg = EnvConfig {
            track: Some(agvrl_envs::TrackSetting::Path(sweepers)),
            race: Some(agvrl_envs::RaceSettings {
                cars: 2,
                start_behind_share: 1.0,
                passer,
                ..Default::default()
            }),
            max_steps: 450,
            racing: Some(agvrl_envs::task::RacingRulesSetting {
                end_below_m: Some(0.0),
                ..Default::default()
            }),
            ..EnvConfig::default()
        };
        let slow = make_racer(RacerKind::PurePursuit, &env_cfg, 0.5, None).unwrap();
        let mut robot =
            SimRobot::race(&env_cfg, cfg.clone(), 0, Faults::default(), vec![Opponent::Racer(slow)]).unwrap();
        let h = robot.handle();
        let th = std::thread::spawn(move || robot.run(Pace::Lockstep, 0).unwrap());
        let car0 = Ros2Config {
            topics: cfg.topics.namespaced("car0"),
            ..cfg.clone()
        };
        let v = Ros2Vehicle::new(car0, true, None).unwrap();
        let task = make_task("racing-oval", &env_cfg, cfg.drive.steering_limit_rad).unwrap();
        // A car has no map: its pure pursuit follows the track's centre line as a CSV.
        let track = env_cfg.track.as_ref().unwrap().load().unwrap();
        let csv: String = track
            .centreline
            .iter()
            .map(|p| format!("{}, {}\n", p[0], p[1]))
            .collect();
        let fast = make_racer(RacerKind::PurePursuit, &env_cfg, 1.0, Some(&csv)).unwrap();
        let brain = Brain::Racer(fast, env_cfg.action_mapping);
        let drive_passer = DrivePasser::of_env("racing-oval", &env_cfg).unwrap();
        assert_eq!(drive_passer.is_some(), passer == PasserSource::Scan);
        let mut lp = DriveLoop::with_brain(v, task, brain, DriveConfig::default(), 0)
            .unwrap()
            .with_passer(drive_passer);
        let mut passing = 0;
        for k in 0..ticks {
            let t = lp.tick().unwrap();
            assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
            passing += u32::from(t.passed.is_some());
        }
        drop(lp);
        let t0 = std::time::Instant::now();
        while h.stats().commands < ticks && t0.elapsed().as_secs() < 10 {
            std::thread::yield_now();
        }
        h.stop();
        th.join().unwrap();
        (h.stats(), passing)
    };
    let (plain, passing) = run(PasserSource::Off);
    assert_eq!(passing, 0);
    assert!(plain.car_contacts >= 1 && plain.at_fault >= 1, "{plain:?}");
    let (s, passing) = run(PasserSource::Scan);
    assert_eq!((s.car_contacts, s.passes, s.terminations), (0, 1, 0), "{s:?}");
    assert!(passing > 10, "the passer drove {passing} ticks");
}

#[test]
fn a_bad_car_toml_is_one_clear_line() {
    let e = Ros2Config::from_toml("[scan]\nn_ray = 3\n").unwrap_err();
    assert!(e.contains("n_ray") && !e.contains('\n'), "{e}");
    let e = Ros2Config::from_toml("[scan]\nangle_min_rad = 1.0\nangle_max_rad = -1.0\n").unwrap_err();
    assert!(e.contains("angle_min_rad"), "{e}");
    let example = include_str!("../car.example.toml");
    assert_eq!(Ros2Config::from_toml(example).unwrap(), Ros2Config::default());
}
