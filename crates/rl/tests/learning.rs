//! Short learning tests on the 1-D reach env: each algorithm must beat standing still by a wide
//! margin, which fails when an action sign, the bootstrap or the target is wrong.

use crate::reach::{Reach, rule_return, vec_env};
use agvrl_rl::{Control, Ppo, PpoConfig, Sac, SacConfig, default_device, evaluate};

fn baselines() -> (f64, f64) {
    let still = rule_return(|_| 0.0);
    let greedy = rule_return(|o| 10.0 * o[1]); // steps straight at the target
    assert!(greedy > still + 5.0, "the env rewards reaching: {greedy} vs {still}");
    (still, greedy)
}

#[test]
fn sac_learns_to_reach() {
    let (still, greedy) = baselines();
    let cfg = SacConfig {
        net_arch: vec![64, 64],
        batch_size: 64,
        learning_starts: 200,
        ..SacConfig::default()
    };
    let mut sac = Sac::new(cfg, vec_env(1), &default_device(), 0).unwrap();
    sac.learn(2500, &mut |_| Control::Continue).unwrap();
    let ret = sac.evaluate(&mut Reach::new(), 20, 1_000).unwrap();
    assert!(
        ret > still + 0.75 * (greedy - still),
        "SAC {ret:.2}, standing still {still:.2}, greedy {greedy:.2}"
    );
}

#[test]
fn ppo_learns_to_reach() {
    let (still, greedy) = baselines();
    let cfg = PpoConfig {
        n_steps: 256,
        learning_rate: 1e-3,
        gamma: 0.9,
        ..PpoConfig::default()
    };
    let mut ppo = Ppo::new(cfg, vec_env(4), &default_device(), 0).unwrap();
    ppo.learn(40_000, &mut |_| Control::Continue).unwrap();
    let mut policy = ppo.policy(&default_device());
    let ret = evaluate(&mut policy, &mut Reach::new(), 20, 1_000).unwrap();
    assert!(
        ret > still + 0.75 * (greedy - still),
        "PPO {ret:.2}, standing still {still:.2}, greedy {greedy:.2}"
    );
}
