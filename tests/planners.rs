//! The classical search drivers in `eval`: the map-aware planner and the frontier explorer cover
//! more ground than random actions; coverage over time (`--coverage-csv`, `coverage-plot`).

use crate::{agvrl, key, stderr, stdout, tmp};
use std::path::Path;

#[test]
fn the_map_aware_planner_covers_more_than_random_actions_on_the_same_car_and_episodes() {
    let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
    let eval = |env: &str, driver: &str| {
        agvrl(&[
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--env",
            env,
            "--episodes",
            "3",
            "--seed",
            "3",
            // The filter the planners were tuned behind (the policy's training shield).
            "--safety-filter",
            "train",
            driver,
        ])
    };
    let p = eval("search-urban-20", "--planner");
    assert!(p.status.success(), "{}", stderr(&p));
    let p = stdout(&p);
    assert_eq!(key(&p, "policy"), "planner");
    assert_eq!(key(&p, "collisions"), "0", "{p}");
    let r = eval("search-urban-20", "--random");
    assert!(r.status.success(), "{}", stderr(&r));
    let r = stdout(&r);
    let cov = |out: &str| key(out, "coverage").parse::<f64>().unwrap();
    // Over 100 held-out episodes the planner covers 0.70, random actions on this car (which
    // reverse half the time) 0.07, and the forward-only random car 0.22.
    assert!(
        cov(&p) > 0.5 && cov(&p) > 2.0 * cov(&r),
        "planner {} random {}",
        cov(&p),
        cov(&r)
    );
    let oval = eval("racing-oval", "--planner");
    assert!(!oval.status.success());
    assert!(stderr(&oval).contains("needs a search env"), "{}", stderr(&oval));
}

#[test]
fn the_frontier_explorer_covers_ground_and_eval_writes_coverage_over_time() {
    let policy = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/policies/search.agvrl");
    let d = tmp("frontier");
    let eval = |driver: &[&str], csv: &Path| {
        let mut args = vec![
            "eval",
            "--policy",
            policy.to_str().unwrap(),
            "--env",
            "search-urban-20",
            "--episodes",
            "3",
            "--seed",
            "3",
            "--coverage-csv",
            csv.to_str().unwrap(),
            "--safety-filter",
            "train",
        ];
        args.extend_from_slice(driver);
        let o = agvrl(&args);
        assert!(o.status.success(), "{driver:?}: {}", stderr(&o));
        stdout(&o)
    };
    let (fcsv, rcsv) = (d.path().join("frontier.csv"), d.path().join("random.csv"));
    let f = eval(&["--planner", "frontier"], &fcsv);
    let r = eval(&["--random"], &rcsv);
    assert_eq!(key(&f, "policy"), "frontier");
    let cov = |out: &str| key(out, "coverage").parse::<f64>().unwrap();
    // Over 100 held-out episodes the explorer covers 0.63 with no map, random actions on
    // this car (which reverse half the time) 0.07.
    assert!(
        cov(&f) > 0.4 && cov(&f) > 3.0 * cov(&r),
        "frontier {} random {}",
        cov(&f),
        cov(&r)
    );
    // The CSV holds every control of every episode; the mean of each episode's last row is
    // the coverage line, and the time to 25 % is where the rows cross it.
    let text = std::fs::read_to_string(&fcsv).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(text.lines().next(), Some("episode,step,time_s,coverage"));
    let last: Vec<f64> = (0..3)
        .map(|e| rows.iter().rfind(|r| r[0] == e as f64).unwrap()[3])
        .collect();
    assert!((last.iter().sum::<f64>() / 3.0 - cov(&f)).abs() < 1e-3, "{last:?}");
    let first_25: Vec<f64> = (0..3)
        .filter_map(|e| rows.iter().find(|r| r[0] == e as f64 && r[3] >= 0.25).map(|r| r[2]))
        .collect();
    assert_eq!(key(&f, "coverage_25_reached"), format!("{}/3", first_25.len()));
    let t25: f64 = key(&f, "time_to_coverage_25_s").parse().unwrap();
    assert!((t25 - first_25.iter().sum::<f64>() / first_25.len() as f64).abs() < 0.06);
    let png = d.path().join("coverage.png");
    let o = agvrl(&[
        "coverage-plot",
        "--out",
        png.to_str().unwrap(),
        &format!("frontier={}", fcsv.display()),
        rcsv.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    let bad = agvrl(&["coverage-plot", "--out", png.to_str().unwrap(), "/nonexistent.csv"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("/nonexistent.csv"), "{}", stderr(&bad));
}
