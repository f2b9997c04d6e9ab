//! The `agvrl` command line (the `agvrl` binary, and the `agvrl` script of the Python wheel).

use crate::bench::{self, BenchPart};
use crate::{circuit, eval, policy_file, probe, race, train, view};
use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "agvrl", version, about = "Train autonomous ground vehicle policies with deep RL and run them on a real car.", long_about = None)]
struct Cli {
    #[command(subcommand)]
    cmd: Option<Cmd>,
}

#[derive(Subcommand)]
enum Cmd {
    /// Train a policy and leave a run directory under runs/ (or --out).
    Train(train::TrainArgs),
    /// Evaluate a trained run with deterministic actions; prints key=value lines.
    Eval(eval::EvalArgs),
    /// Drive one episode (a policy, or random actions) into the rerun viewer or an .rrd file.
    View(view::ViewArgs),
    /// Race policies against each other on one track (held-out races, deterministic actions);
    /// prints each car's wins, places, laps, passes and contacts.
    Race(race::RaceArgs),
    /// Print the settings a policy file drives with (env id, env settings), or write a copy
    /// with other settings embedded (--settings, --set, --out).
    Policy(policy_file::PolicyArgs),
    /// List the environment ids with their observation and action spaces.
    Envs,
    /// Write a generated circuit (racing-circuit's generator) as a map_server track: YAML, PNG
    /// and centre-line CSV.
    Circuit(circuit::CircuitArgs),
    /// Overlay the mean coverage over time of `eval --coverage-csv` files in one PNG.
    CoveragePlot {
        /// The PNG to write.
        #[arg(long, short)]
        out: std::path::PathBuf,
        /// Title above the plot.
        #[arg(long, default_value = "coverage over time")]
        title: String,
        /// CSV files, each as LABEL=FILE or FILE (labelled by its name).
        #[arg(required = true)]
        files: Vec<String>,
    },
    /// Print what the car senses at a pose (LiDAR scan, GPS, IMU) as JSON.
    Probe(probe::ProbeArgs),
    /// Measure speed: simulator, envs, learners; prints key=value lines.
    Bench {
        /// Short runs (a smoke test, not for reporting).
        #[arg(long)]
        quick: bool,
        /// Also run the learning checks (SAC, PPO with gSDE and Gaussian PPO on pendulum, 5 seeds each, scored on the 100 start states shared with SB3; ~15 minutes on 2 cores).
        #[arg(long)]
        learning: bool,
        /// Only this part (learning: the learning checks alone).
        #[arg(long, value_enum)]
        only: Option<BenchPart>,
        /// CPU backend of the learner figures.
        #[arg(long, value_enum, default_value_t = BackendArg::Flex)]
        backend: BackendArg,
    },
}

/// `bench --backend`: the CPU backend of the learner figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendArg {
    /// burn-flex.
    Flex,
    /// burn-ndarray (the `ndarray` feature).
    Ndarray,
}

impl BackendArg {
    /// The backend, or why this build lacks it.
    fn backend(self) -> agvrl_rl::Result<agvrl_rl::CpuBackend> {
        agvrl_rl::CpuBackend::parse(match self {
            Self::Flex => "flex",
            Self::Ndarray => "ndarray",
        })
    }
}

/// Run the CLI on `args` (the program name first); returns the exit status. `--help`,
/// `--version` and usage errors print as clap prints them.
pub fn main_with<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return e.exit_code();
        }
    };
    match run(cli) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {}", agvrl_run::error_line(e.as_ref()));
            1
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.cmd {
        None => train::train(train::TrainArgs::default()),
        Some(Cmd::Train(a)) => train::train(a),
        Some(Cmd::Eval(a)) => eval::eval(a),
        Some(Cmd::View(a)) => view::view(a),
        Some(Cmd::Race(a)) => race::race(a),
        Some(Cmd::Policy(a)) => policy_file::policy(a),
        Some(Cmd::Envs) => envs(),
        Some(Cmd::Circuit(a)) => circuit::circuit(a),
        Some(Cmd::Probe(a)) => probe::probe(a),
        Some(Cmd::CoveragePlot { out, title, files }) => coverage_plot(&out, &title, &files),
        Some(Cmd::Bench {
            quick,
            learning,
            only,
            backend,
        }) => bench::run(quick, learning, only, backend.backend()?),
    }
}

fn coverage_plot(out: &std::path::Path, title: &str, files: &[String]) -> Result<()> {
    use anyhow::Context;
    let mut series = Vec::new();
    for f in files {
        let (label, path) = match f.split_once('=') {
            Some((l, p)) => (l.to_string(), std::path::PathBuf::from(p)),
            None => {
                let p = std::path::PathBuf::from(f);
                let stem = p.file_stem().map_or(f.clone(), |s| s.to_string_lossy().into_owned());
                (stem, p)
            }
        };
        let csv = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        series.push((label, csv));
    }
    crate::plots::coverage_over_time(out, &series, title)?;
    println!("plot={}", out.display());
    Ok(())
}

/// `Box(DIM) in [LOW, HIGH]` of a space, for `agvrl envs`.
fn space_line(s: &agvrl_envs::BoxSpace) -> String {
    let lo = s.low.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = s.high.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    format!("Box({}) in [{lo}, {hi}]", s.dim())
}

fn envs() -> Result<()> {
    for id in agvrl_envs::ENV_IDS {
        let env = agvrl_envs::make(id, &agvrl_envs::EnvConfig::default())?;
        let (o, a) = (space_line(&env.observation_space()), space_line(&env.action_space()));
        println!("{id:<20} obs={o:<28} act={a}  dt={:.4}s", env.dt_s());
    }
    for id in agvrl_envs::MULTI_ENV_IDS {
        let env = agvrl_envs::make_multi(id, &agvrl_envs::EnvConfig::default())?;
        let (o, a) = (space_line(&env.observation_space()), space_line(&env.action_space()));
        println!(
            "{id:<20} obs={o:<28} act={a}  dt={:.4}s  agents={} (multi-agent: agvrl race, agvrl.make_multi)",
            env.dt_s(),
            env.n_agents()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::Cli;
    use clap::CommandFactory;

    #[test]
    fn command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }
}
