//! `agvrl race`: policies race each other (or themselves) on one track, deterministic actions,
//! held-out races; prints each car's wins, places, laps, lap times, encounters, passes,
//! at-fault incidents and contacts as `key=value` lines (docs/racing.md, "Race figures"), and
//! can draw the first race's paths and record it for rerun.

use crate::plots::{self, Path2};
use crate::viz::{self, Recorder};
use agvrl_envs::{MultiEnv as _, RaceSettings};
use agvrl_run::{CarFigures, PolicySettings, RaceReport, WIDTH_BANDS, WidthBand};
use anyhow::{Result, bail};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct RaceArgs {
    /// A policy file per car, or one for every car (repeat the flag).
    #[arg(long = "policy", required = true)]
    pub policies: Vec<PathBuf>,
    /// A classical racer as another car, after the policies' cars: `pure-pursuit` or
    /// `follow-the-gap`, optionally `@SCALE` of its speed (`--racer pure-pursuit@0.75`);
    /// repeat the flag for more. It drives the track's centre line or its LiDAR, its control
    /// applied as it is.
    #[arg(long = "racer", value_name = "KIND[@SCALE]")]
    pub racers: Vec<String>,
    /// Cars on the grid (default: one per policy, two for a single policy; 1 races a lone
    /// car, the lap times to compare with).
    #[arg(long)]
    pub cars: Option<usize>,
    /// Race on this map-file track (a map YAML) instead of the first policy's.
    #[arg(long, conflicts_with = "circuits")]
    pub track: Option<PathBuf>,
    /// Race on generated circuits, a new held-out one every race (the circuit generator's
    /// settings from the first policy's `circuit`, or its defaults).
    #[arg(long)]
    pub circuits: bool,
    /// Start every race in a passing situation: car 0 (the first policy's) 2 m behind car 1
    /// on the centre line, at a place along the lap drawn per race
    /// (`env_config.race.start_behind_share=1`; `start_behind_m` sets the gap).
    #[arg(long)]
    pub start_behind: bool,
    /// Races to run.
    #[arg(long, default_value_t = 10)]
    pub races: usize,
    /// Seed of the first race (held-out races: the grid order and any randomisation).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Race on the training half of the seed space instead of the held-out one (generated
    /// circuits and starts a training run can meet): where a recipe is chosen, so the
    /// held-out races stay a test.
    #[arg(long)]
    pub train_split: bool,
    /// Length of a race, control steps (default: the first policy's evaluation length).
    #[arg(long)]
    pub max_steps: Option<u64>,
    /// Draw the first race's paths, every car's, into this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Draw car 0's gap to every other car over the first race into this PNG: its passes
    /// (circles) and the contacts it caused (crosses) on the line.
    #[arg(long)]
    pub gap_plot: Option<PathBuf>,
    /// Record the first race for the rerun viewer into this .rrd file.
    #[arg(long)]
    pub rerun: Option<PathBuf>,
    /// Override a setting of the first policy's env config (KEY=VALUE, repeatable).
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Also write the figures as JSON (every car's, and per width band on generated circuits)
    /// into this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One car's tally over a set of races.
#[derive(Default)]
struct Tally {
    races: usize,
    place_sum: usize,
    laps: u64,
    lap_times: Vec<f64>,
    f: CarFigures,
}

impl Tally {
    /// Add car `i`'s figures of one race.
    fn add(&mut self, s: &agvrl_envs::RaceSummary, i: usize) {
        let place = s.order.iter().position(|&c| c == i).unwrap_or(s.order.len());
        let behind = s.start_place[i] > 1;
        let f = &mut self.f;
        self.races += 1;
        self.place_sum += place + 1;
        self.laps += s.laps[i] as u64;
        self.lap_times.extend(&s.lap_times_s[i]);
        f.wins += usize::from(place == 0);
        f.starts_behind += usize::from(behind);
        f.wins_from_behind += usize::from(behind && place == 0);
        if let Some(b) = s.best_lap_s[i] {
            f.best_lap_s = Some(f.best_lap_s.map_or(b, |x| x.min(b)));
        }
        f.encounters += s.encounters[i] as u64;
        f.passes += s.passes[i] as u64;
        f.races_with_pass += usize::from(s.passes[i] > 0);
        f.at_fault_incidents += s.at_fault_incidents(i) as u64;
        f.contacts += s.contacts[i] as u64;
        f.at_fault_contacts += s.at_fault[i] as u64;
        f.time_lost_s += s.time_lost_s[i];
        f.crashes += usize::from(s.crashed[i]);
        f.covered_km += s.covered_m[i].max(0.0) / 1000.0;
    }

    fn figures(&self, car: usize, policy: String) -> CarFigures {
        let n = self.races.max(1) as f64;
        CarFigures {
            car,
            policy,
            races: self.races,
            mean_place: self.place_sum as f64 / n,
            laps_per_race: self.laps as f64 / n,
            mean_lap_s: (!self.lap_times.is_empty())
                .then(|| self.lap_times.iter().sum::<f64>() / self.lap_times.len() as f64),
            ..self.f.clone()
        }
    }
}

pub fn race(a: RaceArgs) -> Result<()> {
    if a.races == 0 {
        bail!("--races must be at least 1");
    }
    let racer_specs = a.racers.iter().map(|r| racer_spec(r)).collect::<Result<Vec<_>>>()?;
    let policy_cars = match a.cars {
        Some(n) if n <= racer_specs.len() => bail!(
            "--cars {n} leaves no car for the policies beside {} racers",
            racer_specs.len()
        ),
        Some(n) => n - racer_specs.len(),
        None if racer_specs.is_empty() => a.policies.len().max(2),
        None => a.policies.len(),
    };
    let cars = policy_cars + racer_specs.len();
    if a.policies.len() > 1 && a.policies.len() != policy_cars {
        bail!(
            "{} policies for {policy_cars} cars: give one policy per car, or one for all",
            a.policies.len()
        );
    }
    let sets = [a.set.clone(), a.track.iter().map(|p| agvrl_run::track_set(p)).collect()].concat();
    let mut policies = Vec::new();
    let mut cfg = None;
    for (k, p) in a.policies.iter().enumerate() {
        let mut src = PolicySettings::resolve(None, Some(p), if k == 0 { &sets } else { &[] })?;
        policies.push(src.load_policy()?);
        if k == 0 {
            cfg = Some(src.eval_env_config());
        }
    }
    let Some(mut cfg) = cfg else {
        bail!("--policy is needed");
    };
    cfg.held_out = !a.train_split;
    let race = cfg.race.unwrap_or_default();
    cfg.race = Some(RaceSettings {
        cars,
        // A lone car (--cars 1) has nobody to start behind, whatever its training raced.
        start_behind_share: match (a.start_behind, cars) {
            (true, _) => 1.0,
            (false, 1) => 0.0,
            (false, _) => race.start_behind_share,
        },
        ..race
    });
    if a.circuits {
        cfg.track = None;
        cfg.layout_seed = None;
        cfg.circuit = Some(cfg.circuit.unwrap_or_default());
    }
    if let Some(n) = a.max_steps {
        if n == 0 {
            bail!("--max-steps must be at least 1");
        }
        cfg.max_steps = n;
    }
    let mut env = agvrl_envs::make_race("racing-duel", &cfg)?;
    let mut racers = racer_specs
        .iter()
        .map(|r| crate::racer::make(r, &cfg))
        .collect::<Result<Vec<_>>>()?;
    let car_name = |i: usize| match i.checked_sub(policy_cars) {
        Some(k) => racer_label(&racer_specs[k]),
        None => a.policies[if a.policies.len() == 1 { 0 } else { i }]
            .display()
            .to_string(),
    };
    for (k, p) in policies.iter().enumerate() {
        p.check_spaces(&env.observation_space(), &env.action_space())
            .map_err(|e| anyhow::anyhow!("{}: {e}", a.policies[k].display()))?;
    }
    let single = policies.len() == 1;
    let driver = move |i: usize| if single { 0 } else { i };
    let mut rec = match &a.rerun {
        Some(path) if viz::ENABLED => Some(Recorder::new(
            viz::Sink::File(path.clone()),
            &format!("race of {cars} on {}", cfg.track_suffix().trim_start_matches(" on ")),
            None,
        )?),
        Some(_) => bail!("this agvrl was built without rerun; rebuild with the default features"),
        None => None,
    };
    let mut paths: Vec<Path2> = Vec::new();
    let mut gaps: Vec<plots::GapSeries> = Vec::new();
    let mut tally: Vec<Tally> = (0..cars).map(|_| Tally::default()).collect();
    let mut bands: Vec<Vec<Tally>> = WIDTH_BANDS
        .iter()
        .map(|_| (0..cars).map(|_| Tally::default()).collect())
        .collect();
    for r in 0..a.races {
        let mut obs = env.reset(if r == 0 { Some(a.seed) } else { None })?;
        let first = r == 0;
        if first {
            paths = (0..cars)
                .map(|i| Path2 {
                    xy: vec![],
                    collided: false,
                    label: Some(match i < policy_cars {
                        true => format!("car {i}: {}", name(&a.policies[driver(i)])),
                        false => format!("car {i}: {}", car_name(i)),
                    }),
                })
                .collect();
            gaps = (1..cars)
                .map(|i| plots::GapSeries {
                    label: format!("car 0 against car {i}: {}", car_name(i)),
                    gap: vec![],
                    passes_s: vec![],
                    at_fault_s: vec![],
                })
                .collect();
        }
        let mut step = 0u64;
        // Car 0's distance, passes and contacts it caused so far, and every car's distance.
        let (mut passes0, mut fault0) = (0u32, 0u32);
        let mut distance: Vec<f64> = vec![0.0; cars];
        let summary = loop {
            if first {
                for (i, p) in paths.iter_mut().enumerate() {
                    let q = env.sim().car(i).pose2();
                    p.xy.push((q.x_m, q.y_m));
                }
                if let Some(rec) = rec.as_mut() {
                    let scans: Vec<_> = (0..cars).map(|i| env.frame_of(i).scan.as_ref()).collect();
                    rec.race_step(env.sim(), &scans, r, step)?;
                }
            }
            let mut actions = Vec::with_capacity(cars);
            for (i, o) in obs.iter().enumerate().take(policy_cars) {
                actions.push(match env.done(i) {
                    true => vec![0.0; 2],
                    false => policies[driver(i)].act(o, true)?,
                });
            }
            let mut controls = Vec::with_capacity(racers.len());
            for (k, r) in racers.iter_mut().enumerate() {
                let i = policy_cars + k;
                if step == 0 {
                    r.reset(env.frame_of(i), Some(env.map()));
                }
                controls.push(match env.done(i) {
                    true => agvrl_envs::Control::default(),
                    false => r.control(env.frame_of(i), Some(env.map())),
                });
            }
            let inputs: Vec<agvrl_envs::CarInput<'_>> = actions
                .iter()
                .map(|a| agvrl_envs::CarInput::Action(a))
                .chain(controls.iter().map(|&c| agvrl_envs::CarInput::Control(c)))
                .collect();
            let st = env.step_inputs(&inputs)?;
            step += 1;
            for (i, s) in st.agents.iter().enumerate() {
                if let Some(s) = s {
                    obs[i] = s.obs.clone();
                    if first && s.terminated {
                        paths[i].collided = true;
                    }
                    if let Some(r) = &s.info.race {
                        distance[i] = r.distance_m;
                    }
                }
            }
            if first && a.gap_plot.is_some() {
                let t = step as f64 * env.dt_s();
                let me = st.agents[0].as_ref().and_then(|s| s.info.race.as_ref());
                let (passed, hit) = me.map_or((false, false), |r| (r.passes > passes0, r.at_fault > fault0));
                if let Some(r) = me {
                    (passes0, fault0) = (r.passes, r.at_fault);
                }
                for (k, g) in gaps.iter_mut().enumerate() {
                    let gap = distance[0] - distance[k + 1];
                    g.gap.push((t, gap));
                    // The pass and the contact are with the car car 0 is nearest to.
                    let nearest = (1..cars).min_by(|&x, &y| {
                        (distance[0] - distance[x])
                            .abs()
                            .total_cmp(&(distance[0] - distance[y]).abs())
                    }) == Some(k + 1);
                    if passed && nearest {
                        g.passes_s.push(t);
                    }
                    if hit && nearest {
                        g.at_fault_s.push(t);
                    }
                }
            }
            if let Some(s) = st.summary {
                break s;
            }
        };
        let band = env.sim().circuit().map(|c| {
            WIDTH_BANDS
                .iter()
                .position(|&b| b == agvrl_run::width_band(c.width_m as f64))
                .unwrap_or(0)
        });
        for i in 0..cars {
            tally[i].add(&summary, i);
            if let Some(b) = band {
                bands[b][i].add(&summary, i);
            }
        }
    }
    let track = match &cfg.track {
        Some(t) => t.load()?.name,
        None if cfg.circuit.is_some() || cfg.layout_seed.is_some() => "circuits".into(),
        None => "oval".into(),
    };
    let report = RaceReport {
        env: "racing-duel".into(),
        track: track.clone(),
        cars,
        races: a.races,
        seed: a.seed,
        max_steps: cfg.max_steps,
        split: if cfg.held_out { "held_out" } else { "train" }.into(),
        figures: tally
            .iter()
            .enumerate()
            .map(|(i, t)| t.figures(i, car_name(i)))
            .collect(),
        by_width: WIDTH_BANDS
            .iter()
            .zip(&bands)
            .filter(|(_, b)| b[0].races > 0)
            .map(|(band, b)| WidthBand {
                band: band.to_string(),
                figures: b.iter().enumerate().map(|(i, t)| t.figures(i, car_name(i))).collect(),
            })
            .collect(),
    };
    print!("{}", report.text());
    if let Some(p) = &a.json {
        agvrl_run::write_atomic(p, report.to_json().as_bytes())?;
        println!("json={}", p.display());
    }
    if let Some(out) = &a.plot {
        let scene = env.sim().scene().clone();
        plots::trajectory(
            out,
            &scene,
            &paths,
            &format!("race of {cars} on {track}, seed {}", a.seed),
        )?;
        println!("plot={}", out.display());
    }
    if let Some(out) = &a.gap_plot {
        plots::race_gaps(out, &gaps, &format!("race 1 of {cars} on {track}, seed {}", a.seed))?;
        println!("gap_plot={}", out.display());
    }
    if let Some(rec) = rec
        && let Some(p) = rec.finish()?
    {
        println!("rerun={}", p.display());
    }
    Ok(())
}

/// `KIND[@SCALE]` of `--racer`.
fn racer_spec(text: &str) -> Result<crate::racer::RacerSpec> {
    let (kind, speed_scale) = agvrl_envs::drivers::parse_racer(text).map_err(|e| match e {
        agvrl_envs::EnvError::Config(m) => anyhow::anyhow!("--{m}"),
        e => e.into(),
    })?;
    Ok(crate::racer::RacerSpec {
        kind: match kind {
            agvrl_envs::drivers::RacerKind::PurePursuit => crate::racer::RacerKind::PurePursuit,
            agvrl_envs::drivers::RacerKind::FollowTheGap => crate::racer::RacerKind::FollowTheGap,
        },
        raceline: None,
        speed_scale,
    })
}

fn racer_label(r: &crate::racer::RacerSpec) -> String {
    format!("{}@{}", r.kind.name(), r.speed_scale)
}

/// A policy file's name without its directory (a run's policy.agvrl: the run's name).
fn name(p: &std::path::Path) -> String {
    match p.file_name().and_then(|f| f.to_str()) {
        Some("policy.agvrl") => p
            .parent()
            .and_then(|d| d.file_name())
            .map_or("policy.agvrl".into(), |d| d.to_string_lossy().into_owned()),
        Some(f) => f.to_string(),
        None => p.display().to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::Tally;

    fn summary(passes: [u32; 2]) -> agvrl_envs::RaceSummary {
        agvrl_envs::RaceSummary {
            order: vec![0, 1],
            laps: vec![0, 0],
            best_lap_s: vec![None, None],
            lap_times_s: vec![vec![], vec![]],
            distance_m: vec![10.0, 5.0],
            covered_m: vec![10.0, 5.0],
            start_place: vec![2, 1],
            encounters: vec![passes[0], 0],
            passes: passes.to_vec(),
            contacts: vec![0, 0],
            at_fault: vec![0, 0],
            time_lost_s: vec![0.0, 0.0],
            crashed: vec![false, false],
        }
    }

    /// A race with two passes counts once among the races with a pass; one without, not at all.
    #[test]
    fn a_race_with_passes_counts_once_among_races_with_a_pass() {
        let mut t = Tally::default();
        for p in [[2, 0], [0, 0], [1, 0]] {
            t.add(&summary(p), 0);
        }
        let f = t.figures(0, "p".into());
        assert_eq!((f.races, f.passes, f.races_with_pass), (3, 3, 2));
        assert_eq!(f.races_with_pass_share(), Some(2.0 / 3.0));
    }
}
