//! What a training driver needs of a learner, whichever algorithm it runs.

use crate::device::NetPath;
use crate::error::Result;
use crate::policy::PolicyData;
use crate::progress::{Control, Progress};
use crate::{Ppo, Sac};
use agvrl_envs::Env;
use std::path::Path;

/// A learner as `agvrl train` and the Python trainer drive it: learn in chunks, checkpoint,
/// and hand out the policy.
pub trait Learner {
    /// Train for `steps` more env steps; `callback` sees progress after every update and may
    /// stop the run.
    fn learn(&mut self, steps: u64, callback: &mut dyn FnMut(&Progress<'_>) -> Control) -> Result<()>;
    /// Env steps collected so far (over all envs).
    fn num_timesteps(&self) -> u64;
    /// Write a checkpoint that `load_checkpoint` of the same algorithm resumes from.
    fn save_checkpoint(&self, path: &Path) -> Result<()>;
    /// The policy as it stands (what a policy file stores).
    fn policy_data(&self) -> PolicyData;
    /// Start fresh episodes at the next step, as a learner resumed from a checkpoint does.
    fn restart_episodes(&mut self);
    /// Run the networks on the host kernels or through Burn on the learner's device.
    fn set_net_path(&mut self, path: NetPath);
    /// Where the networks run.
    fn net_path(&self) -> NetPath;
}

impl<E: Env> Learner for Ppo<E> {
    fn learn(&mut self, steps: u64, callback: &mut dyn FnMut(&Progress<'_>) -> Control) -> Result<()> {
        Ppo::learn(self, steps, callback)
    }
    fn num_timesteps(&self) -> u64 {
        Ppo::num_timesteps(self)
    }
    fn save_checkpoint(&self, path: &Path) -> Result<()> {
        Ppo::save_checkpoint(self, path)
    }
    fn policy_data(&self) -> PolicyData {
        Ppo::policy_data(self)
    }
    fn restart_episodes(&mut self) {
        Ppo::restart_episodes(self)
    }
    fn set_net_path(&mut self, path: NetPath) {
        Ppo::set_net_path(self, path)
    }
    fn net_path(&self) -> NetPath {
        Ppo::net_path(self)
    }
}

impl<E: Env> Learner for Sac<E> {
    fn learn(&mut self, steps: u64, callback: &mut dyn FnMut(&Progress<'_>) -> Control) -> Result<()> {
        Sac::learn(self, steps, callback)
    }
    fn num_timesteps(&self) -> u64 {
        Sac::num_timesteps(self)
    }
    fn save_checkpoint(&self, path: &Path) -> Result<()> {
        Sac::save_checkpoint(self, path)
    }
    fn policy_data(&self) -> PolicyData {
        Sac::policy_data(self)
    }
    fn restart_episodes(&mut self) {
        Sac::restart_episodes(self)
    }
    fn set_net_path(&mut self, path: NetPath) {
        Sac::set_net_path(self, path)
    }
    fn net_path(&self) -> NetPath {
        Sac::net_path(self)
    }
}
