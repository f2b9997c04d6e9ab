//! What an evaluation found, as one typed struct: `agvrl eval` prints it, a run directory keeps
//! it (eval.txt for people, eval.json for programs), the last `--progress json` line carries
//! it and Python reads it. The text is rendered from the struct and never parsed back.

use crate::error::{Result, RunError};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::Path;

/// A deterministic evaluation's figures. In JSON the groups are flattened: one object whose
/// keys are the text's keys (`subjects_found=3/5` becomes `subjects_found` and
/// `subjects_placed`; `coverage_25_reached=3/10` counts the episodes, of `episodes`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// Mean undiscounted return per episode.
    pub mean_return: f64,
    /// Episodes evaluated.
    pub episodes: usize,
    /// Episodes that ended in a termination (anything but the time limit).
    pub collisions: usize,
    /// Why each episode ended, in order: `time_limit`, `contact`, `too_close`, ...
    pub ended: Vec<String>,
    /// Search envs with subjects to find.
    #[serde(flatten)]
    pub subjects: Option<SubjectsReport>,
    /// Search envs.
    #[serde(flatten)]
    pub search: Option<SearchReport>,
    /// Search envs driven through the LiDAR safety filter.
    #[serde(flatten)]
    pub filter: Option<FilterReport>,
    /// Racing envs.
    #[serde(flatten)]
    pub racing: Option<RacingReport>,
}

/// Subjects found against subjects placed, summed over episodes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SubjectsReport {
    /// Subjects found.
    pub subjects_found: usize,
    /// Subjects placed.
    pub subjects_placed: usize,
    /// Mean time to a find, s (`None`: nothing found).
    pub mean_find_s: Option<f64>,
}

/// Coverage and the ride of a search evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SearchReport {
    /// Mean final coverage: the fraction of free 0.5 m cells that came within 2 m of the car.
    pub coverage: f64,
    /// Mean path length per episode, m.
    pub distance_m_per_episode: f64,
    /// Mean and 5th percentile (nearest rank) of r_m after every step, m (`None`: no finite r_m).
    pub clearance_mean_m: Option<f64>,
    /// See `clearance_mean_m`.
    pub clearance_p5_m: Option<f64>,
    /// Mean |change of the steering sent| from one control to the next, rad.
    pub steering_change_mean_rad: f64,
    /// Mean time to 25 % coverage over the episodes that reached it, s (`None`: none did).
    pub time_to_coverage_25_s: Option<f64>,
    /// Episodes that reached 25 % coverage.
    pub coverage_25_reached: usize,
    /// Mean time to 50 % coverage over the episodes that reached it, s (`None`: none did).
    pub time_to_coverage_50_s: Option<f64>,
    /// Episodes that reached 50 % coverage.
    pub coverage_50_reached: usize,
}

/// What the safety filter did, per episode.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FilterReport {
    /// Controls the filter changed in any way.
    pub filter_interventions_per_episode: f64,
    /// Controls it steered or braked (`filter_steered + filter_braked`).
    pub filter_corrections_per_episode: f64,
    /// Controls it steered.
    pub filter_steered_per_episode: f64,
    /// Controls it braked.
    pub filter_braked_per_episode: f64,
    /// Back-outs begun.
    pub filter_backouts_per_episode: f64,
    /// Reversing ticks of back-outs.
    pub filter_backout_ticks_per_episode: f64,
}

/// Laps of a racing evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RacingReport {
    /// Laps completed, summed over episodes.
    pub laps: u32,
    /// The best lap, s (`None`: no lap completed).
    pub best_lap_s: Option<f64>,
    /// Episodes that completed a lap and ended without a crash (0 in files written before it
    /// was counted).
    #[serde(default)]
    pub lapped: usize,
    /// The mean over episodes with a lap of each one's first lap, s.
    #[serde(default)]
    pub mean_first_lap_s: Option<f64>,
}

/// A run directory's evaluation: the run's timings, then [`EvalReport`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunReport {
    /// Training wall time of this session, s.
    pub train_s: f64,
    /// Evaluation (and plotting) wall time, s.
    pub eval_s: f64,
    /// The learner's environment steps.
    pub steps: u64,
    /// Stopped (Ctrl-C, a dead parent) before its target steps.
    #[serde(default)]
    pub interrupted: bool,
    /// The run's own deterministic evaluation.
    #[serde(flatten)]
    pub eval: EvalReport,
}

fn opt(v: Option<f64>, decimals: usize, none: &str) -> String {
    v.map_or_else(|| none.to_string(), |x| format!("{x:.decimals$}"))
}

impl EvalReport {
    /// `agvrl eval --json`: eval.json's keys less the run's timings, at full precision.
    pub fn to_json(&self) -> String {
        // Every field is a number, a string, a bool or a list of them: serialising cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// The `key=value` lines `agvrl eval` prints, numbers rounded for reading.
    pub fn lines(&self) -> Vec<String> {
        let mut v = vec![
            format!("mean_return={:.2}", self.mean_return),
            format!("episodes={}", self.episodes),
            format!("collisions={}", self.collisions),
            format!("ended={}", self.ended.join(",")),
        ];
        if let Some(s) = &self.subjects {
            v.push(format!("subjects_found={}/{}", s.subjects_found, s.subjects_placed));
            if let Some(t) = s.mean_find_s {
                v.push(format!("mean_find_s={t:.2}"));
            }
        }
        if let Some(s) = &self.search {
            v.push(format!("coverage={:.3}", s.coverage));
            v.push(format!("distance_m_per_episode={:.1}", s.distance_m_per_episode));
        }
        if let Some(f) = &self.filter {
            v.push(format!(
                "filter_interventions_per_episode={:.1}",
                f.filter_interventions_per_episode
            ));
            v.push(format!(
                "filter_corrections_per_episode={:.1}",
                f.filter_corrections_per_episode
            ));
            v.push(format!(
                "filter_steered_per_episode={:.1}",
                f.filter_steered_per_episode
            ));
            v.push(format!("filter_braked_per_episode={:.1}", f.filter_braked_per_episode));
            v.push(format!(
                "filter_backouts_per_episode={:.2}",
                f.filter_backouts_per_episode
            ));
            v.push(format!(
                "filter_backout_ticks_per_episode={:.1}",
                f.filter_backout_ticks_per_episode
            ));
        }
        if let Some(s) = &self.search {
            if let (Some(mean), Some(p5)) = (s.clearance_mean_m, s.clearance_p5_m) {
                v.push(format!("clearance_mean_m={mean:.3}"));
                v.push(format!("clearance_p5_m={p5:.3}"));
            }
            v.push(format!("steering_change_mean_rad={:.4}", s.steering_change_mean_rad));
            for (pct, t, n) in [
                (25, s.time_to_coverage_25_s, s.coverage_25_reached),
                (50, s.time_to_coverage_50_s, s.coverage_50_reached),
            ] {
                v.push(format!("time_to_coverage_{pct}_s={}", opt(t, 1, "not_reached")));
                v.push(format!("coverage_{pct}_reached={n}/{}", self.episodes));
            }
        }
        if let Some(r) = &self.racing {
            v.push(format!("laps={}", r.laps));
            v.push(format!("best_lap_s={}", opt(r.best_lap_s, 2, "none")));
            v.push(format!("lapped={}/{}", r.lapped, self.episodes));
            v.push(format!("mean_first_lap_s={}", opt(r.mean_first_lap_s, 2, "none")));
        }
        v
    }
}

impl RunReport {
    /// eval.txt: the run's timings, then the evaluation's lines.
    pub fn text(&self) -> String {
        let mut t = format!(
            "train_s={:.1}\neval_s={:.1}\nsteps={}\n",
            self.train_s, self.eval_s, self.steps
        );
        if self.interrupted {
            t.push_str("interrupted=true\n");
        }
        for l in self.eval.lines() {
            let _ = writeln!(t, "{l}");
        }
        t
    }

    /// eval.json: every figure at full precision.
    pub fn to_json(&self) -> String {
        // Every field is a number, a string, a bool or a list of them: serialising cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Read a run directory's eval.json.
    pub fn load(path: &Path) -> Result<Self> {
        read_json(path, |e| RunError::RunDir(format!("{}: {e}", path.display())))
    }
}

/// A JSON report at `path`; `bad` words a file that does not parse as one.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(
    path: &Path,
    bad: impl FnOnce(serde_json::Error) -> RunError,
) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|source| RunError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    serde_json::from_str(&text).map_err(bad)
}
