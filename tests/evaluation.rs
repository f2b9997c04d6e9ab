//! `eval` and `view`: recordings, plots and the search figures, bags of evaluated episodes
//! replaying through the drive loop, a policy file's episodes drawn from the seed and the layout
//! option.

use crate::{agvrl, key, png_summary, rrd_check, stderr, stdout, tmp};
use std::path::Path;

#[test]
fn eval_and_view_write_recordings_and_search_eval_reports_coverage() {
    let d = tmp("rerun");
    let cfg = d.path().join("search.toml");
    std::fs::write(
        &cfg,
        "env = \"search-outdoor-20\"\nalgo = \"ppo\"\nsteps = 256\nseed = 2\nn_envs = 2\nthreads = 1\n\
         procedural_layouts = 1\neval_episodes = 1\n[env_config]\nmax_steps = 60\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 1\n",
    )
    .unwrap();
    let run = d.path().join("run");
    let o = agvrl(&[
        "train",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rrd = d.path().join("eval.rrd");
    let png = d.path().join("paths.png");
    let o = agvrl(&[
        "eval",
        "--run",
        run.to_str().unwrap(),
        "--episodes",
        "2",
        "--rerun",
        rrd.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    for key in ["mean_return=", "episodes=2", "collisions=", "coverage="] {
        assert!(out.contains(key), "{key} missing in:\n{out}");
    }
    let cov: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("coverage="))
        .unwrap()
        .parse()
        .unwrap();
    assert!(cov > 0.0 && cov <= 1.0, "{cov}");
    let dist: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("distance_m_per_episode="))
        .expect("distance_m_per_episode= missing")
        .parse()
        .unwrap();
    // 60 steps of 1/30 s, and the car's top speed is under 2 m/s.
    assert!(dist > 0.0 && dist < 2.0 * 60.0 / 30.0, "{dist}");
    rrd_check(
        &rrd,
        &["world/scene", "world/trajectory", "world/lidar/scan", "plots/speed_mps"],
    );
    assert!(png_summary(&png).2 >= 4);
    // The same episodes on another scene with random actions: the random baseline.
    let o = agvrl(&[
        "eval",
        "--run",
        run.to_str().unwrap(),
        "--episodes",
        "1",
        "--env",
        "search-urban-50",
        "--random",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    for key in ["env=search-urban-50", "policy=random", "coverage="] {
        assert!(out.contains(key), "{key} missing in:\n{out}");
    }
    let o = agvrl(&["eval", "--run", run.to_str().unwrap(), "--env", "pendulum"]);
    assert!(!o.status.success(), "a search policy on the pendulum must be refused");
    assert!(stderr(&o).contains("does not fit"), "{}", stderr(&o));
    // `view` without a policy drives random actions into a file.
    let view = d.path().join("view.rrd");
    let o = agvrl(&[
        "view",
        "--env",
        "racing-oval",
        "--steps",
        "40",
        "--camera",
        "--rerun",
        view.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("policy=random"), "{}", stdout(&o));
    rrd_check(
        &view,
        &[
            "world/vehicle",
            "plots/throttle",
            "camera/rgb",
            "camera/depth",
            "camera/segmentation",
        ],
    );
    // A policy for another env is refused in one line.
    let o = agvrl(&[
        "view",
        "--env",
        "pendulum",
        "--policy",
        run.join("policy.agvrl").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert_eq!(stderr(&o).trim().lines().count(), 1, "{}", stderr(&o));
}

/// `agvrl eval --record`: one bag per episode with the topics of `agvrl-drive --record` in
/// simulated time; the drive loop replaying a bag gives the evaluated actions and commands
/// to within 1e-5 (same CPU) and every filter verdict, with the safety filter in the loop.
#[test]
fn eval_bags_replay_through_the_drive_loop_to_the_evaluated_actions() {
    use agvrl_deploy::bag;
    use agvrl_deploy::hardware::msg;
    const WIDER: &str = "env_config.safety_filter.clearance_m=1.1";
    let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
    let d = tmp("evalbag");
    let bags = d.path().join("bags");
    let o = agvrl(&[
        "eval",
        "--policy",
        policy.to_str().unwrap(),
        "--env",
        "search-urban-20",
        "--layouts",
        "procedural",
        "--episodes",
        "2",
        "--max-steps",
        "300",
        // Episodes where a wider filter corrects the policy (13 times), so the replay
        // checks its verdicts too.
        "--seed",
        "11",
        "--set",
        WIDER,
        "--record",
        bags.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert_eq!(key(&out, "bag_episodes"), "2", "{out}");
    let mut settings = agvrl_run::PolicySettings::resolve(None, Some(&policy), &[WIDER.into()]).unwrap();
    let env_cfg = settings.eval_env_config();
    let (mut messages, mut filtered, mut first_odom) = (0, 0, Vec::new());
    for k in 0..2 {
        let dir = bags.join(format!("episode-{k:03}"));
        let (msgs, damage) = bag::read_messages(&dir).unwrap();
        assert_eq!(damage, None);
        messages += msgs.len();
        let count = |t: &str| msgs.iter().filter(|m| m.topic == t).count();
        // The reset's frame and one per step; a command and a tick per step.
        assert_eq!([count("/scan"), count("/odom"), count("/tf")], [301; 3], "episode {k}");
        assert_eq!([count("/drive"), count("/agvrl/tick")], [300, 300], "episode {k}");
        let odom: msg::Odometry = bag::decode(&msgs.iter().find(|m| m.topic == "/odom").unwrap().data).unwrap();
        first_odom.push(odom.pose.pose.position.x);
        let mut r = agvrl_deploy::replay::Replayer::open(
            &dir,
            None,
            "search-urban-20",
            &env_cfg,
            settings.load_policy().unwrap(),
            30.0,
            0,
        )
        .unwrap();
        let mut ticks = 0;
        while let Some((rec, t)) = r.step().unwrap() {
            let (_, action) = t.inference.as_ref().unwrap();
            // The bag's stamps are whole nanoseconds and the simulator's are not, and the
            // policy's reverse lengths and wait read time continuously: an action may move
            // by an f32 rounding, never more.
            let worst = action
                .iter()
                .zip(&rec.action)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(
                worst <= 1e-5,
                "episode {k} tick {}: {action:?} {:?}",
                rec.tick,
                rec.action
            );
            assert!(
                (t.control.throttle - rec.throttle).abs() <= 1e-5
                    && (t.control.steering_rad - rec.steering_rad).abs() <= 1e-5,
                "episode {k} tick {}",
                rec.tick
            );
            assert_eq!(format!("{:?}", t.intervention).to_lowercase(), rec.intervention);
            filtered += usize::from(rec.intervention != "none");
            ticks += 1;
        }
        assert_eq!(ticks, 300);
        assert_eq!(r.diff.events, 0);
    }
    assert_eq!(key(&out, "bag_messages"), messages.to_string());
    assert_ne!(first_odom[0], first_odom[1], "each episode its own start");
    assert!(filtered > 0, "no filtered control to replay");
    let again = agvrl(&[
        "eval",
        "--policy",
        policy.to_str().unwrap(),
        "--record",
        bags.to_str().unwrap(),
    ]);
    assert!(
        !again.status.success() && stderr(&again).contains("not empty"),
        "{}",
        stderr(&again)
    );
}

#[test]
fn eval_of_a_policy_file_draws_its_episodes_from_the_seed_and_the_layout_option() {
    let d = tmp("evalpolicy");
    let cfg = d.path().join("search.toml");
    std::fs::write(
        &cfg,
        "env = \"search-urban-20\"\nalgo = \"ppo\"\nsteps = 128\nseed = 3\nn_envs = 1\nthreads = 1\n\
         eval_episodes = 1\n[env_config]\nmax_steps = 30\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 1\n",
    )
    .unwrap();
    let run = d.path().join("run");
    let o = agvrl(&[
        "train",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A policy file on its own: it carries its run's settings.
    let policy = d.path().join("p.agvrl");
    std::fs::copy(run.join("policy.agvrl"), &policy).unwrap();
    let ev = |extra: &[&str]| {
        let mut args = vec!["eval", "--policy", policy.to_str().unwrap(), "--episodes", "3"];
        args.extend_from_slice(extra);
        let o = agvrl(&args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
        stdout(&o)
    };
    let a = ev(&["--seed", "11"]);
    assert_eq!(key(&a, "env"), "search-urban-20", "the env comes from the file");
    assert_eq!(key(&a, "seed"), "11");
    assert_eq!(a, ev(&["--seed", "11"]), "same seed, same episodes");
    assert_ne!(key(&a, "mean_return"), key(&ev(&["--seed", "12"]), "mean_return"));
    let p = ev(&["--seed", "11", "--layouts", "procedural"]);
    assert_eq!(key(&p, "layouts"), "procedural");
    assert_ne!(
        key(&a, "coverage"),
        key(&p, "coverage"),
        "procedural maps differ from the built-in one"
    );
    let n = ev(&["--seed", "11", "--preset", "sim2real"]);
    assert_eq!(key(&n, "preset"), "sim2real");
    assert_ne!(key(&a, "mean_return"), key(&n, "mean_return"));
    let r = ev(&["--seed", "11", "--random"]);
    assert_eq!(key(&r, "policy"), "random");
    // Sampled actions: seeded per episode, so repeatable, and not the mean's episodes.
    let s = ev(&["--seed", "11", "--sampled"]);
    assert_eq!(key(&s, "actions"), "sampled");
    assert_eq!(s, ev(&["--seed", "11", "--sampled"]), "same seed, same samples");
    assert_ne!(key(&a, "mean_return"), key(&s, "mean_return"));
    let o = agvrl(&["eval", "--policy", policy.to_str().unwrap(), "--sampled", "--random"]);
    assert!(!o.status.success(), "--sampled drives the policy, --random does not");
    // A file of format 1 without the TOML beside it carries no settings: the env must be
    // named.
    let old = d.path().join("old.agvrl");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/run/tests/fixtures/racing-v1.agvrl"),
        &old,
    )
    .unwrap();
    let o = agvrl(&["eval", "--policy", old.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--env"), "{}", stderr(&o));
    let o = agvrl(&[
        "eval",
        "--policy",
        old.to_str().unwrap(),
        "--env",
        "racing-oval",
        "--episodes",
        "1",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(key(&stdout(&o), "settings"), "default");
}
