//! `TaskEnv<V, T>`: a `Vehicle` driven by a `Task` is an `Env`. The same code runs in simulation
//! and on the car; nothing here asks which vehicle it drives.

use crate::api::{BoxSpace, Env, EnvError, Info, SensorFrame, Step, Vehicle, validate_action};
use crate::task::Task;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// A vehicle, a task, and the episode's seed stream.
pub struct TaskEnv<V, T> {
    vehicle: V,
    task: T,
    rng: StdRng,
    ready: bool,
    last: Option<SensorFrame>,
    held_out: Option<bool>,
}

impl<V: Vehicle, T: Task> TaskEnv<V, T> {
    /// Combine a vehicle and a task.
    pub fn new(vehicle: V, task: T) -> Self {
        Self {
            vehicle,
            task,
            rng: StdRng::seed_from_u64(0),
            ready: false,
            last: None,
            held_out: None,
        }
    }

    /// Draw every episode seed from the evaluation half of the seed space (`true`) or the
    /// training half (`false`); see [`crate::heldout`]. Unset, seeds are used as drawn.
    pub fn with_held_out(mut self, held_out: bool) -> Self {
        self.held_out = Some(held_out);
        self
    }

    /// The vehicle.
    pub fn vehicle(&self) -> &V {
        &self.vehicle
    }

    /// The vehicle, mutably.
    pub fn vehicle_mut(&mut self) -> &mut V {
        &mut self.vehicle
    }

    /// The task.
    pub fn task(&self) -> &T {
        &self.task
    }

    /// The last sensor frame (after the last reset or step).
    pub fn last_frame(&self) -> Option<&SensorFrame> {
        self.last.as_ref()
    }
}

impl<V: Vehicle, T: Task> Env for TaskEnv<V, T> {
    fn observation_space(&self) -> BoxSpace {
        self.task.observation_space()
    }

    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(2, -1.0, 1.0)
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = StdRng::seed_from_u64(s);
        }
        let mut episode_seed: u64 = self.rng.random();
        if let Some(h) = self.held_out {
            episode_seed = crate::heldout::split(episode_seed, h);
        }
        let frame = self.vehicle.reset(episode_seed)?;
        self.task.needs().check(&frame)?;
        self.task.reset(&frame, self.vehicle.map());
        let obs = self.task.observe(&frame);
        self.last = Some(frame);
        self.ready = true;
        Ok((obs, Info::default()))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        let space = self.action_space();
        validate_action(&space, action)?;
        if !self.ready {
            return Err(EnvError::NeedsReset);
        }
        let mut a = action.to_vec();
        space.clamp(&mut a);
        let frame = self.last.as_ref().ok_or(EnvError::NeedsReset)?;
        let control = self.task.control(&a, self.vehicle.steering_limit_rad(), frame);
        let corrected_action = self.task.corrected_action();
        self.vehicle.actuate(control)?;
        let frame = self.vehicle.sense()?;
        self.task.needs().check(&frame)?;
        let out = self.task.evaluate(&frame, self.vehicle.map());
        let obs = self.task.observe(&frame);
        if !obs.iter().all(|v| v.is_finite()) {
            return Err(EnvError::Vehicle("observation is not finite".into()));
        }
        self.last = Some(frame);
        let terminated = out.termination.is_some();
        let truncated = out.truncate && !terminated;
        if terminated || truncated {
            self.ready = false;
        }
        Ok(Step {
            obs,
            reward: out.terms.total(),
            terminated,
            truncated,
            info: Info {
                reward_terms: out.terms,
                termination: out.termination,
                racing: out.racing,
                search: out.search,
                final_obs: None,
                corrected_action,
                ..Info::default()
            },
        })
    }

    fn dt_s(&self) -> f64 {
        self.vehicle.control_period_s()
    }
}
