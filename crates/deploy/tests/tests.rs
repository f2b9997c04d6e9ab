//! agvrl-deploy: the control loop's watchdog and policy checks.

use agvrl_deploy::{DeployError, DriveConfig, DriveLoop, Event};
use agvrl_envs::api::{Control, EnvError, MapInfo, SensorFrame, Vehicle};
use agvrl_envs::{EnvConfig, VecEnv, make, make_task, make_vehicle};
use agvrl_rl::{Policy, Ppo, PpoConfig, default_device};

/// A shipped policy of assets/policies.
fn shipped_policy(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../assets/policies/{name}.agvrl"))
}

/// A scratch directory, removed when the test ends, passed or failed.
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("agvrl-{name}-"))
        .tempdir()
        .unwrap()
}

/// An untrained policy with the spaces of `id`.
fn policy_for(id: &str) -> Policy {
    let env = make(id, &EnvConfig::default()).unwrap();
    let dev = default_device();
    Ppo::new(PpoConfig::default(), VecEnv::new(vec![env], 1).unwrap(), &dev, 0)
        .unwrap()
        .policy(&dev)
}

/// A vehicle whose sensors freeze (stale frames) between two tick counts, or report NaN ranges.
struct Faulty {
    inner: Box<dyn Vehicle>,
    ticks: u64,
    freeze: std::ops::Range<u64>,
    nan: std::ops::Range<u64>,
    last: Option<SensorFrame>,
}

impl Vehicle for Faulty {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        self.inner.reset(seed)
    }
    fn actuate(&mut self, c: Control) -> Result<(), EnvError> {
        self.ticks += 1;
        self.inner.actuate(c)
    }
    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        let mut f = self.inner.sense()?;
        if self.freeze.contains(&self.ticks) {
            return Ok(self.last.clone().unwrap_or(f));
        }
        if self.nan.contains(&self.ticks)
            && let Some(s) = f.scan.as_mut()
        {
            s.ranges[10] = f32::NAN;
        }
        self.last = Some(f.clone());
        Ok(f)
    }
    fn control_period_s(&self) -> f64 {
        self.inner.control_period_s()
    }
    fn steering_limit_rad(&self) -> f64 {
        self.inner.steering_limit_rad()
    }
    fn map(&self) -> Option<&MapInfo> {
        self.inner.map()
    }
}

fn faulty_loop(
    freeze: std::ops::Range<u64>,
    nan: std::ops::Range<u64>,
) -> DriveLoop<Faulty, Box<dyn agvrl_envs::task::Task>> {
    let cfg = EnvConfig::default();
    let inner = make_vehicle("racing-oval", &cfg).unwrap();
    let task = make_task("racing-oval", &cfg, inner.steering_limit_rad()).unwrap();
    let v = Faulty {
        inner,
        ticks: 0,
        freeze,
        nan,
        last: None,
    };
    DriveLoop::new(v, task, policy_for("racing-oval"), DriveConfig::default(), 0).unwrap()
}

#[test]
fn stale_scans_stop_the_car_within_two_periods_and_driving_resumes() {
    // Sensors freeze from tick 10 to 19: the frame sensed at tick 10 is the tick-9 frame.
    let mut lp = faulty_loop(10..20, 0..0);
    let mut first_stop = None;
    for k in 0..30u64 {
        let t = lp.tick().unwrap();
        match &t.event {
            Some(Event::Stale { age_s }) => {
                assert!(k >= 10, "tick {k} stopped on fresh data");
                first_stop.get_or_insert(k);
                assert_eq!(
                    t.control,
                    Control::default(),
                    "a safe stop is zero throttle, straight wheels"
                );
                assert!(*age_s > 2.0 / 30.0);
            }
            Some(e) => panic!("unexpected event {e:?}"),
            None => assert!(!(12..20).contains(&k), "tick {k} drove on stale data"),
        }
    }
    let s = first_stop.expect("the watchdog never fired");
    // The data goes stale at tick 10; two periods later at the latest the car is stopped.
    assert!(s <= 12, "first safe stop at tick {s}");
    let t = lp.tick().unwrap();
    assert!(t.event.is_none(), "fresh data again: driving resumes");
}

#[test]
fn nan_ranges_never_reach_the_policy() {
    let mut lp = faulty_loop(0..0, 5..8);
    for k in 0..12u64 {
        let t = lp.tick().unwrap();
        if (5..8).contains(&k) {
            assert_eq!(t.event, Some(Event::NotFinite { sensor: "scan" }), "tick {k}");
            assert_eq!(t.control, Control::default());
        } else {
            assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
        }
    }
}

#[test]
fn a_policy_for_another_task_refuses_to_start() {
    let cfg = EnvConfig::default();
    let v = make_vehicle("racing-oval", &cfg).unwrap();
    let task = make_task("racing-oval", &cfg, v.steering_limit_rad()).unwrap();
    match DriveLoop::new(v, task, policy_for("pendulum"), DriveConfig::default(), 0) {
        Err(DeployError::Mismatch(m)) => assert!(m.to_string().contains("observation"), "{m}"),
        Err(e) => panic!("wrong error {e}"),
        Ok(_) => panic!("a pendulum policy must not drive a car"),
    }
}

/// ROS 2 over DDS on loopback: the sim-backed robot in a thread, the drive loop here.
#[cfg(feature = "ros2")]
mod ros2_loopback {
    use super::*;
    use agvrl_deploy::hardware::config::{InvalidRay, Reliability};
    use agvrl_deploy::hardware::{Faults, Pace, RobotHandle, Ros2Config, Ros2Vehicle, SimRobot};
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

    use ros2_client::QosProfile;

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
        let env_cfg = EnvConfig {
            race: Some(agvrl_envs::RaceSettings {
                cars: 2,
                grid_gap_m: 2.0,
                ..Default::default()
            }),
            max_steps: 1000,
            ..EnvConfig::default()
        };
        let ctx =
            ros2_client::Context::with_options(ros2_client::ContextOptions::new().domain_id(cfg.domain_id)).unwrap();
        let mut node = ctx
            .new_node(
                ros2_client::NodeName::new("/", "race_listener").unwrap(),
                ros2_client::NodeOptions::new().enable_rosout(false),
            )
            .unwrap();
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
        let car0 = Ros2Config {
            topics: cfg.topics.namespaced("car0"),
            ..cfg.clone()
        };
        let v = Ros2Vehicle::new(car0, true, None).unwrap();
        let task = make_task("racing-oval", &env_cfg, cfg.drive.steering_limit_rad).unwrap();
        let mut lp = DriveLoop::new(v, task, policy(), DriveConfig::default(), 0).unwrap();
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
        let env_cfg = EnvConfig {
            race: Some(agvrl_envs::RaceSettings {
                cars: 3,
                // Rows 3 m apart: closer, follow-the-gap meets pure pursuit in the first turn.
                grid_gap_m: 3.0,
                ..Default::default()
            }),
            max_steps: 1000,
            ..EnvConfig::default()
        };
        let ctx =
            ros2_client::Context::with_options(ros2_client::ContextOptions::new().domain_id(cfg.domain_id)).unwrap();
        let mut node = ctx
            .new_node(
                ros2_client::NodeName::new("/", "racers_listener").unwrap(),
                ros2_client::NodeOptions::new().enable_rosout(false),
            )
            .unwrap();
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
        let car0 = Ros2Config {
            topics: cfg.topics.namespaced("car0"),
            ..cfg.clone()
        };
        let v = Ros2Vehicle::new(car0, true, None).unwrap();
        let task = make_task("racing-oval", &env_cfg, cfg.drive.steering_limit_rad).unwrap();
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

    #[test]
    fn a_bad_car_toml_is_one_clear_line() {
        let e = Ros2Config::from_toml("[scan]\nn_ray = 3\n").unwrap_err();
        assert!(e.contains("n_ray") && !e.contains('\n'), "{e}");
        let e = Ros2Config::from_toml("[scan]\nangle_min_rad = 1.0\nangle_max_rad = -1.0\n").unwrap_err();
        assert!(e.contains("angle_min_rad"), "{e}");
        let example = include_str!("../car.example.toml");
        assert_eq!(Ros2Config::from_toml(example).unwrap(), Ros2Config::default());
    }
}

/// The deploy binary's dependency tree (normal edges, default features): no viewer, no
/// TLS / OpenSSL (a static link needs none), no zenoh, and inference only (no autodiff, no
/// second CPU backend). Cheaper than a static build in CI.
#[test]
fn deploy_links_no_rerun_openssl_zenoh_or_autodiff() {
    let cargo = option_env!("CARGO").unwrap_or("cargo");
    let out = std::process::Command::new(cargo)
        .args([
            "tree",
            "-p",
            "agvrl-deploy",
            "-e",
            "normal",
            "--prefix",
            "none",
            "--offline",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let tree = String::from_utf8(out.stdout).unwrap();
    let names: Vec<&str> = tree.lines().filter_map(|l| l.split_whitespace().next()).collect();
    assert!(names.contains(&"ros2-client"), "the ros2 feature is on by default");
    for bad in [
        "rerun",
        "openssl",
        "openssl-sys",
        "native-tls",
        "zenoh",
        "ring",
        "plotters",
        "burn-autodiff",
        "burn-optim",
        "burn-ndarray",
    ] {
        assert!(!names.contains(&bad), "agvrl-deploy depends on {bad}");
    }
}

/// `--trace` records what the policy saw and did; `--check-trace` reproduces it exactly and
/// rejects a trace whose action was changed by more than the tolerance.
#[test]
fn a_trace_replays_to_the_same_actions_and_a_changed_action_is_caught() {
    let dir = scratch("trace");
    let trace = dir.path().join("run.jsonl");
    let policy = shipped_policy("racing-oval-ppo");
    let drive = |args: &[&std::ffi::OsStr]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
            .arg("--policy")
            .arg(&policy)
            .args(args)
            .output()
            .unwrap()
    };
    let o = drive(&[
        "--steps".as_ref(),
        "60".as_ref(),
        "--quiet".as_ref(),
        "--trace".as_ref(),
        trace.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&trace).unwrap();
    assert_eq!(text.lines().count(), 60);
    assert!(!dir.path().join("run.jsonl.part").exists());

    let o = drive(&[
        "--check-trace".as_ref(),
        trace.as_os_str(),
        "--tolerance".as_ref(),
        "0".as_ref(),
    ]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && out.contains("rows=60 max_action_diff=0e0"),
        "{out}"
    );

    // Tick 30's throttle moved by 1e-3.
    let mut rows: Vec<serde_json::Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let a = rows[29]["action"][0].as_f64().unwrap();
    rows[29]["action"][0] = serde_json::json!(a + 1e-3);
    let bad = dir.path().join("bad.jsonl");
    std::fs::write(&bad, rows.iter().map(|r| format!("{r}\n")).collect::<String>()).unwrap();
    let o = drive(&["--check-trace".as_ref(), bad.as_os_str()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("(tick 30)"), "{err}");
}

/// The shipped search policy, with its settings file (the safety filter on), drives every
/// search scene in `agvrl-drive` on the simulated car without a termination or a watchdog stop.
#[test]
fn the_shipped_search_policy_drives_every_search_scene_in_agvrl_drive() {
    let policy = shipped_policy("search");
    for env in [
        "search-outdoor-20",
        "search-urban-20",
        "search-outdoor-50",
        "search-urban-50",
    ] {
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
            .arg("--policy")
            .arg(&policy)
            .args(["--env", env, "--steps", "1000", "--seed", "3", "--quiet"])
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{env}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(
            out.contains("summary ticks=1000 events=0 terminations=0 filter_interventions="),
            "{env}: {out}"
        );
    }
}

/// agvrl-drive reads a policy's settings with the run config type `agvrl train` writes: a
/// `--set` key `agvrl train` would refuse (a typo) stops the drive with the key named, instead
/// of driving on defaults; spelt right, it drives. A file of format 1 drives with the TOML
/// beside it.
#[test]
fn agvrl_drive_refuses_a_setting_that_agvrl_train_would_refuse() {
    let drive = |policy: &std::path::Path, set: &[&str]| {
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"));
        c.arg("--policy").arg(policy).args(["--steps", "5", "--quiet"]);
        for s in set {
            c.args(["--set", s]);
        }
        c.output().unwrap()
    };
    let policy = shipped_policy("racing-oval-ppo");
    let o = drive(&policy, &["env_config.substepz=8"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("substepz"), "{err}");
    let o = drive(&policy, &["env_config.substeps=8"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let old = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../run/tests/fixtures/racing-v1.agvrl");
    let o = drive(&old, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `agvrl-drive --record` on the simulated car: a rosbag2 bag whose topics hold one message
/// per tick (plus the first frame's), decoding back to what the drive did: the ticks' actions
/// are the --trace of the same run, the commands the ticks' controls scaled to speed.
#[test]
fn a_recorded_drive_decodes_back_to_the_drive() {
    use agvrl_deploy::bag;
    use agvrl_deploy::hardware::msg;
    let dir = scratch("bag");
    let (bag_dir, trace) = (dir.path().join("drive"), dir.path().join("trace.jsonl"));
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-oval-ppo"))
        .args(["--steps", "90", "--quiet", "--record"])
        .arg(&bag_dir)
        .arg("--trace")
        .arg(&trace)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (msgs, damage) = bag::read_messages(&bag_dir).unwrap();
    assert_eq!(damage, None);
    assert!(out.contains(&format!(" bag_messages={}", msgs.len())), "{out}");
    let count = |t: &str| msgs.iter().filter(|m| m.topic == t).count();
    // The first tick senses the reset's frame (recorded once), each later one a new frame.
    assert_eq!([count("/scan"), count("/imu"), count("/odom"), count("/tf")], [90; 4]);
    assert_eq!([count("/drive"), count("/agvrl/tick")], [90, 90]);
    assert_eq!([count("/tf_static"), count("/robot_description")], [1, 1]);
    let urdf: msg::StdString =
        bag::decode(&msgs.iter().find(|m| m.topic == "/robot_description").unwrap().data).unwrap();
    assert!(urdf.data.contains("<robot"), "the URDF");
    // Log time is simulated time: one control period per tick.
    let scans: Vec<&bag::BagMessage> = msgs.iter().filter(|m| m.topic == "/scan").collect();
    for (k, m) in scans.iter().enumerate() {
        let s: msg::LaserScan = bag::decode(&m.data).unwrap();
        assert_eq!(s.ranges.len(), 100);
        assert!(
            (m.log_ns as f64 * 1e-9 - k as f64 / 30.0).abs() < 1e-6,
            "scan {k} at {}",
            m.log_ns
        );
        let stamp_ns = s.header.stamp.sec as i64 * 1_000_000_000 + s.header.stamp.nanosec as i64;
        assert!(
            (stamp_ns - m.log_ns as i64).abs() <= 1,
            "log time is the stamp: {stamp_ns} {}",
            m.log_ns
        );
    }
    let rows: Vec<serde_json::Value> = std::fs::read_to_string(&trace)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let ticks: Vec<msg::Tick> = msgs
        .iter()
        .filter(|m| m.topic == "/agvrl/tick")
        .map(|m| bag::decode(&m.data).unwrap())
        .collect();
    let drives: Vec<msg::AckermannDriveStamped> = msgs
        .iter()
        .filter(|m| m.topic == "/drive")
        .map(|m| bag::decode(&m.data).unwrap())
        .collect();
    for ((t, row), d) in ticks.iter().zip(&rows).zip(&drives) {
        let action: Vec<f32> = serde_json::from_value(row["action"].clone()).unwrap();
        assert_eq!(t.action, action, "tick {}", t.tick);
        assert_eq!(t.observation.len(), 104);
        assert!(
            (d.drive.speed as f64 - t.throttle * 1.79).abs() < 0.02,
            "tick {}: {d:?}",
            t.tick
        );
        assert_eq!(d.drive.steering_angle, t.steering_rad as f32);
    }
    // metadata.yaml counts what the file holds.
    let meta = std::fs::read_to_string(bag_dir.join("metadata.yaml")).unwrap();
    assert!(meta.contains(&format!("  message_count: {}\n", msgs.len())), "{meta}");
    assert!(
        meta.contains("name: /agvrl/tick\n        type: agvrl_msgs/msg/Tick"),
        "{meta}"
    );
}

/// A bag cut short (a killed recording) reads up to its last complete chunk, says where it
/// stopped, and `--reindex` rebuilds its metadata.yaml from what is left.
#[test]
fn a_truncated_bag_yields_its_intact_messages_and_reindexes() {
    use agvrl_deploy::bag::{self, BagWriter, Offered, Topic};
    use agvrl_deploy::hardware::msg;
    let dir = scratch("cut");
    let d = dir.path().join("b");
    let mut w = BagWriter::create(&d).unwrap();
    let scan = w
        .add_topic(Topic {
            name: "/scan".into(),
            ty: "sensor_msgs/msg/LaserScan".into(),
            offered: Offered::Sensor,
        })
        .unwrap();
    let n = 3000u64; // about 3.5 MB: four 1 MiB chunks
    for k in 0..n {
        let m = msg::LaserScan {
            ranges: vec![k as f32; 270],
            ..msg::LaserScan::default()
        };
        w.write(scan, k, k, &bag::cdr(&m)).unwrap();
    }
    assert!(BagWriter::create(&d).is_err(), "a bag never overwrites another");
    w.finish().unwrap();
    let path = d.join(bag::MCAP_FILE);
    let full = std::fs::read(&path).unwrap();
    let (all, damage) = bag::read_messages(&d).unwrap();
    assert_eq!((all.len() as u64, damage), (n, None));
    std::fs::write(&path, &full[..full.len() * 6 / 10]).unwrap();
    std::fs::remove_file(d.join("metadata.yaml")).unwrap();
    let (part, damage) = bag::read_messages(&d).unwrap();
    let why = damage.expect("the cut is reported");
    assert!(
        why.contains(bag::MCAP_FILE) && why.contains(&format!("after {} intact", part.len())),
        "{why}"
    );
    assert!(
        part.len() as u64 >= n / 2 - 500 && (part.len() as u64) < n,
        "{} of {n}",
        part.len()
    );
    for (k, m) in part.iter().enumerate() {
        let s: msg::LaserScan = bag::decode(&m.data).unwrap();
        assert_eq!(s.ranges[0], k as f32, "messages come back in order, intact");
    }
    let meta = reindex(&d);
    assert!(meta.contains(&format!("  message_count: {}\n", part.len())), "{meta}");
    // Garbage is an error naming the file, not a panic.
    std::fs::write(&path, b"not an mcap file at all").unwrap();
    let e = bag::read_messages(&d).unwrap_err().to_string();
    assert!(e.contains(bag::MCAP_FILE), "{e}");
}

/// A bag of another stack (its MCAP file named `<bag>_0.mcap`, no `/agvrl/tick`) is found and
/// reindexed under its own file name; a directory without an MCAP file, or with several (a split
/// bag), is refused by name; a log clock that jumps back or ahead is named, not a panic.
#[test]
fn foreign_bags_are_found_by_their_mcap_file_and_clock_jumps_are_named() {
    use agvrl_deploy::bag::{self, BagWriter, Offered, Topic};
    use agvrl_deploy::hardware::{Ros2Config, msg};
    let dir = scratch("foreign");
    let d = dir.path().join("carlog");
    let mut w = BagWriter::create(&d).unwrap();
    let topic = |name: &str, ty: &str| Topic {
        name: name.into(),
        ty: ty.into(),
        offered: Offered::Sensor,
    };
    let scan = w.add_topic(topic("/scan", "sensor_msgs/msg/LaserScan")).unwrap();
    let imu = w.add_topic(topic("/imu", "sensor_msgs/msg/Imu")).unwrap();
    let odom = w.add_topic(topic("/odom", "nav_msgs/msg/Odometry")).unwrap();
    // 1 s at 30 Hz, then the clock steps back 0.5 s, then ahead 3 s.
    let t0 = 1_764_000_000_000_000_000u64;
    let times: Vec<u64> = (0..30)
        .map(|k| t0 + k * 33_333_333)
        .chain([t0 + 500_000_000, t0 + 3_500_000_000])
        .collect();
    for &t in &times {
        let header = agvrl_deploy::hardware::mapping::header(t as f64 * 1e-9, "laser");
        let s = msg::LaserScan {
            header: header.clone(),
            ranges: vec![2.0; 100],
            ..msg::LaserScan::default()
        };
        w.write(scan, t, t, &bag::cdr(&s)).unwrap();
        let i = msg::Imu {
            header: header.clone(),
            ..msg::Imu::default()
        };
        w.write(imu, t, t, &bag::cdr(&i)).unwrap();
        let o = msg::Odometry {
            header,
            ..msg::Odometry::default()
        };
        w.write(odom, t, t, &bag::cdr(&o)).unwrap();
    }
    w.finish().unwrap();
    std::fs::rename(d.join(bag::MCAP_FILE), d.join("carlog_0.mcap")).unwrap();
    std::fs::remove_file(d.join("metadata.yaml")).unwrap();
    assert_eq!(bag::mcap_file(&d).unwrap(), d.join("carlog_0.mcap"));
    let (s, damage) = bag::reindex(&d).unwrap();
    assert_eq!((s.messages(), damage), (3 * 32, None));
    let meta = std::fs::read_to_string(d.join("metadata.yaml")).unwrap();
    assert!(meta.contains("- path: carlog_0.mcap"), "{meta}");
    let r = agvrl_deploy::replay::Replay::open(&d, Ros2Config::default(), None, 30.0).unwrap();
    assert!(!r.recorded());
    assert_eq!(r.clock_jumps.len(), 2, "{:?}", r.clock_jumps);
    assert!(r.clock_jumps[0].contains("backwards") && r.clock_jumps[1].contains("forwards"));
    // Ticks on the log clock from the first complete frame to the last message.
    assert_eq!(r.ticks().len(), 106, "3.5 s at 30 Hz");
    // No MCAP file, or two: refused by name.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let e = bag::read_messages(&empty).unwrap_err().to_string();
    assert!(e.contains("no .mcap file") && e.contains("empty"), "{e}");
    std::fs::copy(d.join("carlog_0.mcap"), d.join("carlog_1.mcap")).unwrap();
    let e = bag::read_messages(&d).unwrap_err().to_string();
    assert!(e.contains("split bag") && e.contains("carlog_1.mcap"), "{e}");
}

/// `--dump` of a bag with a message that does not decode: every message is a row (that one with
/// `"msg": null` and the reason), the bad one is named by index, topic and log time, and the
/// exit status says a message did not decode; `--replay` skips it and counts it. (A topic of a
/// schema without a decoder: python/tests/test_car_log_replay.py.)
#[test]
fn a_bag_with_a_bad_message_dumps_every_row_and_replays() {
    use agvrl_deploy::bag::{self, BagWriter, Offered, Topic};
    let dir = scratch("unknown");
    let d = dir.path().join("b");
    let (ok, _, err) = drive_cli(&[
        "--policy".as_ref(),
        shipped_policy("racing-oval-ppo").as_os_str(),
        "--steps".as_ref(),
        "30".as_ref(),
        "--quiet".as_ref(),
        "--record".as_ref(),
        d.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let (msgs, _) = bag::read_messages(&d).unwrap();
    let copy = dir.path().join("c");
    let mut w = BagWriter::create(&copy).unwrap();
    let mut index = std::collections::HashMap::new();
    let mut add = |w: &mut BagWriter, name: &str, ty: &str| {
        *index.entry(name.to_string()).or_insert_with(|| {
            w.add_topic(Topic {
                name: name.into(),
                ty: ty.into(),
                offered: Offered::Reliable,
            })
            .unwrap()
        })
    };
    let mut bad_at = 0;
    for (k, m) in msgs.iter().enumerate() {
        let i = add(&mut w, &m.topic, &m.ty);
        // The tenth scan's bytes cut in half: it no longer decodes.
        let data = if m.topic == "/scan" && bad_at == 0 && k > 60 {
            bad_at = m.log_ns;
            m.data[..m.data.len() / 2].to_vec()
        } else {
            m.data.clone()
        };
        w.write(i, m.log_ns, m.publish_ns, &data).unwrap();
    }
    w.finish().unwrap();
    let (ok, out, err) = drive_cli(&["--dump".as_ref(), copy.as_os_str()]);
    assert!(!ok, "a message that does not decode fails the dump");
    let rows: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(rows.len(), msgs.len(), "every message is a row");
    let nulls: Vec<&serde_json::Value> = rows.iter().filter(|r| r["msg"].is_null()).collect();
    assert_eq!(nulls.len(), 1, "{nulls:?}");
    assert_eq!(nulls[0]["topic"], "/scan");
    assert!(
        err.contains(&format!("log time {bad_at} ns")) && err.contains("/scan"),
        "{err}"
    );
    let (ok, out, err) = drive_cli(&[
        "--policy".as_ref(),
        shipped_policy("racing-oval-ppo").as_os_str(),
        "--replay".as_ref(),
        copy.as_os_str(),
        "--fast".as_ref(),
        "--quiet".as_ref(),
    ]);
    assert!(ok, "{err}");
    assert_eq!(kv(&out, "bad_messages"), 1.0, "{out}");
}

/// A drive whose stdout is closed early (`agvrl-drive ... | head -1`) drives on to the end and
/// exits cleanly: printing never panics the control loop.
#[test]
fn a_closed_stdout_does_not_stop_the_drive() {
    use std::io::BufRead;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-oval-ppo"))
        .args(["--steps", "600"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("tick="), "{first}");
    // The reader is dropped here: later lines meet a closed pipe.
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && !err.contains("panicked"), "{err}");
}

/// A recording killed mid-drive (SIGKILL: no summary, no metadata.yaml) leaves a bag whose
/// flushed chunks read back whole, and `--reindex` gives it a metadata.yaml.
#[test]
fn a_killed_recording_leaves_a_readable_bag() {
    use agvrl_deploy::bag;
    let dir = scratch("killed");
    let d = dir.path().join("drive");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-oval-ppo"))
        .args(["--steps", "0", "--realtime", "--quiet", "--record"])
        .arg(&d)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // The writer flushes every second; wait for two flushes' worth of file.
    let t0 = std::time::Instant::now();
    let path = d.join(bag::MCAP_FILE);
    while std::fs::metadata(&path).map_or(0, |m| m.len()) < 200_000 && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!d.join("metadata.yaml").exists(), "killed before finishing");
    let (msgs, _damage) = bag::read_messages(&d).unwrap();
    let ticks = msgs.iter().filter(|m| m.topic == "/agvrl/tick").count();
    assert!(
        ticks >= 10,
        "{ticks} ticks readable of a drive killed after {:?}",
        t0.elapsed()
    );
    for m in &msgs {
        agvrl_deploy::record::decode_json(m).unwrap_or_else(|e| panic!("{} {}: {e}", m.topic, m.log_ns));
    }
    let meta = reindex(&d);
    assert!(meta.contains(&format!("  message_count: {}\n", msgs.len())), "{meta}");
}

/// `agvrl-drive --reindex DIR`, then DIR's new metadata.yaml.
fn reindex(d: &std::path::Path) -> String {
    let (ok, _, err) = drive_cli(&["--reindex".as_ref(), d.as_os_str()]);
    assert!(ok, "{err}");
    std::fs::read_to_string(d.join("metadata.yaml")).unwrap()
}

/// Run agvrl-drive with `args`; (success, stdout, stderr).
fn drive_cli(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `agvrl-drive --policy POLICY --replay BAG --fast --check --tolerance 0`: the same bits on the
/// CPU that recorded.
fn replay_check(policy: &std::path::Path, bag: &std::path::Path) -> (bool, String, String) {
    drive_cli(&[
        "--policy".as_ref(),
        policy.as_os_str(),
        "--replay".as_ref(),
        bag.as_os_str(),
        "--fast".as_ref(),
        "--check".as_ref(),
        "--quiet".as_ref(),
        "--tolerance".as_ref(),
        "0".as_ref(),
    ])
}

/// The `key=value` of a summary line.
fn kv(out: &str, key: &str) -> f64 {
    out.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .unwrap_or_else(|| panic!("no {key} in {out}"))
        .parse()
        .unwrap()
}

/// `--replay --check` on a bag of the simulated car: the frames rebuilt from its messages
/// (through the code a ROS 2 car's go through) give the recorded commands, bit for bit on the
/// same CPU; a bag whose scans were changed is caught.
#[test]
fn a_replayed_bag_gives_the_recorded_commands_and_a_changed_scan_is_caught() {
    use agvrl_deploy::bag::{self, BagWriter, Offered, Topic};
    use agvrl_deploy::hardware::msg;
    let dir = scratch("replay");
    let (rec, changed) = (dir.path().join("rec"), dir.path().join("changed"));
    let policy = shipped_policy("racing-oval-ppo");
    let p = policy.as_os_str();
    let (ok, _, err) = drive_cli(&[
        "--policy".as_ref(),
        p,
        "--steps".as_ref(),
        "300".as_ref(),
        "--quiet".as_ref(),
        "--record".as_ref(),
        rec.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let replay = |bag: &std::path::Path| replay_check(&policy, bag);
    let (ok, out, err) = replay(&rec);
    assert!(ok, "{out}{err}");
    assert_eq!(kv(&out, "ticks"), 300.0, "{out}");
    assert_eq!(kv(&out, "events_differ"), 0.0, "{out}");
    // Copy the bag with the ranges of the scans from tick 100 on halved.
    let (msgs, _) = bag::read_messages(&rec).unwrap();
    let mut w = BagWriter::create(&changed).unwrap();
    let mut index = std::collections::HashMap::new();
    for m in &msgs {
        let i = *index.entry(m.topic.clone()).or_insert_with(|| {
            w.add_topic(Topic {
                name: m.topic.clone(),
                ty: m.ty.clone(),
                offered: Offered::Reliable,
            })
            .unwrap()
        });
        let mut data = m.data.clone();
        if m.topic == "/scan" && m.log_ns > 100 * 33_333_333 {
            let mut s: msg::LaserScan = bag::decode(&m.data).unwrap();
            s.ranges.iter_mut().for_each(|r| *r *= 0.5);
            data = bag::cdr(&s);
        }
        w.write(i, m.log_ns, m.publish_ns, &data).unwrap();
    }
    w.finish().unwrap();
    let (ok, out, _) = replay(&changed);
    assert!(!ok, "a changed scan must fail the check: {out}");
    assert!(kv(&out, "action_diff_max") > 1e-3, "{out}");
}

/// Random damage to a recorded bag (flipped bytes, cuts, both; 300 seeded cases) never panics
/// the reader or the message decoders: each case reads up to the damage or is refused with an
/// error, and every message that comes back decodes or is refused.
#[test]
fn damaged_bags_never_panic_the_reader_or_the_decoders() {
    use agvrl_deploy::bag;
    use rand::{RngExt, SeedableRng};
    let dir = scratch("fuzzbag");
    let d = dir.path().join("rec");
    let (ok, _, err) = drive_cli(&[
        "--policy".as_ref(),
        shipped_policy("racing-oval-camera").as_os_str(),
        "--steps".as_ref(),
        "20".as_ref(),
        "--quiet".as_ref(),
        "--record".as_ref(),
        d.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let path = d.join(bag::MCAP_FILE);
    let good = std::fs::read(&path).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let (mut refused, mut cut_short, mut bad_messages) = (0, 0, 0);
    for case in 0..300 {
        let mut b = good.clone();
        if case % 3 != 1 {
            for _ in 0..rng.random_range(1..9) {
                let i = rng.random_range(0..b.len());
                b[i] ^= 1 << rng.random_range(0..8);
            }
        }
        if case % 3 != 0 {
            b.truncate(rng.random_range(0..b.len()));
        }
        std::fs::write(&path, &b).unwrap();
        let r = std::panic::catch_unwind(|| match bag::read_messages(&d) {
            Ok((msgs, damage)) => (
                false,
                damage.is_some(),
                msgs.iter()
                    .filter(|m| agvrl_deploy::record::decode_json(m).is_err())
                    .count(),
            ),
            Err(_) => (true, false, 0),
        });
        let (r, c, m) = r.unwrap_or_else(|_| panic!("case {case} panicked"));
        refused += usize::from(r);
        cut_short += usize::from(c);
        bad_messages += m;
    }
    // The 200 cut files are noticed (refused, or read up to where they stop); flipped bytes
    // mostly are (a chunk's CRC), though a flip in an unchecked summary field may not be.
    assert!(refused + cut_short >= 200, "refused {refused}, cut short {cut_short}");
    eprintln!("refused {refused}, cut short {cut_short}, messages refused by a decoder {bad_messages}");
}

/// The fuzz targets' seeds and every input their runs kept (fuzz/seeds, fuzz/regressions; see
/// docs/reliability.md) go through the same bodies on stable: none panics. CI replays; it does
/// not fuzz.
#[test]
fn fuzz_regressions_replay_without_panic() {
    use agvrl_deploy::bag::fuzz;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    type Body = fn(&[u8]);
    let targets: [(&str, Body); 7] = [
        ("bag_reader", fuzz::read_and_decode),
        ("ros2_messages", fuzz::ros2_message),
        ("policy_file", agvrl_run::fuzz::policy_file),
        ("checkpoint", agvrl_rl::fuzz::checkpoint),
        ("run_toml", agvrl_run::fuzz::run_toml),
        ("asset_files", agvrl_sim::fuzz::asset_file),
        ("map_file", agvrl_sim::fuzz::map_file),
    ];
    let mut replayed = 0;
    for (target, body) in targets {
        for kind in ["seeds", "regressions"] {
            let Ok(dir) = std::fs::read_dir(root.join(kind).join(target)) else {
                continue;
            };
            for entry in dir {
                let path = entry.unwrap().path();
                let bytes = std::fs::read(&path).unwrap();
                body(&bytes);
                replayed += 1;
            }
        }
    }
    assert!(replayed >= 36, "the seeds are missing: {replayed} inputs");
    // Seeds the decoders refuse would leave the fuzzer at the first check.
    for entry in std::fs::read_dir(root.join("seeds/policy_file")).unwrap() {
        let path = entry.unwrap().path();
        let bytes = agvrl_rl::fuzz::with_crc(&std::fs::read(&path).unwrap());
        agvrl_rl::PolicyData::from_bytes(&path, &bytes).unwrap();
    }
}

/// A served race's flags are checked before DDS starts, each refusal one clear line.
#[test]
fn a_served_race_refuses_bad_opponents_and_car_counts() {
    let p = shipped_policy("racing-oval-ppo");
    let p = p.as_os_str();
    let run = |args: &[&str], extra: &[&std::ffi::OsStr]| {
        let mut all: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
        all.extend_from_slice(extra);
        let (ok, _, err) = drive_cli(&all);
        assert!(!ok, "{args:?} was accepted");
        err
    };
    let e = run(&["--serve-sim", "racing-duel"], &[]);
    assert!(e.contains("--opponent FILE or --opponent KIND[@SCALE]"), "{e}");
    let e = run(&["--serve-sim", "racing-oval", "--opponent"], &[p]);
    assert!(e.contains("--serve-sim racing-duel"), "{e}");
    let e = run(&["--serve-sim", "racing-duel", "--cars", "9", "--opponent"], &[p]);
    assert!(e.contains("--cars must be 2 to 8"), "{e}");
    let e = run(
        &["--serve-sim", "racing-duel", "--cars", "4", "--opponent"],
        &[p, "--opponent".as_ref(), p],
    );
    assert!(e.contains("2 opponents for 3 opponent cars"), "{e}");
    let e = run(&["--serve-sim", "racing-duel", "--opponent", "pure-pursuit@1.5"], &[]);
    assert!(
        e.contains("--opponent racer 'pure-pursuit@1.5': the speed scale must be in (0, 1]"),
        "{e}"
    );
    let e = run(&["--serve-sim", "racing-duel", "--opponent", "no-such.agvrl"], &[]);
    assert!(e.contains("no-such.agvrl"), "{e}");
    let e = run(
        &["--serve-sim", "racing-duel", "--namespace", "car0", "--opponent"],
        &[p],
    );
    assert!(e.contains("--namespace"), "{e}");
}

/// A classical racer drives through the drive loop as a policy does: pure pursuit and
/// follow-the-gap each lap the bean on the simulated car without a termination or a watchdog
/// event; a bad raceline is named by its line.
#[test]
fn a_racer_laps_the_bean_through_the_drive_loop() {
    use agvrl_deploy::run_loop::Brain;
    use agvrl_envs::drivers::{RacerKind, make_racer};
    let yaml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let cfg = EnvConfig {
        track: Some(agvrl_envs::TrackSetting::Path(yaml)),
        ..EnvConfig::default()
    };
    for kind in RacerKind::ALL {
        let v = make_vehicle("racing-oval", &cfg).unwrap();
        let task = make_task("racing-oval", &cfg, v.steering_limit_rad()).unwrap();
        let brain = Brain::Racer(make_racer(kind, &cfg, 1.0, None).unwrap(), cfg.action_mapping);
        let mut lp = DriveLoop::with_brain(v, task, brain, DriveConfig::default(), 0).unwrap();
        let mut laps = 0;
        for _ in 0..2400 {
            let t = lp.tick().unwrap();
            assert_eq!(t.termination, None, "{}", kind.name());
            assert_eq!(t.event, None, "{}", kind.name());
            laps = t.racing.map_or(0, |r| r.laps);
            if laps >= 1 {
                break;
            }
        }
        assert!(laps >= 1, "{} did not lap the bean", kind.name());
    }
    let e = make_racer(RacerKind::PurePursuit, &cfg, 1.0, Some("x, y\n1, oops\n"))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("raceline") && e.contains("line 2"), "{e}");
}

/// `agvrl-drive --racer ... --record` records a racer's drive as a policy's: one command and one
/// tick per step on the simulated car, the commands within that car's own steering limit
/// (follow-the-gap on the F1TENTH car, chosen with `--set`, steers to its 0.4189 rad at the
/// bean's hairpin, past XTENTH-CAR's 0.36).
#[test]
fn a_racers_drive_records_a_bag_within_its_cars_limits() {
    use agvrl_deploy::bag;
    use agvrl_deploy::hardware::msg;
    let dir = scratch("racer-bag");
    let bag_dir = dir.path().join("drive");
    let yaml = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/tracks/bean.yaml");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .args(["--racer", "follow-the-gap", "--track"])
        .arg(&yaml)
        .args([
            "--set",
            "env_config.vehicle=\"f1tenth\"",
            "--set",
            "env_config.brake_mps2=6.0",
        ])
        .args(["--steps", "600", "--quiet", "--record"])
        .arg(&bag_dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (msgs, damage) = bag::read_messages(&bag_dir).unwrap();
    assert_eq!(damage, None);
    let count = |t: &str| msgs.iter().filter(|m| m.topic == t).count();
    assert_eq!([count("/drive"), count("/agvrl/tick")], [600, 600]);
    let steer: Vec<f32> = msgs
        .iter()
        .filter(|m| m.topic == "/drive")
        .map(|m| {
            bag::decode::<msg::AckermannDriveStamped>(&m.data)
                .unwrap()
                .drive
                .steering_angle
                .abs()
        })
        .collect();
    let widest = steer.iter().cloned().fold(0.0f32, f32::max);
    assert!(widest > 0.36 && widest <= 0.4189 + 1e-6, "widest steering {widest}");
}

/// The shipped generalist drives a held-out generated circuit (a seed from the evaluation half,
/// never trained on) in agvrl-drive: a full lap with no crash and no watchdog event.
#[test]
fn the_shipped_generalist_laps_a_held_out_circuit_in_agvrl_drive() {
    let seed = (agvrl_envs::heldout::EVAL_BIT | 5).to_string();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_agvrl-drive"))
        .arg("--policy")
        .arg(shipped_policy("racing-any-track"))
        .args(["--steps", "9000", "--seed", &seed, "--quiet"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains(" events=0 terminations=0 "), "{out}");
    assert!(!out.contains(" laps=0 "), "{out}");
}
