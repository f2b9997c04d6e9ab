//! Driving episodes for evaluation and viewing, with a look into the simulator at every step
//! (pose, scan, camera) for plots and rerun recordings.

use agvrl_envs::task::{Intervention, Task};
use agvrl_envs::wrappers::TimeLimit;
use agvrl_envs::{EnvConfig, Info, SensorFrame, SimCar, Step, TaskEnv, Vehicle, make, make_sim_car, make_task};
use agvrl_sim::Sim;
use anyhow::Result;
use rand_xoshiro::SplitMix64;
use rand_xoshiro::rand_core::{Rng as _, SeedableRng};

/// A vehicle env as `agvrl_envs::make` builds it, with its simulated car's type kept so the
/// simulator behind it can be inspected.
pub type SimEnv = TimeLimit<TaskEnv<SimCar, Box<dyn Task>>>;

/// Build vehicle env `id` like `agvrl_envs::make` does; `None` for envs without a vehicle.
pub fn make_sim_env(id: &str, cfg: &EnvConfig) -> Result<Option<SimEnv>> {
    if agvrl_envs::registry::scene_of(id).is_none() {
        // Still validates the id (and names the valid ones).
        make(id, cfg)?;
        return Ok(None);
    }
    let vehicle = make_sim_car(id, cfg)?;
    let task = make_task(id, cfg, vehicle.steering_limit_rad())?;
    Ok(Some(TimeLimit::new(
        TaskEnv::new(vehicle, task).with_held_out(cfg.held_out),
        cfg.max_steps,
    )))
}

/// One control step as viewers see it.
pub struct StepView<'a> {
    /// Episode index (from 0).
    pub episode: usize,
    /// Step within the episode; 0 is the state right after reset.
    pub step: u64,
    /// Reward of this step (0 after reset).
    pub reward: f64,
    /// What the vehicle sensed after the step.
    pub frame: &'a SensorFrame,
    /// The simulator (ground-truth pose, scene).
    pub sim: &'a Sim,
    /// Whether the episode ends here.
    pub done: bool,
    /// Whether it ended by termination (a collision).
    pub terminated: bool,
    /// The step's info (`None` right after reset).
    pub info: Option<&'a Info>,
    /// What the driver saw and did for this step (`None` right after reset, and for drivers
    /// without observations, as the planner).
    pub acted: Option<&'a Acted>,
    /// What the safety filter did to this step's control.
    pub intervention: Intervention,
}

/// The observation a driver acted on, its action, and how long it took.
#[derive(Clone, Debug, Default)]
pub struct Acted {
    pub observation: Vec<f32>,
    pub action: Vec<f32>,
    pub act_us: f64,
}

/// Called at every step of every episode.
pub type Observer<'a> = dyn FnMut(&StepView<'_>) -> Result<()> + 'a;

/// Report the current state of `env` to `obs`.
/// `st` is the step taken (`None` right after reset, `step` 0).
pub fn observe(
    env: &SimEnv,
    obs: &mut Observer<'_>,
    episode: usize,
    step: u64,
    st: Option<&Step>,
    acted: Option<&Acted>,
) -> Result<()> {
    let inner = env.inner();
    if let Some(frame) = inner.last_frame() {
        let sim = inner.vehicle().sim();
        obs(&StepView {
            episode,
            step,
            reward: st.map_or(0.0, |s| s.reward),
            frame,
            sim,
            done: st.is_some_and(|s| s.done()),
            terminated: st.is_some_and(|s| s.terminated),
            info: st.map(|s| &s.info),
            acted: acted.filter(|_| st.is_some()),
            intervention: if st.is_some() {
                inner.task().intervention()
            } else {
                Intervention::None
            },
        })?;
    }
    Ok(())
}

/// Forward speed of the base, m/s.
pub fn speed_mps(frame: &SensorFrame) -> f64 {
    frame.imu.as_ref().map_or(0.0, |i| i.lin_vel_b[0])
}

/// Uniform random actions in a box (`eval --random`, the `view` command without a policy),
/// seeded: rand_xoshiro's SplitMix64, 24 bits per element.
pub struct RandomActions {
    rng: SplitMix64,
}

impl RandomActions {
    pub fn new(seed: u64) -> Self {
        Self {
            rng: SplitMix64::seed_from_u64(seed ^ 0x2545_f491_4f6c_dd1d),
        }
    }

    pub fn sample(&mut self, low: &[f32], high: &[f32]) -> Vec<f32> {
        low.iter()
            .zip(high)
            .map(|(&l, &h)| {
                let u = (self.rng.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
                l + u * (h - l)
            })
            .collect()
    }
}

/// Drive one episode of `env` with `act`, reporting every step. Returns the return and the
/// last step.
pub fn drive(
    env: &mut SimEnv,
    seed: u64,
    episode: usize,
    act: &mut dyn FnMut(&[f32]) -> Result<Vec<f32>>,
    obs: &mut Observer<'_>,
) -> Result<(f64, Step)> {
    let last = std::cell::RefCell::new(Acted::default());
    let timed = |o: &[f32]| {
        let t0 = std::time::Instant::now();
        let action = act(o)?;
        let act_us = t0.elapsed().as_secs_f64() * 1e6;
        let mut l = last.borrow_mut();
        l.observation.clear();
        l.observation.extend_from_slice(o);
        l.action.clone_from(&action);
        l.act_us = act_us;
        Ok(action)
    };
    agvrl_rl::eval::run_episode(env, seed, timed, |env, k, st| {
        observe(env, obs, episode, k, st, Some(&last.borrow()))
    })
}
