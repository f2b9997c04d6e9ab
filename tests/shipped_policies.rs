//! The shipped policies in `eval`: the search policy drives held-out outdoor episodes without a
//! termination, the camera-only racing policy laps the oval from depth alone.

use crate::{agvrl, key, stderr, stdout};
use std::path::Path;

/// The policy carries its own safety: without the filter it drives 3 held-out outdoor-20
/// episodes to the time limit, and with it the filter steers or brakes at most 20 of its
/// 1,000 controls per episode (the search targets' bound).
#[test]
fn shipped_search_policy_drives_held_out_outdoor_episodes_without_a_termination() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let policy = root.join("assets/policies/search.agvrl");
    let eval_on = |env: &str, episodes: &str, filter: &[&str]| {
        let mut args = vec![
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--env",
            env,
            "--episodes",
            episodes,
            "--seed",
            "7",
        ];
        args.extend_from_slice(filter);
        let o = agvrl(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let eval = |filter: &[&str]| eval_on("search-outdoor-20", "3", filter);
    let bare = eval(&["--safety-filter", "off"]);
    assert_eq!(key(&bare, "safety_filter"), "off");
    assert_eq!(key(&bare, "ended"), "time_limit,time_limit,time_limit", "{bare}");
    // Its embedded settings turn the safety filter on.
    let out = eval(&[]);
    assert_eq!(key(&out, "episodes"), "3");
    assert_eq!(key(&out, "safety_filter"), "on");
    assert_eq!(key(&out, "ended"), "time_limit,time_limit,time_limit", "{out}");
    assert_eq!(key(&out, "collisions"), "0");
    let corrections: f64 = key(&out, "filter_corrections_per_episode").parse().unwrap();
    assert!(corrections <= 20.0, "{out}");
    let cov: f64 = key(&out, "coverage").parse().unwrap();
    assert!(cov > 0.2, "coverage {cov}");
    let bare_cov: f64 = key(&bare, "coverage").parse().unwrap();
    assert!(bare_cov >= 0.95 * cov, "bare coverage {bare_cov}, filtered {cov}");
    // Among buildings, the wider shield it was trained behind steps in more often than the
    // backstop it drives behind.
    let urban = |filter: &str| {
        let out = eval_on("search-urban-20", "1", &["--safety-filter", filter]);
        assert_eq!(key(&out, "safety_filter"), filter);
        key(&out, "filter_corrections_per_episode").parse::<f64>().unwrap()
    };
    let (backstop, shield) = (urban("on"), urban("train"));
    assert!(shield > backstop, "shield {shield}, backstop {backstop}");
    // The same policy fits every search scene's spaces.
    for env in ["search-urban-20", "search-outdoor-50", "search-urban-50"] {
        let o = agvrl(&[
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--env",
            env,
            "--episodes",
            "1",
            "--layouts",
            "procedural",
        ]);
        assert!(o.status.success(), "{env}: {}", stderr(&o));
    }
}

/// The shipped camera-only racing policy (a 64x48 depth image, no LiDAR in its observation)
/// laps the oval in a held-out 100 s episode, with clean sensors and under sim2real's
/// depth noise, holes and dynamics.
#[test]
fn the_shipped_camera_policy_laps_the_oval_from_depth_alone() {
    let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/racing-oval-camera.agvrl");
    for preset in [&[][..], &["--preset", "sim2real"]] {
        let mut args = vec![
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--episodes",
            "1",
            "--seed",
            "7",
        ];
        args.extend(preset);
        let o = agvrl(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        assert_eq!(key(&out, "collisions"), "0", "{preset:?}: {out}");
        assert!(key(&out, "laps").parse::<u32>().unwrap() >= 2, "{preset:?}: {out}");
    }
    let settings = agvrl(&["policy", policy.to_str().unwrap()]);
    let settings = stdout(&settings);
    assert!(
        settings.contains("ranges = \"off\"") && settings.contains("depth_only = true"),
        "{settings}"
    );
}

/// Every shipped policy acts the same on the host kernels (what the learners' host rollouts
/// compute) as through Burn (what `Policy::act` runs by default): over 1,000 steps of its own
/// env, driven by its Burn actions from a held-out seed, the largest difference between the
/// two paths' deterministic actions stays under 1e-6 (f32 rounding: the host's rational tanh
/// and the matrix products' summation order).
#[test]
fn every_shipped_policy_acts_the_same_on_either_network_path() {
    use agvrl_envs::Env;
    use agvrl_rl::NetPath;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for name in [
        "search",
        "racing-oval-ppo",
        "racing-oval-camera",
        "racing-any-track",
        "racing-overtake",
    ] {
        let path = root.join(format!("assets/policies/{name}.agvrl"));
        let mut settings = agvrl_run::PolicySettings::resolve(None, Some(&path), &[]).unwrap();
        let mut burn = settings.load_policy().unwrap();
        let mut host = settings.load_policy().unwrap();
        assert_eq!(burn.net_path(), NetPath::Burn, "{name}: the default path");
        host.set_net_path(NetPath::Host);
        let id = settings.env_id(None).unwrap();
        let mut env = agvrl_envs::make(&id, &settings.eval_env_config()).unwrap();
        let (mut obs, _) = env.reset(Some(1_000_000)).unwrap();
        let (mut worst, mut moved) = (0.0f32, 0.0f32);
        for _ in 0..1000 {
            let (a, b) = (burn.act(&obs, true).unwrap(), host.act(&obs, true).unwrap());
            worst = a.iter().zip(&b).fold(worst, |m, (a, b)| m.max((a - b).abs()));
            moved = moved.max(a[0].abs());
            let st = env.step(&a).unwrap();
            obs = if st.done() { env.reset(None).unwrap().0 } else { st.obs };
        }
        eprintln!("{name}: largest action difference {worst:.2e}");
        assert!(worst < 1e-6, "{name}: {worst}");
        assert!(moved > 0.05, "{name}: the policy never acted");
    }
}
