//! rosbag2 bags of a drive (`--record`): decoded back to the drive, cut short or killed and
//! reindexed, bags of another stack, a message that does not decode in `--dump` and `--replay`.

use crate::{drive_cli, kv, scratch, shipped_policy};

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
