//! `--racer pure-pursuit|follow-the-gap`: the classical racers of agvrl-envs (`drivers`) as
//! drivers of `agvrl eval`, on the same car, settings and held-out episodes as a policy. Their
//! controls reach the drive through the env's action mapping (and its safety filter, when on),
//! as a policy's actions do.

use crate::episode::{Observer, SimEnv, observe};
use agvrl_envs::drivers::Driver;
use agvrl_envs::{EnvConfig, Step, Vehicle};
use anyhow::{Context, Result};
use std::cell::RefCell;
use std::path::PathBuf;

/// Which classical racer drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RacerKind {
    /// Pure pursuit along a raceline (`--raceline`) or the track's centre line, at a speed
    /// profile from the car's limits: needs the pose (GPS) and the track.
    PurePursuit,
    /// Follow-the-gap from the LiDAR alone.
    FollowTheGap,
}

impl RacerKind {
    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::PurePursuit => "pure-pursuit",
            Self::FollowTheGap => "follow-the-gap",
        }
    }
}

/// What a racer needs besides the env: its path file and speed scale.
#[derive(Clone, Debug)]
pub struct RacerSpec {
    pub kind: RacerKind,
    /// Pure pursuit's path: F1TENTH's raceline CSV or an x, y CSV (None: the centre line).
    pub raceline: Option<PathBuf>,
    /// Scales the speed profile (pure pursuit) or the top speed (follow-the-gap).
    pub speed_scale: f64,
}

/// Build the racer `spec` for the car of `cfg`.
pub fn make(spec: &RacerSpec, cfg: &EnvConfig) -> Result<Box<dyn Driver>> {
    let kind = match spec.kind {
        RacerKind::PurePursuit => agvrl_envs::drivers::RacerKind::PurePursuit,
        RacerKind::FollowTheGap => agvrl_envs::drivers::RacerKind::FollowTheGap,
    };
    let text = match &spec.raceline {
        Some(p) => Some(std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?),
        None => None,
    };
    agvrl_envs::drivers::make_racer(kind, cfg, spec.speed_scale, text.as_deref()).map_err(|e| match &spec.raceline {
        Some(p) => anyhow::anyhow!("{}: {e}", p.display()),
        None => e.into(),
    })
}

/// Drive one episode of `env` with `racer`, reporting every step to `obs`.
pub fn drive(
    env: &mut SimEnv,
    racer: &mut dyn Driver,
    cfg: &EnvConfig,
    seed: u64,
    episode: usize,
    obs: &mut Observer<'_>,
) -> Result<(f64, Step)> {
    let next = RefCell::new(vec![0.0f32; 2]);
    let racer = RefCell::new(racer);
    agvrl_rl::eval::run_episode(
        env,
        seed,
        |_| Ok::<_, anyhow::Error>(next.borrow().clone()),
        |env, k, st| {
            observe(env, obs, episode, k, st, None)?;
            let inner = env.inner();
            let vehicle = inner.vehicle();
            let (Some(frame), map) = (inner.last_frame(), vehicle.map()) else {
                return Ok(());
            };
            let mut r = racer.borrow_mut();
            if k == 0 {
                r.reset(frame, map);
                if let Some(n) = r.raceline_points_moved() {
                    eprintln!("episode {episode}: raceline_points_moved={n}");
                }
            }
            let c = r.control(frame, map);
            let [a0, a1] = cfg.action_mapping.action(c, vehicle.steering_limit_rad());
            *next.borrow_mut() = vec![a0 as f32, a1 as f32];
            Ok(())
        },
    )
}
