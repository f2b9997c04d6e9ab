//! Gymnasium's Pendulum-v1, exactly: the reference task for checking SAC and PPO against
//! published learning results.

use crate::api::{BoxSpace, Env, EnvError, Info, Step, validate_action};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use std::f64::consts::PI;

/// Pendulum-v1 constants (gymnasium/envs/classic_control/pendulum.py).
pub mod consts {
    /// Gravity, m/s^2.
    pub const G: f64 = 10.0;
    /// Mass, kg.
    pub const M: f64 = 1.0;
    /// Length, m.
    pub const L: f64 = 1.0;
    /// Integration step, s.
    pub const DT: f64 = 0.05;
    /// Angular speed limit, rad/s.
    pub const MAX_SPEED: f64 = 8.0;
    /// Torque limit, N m.
    pub const MAX_TORQUE: f64 = 2.0;
}
use consts::*;

/// The swing-up pendulum. Observation `[cos theta, sin theta, theta_dot]`, action a torque in
/// `[-2, 2]` N m. Wrap it in `TimeLimit` (200 steps) as `make("pendulum", &agvrl_envs::EnvConfig::default())` does.
pub struct Pendulum {
    theta: f64,
    theta_dot: f64,
    rng: StdRng,
    ready: bool,
}

impl Default for Pendulum {
    fn default() -> Self {
        Self::new()
    }
}

impl Pendulum {
    /// A pendulum that needs `reset` before `step`.
    pub fn new() -> Self {
        Self {
            theta: 0.0,
            theta_dot: 0.0,
            rng: StdRng::seed_from_u64(0),
            ready: false,
        }
    }

    /// Current (theta, theta_dot), radians and rad/s.
    pub fn state(&self) -> (f64, f64) {
        (self.theta, self.theta_dot)
    }

    /// Set the state directly (tests, closed-form checks).
    pub fn set_state(&mut self, theta: f64, theta_dot: f64) {
        self.theta = theta;
        self.theta_dot = theta_dot;
        self.ready = true;
    }

    fn obs(&self) -> Vec<f32> {
        vec![self.theta.cos() as f32, self.theta.sin() as f32, self.theta_dot as f32]
    }
}

/// Wrap an angle to [-pi, pi).
pub fn angle_normalize(x: f64) -> f64 {
    (x + PI).rem_euclid(2.0 * PI) - PI
}

impl Env for Pendulum {
    fn observation_space(&self) -> BoxSpace {
        BoxSpace {
            low: vec![-1.0, -1.0, -MAX_SPEED as f32],
            high: vec![1.0, 1.0, MAX_SPEED as f32],
        }
    }

    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(1, -MAX_TORQUE as f32, MAX_TORQUE as f32)
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = StdRng::seed_from_u64(s);
        }
        self.theta = self.rng.random_range(-PI..PI);
        self.theta_dot = self.rng.random_range(-1.0..1.0);
        self.ready = true;
        Ok((self.obs(), Info::default()))
    }

    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        validate_action(&self.action_space(), action)?;
        if !self.ready {
            return Err(EnvError::NeedsReset);
        }
        let u = (action[0] as f64).clamp(-MAX_TORQUE, MAX_TORQUE);
        let (th, thdot) = (self.theta, self.theta_dot);
        let cost = angle_normalize(th).powi(2) + 0.1 * thdot * thdot + 0.001 * u * u;
        let new_thdot =
            (thdot + (3.0 * G / (2.0 * L) * th.sin() + 3.0 / (M * L * L) * u) * DT).clamp(-MAX_SPEED, MAX_SPEED);
        self.theta = th + new_thdot * DT;
        self.theta_dot = new_thdot;
        Ok(Step {
            obs: self.obs(),
            reward: -cost,
            terminated: false,
            truncated: false,
            info: Info::default(),
        })
    }

    fn dt_s(&self) -> f64 {
        DT
    }
}
