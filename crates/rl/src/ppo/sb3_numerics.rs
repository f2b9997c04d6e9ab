//! PPO's loss, clip fraction and gradients against Stable-Baselines3's, on numbers SB3
//! computed: the weights after one update on Pendulum (some ratios clipped) and one minibatch,
//! with SB3's own policy and PPO.train's loss under autograd
//! (`tools/parity/sb3_gradient_check.py --write-golden`; `sb3_clip_fraction` was added to the
//! two files later, by SB3 2.9.2 at their stored weights, where it reproduced their losses).

use crate::learning::{pendulum_envs, zoo_pendulum_ppo_config};
use crate::{Ppo, default_device};
use serde::Deserialize;

#[derive(Deserialize)]
struct Golden {
    use_sde: bool,
    params: Vec<Vec<f32>>,
    obs: Vec<f32>,
    actions: Vec<f32>,
    old_log_prob: Vec<f32>,
    advantages: Vec<f32>,
    returns: Vec<f32>,
    /// SB3's clip fraction at these weights (the file's `clip_fraction` is agvrl's at dump time).
    sb3_clip_fraction: f64,
    sb3_pg_loss: f64,
    sb3_vf_loss: f64,
    sb3_grads: Vec<Vec<f32>>,
}

fn check(file: &str) {
    let path = format!("{}/tests/data/{file}", env!("CARGO_MANIFEST_DIR"));
    let g: Golden = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert!(g.sb3_clip_fraction > 0.0, "the minibatch exercises the clipped branch");
    let cfg = zoo_pendulum_ppo_config(g.use_sde);
    let mut ppo = Ppo::new(cfg, pendulum_envs(4).unwrap(), &default_device(), 0).unwrap();
    let mb = [&g.obs[..], &g.actions, &g.old_log_prob, &g.advantages, &g.returns];
    let (pg, vf, clip_fraction, grads) = ppo.gradients_at(g.params.clone(), mb).unwrap();
    // The same samples clipped: a count out of the minibatch, so equal to rounding.
    let n = g.old_log_prob.len() as f64;
    assert!(
        ((clip_fraction - g.sb3_clip_fraction) * n).abs() < 0.5,
        "clip fraction {clip_fraction} vs SB3 {}",
        g.sb3_clip_fraction
    );
    assert!(
        (pg - g.sb3_pg_loss).abs() <= 1e-5 * g.sb3_pg_loss.abs().max(1e-3),
        "pg loss {pg} vs SB3 {}",
        g.sb3_pg_loss
    );
    assert!(
        (vf - g.sb3_vf_loss).abs() <= 1e-5 * g.sb3_vf_loss.abs(),
        "value loss {vf} vs SB3 {}",
        g.sb3_vf_loss
    );
    assert_eq!(grads.len(), g.sb3_grads.len());
    for (i, (ours, sb3)) in grads.iter().zip(&g.sb3_grads).enumerate() {
        let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>().sqrt();
        let diff = norm(&mut ours.iter().zip(sb3).map(|(a, b)| (*a - *b) as f64));
        let size = norm(&mut sb3.iter().map(|b| *b as f64));
        assert!(
            size > 0.0 && diff <= 1e-4 * size,
            "gradient tensor {i}: |ours - SB3| = {diff:e}, |SB3| = {size:e}"
        );
    }
}

#[test]
fn ppo_gsde_loss_and_gradients_match_stable_baselines3() {
    check("sb3_ppo_minibatch_sde.json");
}

#[test]
fn ppo_gaussian_loss_and_gradients_match_stable_baselines3() {
    check("sb3_ppo_minibatch_gaussian.json");
}
