//! The NatureCNN image encoder in PPO and SAC: shapes, policy files and checkpoints
//! with an encoder, and a task only the image can solve.

use agvrl_envs::api::validate_action;
use agvrl_envs::{BoxSpace, Env, EnvError, Info, Step, VecEnv};
use agvrl_rl::host_cnn::Encoder;
use agvrl_rl::nets::Init;
use agvrl_rl::rng::Rng;
use agvrl_rl::{Control, ImageSpec, Policy, PolicyData, Ppo, PpoConfig, RlError, Sac, SacConfig, default_device};
use std::path::PathBuf;

fn tmp(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("agvrl-rl-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}-{}", std::process::id()))
}

const SIDE: usize = 36;
const N_VEC: usize = 2;

/// One-step episodes: a bright vertical bar lies in the left or the right half of a 1x36x36
/// image; reward 1 when the action's sign points to its side (negative: left), else 0. The
/// vector part is noise, so only the image tells the side: chance scores 0.5.
struct BarSide {
    rng: Rng,
    right: bool,
}

impl BarSide {
    fn new() -> Self {
        Self {
            rng: Rng::new(0),
            right: false,
        }
    }

    fn spec() -> ImageSpec {
        ImageSpec {
            features_dim: 32,
            ..ImageSpec::new(1, SIDE, SIDE)
        }
    }

    fn obs(&mut self) -> Vec<f32> {
        self.right = self.rng.uniform() < 0.5;
        let mut o: Vec<f32> = (0..N_VEC).map(|_| self.rng.normal() as f32).collect();
        // A 4-pixel-wide bar at a random column of its half, over dim noise.
        let half = SIDE / 2;
        let col = self.rng.below(half - 4) + if self.right { half } else { 0 };
        for _ in 0..SIDE {
            for x in 0..SIDE {
                let bar = (col..col + 4).contains(&x);
                o.push(if bar { 1.0 } else { 0.2 * self.rng.uniform() as f32 });
            }
        }
        o
    }
}

impl Env for BarSide {
    fn observation_space(&self) -> BoxSpace {
        let mut s = BoxSpace::uniform(N_VEC + SIDE * SIDE, 0.0, 1.0);
        s.low[..N_VEC].fill(-10.0);
        s.high[..N_VEC].fill(10.0);
        s
    }
    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(1, -1.0, 1.0)
    }
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = Rng::new(s);
        }
        Ok((self.obs(), Info::default()))
    }
    fn step(&mut self, action: &[f32]) -> Result<Step, EnvError> {
        validate_action(&self.action_space(), action)?;
        let hit = (action[0] > 0.0) == self.right;
        Ok(Step {
            obs: self.obs(),
            reward: hit as u8 as f64,
            terminated: true,
            truncated: false,
            info: Info::default(),
        })
    }
    fn dt_s(&self) -> f64 {
        0.1
    }
}

fn vec_env(n: usize) -> VecEnv<BarSide> {
    VecEnv::new((0..n).map(|_| BarSide::new()).collect(), 1).unwrap()
}

#[test]
fn encoder_output_shapes_for_depth_and_rgb_images() {
    for (channels, features) in [(1, 64), (3, 256)] {
        let spec = ImageSpec {
            features_dim: features,
            ..ImageSpec::new(channels, 48, 64)
        };
        let enc = Encoder::new(spec, &spec.init(Init::TorchDefault, &mut Rng::new(1)).unwrap()).unwrap();
        // 3 rows of a 5-value vector part and the image.
        let o = 5 + spec.len();
        let mut rng = Rng::new(2);
        let obs: Vec<f32> = (0..3 * o).map(|_| rng.uniform() as f32).collect();
        let out = enc.forward(&obs, o).unwrap();
        assert_eq!(out.len(), 3 * (5 + features), "{channels} channels");
        // The vector part passes through; features are ReLU outputs, not all zero.
        assert_eq!(&out[..5], &obs[..5]);
        let feats = &out[5..5 + features];
        assert!(feats.iter().all(|v| *v >= 0.0) && feats.iter().any(|v| *v > 0.0));
        // Another image gives other features.
        assert_ne!(&out[5..5 + features], &out[5 + features + 5..2 * (5 + features)]);
        assert!(matches!(enc.forward(&obs[..o - 1], o), Err(RlError::Shape { .. })));
    }
    let too_small = PpoConfig {
        image: Some(ImageSpec::new(1, 30, 64)),
        ..PpoConfig::default()
    };
    let e = too_small.validate().unwrap_err().to_string();
    assert!(e.contains("too small") && e.contains("36x36"), "{e}");
}

#[test]
fn image_config_in_toml() {
    let c = PpoConfig::from_toml("n_steps = 64\nimage = { channels = 1, height = 48, width = 64 }\n").unwrap();
    assert_eq!(c.image, Some(ImageSpec::new(1, 48, 64)));
    assert_eq!(c.image.unwrap().features_dim, 256);
    assert_eq!(PpoConfig::from_toml(&c.to_toml().unwrap()).unwrap(), c);
    let s = SacConfig::from_toml("[image]\nchannels = 3\nheight = 36\nwidth = 36\nfeatures_dim = 64\n").unwrap();
    assert_eq!(s.image.unwrap().features_dim, 64);
    assert_eq!(SacConfig::from_toml(&s.to_toml().unwrap()).unwrap(), s);
    assert!(PpoConfig::from_toml("image = { channels = 1, height = 48, width = 64, depth = 1 }").is_err());
    assert_eq!(PpoConfig::default().image, None);
    // An image wider than the observation is refused when the learner is built.
    let cfg = PpoConfig {
        image: Some(ImageSpec::new(2, SIDE, SIDE)),
        ..PpoConfig::default()
    };
    assert!(matches!(
        Ppo::new(cfg, vec_env(1), &default_device(), 0),
        Err(RlError::Config(_))
    ));
}

fn small_ppo(seed: u64, normalize_obs: bool) -> Ppo<BarSide> {
    let cfg = PpoConfig {
        n_steps: 32,
        batch_size: 32,
        n_epochs: 2,
        net_arch: vec![16],
        normalize_obs,
        image: Some(BarSide::spec()),
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(cfg, vec_env(2), &default_device(), seed).unwrap();
    ppo.learn(64, &mut |_| Control::Continue).unwrap();
    ppo
}

fn observations(n: usize) -> Vec<f32> {
    let mut env = BarSide::new();
    let (mut obs, _) = env.reset(Some(99)).unwrap();
    for _ in 1..n {
        obs.extend(env.reset(None).unwrap().0);
    }
    obs
}

#[test]
fn ppo_cnn_policy_round_trip_gives_identical_actions() {
    let ppo = small_ppo(0, true);
    let path = tmp("ppo-cnn.policy");
    ppo.save_policy(&path).unwrap();
    let data = PolicyData::load(&path).unwrap();
    assert_eq!(data, ppo.policy_data());
    let enc = data.encoder.as_ref().unwrap();
    assert_eq!(enc.spec, BarSide::spec());
    // The normaliser covers the vector part only; the MLP sees vector + features.
    assert_eq!(data.normalizer.as_ref().unwrap().dim(), N_VEC);
    assert_eq!(data.net.sizes[0], N_VEC + 32);
    let obs = observations(4);
    let mut a = Policy::load(&path).unwrap();
    let mut b = ppo.policy(&default_device());
    let (xa, xb) = (a.act(&obs, true).unwrap(), b.act(&obs, true).unwrap());
    assert_eq!(xa, xb);
    assert_eq!(xa.len(), 4);
    // A file whose encoder arrays were dropped is refused.
    let mut broken = data.clone();
    broken.encoder.as_mut().unwrap().params.data.pop();
    broken.encoder.as_mut().unwrap().params.shapes.pop();
    std::fs::write(&path, broken.to_bytes().unwrap()).unwrap();
    assert!(matches!(Policy::load(&path), Err(RlError::BadFile { .. })));
}

#[test]
fn sac_cnn_policy_and_checkpoint_round_trip() {
    let cfg = SacConfig {
        net_arch: vec![16],
        batch_size: 16,
        learning_starts: 20,
        normalize_obs: true,
        image: Some(BarSide::spec()),
        ..SacConfig::default()
    };
    let mut sac = Sac::new(cfg, vec_env(2), &default_device(), 3).unwrap();
    sac.learn(40, &mut |_| Control::Continue).unwrap();
    let path = tmp("sac-cnn.policy");
    sac.save_policy(&path).unwrap();
    let obs = observations(3);
    let mut a = Policy::load(&path).unwrap();
    assert_eq!(
        a.act(&obs, true).unwrap(),
        sac.policy(&default_device()).act(&obs, true).unwrap()
    );
    let (c1, c2) = (tmp("sac-cnn-a.ckpt"), tmp("sac-cnn-b.ckpt"));
    sac.save_checkpoint(&c1).unwrap();
    let mut resumed = Sac::load_checkpoint(&c1, vec_env(2), &default_device()).unwrap();
    resumed.save_checkpoint(&c2).unwrap();
    assert_eq!(std::fs::read(&c1).unwrap(), std::fs::read(&c2).unwrap());
    assert_eq!(resumed.policy_data(), sac.policy_data());
    // Training on updates the actor's encoder.
    let before = resumed.policy_data().encoder.unwrap().params;
    resumed.learn(4, &mut |_| Control::Continue).unwrap();
    assert_ne!(resumed.policy_data().encoder.unwrap().params, before);
}

/// (That a resumed learner with the CNN trains on as if never stopped: resume.rs.)
#[test]
fn ppo_with_the_cnn_is_deterministic_per_seed() {
    let a = small_ppo(1, false).policy_data();
    assert_eq!(small_ppo(1, false).policy_data(), a);
    assert_ne!(small_ppo(2, false).policy_data().encoder, a.encoder);
}

#[test]
fn ppo_with_the_cnn_learns_a_task_only_the_image_solves() {
    let cfg = PpoConfig {
        n_steps: 64,
        batch_size: 64,
        n_epochs: 4,
        learning_rate: 1e-3,
        net_arch: vec![32],
        image: Some(BarSide::spec()),
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(cfg, vec_env(4), &default_device(), 0).unwrap();
    ppo.learn(4 * 64 * 12, &mut |_| Control::Continue).unwrap();
    let score = ppo.evaluate(&mut BarSide::new(), 200, 10_000).unwrap();
    assert!(score > 0.85, "mean reward {score:.3}, chance 0.5");
}

#[test]
fn format_1_policy_files_still_load_and_act_the_same() {
    // Written by the build before the encoder (format 1): PPO, pendulum, net [4], normalised.
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/v1_ppo_pendulum.policy");
    assert_eq!(
        u32::from_le_bytes(std::fs::read(&path).unwrap()[8..12].try_into().unwrap()),
        1
    );
    let mut p = Policy::load(&path).unwrap();
    assert!(p.data().encoder.is_none());
    // The action that build computed for this observation, bit for bit.
    let a = p.act(&[0.5, -0.5, 1.0], true).unwrap();
    assert_eq!(a[0].to_bits(), 0x3ca3_5915, "{a:?}");
    // Saved again it is a file of today's format with the same contents.
    let again = tmp("v1-resaved.policy");
    p.save(&again).unwrap();
    assert_eq!(
        u32::from_le_bytes(std::fs::read(&again).unwrap()[8..12].try_into().unwrap()),
        agvrl_rl::POLICY_FORMAT_VERSION
    );
    assert_eq!(&PolicyData::load(&again).unwrap(), p.data());
}
