//! What `agvrl race` found, as one typed struct: printed as `key=value` lines and written as
//! JSON by `--json` (docs/racing.md, "Race figures"). The text is rendered from the struct and
//! never parsed back.

use crate::error::{Result, RunError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A set of races and every car's figures over them.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RaceReport {
    /// The multi-car env raced.
    pub env: String,
    /// The track's name, `circuits` for generated circuits, `oval` for the oval.
    pub track: String,
    /// Cars per race.
    pub cars: usize,
    /// Races run.
    pub races: usize,
    /// Seed of the first race.
    pub seed: u64,
    /// Length of a race, control steps.
    pub max_steps: u64,
    /// `held_out` or `train`: which half of the seed space the races came from.
    pub split: String,
    /// Every car's figures over all the races, car 0 first.
    pub figures: Vec<CarFigures>,
    /// On generated circuits, the same figures per band of track width.
    pub by_width: Vec<WidthBand>,
}

/// The races run on circuits of one band of track width.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WidthBand {
    /// `le2m` (at most 2 m), `2to3m` or `ge3m` (at least 3 m).
    pub band: String,
    /// Every car's figures over this band's races.
    pub figures: Vec<CarFigures>,
}

/// One car's figures over a set of races (docs/racing.md, "Race figures").
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CarFigures {
    /// Car index on the grid.
    pub car: usize,
    /// Who drove it: a policy file or a classical racer (`pure-pursuit@0.75`).
    pub policy: String,
    /// Races in this set.
    pub races: usize,
    /// Races won.
    pub wins: usize,
    /// Mean finishing place, 1 first.
    pub mean_place: f64,
    /// Laps completed per race.
    pub laps_per_race: f64,
    /// Mean time of every completed lap, seconds.
    pub mean_lap_s: Option<f64>,
    /// Fastest lap, seconds.
    pub best_lap_s: Option<f64>,
    /// Encounters begun as the car behind.
    pub encounters: u64,
    /// Passes made.
    pub passes: u64,
    /// Races in which it made at least one pass.
    #[serde(default)]
    pub races_with_pass: usize,
    /// Contacts its front caused, and its own crashes.
    pub at_fault_incidents: u64,
    /// Races started behind another car.
    pub starts_behind: usize,
    /// Of those, races won.
    pub wins_from_behind: usize,
    /// Contacts with other cars begun.
    pub contacts: u64,
    /// Of those, caused by its front.
    pub at_fault_contacts: u64,
    /// Time lost to contacts, seconds, over all races.
    pub time_lost_s: f64,
    /// Races that ended in its crash.
    pub crashes: usize,
    /// Ground covered along the centre line, kilometres.
    pub covered_km: f64,
}

impl CarFigures {
    /// Passes per encounter.
    pub fn pass_success(&self) -> Option<f64> {
        share(self.passes, self.encounters)
    }

    /// At-fault incidents per pass or at-fault incident.
    pub fn at_fault_share(&self) -> Option<f64> {
        share(self.at_fault_incidents, self.passes + self.at_fault_incidents)
    }

    /// Races with at least one pass, per race.
    pub fn races_with_pass_share(&self) -> Option<f64> {
        share(self.races_with_pass as u64, self.races as u64)
    }

    /// Wins per start behind.
    pub fn win_rate_from_behind(&self) -> Option<f64> {
        share(self.wins_from_behind as u64, self.starts_behind as u64)
    }

    /// Crashes per kilometre covered.
    pub fn crashes_per_km(&self) -> Option<f64> {
        (self.covered_km > 0.0).then(|| self.crashes as f64 / self.covered_km)
    }

    /// The figures as one line of `key=value` pairs, `prefix` first.
    pub fn line(&self, prefix: &str) -> String {
        let n = self.races.max(1) as f64;
        let opt = |v: Option<f64>| v.map_or("none".to_string(), |v| format!("{v:.2}"));
        format!(
            "{prefix}car={} policy={} races={} wins={} win_rate={:.2} mean_place={:.2} laps_per_race={:.2} mean_lap_s={} best_lap_s={} encounters={} passes={} pass_success={} races_with_pass={} races_with_pass_share={} at_fault_incidents={} at_fault_share={} starts_behind={} wins_from_behind={} win_rate_from_behind={} contacts_per_race={:.2} at_fault_per_race={:.2} time_lost_s_per_race={:.2} crashes={} covered_km={:.2} crashes_per_km={}",
            self.car,
            self.policy,
            self.races,
            self.wins,
            self.wins as f64 / n,
            self.mean_place,
            self.laps_per_race,
            opt(self.mean_lap_s),
            opt(self.best_lap_s),
            self.encounters,
            self.passes,
            opt(self.pass_success()),
            self.races_with_pass,
            opt(self.races_with_pass_share()),
            self.at_fault_incidents,
            opt(self.at_fault_share()),
            self.starts_behind,
            self.wins_from_behind,
            opt(self.win_rate_from_behind()),
            self.contacts as f64 / n,
            self.at_fault_contacts as f64 / n,
            self.time_lost_s / n,
            self.crashes,
            self.covered_km,
            self.crashes_per_km().map_or("none".to_string(), |v| format!("{v:.3}")),
        )
    }
}

fn share(a: u64, b: u64) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

impl RaceReport {
    /// The printed form: a header line, each car's line, then each width band's car lines.
    pub fn text(&self) -> String {
        let mut t = format!(
            "env={} track={} cars={} races={} seed={} max_steps={} split={}\n",
            self.env, self.track, self.cars, self.races, self.seed, self.max_steps, self.split
        );
        for f in &self.figures {
            t.push_str(&f.line(""));
            t.push('\n');
        }
        for b in &self.by_width {
            for f in &b.figures {
                t.push_str(&f.line(&format!("width={} ", b.band)));
                t.push('\n');
            }
        }
        t
    }

    /// Every figure at full precision.
    pub fn to_json(&self) -> String {
        // Numbers, strings and lists of them: serialising cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Read a report `agvrl race --json` wrote.
    pub fn load(path: &Path) -> Result<Self> {
        crate::report::read_json(path, |e| {
            RunError::Config(format!("{}: not a race report: {e}", path.display()))
        })
    }
}

/// The width bands, narrowest first (see [`WidthBand::band`]).
pub const WIDTH_BANDS: [&str; 3] = ["le2m", "2to3m", "ge3m"];

/// The width band of a circuit `width_m` wide.
pub fn width_band(width_m: f64) -> &'static str {
    WIDTH_BANDS[usize::from(width_m > 2.0) + usize::from(width_m >= 3.0)]
}
