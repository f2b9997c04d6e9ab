//! The evaluation report: eval.json round-trips, eval.txt renders the same figures.

use agvrl_run::{EvalReport, FilterReport, RacingReport, RunReport, SearchReport, SubjectsReport};
use serde_json::Value;

fn search_run() -> RunReport {
    RunReport {
        train_s: 301.25,
        eval_s: 12.049,
        steps: 6_000_000,
        interrupted: true,
        eval: EvalReport {
            mean_return: -12.345_678,
            episodes: 10,
            collisions: 2,
            ended: vec!["time_limit".into(), "too_close".into(), "contact".into()],
            subjects: Some(SubjectsReport {
                subjects_found: 3,
                subjects_placed: 5,
                mean_find_s: Some(7.125_1),
            }),
            search: Some(SearchReport {
                coverage: 0.675_49,
                distance_m_per_episode: 88.04,
                clearance_mean_m: Some(1.234_567),
                clearance_p5_m: Some(0.612_3),
                steering_change_mean_rad: 0.012_345_6,
                time_to_coverage_25_s: Some(9.96),
                coverage_25_reached: 9,
                time_to_coverage_50_s: None,
                coverage_50_reached: 0,
            }),
            filter: Some(FilterReport {
                filter_interventions_per_episode: 30.06,
                filter_corrections_per_episode: 25.04,
                filter_steered_per_episode: 20.0,
                filter_braked_per_episode: 5.04,
                filter_backouts_per_episode: 0.125,
                filter_backout_ticks_per_episode: 3.3,
            }),
            racing: None,
        },
    }
}

fn racing_run() -> RunReport {
    RunReport {
        eval: EvalReport {
            mean_return: 512.0,
            episodes: 3,
            ended: vec!["time_limit".into(); 3],
            racing: Some(RacingReport {
                laps: 7,
                best_lap_s: None,
                lapped: 2,
                mean_first_lap_s: Some(31.25),
            }),
            ..EvalReport::default()
        },
        ..RunReport::default()
    }
}

#[test]
fn eval_json_round_trips_every_group_and_the_absence_of_one() {
    let d = tempfile::tempdir().unwrap();
    for r in [search_run(), racing_run(), RunReport::default()] {
        let p = d.path().join("eval.json");
        agvrl_run::write_atomic(&p, r.to_json().as_bytes()).unwrap();
        assert_eq!(RunReport::load(&p).unwrap(), r);
    }
    // Flat: the text's keys, not nested groups.
    let v: Value = serde_json::from_str(&search_run().to_json()).unwrap();
    assert_eq!(v["coverage"], 0.675_49);
    assert_eq!(v["filter_backouts_per_episode"], 0.125);
    assert_eq!(v["time_to_coverage_50_s"], Value::Null);
    assert!(v.get("laps").is_none() && v.get("search").is_none());
}

#[test]
fn a_malformed_eval_json_is_an_error_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("eval.json");
    std::fs::write(&p, "{\"train_s\": \"fast\"}").unwrap();
    let e = RunReport::load(&p).unwrap_err().to_string();
    assert!(e.contains("eval.json"), "{e}");
}

/// Every `key=value` of eval.txt is the JSON's figure of that key, rounded as printed.
fn agrees(key: &str, text: &str, json: &Value) -> bool {
    let near = |t: &str, x: f64| {
        let decimals = t.split_once('.').map_or(0, |(_, f)| f.len());
        t.parse::<f64>()
            .is_ok_and(|v| (v - x).abs() <= 0.5 * 10f64.powi(-(decimals as i32)) + 1e-12)
    };
    match (key, json.get(key)) {
        ("ended", Some(Value::Array(a))) => text
            .split(',')
            .filter(|e| !e.is_empty())
            .eq(a.iter().map(|e| e.as_str().unwrap())),
        ("subjects_found", Some(n)) => text == format!("{n}/{}", json["subjects_placed"]),
        ("lapped", Some(n)) => text == format!("{n}/{}", json["episodes"]),
        (k, Some(n)) if k.starts_with("coverage_") && k.ends_with("_reached") => {
            text == format!("{n}/{}", json["episodes"])
        }
        (_, Some(Value::Null)) => text == "none" || text == "not_reached",
        (_, Some(Value::Bool(b))) => text == b.to_string(),
        (_, Some(n)) => n.as_f64().is_some_and(|x| near(text, x)),
        (_, None) => false,
    }
}

#[test]
fn eval_txt_prints_the_json_figures_rounded() {
    for r in [search_run(), racing_run(), RunReport::default()] {
        let json: Value = serde_json::from_str(&r.to_json()).unwrap();
        let text = r.text();
        let mut printed = Vec::new();
        for line in text.lines() {
            let (k, v) = line.split_once('=').unwrap();
            assert!(agrees(k, v, &json), "{line} against {}", json[k]);
            printed.push(k);
        }
        // What the text leaves out: subjects_placed (folded into subjects_found), interrupted
        // when false, and figures that are null (no finite clearance, nothing found).
        for (k, v) in json.as_object().unwrap() {
            let folded = k == "subjects_placed" || (k == "interrupted" && v == false) || v.is_null();
            assert!(printed.contains(&k.as_str()) || folded, "{k} missing from\n{text}");
        }
    }
}

fn race() -> agvrl_run::RaceReport {
    use agvrl_run::{CarFigures, RaceReport, WidthBand};
    let learner = CarFigures {
        car: 0,
        policy: "runs/a/policy.agvrl".into(),
        races: 4,
        wins: 3,
        mean_place: 1.25,
        laps_per_race: 0.5,
        mean_lap_s: Some(40.125),
        best_lap_s: Some(39.5),
        encounters: 4,
        passes: 3,
        races_with_pass: 2,
        at_fault_incidents: 1,
        starts_behind: 4,
        wins_from_behind: 3,
        contacts: 2,
        at_fault_contacts: 1,
        time_lost_s: 0.4,
        crashes: 0,
        covered_km: 0.5,
    };
    let opponent = CarFigures {
        car: 1,
        policy: "pure-pursuit@0.75".into(),
        encounters: 0,
        passes: 0,
        races_with_pass: 0,
        at_fault_incidents: 0,
        starts_behind: 0,
        crashes: 1,
        covered_km: 0.25,
        ..learner.clone()
    };
    RaceReport {
        env: "racing-duel".into(),
        track: "circuits".into(),
        cars: 2,
        races: 4,
        seed: 7,
        max_steps: 3600,
        split: "held_out".into(),
        figures: vec![learner.clone(), opponent.clone()],
        by_width: vec![WidthBand {
            band: "2to3m".into(),
            figures: vec![learner, opponent],
        }],
    }
}

/// `agvrl race --json` round-trips; the printed lines carry the shares computed from the counts,
/// and `none` where a share has nothing to divide by.
#[test]
fn race_report_round_trips_and_prints_its_shares() {
    let r = race();
    let back: agvrl_run::RaceReport = serde_json::from_str(&r.to_json()).unwrap();
    assert_eq!(back, r);
    let text = r.text();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 5, "{text}");
    assert!(
        lines[0].starts_with("env=racing-duel track=circuits cars=2 races=4 seed=7"),
        "{text}"
    );
    let l = lines[1];
    for kv in [
        "pass_success=0.75",
        "races_with_pass=2",
        "races_with_pass_share=0.50",
        "at_fault_share=0.25",
        "win_rate_from_behind=0.75",
        "contacts_per_race=0.50",
        "crashes_per_km=0.000",
        "mean_lap_s=40.12",
    ] {
        assert!(l.split(' ').any(|w| w == kv), "{kv} in {l}");
    }
    let o = lines[2];
    for kv in [
        "pass_success=none",
        "races_with_pass_share=0.00",
        "at_fault_share=none",
        "win_rate_from_behind=none",
        "crashes_per_km=4.000",
    ] {
        assert!(o.split(' ').any(|w| w == kv), "{kv} in {o}");
    }
    assert!(lines[3].starts_with("width=2to3m car=0 "), "{text}");
}

/// The width bands: at most 2 m, under 3 m, 3 m and more.
#[test]
fn width_bands_split_at_two_and_three_metres() {
    use agvrl_run::width_band;
    let got: Vec<&str> = [1.5, 2.0, 2.01, 2.99, 3.0, 3.5].into_iter().map(width_band).collect();
    assert_eq!(got, ["le2m", "le2m", "2to3m", "2to3m", "ge3m", "ge3m"]);
}
