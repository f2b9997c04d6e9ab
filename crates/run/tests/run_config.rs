//! The run TOML: round trips, --set, and errors that name their file.

use agvrl_rl::Algorithm;
use agvrl_run::RunConfig;

/// The run TOML (shared by `agvrl train` and agvrl-drive) round-trips, takes `--set` overrides
/// on dotted keys, and its errors start with the file they come from.
#[test]
fn a_run_config_round_trips_and_its_errors_name_the_file() {
    let text = "env = \"search-urban-20\"\nalgo = \"sac\"\n[env_config]\nsubsteps = 5\n";
    let c = RunConfig::from_toml(text, "x.toml").unwrap();
    assert_eq!((c.algo, c.env_config.sim.substeps), (Algorithm::Sac, 5));
    assert_eq!(RunConfig::from_toml(&c.to_toml().unwrap(), "back").unwrap(), c);
    let c = RunConfig::from_toml_with(text, "x.toml", &["env_config.lidar.n_rays=40".into()]).unwrap();
    assert_eq!(c.env_config.sim.lidar.n_rays, 40);
    let e = RunConfig::from_toml("env = \"search-mars\"", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("x.toml: unknown env id 'search-mars'"), "{e}");
    let e = RunConfig::from_toml("[env_config]\nheld_out = true", "y.toml")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("y.toml: env_config.held_out"), "{e}");
}
