//! A learner resumed from its checkpoint trains on exactly as the run that never stopped:
//! N + M steps straight against N steps, a checkpoint, a fresh learner on fresh envs loaded
//! from it (as `agvrl train --resume` builds it) and M more; the final policies and
//! checkpoints must be the same bytes.
//!
//! What a checkpoint cannot hold: the envs' own state (mid-episode position, their random
//! streams), since the `Env` trait has no snapshot; a resumed learner starts fresh episodes.
//! [`Lap`] makes that restart invisible, so everything else can be compared bit for bit: its
//! episodes last exactly `len` steps, N falls on an episode end of every env, and its reset
//! ignores the seed, so the resumed learner's fresh reset is the autoreset the straight run
//! got.

use agvrl_envs::api::validate_action;
use agvrl_envs::{BoxSpace, Env, EnvError, Info, Step, VecEnv};
use agvrl_rl::{Control, ImageSpec, Learner, Ppo, PpoConfig, Sac, SacConfig, default_device};
use std::path::{Path, PathBuf};

fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("agvrl-rl-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}-{}", std::process::id()))
}

/// Image side: the smallest the NatureCNN takes.
const SIDE: usize = 36;

/// `x` starts at 0 every episode, the action (in [-1, 1]) moves it by a tenth, reward
/// `-|0.5 - x|`; truncated after exactly `len` steps (bootstrapped). Observation `[x,
/// 0.5 - x, t / len]`, then, with `image`, a 1x36x36 image with a bar at the column of `x`.
struct Lap {
    x: f32,
    t: usize,
    len: usize,
    image: bool,
}

impl Lap {
    fn obs(&self) -> Vec<f32> {
        let mut o = vec![self.x, 0.5 - self.x, self.t as f32 / self.len as f32];
        if self.image {
            let col = (((self.x + 1.0) / 2.0).clamp(0.0, 1.0) * (SIDE - 4) as f32) as usize;
            for _ in 0..SIDE {
                o.extend((0..SIDE).map(|c| if (col..col + 4).contains(&c) { 1.0 } else { 0.1 }));
            }
        }
        o
    }
}

impl Env for Lap {
    fn observation_space(&self) -> BoxSpace {
        let mut s = BoxSpace::uniform(3 + if self.image { SIDE * SIDE } else { 0 }, 0.0, 1.0);
        s.low[..3].fill(-10.0);
        s.high[..3].fill(10.0);
        s
    }
    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(1, -1.0, 1.0)
    }
    fn reset(&mut self, _seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        (self.x, self.t) = (0.0, 0);
        Ok((self.obs(), Info::default()))
    }
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        validate_action(&self.action_space(), action)?;
        self.x = (self.x + 0.1 * action[0]).clamp(-2.0, 2.0);
        self.t += 1;
        Ok(Step {
            obs: self.obs(),
            reward: -(0.5 - self.x).abs() as f64,
            terminated: false,
            truncated: self.t == self.len,
            info: Info::default(),
        })
    }
    fn dt_s(&self) -> f64 {
        0.1
    }
}

const N_ENVS: usize = 2;

fn laps(len: usize, image: bool) -> VecEnv<Lap> {
    let envs = (0..N_ENVS)
        .map(|_| Lap {
            x: 0.0,
            t: 0,
            len,
            image,
        })
        .collect();
    VecEnv::new(envs, 1).unwrap()
}

/// Train `n + m` steps straight with one learner from `fresh`; and `n` steps with another,
/// its checkpoint, `resume` of that file (a fresh learner on fresh envs), `m` more steps. The
/// two must end with the same policy and write the same checkpoint bytes.
fn resumed_equals_straight<L: Learner>(name: &str, fresh: impl Fn() -> L, resume: impl Fn(&Path) -> L, n: u64, m: u64) {
    let go = |l: &mut L, steps| l.learn(steps, &mut |_| Control::Continue).unwrap();
    let mut straight = fresh();
    go(&mut straight, n + m);
    let mut first = fresh();
    go(&mut first, n);
    let at_n = first.policy_data();
    let ckpt = tmp(&format!("{name}-at-n.ckpt"));
    first.save_checkpoint(&ckpt).unwrap();
    drop(first);
    let mut resumed = resume(&ckpt);
    assert_eq!(resumed.num_timesteps(), n, "the checkpoint falls at step N");
    go(&mut resumed, m);
    assert_eq!(resumed.num_timesteps(), straight.num_timesteps());
    // Training went on after the resume: the comparison is between two trained policies.
    assert_ne!(
        resumed.policy_data().params,
        at_n.params,
        "no training after the resume"
    );
    assert!(
        resumed.policy_data() == straight.policy_data(),
        "the resumed run's policy differs from the straight run's"
    );
    assert_eq!(
        resumed.policy_data().to_bytes().unwrap(),
        straight.policy_data().to_bytes().unwrap()
    );
    let (a, b) = (
        tmp(&format!("{name}-straight.ckpt")),
        tmp(&format!("{name}-resumed.ckpt")),
    );
    straight.save_checkpoint(&a).unwrap();
    resumed.save_checkpoint(&b).unwrap();
    let (a, b) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    let first = a.iter().zip(&b).position(|(p, q)| p != q);
    assert!(
        a == b,
        "the checkpoints differ (lengths {} {}) from byte {first:?}: {:?}",
        a.len(),
        b.len(),
        first.map(|i| String::from_utf8_lossy(&a[i.saturating_sub(80)..(i + 40).min(a.len())]).into_owned())
    );
}

/// PPO as `agvrl train` sets it up (threads, the learning rate's schedule over the run).
fn ppo(learner: Ppo<Lap>, threads: usize, run_steps: u64) -> Ppo<Lap> {
    let mut learner = learner;
    learner.set_threads(threads).unwrap();
    learner.set_schedule_steps(run_steps);
    learner
}

#[test]
fn ppo_resumed_from_a_checkpoint_trains_as_if_never_stopped() {
    const LEN: usize = 16;
    let cfg = PpoConfig {
        n_steps: 2 * LEN,
        batch_size: 32,
        n_epochs: 4,
        net_arch: vec![16],
        normalize_obs: true,
        learning_rate_final: Some(1e-4),
        ..PpoConfig::default()
    };
    let rollout = (cfg.n_steps * N_ENVS) as u64;
    let (n, m) = (2 * rollout, 2 * rollout);
    let dev = default_device();
    resumed_equals_straight(
        "ppo",
        || ppo(Ppo::new(cfg.clone(), laps(LEN, false), &dev, 4).unwrap(), 1, n + m),
        |p| ppo(Ppo::load_checkpoint(p, laps(LEN, false), &dev).unwrap(), 1, n + m),
        n,
        m,
    );
}

#[test]
fn ppo_with_an_image_resumed_from_a_checkpoint_trains_as_if_never_stopped() {
    const LEN: usize = 8;
    let cfg = PpoConfig {
        n_steps: 2 * LEN,
        batch_size: 16,
        n_epochs: 2,
        net_arch: vec![16],
        normalize_obs: true,
        image: Some(ImageSpec {
            features_dim: 16,
            ..ImageSpec::new(1, SIDE, SIDE)
        }),
        ..PpoConfig::default()
    };
    let rollout = (cfg.n_steps * N_ENVS) as u64;
    let (n, m) = (2 * rollout, 2 * rollout);
    let dev = default_device();
    resumed_equals_straight(
        "ppo-cnn",
        || ppo(Ppo::new(cfg.clone(), laps(LEN, true), &dev, 5).unwrap(), 2, n + m),
        |p| ppo(Ppo::load_checkpoint(p, laps(LEN, true), &dev).unwrap(), 2, n + m),
        n,
        m,
    );
}

#[test]
fn sac_resumed_from_a_checkpoint_trains_as_if_never_stopped() {
    const LEN: usize = 5;
    let cfg = SacConfig {
        net_arch: vec![16, 16],
        batch_size: 16,
        learning_starts: 20,
        // The buffer wraps before N, and N (25 vector steps) falls between two rounds of
        // `train_freq`.
        buffer_size: 40,
        train_freq: 2,
        normalize_obs: true,
        ..SacConfig::default()
    };
    let (n, m) = ((5 * LEN * N_ENVS) as u64, (7 * LEN * N_ENVS) as u64);
    let dev = default_device();
    let threads = |mut s: Sac<Lap>| {
        s.set_threads(2).unwrap();
        s
    };
    resumed_equals_straight(
        "sac",
        || threads(Sac::new(cfg.clone(), laps(LEN, false), &dev, 6).unwrap()),
        |p| threads(Sac::load_checkpoint(p, laps(LEN, false), &dev).unwrap()),
        n,
        m,
    );
}
