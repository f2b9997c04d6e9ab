//! What a `--policy FILE` means: embedded settings first, then (files of formats 1 and 2) the
//! TOML beside it or its run directory's config; `--set` on top; clear errors otherwise.

use agvrl_rl::PolicyData;
use agvrl_run::{PolicySettings, SettingsSource, files};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("agvrl-run-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

const SETTINGS: &str = "env = \"racing-oval\"\n[env_config]\nmax_steps = 777\n";

#[test]
fn a_format_1_file_still_loads_with_the_toml_beside_it() {
    let p = fixture("racing-v1.agvrl");
    let data = PolicyData::load(&p).unwrap();
    assert_eq!(data.settings_toml, None);
    let s = PolicySettings::resolve(None, Some(&p), &[]).unwrap();
    assert_eq!(s.source, SettingsSource::Beside(fixture("racing-v1.toml")));
    assert_eq!(s.env_id(None).unwrap(), "racing-oval");
    // The TOML's evaluation limit (eval_max_steps) is the one an evaluation takes.
    assert_eq!(s.eval_env_config().max_steps, 3000);
    assert_eq!(s.drive_env_config().max_steps, 1000);
}

#[test]
fn embedded_settings_win_over_a_toml_beside_the_file_and_set_overrides_them() {
    let d = scratch("embedded");
    let p = d.join("racing.agvrl");
    let mut data = PolicyData::load(&fixture("racing-v1.agvrl")).unwrap();
    data.settings_toml = Some(SETTINGS.into());
    data.save(&p).unwrap();
    std::fs::write(d.join("racing.toml"), "env = \"search-urban-20\"\n").unwrap();
    let s = PolicySettings::resolve(None, Some(&p), &[]).unwrap();
    assert_eq!(s.source, SettingsSource::Embedded(p.clone()));
    assert_eq!(s.env_id(None).unwrap(), "racing-oval");
    assert_eq!(s.drive_env_config().max_steps, 777);
    assert_eq!(s.env_id(Some("search-urban-50")).unwrap(), "search-urban-50");
    let s = PolicySettings::resolve(None, Some(&p), &["env_config.max_steps=55".into()]).unwrap();
    assert_eq!(s.drive_env_config().max_steps, 55);
    // A key `agvrl train` would refuse is refused here too, named.
    let e = PolicySettings::resolve(None, Some(&p), &["env_config.max_stepz=55".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("max_stepz"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_policy_without_settings_needs_env_and_has_nothing_to_set() {
    let d = scratch("bare");
    let p = d.join("bare.agvrl");
    std::fs::copy(fixture("racing-v1.agvrl"), &p).unwrap();
    let s = PolicySettings::resolve(None, Some(&p), &[]).unwrap();
    assert_eq!(s.source, SettingsSource::None);
    let e = s.env_id(None).unwrap_err().to_string();
    assert!(e.contains("--env is needed") && e.contains("bare.agvrl"), "{e}");
    assert_eq!(s.env_id(Some("racing-oval")).unwrap(), "racing-oval");
    let e = PolicySettings::resolve(None, Some(&p), &["env_config.max_steps=5".into()])
        .unwrap_err()
        .to_string();
    assert!(e.contains("carries no settings"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_run_directory_gives_its_config_and_its_policy() {
    let d = scratch("rundir");
    std::fs::copy(fixture("racing-v1.agvrl"), d.join(files::POLICY)).unwrap();
    std::fs::write(d.join(files::CONFIG), SETTINGS).unwrap();
    for s in [
        PolicySettings::resolve(Some(&d), None, &[]).unwrap(),
        PolicySettings::resolve(None, Some(&d.join(files::POLICY)), &[]).unwrap(),
    ] {
        assert_eq!(s.source, SettingsSource::RunDir(d.join(files::CONFIG)));
        assert_eq!(s.policy, d.join(files::POLICY));
        assert_eq!(s.eval_env_config().max_steps, 777);
    }
    let e = PolicySettings::resolve(Some(&d.join("nope")), None, &[])
        .unwrap_err()
        .to_string();
    assert!(e.contains("is not a run directory"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}
