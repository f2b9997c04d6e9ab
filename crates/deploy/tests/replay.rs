//! Replays of a drive: `--check-trace` and `--replay --check` reproduce the recorded actions and
//! commands bit for bit, and catch a changed action or scan.

use crate::{drive_cli, kv, replay_check, scratch, shipped_policy};

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
