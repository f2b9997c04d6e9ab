//! A 1-D reach-the-target env: small enough for SAC and PPO to solve in seconds, and it fails
//! loudly when a sign or the target is wrong.

use agvrl_envs::api::validate_action;
use agvrl_envs::{BoxSpace, Env, EnvError, Info, Step};
use agvrl_rl::rng::Rng;

/// Position `x` and target `g` in [-1, 1]; the action (in [-2, 2], scaled by 0.1) moves `x`.
/// Observation `[x, g - x]`; reward `-|g - x|` per step; terminates within 0.05 of the target,
/// truncates after 20 steps.
pub struct Reach {
    x: f32,
    g: f32,
    t: u32,
    rng: Rng,
}

impl Reach {
    pub fn new() -> Self {
        Self {
            x: 0.0,
            g: 0.0,
            t: 0,
            rng: Rng::new(0),
        }
    }

    fn obs(&self) -> Vec<f32> {
        vec![self.x, self.g - self.x]
    }
}

impl Env for Reach {
    fn observation_space(&self) -> BoxSpace {
        BoxSpace::uniform(2, -3.0, 3.0)
    }
    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(1, -2.0, 2.0)
    }
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = Rng::new(s);
        }
        self.x = (self.rng.uniform() * 2.0 - 1.0) as f32;
        self.g = (self.rng.uniform() * 2.0 - 1.0) as f32;
        self.t = 0;
        Ok((self.obs(), Info::default()))
    }
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        validate_action(&self.action_space(), action)?;
        self.x = (self.x + 0.1 * action[0].clamp(-2.0, 2.0)).clamp(-1.5, 1.5);
        self.t += 1;
        let d = (self.g - self.x).abs();
        let terminated = d < 0.05;
        let truncated = !terminated && self.t >= 20;
        Ok(Step {
            obs: self.obs(),
            reward: -d as f64,
            terminated,
            truncated,
            info: Info::default(),
        })
    }
    fn dt_s(&self) -> f64 {
        0.1
    }
}

/// Mean return of 20 episodes of a fixed action rule (for baselines).
pub fn rule_return(rule: impl Fn(&[f32]) -> f32) -> f64 {
    let mut env = Reach::new();
    let mut total = 0.0;
    for k in 0..20 {
        let (mut obs, _) = env.reset(Some(1_000 + k)).unwrap();
        loop {
            let st = env.step(&[rule(&obs).clamp(-2.0, 2.0)]).unwrap();
            total += st.reward;
            if st.done() {
                break;
            }
            obs = st.obs;
        }
    }
    total / 20.0
}

pub fn vec_env(n: usize) -> agvrl_envs::VecEnv<Reach> {
    agvrl_envs::VecEnv::new((0..n).map(|_| Reach::new()).collect(), 1).unwrap()
}
