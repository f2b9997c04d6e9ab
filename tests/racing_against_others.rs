//! Self-play and `agvrl race`: a duel policy trained by self-play races the single-car one, races
//! on generated circuits against a classical racer, `--json`, one policy per car.

use crate::{agvrl, png_summary, rrd_check, stderr, stdout, tmp};
use std::path::Path;

fn key<'a>(line: &'a str, k: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(&format!("{k}=")))
        .unwrap_or_else(|| panic!("no {k}= in {line}"))
}

/// configs/duel.toml trains by self-play (a tiny run, twice: the same policy file, bit for
/// bit); the policy drives alone in `eval`, and `agvrl race` races it against the shipped
/// single-car policy: a line per car, the first race's paths drawn, and a recording with
/// every car its own entity.
#[test]
fn self_play_trains_a_duel_policy_that_races_the_single_car_one() {
    let d = tmp("duel");
    let train = |out: &Path| {
        let o = agvrl(&[
            "train",
            "--config",
            "configs/duel.toml",
            "--set",
            "steps=1024",
            "--set",
            "n_envs=2",
            "--set",
            "ppo.n_steps=128",
            "--set",
            "ppo.batch_size=64",
            "--set",
            "ppo.n_epochs=1",
            "--set",
            "eval_episodes=1",
            "--set",
            "eval_max_steps=60",
            "--set",
            "env_config.max_steps=100",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out.join("policy.agvrl")).unwrap()
    };
    let (a, b) = (train(&d.path().join("a")), train(&d.path().join("b")));
    assert!(a == b, "the same self-play run twice gives the same policy file");
    let policy = d.path().join("a/policy.agvrl");
    let eval = agvrl(&[
        "eval",
        "--policy",
        policy.to_str().unwrap(),
        "--episodes",
        "1",
        "--max-steps",
        "50",
    ]);
    assert!(eval.status.success(), "{}", stderr(&eval));
    assert!(stdout(&eval).contains("env=racing-oval") && stdout(&eval).contains("track=bean"));
    let (png, rrd) = (d.path().join("race.png"), d.path().join("race.rrd"));
    let o = agvrl(&[
        "race",
        "--policy",
        policy.to_str().unwrap(),
        "--policy",
        "assets/policies/racing-oval-ppo.agvrl",
        "--races",
        "2",
        "--max-steps",
        "120",
        "--plot",
        png.to_str().unwrap(),
        "--rerun",
        rrd.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let cars: Vec<&str> = out.lines().filter(|l| l.starts_with("car=")).collect();
    assert_eq!(cars.len(), 2, "{out}");
    assert!(out.contains("track=bean cars=2 races=2"), "{out}");
    let wins: f64 = cars.iter().map(|l| key(l, "win_rate").parse::<f64>().unwrap()).sum();
    assert!((wins - 1.0).abs() < 1e-9, "one winner a race: {out}");
    for l in &cars {
        for k in [
            "mean_place",
            "laps_per_race",
            "encounters",
            "passes",
            "pass_success",
            "races_with_pass",
            "races_with_pass_share",
            "at_fault_incidents",
            "at_fault_share",
            "wins_from_behind",
            "contacts_per_race",
            "time_lost_s_per_race",
            "crashes",
        ] {
            key(l, k);
        }
    }
    let (w, h, colours) = png_summary(&png);
    assert!(w > 400 && h > 300 && colours > 5, "{w}x{h}, {colours} colours");
    rrd_check(
        &rrd,
        &["world/car_0", "world/car_1", "world/paths/car_1", "world/lidar/car_0"],
    );
    // On generated circuits, a new one each race, from a start 2 m behind pure pursuit at
    // 0.75 of its speed: every race begins with an encounter for car 0.
    let circuits = |extra: &[&str]| {
        let args = [
            &[
                "race",
                "--policy",
                "assets/policies/racing-any-track.agvrl",
                "--racer",
                "pure-pursuit@0.75",
                "--circuits",
                "--start-behind",
                "--races",
                "2",
                "--max-steps",
                "150",
            ][..],
            extra,
        ]
        .concat();
        let o = agvrl(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let json = d.path().join("race.json");
    let gap = d.path().join("gap.png");
    let out = circuits(&["--json", json.to_str().unwrap(), "--gap-plot", gap.to_str().unwrap()]);
    let (w, h, colours) = png_summary(&gap);
    assert!(w > 400 && h > 300 && colours > 5, "gap plot {w}x{h}, {colours} colours");
    assert!(out.contains("track=circuits cars=2 races=2"), "{out}");
    // --json holds the printed figures, and every race falls in one width band.
    let report = agvrl_run::RaceReport::load(&json).unwrap();
    assert_eq!(
        report.text(),
        out.lines()
            .filter(|l| !l.starts_with("json=") && !l.starts_with("gap_plot="))
            .map(|l| format!("{l}\n"))
            .collect::<String>()
    );
    for (i, all) in report.figures.iter().enumerate() {
        let bands: Vec<&agvrl_run::CarFigures> = report.by_width.iter().map(|b| &b.figures[i]).collect();
        assert_eq!(bands.iter().map(|f| f.races).sum::<usize>(), 2, "{out}");
        assert_eq!(bands.iter().map(|f| f.encounters).sum::<u64>(), all.encounters, "{out}");
        assert_eq!(
            bands.iter().map(|f| f.at_fault_incidents).sum::<u64>(),
            all.at_fault_incidents,
            "{out}"
        );
        let km: f64 = bands.iter().map(|f| f.covered_km).sum();
        assert!((km - all.covered_km).abs() < 1e-9 && all.covered_km > 0.0, "{out}");
    }
    let car = |i: usize| out.lines().find(|l| l.starts_with(&format!("car={i} "))).unwrap();
    assert_eq!(key(car(0), "starts_behind"), "2", "{out}");
    assert_eq!(key(car(1), "starts_behind"), "0", "{out}");
    assert_eq!(key(car(1), "policy"), "pure-pursuit@0.75", "{out}");
    assert!(key(car(0), "encounters").parse::<u32>().unwrap() >= 2, "{out}");
    assert!(out.contains(" split=held_out"), "{out}");
    // A lone car starts on the grid though the shipped passing policy trained from behind.
    let o = agvrl(&[
        "race",
        "--policy",
        "assets/policies/racing-overtake.agvrl",
        "--cars",
        "1",
        "--circuits",
        "--races",
        "1",
        "--max-steps",
        "60",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("cars=1 races=1"), "{}", stdout(&o));
    // --train-split races the training half of the seed space.
    let train = circuits(&["--train-split"]);
    assert!(train.contains(" split=train"), "{train}");
    let o = agvrl(&["race", "--policy", "a.agvrl", "--policy", "b.agvrl", "--cars", "3"]);
    assert!(!o.status.success());
    assert_eq!(
        stderr(&o).trim(),
        "error: 2 policies for 3 cars: give one policy per car, or one for all"
    );
}
