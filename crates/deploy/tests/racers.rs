//! Classical racers in agvrl-drive: a served race's checks of opponents and car counts, a racer
//! lapping the bean through the drive loop, a racer's recorded drive within its car's limits.

use crate::{drive_cli, scratch, shipped_policy};
use agvrl_deploy::{DriveConfig, DriveLoop};
use agvrl_envs::{EnvConfig, make_task, make_vehicle};

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
