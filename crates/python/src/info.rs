//! `Info` as Python sees it: a flat dict of plain values for one env, and Gymnasium's vector
//! form (a dict of numpy arrays, one entry per env, with a `_key` mask) for a batch.

use agvrl_envs::Info;
use agvrl_envs::api::{RewardTerms, TerminationCause};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Termination causes by code; code 0 is "none", code `k` is `CAUSES[k - 1]`.
pub const CAUSES: [&str; 4] = ["contact", "too_close", "flipped", "out_of_bounds"];

fn cause(c: TerminationCause) -> &'static str {
    match c {
        TerminationCause::Contact => CAUSES[0],
        TerminationCause::TooClose => CAUSES[1],
        TerminationCause::Flipped => CAUSES[2],
        TerminationCause::OutOfBounds => CAUSES[3],
    }
}

fn code(c: Option<TerminationCause>) -> i8 {
    c.map_or(0, |c| {
        CAUSES.iter().position(|n| *n == cause(c)).map_or(0, |k| k as i8 + 1)
    })
}

fn terms(t: &RewardTerms) -> [(&'static str, f64); 13] {
    [
        ("throttle", t.throttle),
        ("steering", t.steering),
        ("clearance", t.clearance),
        ("band", t.band),
        ("collision", t.collision),
        ("slow", t.slow),
        ("proximity", t.proximity),
        ("coverage", t.coverage),
        ("filter", t.filter),
        ("stale", t.stale),
        ("progress", t.progress),
        ("car_contact", t.car_contact),
        ("position", t.position),
    ]
}

/// Which metrics an env reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Racing,
    Search,
    Other,
}

impl Kind {
    pub fn of(id: &str) -> Self {
        match agvrl_envs::registry::spec(id).map(|s| s.task) {
            Some(agvrl_envs::TaskKind::Racing) => Kind::Racing,
            Some(agvrl_envs::TaskKind::Search) => Kind::Search,
            _ => Kind::Other,
        }
    }
}

/// One env's info: `reward_terms` (a dict), `termination` (a cause name, on a terminating step),
/// racing (`laps`, `progress_laps`, `last_lap_s`, `best_lap_s`) or search (`coverage`,
/// `distance_m`, `subjects_found`, `subjects_total`, `find_times_s`, `filter_interventions`) metrics, a car's
/// standing in a race (`race`: `position`, `distance_m`, `contacts`, `at_fault`, `encounters`,
/// `passes`, `time_lost_s`, `crashed`), and `episode` (`r`, `l`) on the step that ends an episode.
pub fn single<'py>(py: Python<'py>, info: &Info) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let rt = PyDict::new(py);
    for (k, v) in terms(&info.reward_terms) {
        rt.set_item(k, v)?;
    }
    d.set_item("reward_terms", rt)?;
    if let Some(c) = info.termination {
        d.set_item("termination", cause(c))?;
    }
    if let Some(r) = &info.racing {
        d.set_item("laps", r.laps)?;
        d.set_item("progress_laps", r.progress_laps)?;
        if let Some(x) = r.last_lap_s {
            d.set_item("last_lap_s", x)?;
        }
        if let Some(x) = r.best_lap_s {
            d.set_item("best_lap_s", x)?;
        }
    }
    if let Some(s) = &info.search {
        d.set_item("coverage", s.coverage)?;
        d.set_item("distance_m", s.distance_m)?;
        d.set_item("subjects_found", s.subjects_found)?;
        d.set_item("subjects_total", s.subjects_total)?;
        d.set_item("find_times_s", s.find_times_s.clone())?;
        d.set_item("filter_interventions", s.filter_interventions)?;
    }
    if let Some(r) = &info.race {
        let race = PyDict::new(py);
        race.set_item("position", r.position)?;
        race.set_item("distance_m", r.distance_m)?;
        race.set_item("contacts", r.contacts)?;
        race.set_item("at_fault", r.at_fault)?;
        race.set_item("encounters", r.encounters)?;
        race.set_item("passes", r.passes)?;
        race.set_item("time_lost_s", r.time_lost_s)?;
        race.set_item("crashed", r.crashed)?;
        d.set_item("race", race)?;
    }
    if let Some(e) = &info.episode {
        let ep = PyDict::new(py);
        ep.set_item("r", e.ret)?;
        ep.set_item("l", e.len)?;
        d.set_item("episode", ep)?;
    }
    Ok(d)
}

/// Set `key` to `values` and `_key` to `mask`.
fn put<'py, T: numpy::Element>(d: &Bound<'py, PyDict>, key: &str, values: Vec<T>, mask: Vec<bool>) -> PyResult<()> {
    let py = d.py();
    d.set_item(key, PyArray1::from_vec(py, values))?;
    d.set_item(format!("_{key}"), PyArray1::from_vec(py, mask))
}

/// Gymnasium's vector info for `infos` (env `i` where `only[i]`, all without `only`): every
/// value an array with one entry per env and a `_key` mask of the envs that report it.
/// `termination` holds codes (0 none, `k` = `TERMINATION_CAUSES[k - 1]`). Envs whose episode
/// ended carry `episode` (`r`, `l`); under same-step auto-reset `final_obs` (an object array)
/// and `final_info` (this same form) hold what the ended episodes' last step reported.
pub fn batch<'py>(py: Python<'py>, kind: Kind, infos: &[Info], only: Option<&[bool]>) -> PyResult<Bound<'py, PyDict>> {
    let n = infos.len();
    let has = |i: usize| only.is_none_or(|m| m[i]);
    let all: Vec<bool> = (0..n).map(has).collect();
    let d = PyDict::new(py);
    let rt = PyDict::new(py);
    for (k, name) in terms(&RewardTerms::default()).iter().map(|x| x.0).enumerate() {
        rt.set_item(
            name,
            PyArray1::from_vec(py, infos.iter().map(|i| terms(&i.reward_terms)[k].1).collect()),
        )?;
    }
    d.set_item("reward_terms", rt)?;
    d.set_item("_reward_terms", PyArray1::from_vec(py, all.clone()))?;
    let codes: Vec<i8> = infos.iter().map(|i| code(i.termination)).collect();
    let ended: Vec<bool> = codes.iter().map(|&c| c > 0).collect();
    put(&d, "termination", codes, ended)?;
    match kind {
        Kind::Racing => {
            let r = |f: &dyn Fn(&agvrl_envs::api::RacingInfo) -> f64| -> (Vec<f64>, Vec<bool>) {
                let v = infos
                    .iter()
                    .map(|i| i.racing.as_ref().map_or(f64::NAN, f))
                    .collect::<Vec<_>>();
                let m = infos
                    .iter()
                    .enumerate()
                    .map(|(k, i)| has(k) && i.racing.is_some())
                    .collect();
                (v, m)
            };
            let laps = infos
                .iter()
                .map(|i| i.racing.as_ref().map_or(0, |x| i64::from(x.laps)))
                .collect();
            put(&d, "laps", laps, r(&|_| 0.0).1)?;
            let (v, m) = r(&|x| x.progress_laps);
            put(&d, "progress_laps", v, m)?;
            for (key, get) in [
                (
                    "last_lap_s",
                    (|x: &agvrl_envs::api::RacingInfo| x.last_lap_s) as fn(&_) -> Option<f64>,
                ),
                ("best_lap_s", |x| x.best_lap_s),
            ] {
                let v = infos
                    .iter()
                    .map(|i| i.racing.as_ref().and_then(get).unwrap_or(f64::NAN))
                    .collect::<Vec<_>>();
                let m = v.iter().enumerate().map(|(k, x)| has(k) && !x.is_nan()).collect();
                put(&d, key, v, m)?;
            }
        }
        Kind::Search => {
            let m: Vec<bool> = infos
                .iter()
                .enumerate()
                .map(|(k, i)| has(k) && i.search.is_some())
                .collect();
            let s = |f: &dyn Fn(&agvrl_envs::api::SearchInfo) -> f64| -> Vec<f64> {
                infos.iter().map(|i| i.search.as_ref().map_or(f64::NAN, f)).collect()
            };
            put(&d, "coverage", s(&|x| x.coverage), m.clone())?;
            put(&d, "distance_m", s(&|x| x.distance_m), m.clone())?;
            let c = |f: &dyn Fn(&agvrl_envs::api::SearchInfo) -> usize| -> Vec<i64> {
                infos.iter().map(|i| i.search.as_ref().map_or(0, f) as i64).collect()
            };
            put(&d, "subjects_found", c(&|x| x.subjects_found), m.clone())?;
            put(&d, "subjects_total", c(&|x| x.subjects_total), m.clone())?;
            put(&d, "filter_interventions", c(&|x| x.filter_interventions as usize), m)?;
        }
        Kind::Other => {}
    }
    if infos.iter().any(|i| i.episode.is_some()) {
        let ep = PyDict::new(py);
        ep.set_item(
            "r",
            PyArray1::from_vec(py, infos.iter().map(|i| i.episode.map_or(0.0, |e| e.ret)).collect()),
        )?;
        ep.set_item(
            "l",
            PyArray1::from_vec(
                py,
                infos.iter().map(|i| i.episode.map_or(0, |e| e.len as i64)).collect(),
            ),
        )?;
        d.set_item("episode", ep)?;
        d.set_item(
            "_episode",
            PyArray1::from_vec(py, infos.iter().map(|i| i.episode.is_some()).collect()),
        )?;
    }
    if infos.iter().any(|i| i.final_obs.is_some()) {
        let objs: Vec<Py<PyAny>> = infos
            .iter()
            .map(|i| match &i.final_obs {
                Some(o) => PyArray1::from_slice(py, o).into_any().unbind(),
                None => py.None(),
            })
            .collect();
        let mask: Vec<bool> = infos.iter().map(|i| i.final_obs.is_some()).collect();
        d.set_item("final_obs", PyArray1::from_vec(py, objs))?;
        d.set_item("_final_obs", PyArray1::from_vec(py, mask.clone()))?;
        let plain: Vec<Info> = infos
            .iter()
            .map(|i| Info {
                final_obs: None,
                ..i.clone()
            })
            .collect();
        let fi = batch(py, kind, &plain, Some(&mask))?;
        d.set_item("final_info", fi)?;
        d.set_item("_final_info", PyArray1::from_vec(py, mask))?;
    }
    Ok(d)
}

/// A race's results (`RaceSummary`) as a dict of per-car lists.
pub fn race_summary<'py>(py: Python<'py>, s: &agvrl_envs::RaceSummary) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("order", s.order.clone())?;
    d.set_item("laps", s.laps.clone())?;
    d.set_item("best_lap_s", s.best_lap_s.clone())?;
    d.set_item("lap_times_s", s.lap_times_s.clone())?;
    d.set_item("distance_m", s.distance_m.clone())?;
    d.set_item("start_place", s.start_place.clone())?;
    d.set_item("encounters", s.encounters.clone())?;
    d.set_item("passes", s.passes.clone())?;
    d.set_item("contacts", s.contacts.clone())?;
    d.set_item("at_fault", s.at_fault.clone())?;
    d.set_item("time_lost_s", s.time_lost_s.clone())?;
    d.set_item("crashed", s.crashed.clone())?;
    Ok(d)
}
