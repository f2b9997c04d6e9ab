use crate::api::{BoxSpace, Env, EnvError, Info, Step};

/// Truncates episodes after `max_steps` steps (Gymnasium's `TimeLimit`, the only source of
/// truncation). A step that both terminates and hits the limit is reported as terminated only.
pub struct TimeLimit<E> {
    inner: E,
    max_steps: u64,
    elapsed: u64,
}

impl<E: Env> TimeLimit<E> {
    /// Wrap `inner`, cutting episodes at `max_steps` steps.
    pub fn new(inner: E, max_steps: u64) -> Self {
        Self {
            inner,
            max_steps,
            elapsed: 0,
        }
    }

    /// The wrapped env.
    pub fn inner(&self) -> &E {
        &self.inner
    }

    /// The wrapped env, mutably.
    pub fn inner_mut(&mut self) -> &mut E {
        &mut self.inner
    }

    /// Steps taken in the current episode.
    pub fn elapsed(&self) -> u64 {
        self.elapsed
    }
}

impl<E: Env> Env for TimeLimit<E> {
    fn observation_space(&self) -> BoxSpace {
        self.inner.observation_space()
    }
    fn action_space(&self) -> BoxSpace {
        self.inner.action_space()
    }
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        self.elapsed = 0;
        self.inner.reset(seed)
    }
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        let mut st = self.inner.step(action)?;
        self.elapsed += 1;
        if self.elapsed >= self.max_steps && !st.terminated {
            st.truncated = true;
        }
        Ok(st)
    }
    fn dt_s(&self) -> f64 {
        self.inner.dt_s()
    }
    fn critic_obs_dim(&self) -> usize {
        self.inner.critic_obs_dim()
    }
}
