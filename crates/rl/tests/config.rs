//! Defaults are SB3's, and TOML overrides behave like rl-zoo3's.

use agvrl_rl::nets::Activation;
use agvrl_rl::sac::EntCoef;
use agvrl_rl::{PpoConfig, SacConfig};

/// `SacConfig::default()` against SB3's `SAC.__init__` defaults, field by field (the pattern
/// names every field, so a new one must be added here). One deliberate difference:
/// `gradient_steps` is -1 (SB3's meaning: as many gradient steps as env steps collected) where
/// SB3's default is 1 per round; with one env both take one gradient step per env step.
#[test]
fn sac_defaults_are_sb3s_with_one_gradient_step_per_env_step() {
    let SacConfig {
        learning_rate,
        buffer_size,
        learning_starts,
        batch_size,
        tau,
        gamma,
        train_freq,
        gradient_steps,
        ent_coef,
        target_update_interval,
        target_entropy,
        net_arch,
        normalize_obs,
        image,
    } = SacConfig::default();
    let c = SacConfig::default();
    assert_eq!(learning_rate, 3e-4);
    assert_eq!(buffer_size, 1_000_000);
    assert_eq!(learning_starts, 100);
    assert_eq!(batch_size, 256);
    assert_eq!(tau, 0.005);
    assert_eq!(gamma, 0.99);
    assert_eq!(train_freq, 1);
    // The shipped default: -1, not SB3's 1.
    assert_eq!(gradient_steps, -1);
    assert_eq!(
        c.gradient_steps_per_round(1),
        1,
        "SB3's gradient_steps = 1 with n_envs = 1"
    );
    assert_eq!(
        c.gradient_steps_per_round(8),
        8,
        "one per env step, where SB3's 1 would be one per 8"
    );
    assert_eq!(ent_coef, EntCoef::Auto("auto".into()));
    assert_eq!(ent_coef.auto_init().unwrap(), Some(1.0), "SB3's \"auto\" starts at 1.0");
    assert_eq!(target_update_interval, 1);
    // SB3's target_entropy "auto" is -dim(action); None resolves to the same in `Sac::new`.
    assert_eq!(target_entropy, None);
    // SB3's net_arch for SAC: [256, 256] for actor and critics.
    assert_eq!(net_arch, vec![256, 256]);
    // SB3 normalises nothing without VecNormalize and has no image unless the env has one.
    assert!(!normalize_obs);
    assert!(image.is_none());
    // SB3's use_sde = False: agvrl's SAC has no gSDE, so there is no field to check.
}

/// `gradient_steps` from a TOML table: a count as given, -1 as one per env step of the round
/// (`train_freq` x n_envs), and 0 or below -1 refused by name.
#[test]
fn sac_gradient_steps_from_toml_count_per_round() {
    let c = SacConfig::from_toml("train_freq = 2\ngradient_steps = 3").unwrap();
    assert_eq!(c.gradient_steps_per_round(8), 3);
    let c = SacConfig::from_toml("train_freq = 2").unwrap();
    assert_eq!(c.gradient_steps_per_round(8), 16);
    for bad in ["gradient_steps = 0", "gradient_steps = -2"] {
        let e = SacConfig::from_toml(bad).unwrap_err().to_string();
        assert!(e.contains("gradient_steps"), "{bad}: {e}");
    }
}

#[test]
fn ppo_defaults_are_sb3s() {
    let c = PpoConfig::default();
    assert_eq!(c.learning_rate, 3e-4);
    assert_eq!(c.n_steps, 2048);
    assert_eq!(c.batch_size, 64);
    assert_eq!(c.n_epochs, 10);
    assert_eq!(c.gamma, 0.99);
    assert_eq!(c.gae_lambda, 0.95);
    assert_eq!(c.clip_range, 0.2);
    assert_eq!(c.clip_range_vf, None);
    assert!(c.normalize_advantage);
    assert_eq!(c.ent_coef, 0.0);
    assert_eq!(c.vf_coef, 0.5);
    assert_eq!(c.max_grad_norm, 0.5);
    assert_eq!(c.target_kl, None);
    assert_eq!(c.net_arch, vec![64, 64]);
    assert_eq!(c.activation_fn, Activation::Tanh);
    assert!(c.ortho_init);
    assert_eq!(c.log_std_init, 0.0);
    assert!(!c.use_sde);
    assert_eq!(c.sde_sample_freq, -1);
    assert!(!c.normalize_obs);
}

#[test]
fn toml_overrides_a_subset_and_round_trips() {
    let c = PpoConfig::from_toml("n_steps = 1024\ngamma = 0.9\nlearning_rate = 1e-3\n").unwrap();
    assert_eq!((c.n_steps, c.gamma, c.learning_rate), (1024, 0.9, 1e-3));
    assert_eq!(c.batch_size, 64);
    assert_eq!(PpoConfig::from_toml(&c.to_toml().unwrap()).unwrap(), c);
    let s = SacConfig::from_toml("ent_coef = 0.1\nnet_arch = [64, 64]\n").unwrap();
    assert_eq!(s.ent_coef, EntCoef::Fixed(0.1));
    assert_eq!(SacConfig::from_toml(&s.to_toml().unwrap()).unwrap(), s);
    assert_eq!(
        SacConfig::from_toml("ent_coef = \"auto_0.1\"")
            .unwrap()
            .ent_coef
            .auto_init()
            .unwrap(),
        Some(0.1)
    );
}

#[test]
fn unknown_keys_and_unsupported_options_are_rejected() {
    assert!(SacConfig::from_toml("learnign_rate = 1e-3").is_err());
    assert!(SacConfig::from_toml("ent_coef = \"sometimes\"").is_err());
    assert!(PpoConfig::from_toml("n_steps = 0").is_err());
    assert!(
        PpoConfig::from_toml("use_sde = true\nsde_sample_freq = 4")
            .unwrap()
            .use_sde
    );
}
