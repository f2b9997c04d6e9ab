//! Speed figures as `key=value` lines (`agvrl bench`): each is the median of `reps`
//! repetitions after a warm-up, on the given CPU backend, single process, one thread unless
//! the line says `threads=2`.
//!
//! `sac_gflops` counts the matrix-product FLOPs one update of `sac/host.rs` performs
//! (`sac_update_flops`); `sgemm_gflops` is a plain 256x256x256 product on the backend, near
//! the ceiling of the host path's products too (matrixmultiply's AVX-512 kernel measured
//! 141-149 GFLOP/s on the update's shapes, one thread). SAC and PPO without an image run on
//! the host, so `--backend` changes only the figures that go through Burn: `sgemm_gflops`,
//! `policy_infer_us` and the CNN lines.
//!
//! What profiling showed (perf, 2-core AVX-512 machine): through Burn, SAC's update was ~70 %
//! GEMM, a tenth went to per-op dispatch and graph work repeated in every row block, and
//! autodiff registers every op under one process-wide lock; on the host a second thread gets
//! 1.7x. Burn's `x86-v4` feature (AVX-512 kernels, picked at run time) doubled flex's 256^3
//! product (74 -> 148 GFLOP/s, one thread). ndarray's GEMM is fast too but its per-op
//! overhead makes inference ~4x slower, so flex is the default.
//! PPO's small tanh nets spent 2/3 of the update in libm's scalar `tanhf`; tanh is now
//! `2 sigmoid(2x) - 1`, and PPO's loss head is fused on the host (see `ppo/update.rs`).
//! Burn's `rayon`/`simd` options gave no measurable gain on this busy machine and are off.
//!
//! `cnn_forward_us` times the NatureCNN encoder alone (batch 1, one 1x48x64 image);
//! `ppo_cnn_steps_per_s` a small PPO run with it (rollout and update) on random observations,
//! each minibatch split over two threads (`_1thread`: on one). Both run on the host
//! (`host_cnn.rs`: im2col and the `gemm` crate's kernels), whatever `--backend` says.

use super::median;
use agvrl_envs::{BoxSpace, Env, EnvError, Info, Step, VecEnv, make};
use agvrl_rl::cnn::ImageSpec;
use agvrl_rl::host_cnn::Encoder;
use agvrl_rl::nets::{Activation, Init, MlpSpec};
use agvrl_rl::policy::{ActionHead, Algorithm, Policy, PolicyData};
use agvrl_rl::rng::Rng;
use agvrl_rl::{Control, CpuBackend, NetPath, Ppo, PpoConfig, Result, Sac, SacConfig};
use burn::tensor::{Tensor, TensorData};
use std::time::Instant;

/// Observation width of the SAC and inference benchmarks.
const BENCH_OBS_DIM: usize = 100;
/// Action width of the SAC and inference benchmarks.
const BENCH_ACT_DIM: usize = 2;

/// An env with random observations, for timing learners without simulation cost.
struct RandomEnv {
    rng: Rng,
    obs_dim: usize,
    act_dim: usize,
    t: u64,
}

impl RandomEnv {
    /// Observations of `obs_dim` random values, actions of `act_dim` in [-1, 1], 1000-step episodes.
    fn new(obs_dim: usize, act_dim: usize) -> Self {
        Self {
            rng: Rng::new(0),
            obs_dim,
            act_dim,
            t: 0,
        }
    }

    fn obs(&mut self) -> Vec<f32> {
        (0..self.obs_dim).map(|_| self.rng.normal() as f32).collect()
    }
}

impl Env for RandomEnv {
    fn observation_space(&self) -> BoxSpace {
        BoxSpace::uniform(self.obs_dim, f32::NEG_INFINITY, f32::INFINITY)
    }
    fn action_space(&self) -> BoxSpace {
        BoxSpace::uniform(self.act_dim, -1.0, 1.0)
    }
    fn reset(&mut self, seed: Option<u64>) -> std::result::Result<(Vec<f32>, Info), EnvError> {
        if let Some(s) = seed {
            self.rng = Rng::new(s);
        }
        self.t = 0;
        Ok((self.obs(), Info::default()))
    }
    fn step(&mut self, action: &[f32]) -> std::result::Result<Step, EnvError> {
        agvrl_envs::api::validate_action(&self.action_space(), action)?;
        self.t += 1;
        let reward = -action.iter().map(|a| (*a as f64).powi(2)).sum::<f64>();
        Ok(Step {
            obs: self.obs(),
            reward,
            terminated: false,
            truncated: self.t >= 1000,
            info: Info::default(),
        })
    }
    fn dt_s(&self) -> f64 {
        0.05
    }
}

/// Matrix-product FLOPs of one SAC update (batch `b`, obs `o`, action `a`, hidden `h`):
/// actor forward on `[obs; next_obs]` (once: the actor loss reuses its obs rows), target
/// critics forward, critics forward and backward (no input gradient at the first layer),
/// critics forward and input-backward for the actor loss (at the first layer only for the
/// action's columns), actor backward (no input gradient).
fn sac_update_flops(b: usize, o: usize, a: usize, h: &[usize]) -> f64 {
    let chain = |input: usize, out: usize| -> (usize, usize) {
        // (all layer MACs, MACs of layers after the first)
        let mut sizes = vec![input];
        sizes.extend(h);
        sizes.push(out);
        let all: usize = sizes.windows(2).map(|w| w[0] * w[1]).sum();
        (all, all - sizes[0] * sizes[1])
    };
    let (actor, actor_rest) = chain(o, 2 * a);
    let (critic, critic_rest) = chain(o + a, 1);
    let (critic, critic_rest) = (2 * critic, 2 * critic_rest);
    let first = h.first().copied().unwrap_or(1);
    let macs = 2 * actor // actor on obs and next_obs (the actor loss reuses the obs rows)
        + critic // target
        + critic + critic + critic_rest // critic loss forward, weight grads, input grads
        + critic + critic_rest + 2 * a * first // actor loss: forward, input grads down to the action
        + actor + actor_rest; // actor weight and input grads
    2.0 * (macs * b) as f64
}

/// The benchmark lines on `backend`. `quick` uses fewer repetitions and iterations.
pub(super) fn run_on(backend: CpuBackend, quick: bool) -> Result<Vec<String>> {
    let device = backend.device();
    let reps = if quick { 3 } else { 7 };
    let mut lines = vec![format!("backend={} reps={reps}", backend.name())];

    // Plain 256^3 products: one thread, then one independent product per thread on two.
    let mut rng = Rng::new(1);
    let inner = 50;
    let sgemm = |threads: usize, rng: &mut Rng| -> Result<f64> {
        let mats: Vec<(Tensor<2>, Tensor<2>)> = (0..threads)
            .map(|_| {
                let mut m = || Tensor::<2>::from_data(TensorData::new(rng.normals(256 * 256), [256, 256]), &device);
                (m(), m())
            })
            .collect();
        let run = |(x, y): &(Tensor<2>, Tensor<2>)| -> Result<f32> {
            let mut acc = 0.0f32;
            for _ in 0..inner {
                acc += agvrl_rl::nets::to_vec(x.clone().matmul(y.clone()).narrow(0, 0, 1).narrow(1, 0, 1))?[0];
            }
            Ok(acc)
        };
        let mut gf = vec![];
        for r in 0..=reps {
            let t = Instant::now();
            let accs: Vec<Result<f32>> = std::thread::scope(|s| {
                let hs: Vec<_> = mats.iter().map(|m| s.spawn(move || run(m))).collect();
                hs.into_iter()
                    .map(|h| {
                        h.join()
                            .map_err(|_| agvrl_rl::RlError::Tensor("bench thread panicked".into()))?
                    })
                    .collect()
            });
            let s = t.elapsed().as_secs_f64();
            for a in accs {
                std::hint::black_box(a?);
            }
            if r > 0 {
                gf.push(2.0 * 256f64.powi(3) * (inner * threads) as f64 / s / 1e9);
            }
        }
        Ok(median(gf))
    };
    lines.push(format!(
        "sgemm_gflops={:.1} threads=1 size=256x256x256 reps={reps}",
        sgemm(1, &mut rng)?
    ));
    lines.push(format!("sgemm_gflops_2threads={:.1} reps={reps}", sgemm(2, &mut rng)?));

    // SAC updates (one update per env step, buffer pre-filled), on 1 and 2 threads.
    let (o, a) = (BENCH_OBS_DIM, BENCH_ACT_DIM);
    let cfg = SacConfig {
        learning_starts: 256,
        buffer_size: 100_000,
        ..SacConfig::default()
    };
    let flops = sac_update_flops(cfg.batch_size, o, a, &cfg.net_arch);
    let n = if quick { 20 } else { 50 };
    let sac_ups = |threads: usize, path: NetPath| -> Result<f64> {
        let env = VecEnv::new(vec![RandomEnv::new(o, a)], 1)?;
        let mut sac = Sac::new(cfg.clone(), env, &device, 0)?;
        sac.set_threads(threads)?;
        sac.set_net_path(path);
        sac.learn(300, &mut |_| Control::Continue)?;
        let mut ups = vec![];
        for _ in 0..reps {
            let t = Instant::now();
            sac.learn(n, &mut |_| Control::Continue)?;
            ups.push(n as f64 / t.elapsed().as_secs_f64());
        }
        Ok(median(ups))
    };
    let (one, two) = (sac_ups(1, NetPath::Host)?, sac_ups(2, NetPath::Host)?);
    // The headline figure is the faster setting: a second thread only helps when a core is free.
    let (best, threads) = if two > one { (two, 2) } else { (one, 1) };
    lines.push(format!(
        "sac_updates_per_s={best:.1} threads={threads} obs={o} act={a} batch=256 net=256x256 reps={reps}"
    ));
    lines.push(format!(
        "sac_updates_per_s_1thread={one:.1} sac_updates_per_s_2threads={two:.1} reps={reps}"
    ));
    lines.push(format!(
        "sac_gflops={:.1} threads={threads} gflop_per_update={:.3} reps={reps}",
        best * flops / 1e9,
        flops / 1e9
    ));
    // The same updates through Burn's autodiff on this backend: what a GPU runs.
    lines.push(format!(
        "sac_burn_updates_per_s={:.1} threads=1 reps={reps}",
        sac_ups(1, NetPath::Burn)?
    ));

    // PPO: pendulum, 8 envs, SB3 defaults; one iteration = 8 x 2048 steps + 10 epochs.
    let ppo_reps = if quick { 1 } else { 3 };
    let ppo_sps = |path: NetPath| -> Result<f64> {
        let envs = (0..8)
            .map(|_| make("pendulum", &agvrl_envs::EnvConfig::default()))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let mut ppo = Ppo::new(PpoConfig::default(), VecEnv::new(envs, 1)?, &device, 0)?;
        ppo.set_net_path(path);
        let per_iter = 8 * 2048;
        ppo.learn(per_iter, &mut |_| Control::Continue)?;
        let mut sps = vec![];
        for _ in 0..ppo_reps {
            let t = Instant::now();
            ppo.learn(per_iter, &mut |_| Control::Continue)?;
            sps.push(per_iter as f64 / t.elapsed().as_secs_f64());
        }
        Ok(median(sps))
    };
    lines.push(format!(
        "ppo_steps_per_s={:.0} env=pendulum n_envs=8 n_steps=2048 reps={ppo_reps}",
        ppo_sps(NetPath::Host)?
    ));
    lines.push(format!(
        "ppo_burn_steps_per_s={:.0} env=pendulum n_envs=8 n_steps=2048 reps={ppo_reps}",
        ppo_sps(NetPath::Burn)?
    ));

    // Policy inference, batch 1.
    let net = MlpSpec {
        n_members: 1,
        sizes: vec![o, 256, 256, 2 * a],
        activation: Activation::Relu,
        activate_last: false,
    };
    let params = net.init(&[Init::TorchDefault], &mut rng);
    let data = PolicyData {
        algorithm: Algorithm::Sac,
        observation_space: BoxSpace::uniform(o, f32::NEG_INFINITY, f32::INFINITY),
        action_space: BoxSpace::uniform(a, -1.0, 1.0),
        net,
        params,
        head: ActionHead::SquashedGaussian,
        normalizer: Some(agvrl_rl::ObsNormalizer::new(o)),
        config_toml: String::new(),
        settings_toml: None,
        encoder: None,
    };
    let mut policy = Policy::new(data, &device);
    let obs = rng.normals(o);
    let calls = 2000;
    let mut infer_us = |path: NetPath| -> Result<f64> {
        policy.set_net_path(path);
        let mut us = vec![];
        for r in 0..=reps {
            let t = Instant::now();
            for _ in 0..calls {
                std::hint::black_box(policy.act(&obs, true)?);
            }
            if r > 0 {
                us.push(t.elapsed().as_secs_f64() * 1e6 / calls as f64);
            }
        }
        Ok(median(us))
    };
    lines.push(format!(
        "policy_infer_us={:.1} obs={o} act={a} net=256x256 batch=1 reps={reps}",
        infer_us(NetPath::Burn)?
    ));
    lines.push(format!(
        "policy_infer_host_us={:.1} reps={reps}",
        infer_us(NetPath::Host)?
    ));

    // NatureCNN encoder alone, batch 1, one 48x64 depth image.
    let spec = ImageSpec::new(1, 48, 64);
    let enc = Encoder::new(spec, &spec.init(Init::TorchDefault, &mut rng)?)?;
    let image: Vec<f32> = (0..spec.len()).map(|_| rng.uniform() as f32).collect();
    let calls = if quick { 200 } else { 500 };
    let mut us = vec![];
    for r in 0..=reps {
        let t = Instant::now();
        for _ in 0..calls {
            std::hint::black_box(enc.forward(&image, spec.len())?);
        }
        if r > 0 {
            us.push(t.elapsed().as_secs_f64() * 1e6 / calls as f64);
        }
    }
    lines.push(format!(
        "cnn_forward_us={:.1} image=1x48x64 features=256 batch=1 mflop={:.1} reps={reps}",
        median(us),
        2.0 * spec.macs()? as f64 / 1e6
    ));

    // PPO with that encoder on random observations (vector 8 + image): rollouts and updates,
    // each minibatch on one thread, then split over two.
    let cnn_sps = |threads: usize, path: NetPath| -> Result<f64> {
        let cfg = PpoConfig {
            n_steps: 256,
            image: Some(spec),
            ..PpoConfig::default()
        };
        let env = VecEnv::new(vec![RandomEnv::new(8 + spec.len(), a)], 1)?;
        let mut ppo = Ppo::new(cfg, env, &device, 0)?;
        ppo.set_threads(threads)?;
        ppo.set_net_path(path);
        ppo.learn(256, &mut |_| Control::Continue)?;
        let mut sps = vec![];
        for _ in 0..ppo_reps {
            let t = Instant::now();
            ppo.learn(256, &mut |_| Control::Continue)?;
            sps.push(256.0 / t.elapsed().as_secs_f64());
        }
        Ok(median(sps))
    };
    let (one, two) = (cnn_sps(1, NetPath::Host)?, cnn_sps(2, NetPath::Host)?);
    lines.push(format!(
        "ppo_cnn_steps_per_s={two:.0} threads=2 image=1x48x64 n_envs=1 n_steps=256 batch=64 n_epochs=10 reps={ppo_reps}"
    ));
    lines.push(format!("ppo_cnn_steps_per_s_1thread={one:.0} reps={ppo_reps}"));
    lines.push(format!(
        "ppo_cnn_burn_steps_per_s={:.0} reps={ppo_reps}",
        cnn_sps(1, NetPath::Burn)?
    ));
    Ok(lines)
}
