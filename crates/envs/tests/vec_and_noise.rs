//! Vector envs against single envs (any thread count, the autoreset modes, a NaN row) and the
//! wrappers: seeded noise, latency, domain randomisation, the time limit.

use super::*;

fn actions(n: usize, t: usize) -> Vec<f32> {
    (0..n * 2)
        .map(|k| (((t * 7 + k * 13) % 17) as f32 / 8.0) - 1.0)
        .collect()
}

#[test]
fn vec_env_equals_serial_stepping_for_any_thread_count() {
    const N: usize = 5;
    let cfg = EnvConfig {
        max_steps: 40,
        ..quick_cfg()
    };
    let mk = || {
        (0..N)
            .map(|_| make("search-urban-20", &cfg).unwrap())
            .collect::<Vec<_>>()
    };
    let mut v1 = VecEnv::new(mk(), 1).unwrap();
    // 2 and 3 threads over 5 envs: uneven chunks, and threads take over each other's envs.
    let mut v2 = VecEnv::new(mk(), 2).unwrap();
    let mut v3 = VecEnv::new(mk(), 3).unwrap();
    let mut serial = mk();
    let (o1, _) = v1.reset(Some(10)).unwrap();
    let (o2, _) = v2.reset(Some(10)).unwrap();
    let (o3, _) = v3.reset(Some(10)).unwrap();
    let mut os: Vec<f32> = Vec::new();
    for (i, e) in serial.iter_mut().enumerate() {
        os.extend(e.reset(Some(10 + i as u64)).unwrap().0);
    }
    assert_eq!(o1, o2);
    assert_eq!(o1, o3);
    assert_eq!(o1, os);
    let mut saw_done = false;
    for t in 0..100 {
        let a = actions(N, t);
        let s1 = v1.step(&a).unwrap();
        let s2 = v2.step(&a).unwrap();
        let s3 = v3.step(&a).unwrap();
        assert_eq!(s1.obs, s2.obs);
        assert_eq!(s1.obs, s3.obs);
        assert_eq!(s1.rewards, s2.rewards);
        assert_eq!(s1.rewards, s3.rewards);
        assert_eq!(s1.terminated, s3.terminated);
        for (i, e) in serial.iter_mut().enumerate() {
            let st = e.step(&a[i * 2..i * 2 + 2]).unwrap();
            assert_eq!(st.reward, s1.rewards[i]);
            if st.done() {
                saw_done = true;
                assert_eq!(
                    s1.infos[i].final_obs.as_ref(),
                    Some(&st.obs),
                    "final_obs keeps the last observation"
                );
                assert!(s1.infos[i].episode.is_some());
                let (o, _) = e.reset(None).unwrap();
                assert_eq!(&s1.obs[i * 104..(i + 1) * 104], &o[..]);
            } else {
                assert_eq!(&s1.obs[i * 104..(i + 1) * 104], &st.obs[..]);
            }
        }
    }
    assert!(saw_done, "the test must cross an auto-reset");
}

/// Single envs stepped in a loop the way Gymnasium's `NEXT_STEP` mode describes: an env
/// whose episode ended resets on its next step instead of stepping.
#[test]
fn next_step_autoreset_equals_single_envs_reset_on_the_following_step() {
    const N: usize = 3;
    let cfg = EnvConfig {
        max_steps: 25,
        ..quick_cfg()
    };
    let mk = || {
        (0..N)
            .map(|_| make("search-urban-20", &cfg).unwrap())
            .collect::<Vec<_>>()
    };
    let mut v = VecEnv::with_autoreset(mk(), 2, Autoreset::NextStep).unwrap();
    let mut serial = mk();
    let (o, _) = v.reset(Some(5)).unwrap();
    let mut os = Vec::new();
    for (i, e) in serial.iter_mut().enumerate() {
        os.extend(e.reset(Some(5 + i as u64)).unwrap().0);
    }
    assert_eq!(o, os);
    let mut ended = [false; N];
    let (mut ends, mut resets) = (0, 0);
    for t in 0..80 {
        let a = actions(N, t);
        let s = v.step(&a).unwrap();
        for (i, e) in serial.iter_mut().enumerate() {
            let row = &s.obs[i * 104..(i + 1) * 104];
            if ended[i] {
                resets += 1;
                let (o, _) = e.reset(None).unwrap();
                assert_eq!(row, &o[..]);
                assert_eq!((s.rewards[i], s.terminated[i], s.truncated[i]), (0.0, false, false));
                assert!(s.infos[i].episode.is_none());
                ended[i] = false;
            } else {
                let st = e.step(&a[i * 2..i * 2 + 2]).unwrap();
                assert_eq!(row, &st.obs[..], "no reset within the ending step");
                assert_eq!(
                    (s.rewards[i], s.terminated[i], s.truncated[i]),
                    (st.reward, st.terminated, st.truncated)
                );
                assert!(s.infos[i].final_obs.is_none());
                ended[i] = st.done();
                ends += usize::from(st.done());
                assert_eq!(s.infos[i].episode.is_some(), st.done());
            }
        }
    }
    assert!(ends >= N && resets >= N, "ends {ends}, resets {resets}");
}

#[test]
fn disabled_autoreset_refuses_an_ended_env_until_a_masked_reset() {
    let cfg = EnvConfig {
        max_steps: 5,
        ..quick_cfg()
    };
    let mk = || (0..2).map(|_| make("racing-oval", &cfg).unwrap()).collect::<Vec<_>>();
    let mut v = VecEnv::with_autoreset(mk(), 1, Autoreset::Disabled).unwrap();
    let mut solo = mk();
    let (o0, _) = v.reset(Some(1)).unwrap();
    let mut last = Vec::new();
    for t in 0..5 {
        let s = v.step(&actions(2, t)).unwrap();
        last = s.obs.clone();
        assert_eq!(s.truncated, [t == 4, t == 4]);
    }
    let e = v.step(&actions(2, 5)).unwrap_err();
    assert!(matches!(e.innermost(), EnvError::NeedsReset), "{e}");
    assert!(e.to_string().starts_with("env 0:"), "{e}");
    // Only env 1 resets, with its own seed; env 0 keeps its last observation.
    let (o, infos) = v.reset_envs(vec![None, Some(77)], Some(vec![false, true])).unwrap();
    assert_eq!(infos.len(), 2);
    assert_eq!(&o[..o.len() / 2], &last[..last.len() / 2]);
    assert_eq!(&o[o.len() / 2..], &solo[1].reset(Some(77)).unwrap().0[..]);
    assert_ne!(&o[o.len() / 2..], &o0[o0.len() / 2..]);
    assert!(v.step(&actions(2, 6)).is_err(), "env 0 still needs its reset");
    assert!(v.reset_envs(vec![None], None).is_err(), "one seed per env");
}

#[test]
fn a_nan_action_in_any_row_steps_no_env() {
    let mk = || {
        (0..2)
            .map(|_| make("racing-oval", &quick_cfg()).unwrap())
            .collect::<Vec<_>>()
    };
    let mut v = VecEnv::new(mk(), 2).unwrap();
    let mut w = VecEnv::new(mk(), 2).unwrap();
    v.reset(Some(2)).unwrap();
    w.reset(Some(2)).unwrap();
    let e = v.step(&[0.5, 0.0, f32::NAN, 0.0]).unwrap_err();
    assert_eq!(e.to_string(), "env 1: action element 0 is not finite (NaN)");
    // Env 0 did not move: both vectors still agree after the same valid step.
    assert_eq!(v.step(&actions(2, 0)).unwrap().obs, w.step(&actions(2, 0)).unwrap().obs);
}

#[test]
fn vec_env_of_tiny_envs_on_two_threads_equals_one_thread() {
    // Pendulum rounds are too short to hand over: the caller's thread steps them alone,
    // after a first round on both threads; results must not change either way.
    let mk = || {
        (0..8)
            .map(|_| make("pendulum", &EnvConfig::default()).unwrap())
            .collect::<Vec<_>>()
    };
    let mut v1 = VecEnv::new(mk(), 1).unwrap();
    let mut v2 = VecEnv::new(mk(), 2).unwrap();
    assert_eq!(v1.reset(Some(3)).unwrap().0, v2.reset(Some(3)).unwrap().0);
    let mut ended = 0;
    for t in 0..450 {
        // One torque per env.
        let a: Vec<f32> = actions(4, t).iter().map(|x| x * 2.0).collect();
        let (s1, s2) = (v1.step(&a).unwrap(), v2.step(&a).unwrap());
        assert_eq!(s1.obs, s2.obs);
        assert_eq!(s1.rewards, s2.rewards);
        assert_eq!(s1.truncated, s2.truncated);
        ended += s1.truncated.iter().filter(|&&x| x).count();
        for (i1, i2) in s1.infos.iter().zip(&s2.infos) {
            assert_eq!(i1.final_obs, i2.final_obs);
        }
    }
    assert_eq!(ended, 16, "two 200-step time limits per env");
}

#[test]
fn noise_is_seeded_and_changes_observations() {
    let run = |cfg: &EnvConfig| {
        let mut env = make("search-outdoor-20", cfg).unwrap();
        let mut out = vec![env.reset(Some(4)).unwrap().0];
        for t in 0..30 {
            out.push(env.step(&actions(1, t)).unwrap().obs);
        }
        out
    };
    let clean = run(&EnvConfig::default());
    let noisy = run(&EnvConfig::sim2real());
    assert_eq!(noisy, run(&EnvConfig::sim2real()), "same seed, same noise");
    assert_ne!(clean, noisy);
}

#[test]
fn latency_delays_commands_by_k_periods() {
    let base = EnvConfig {
        spawn: SpawnMode::Fixed,
        ..quick_cfg()
    };
    let late = EnvConfig {
        noise: wrappers::NoiseConfig {
            latency_steps: 3,
            ..Default::default()
        },
        ..base.clone()
    };
    let mut a = make("search-outdoor-20", &base).unwrap();
    let mut b = make("search-outdoor-20", &late).unwrap();
    a.reset(Some(0)).unwrap();
    b.reset(Some(0)).unwrap();
    // Without latency: three idle periods, then the commands. With 3 periods of latency:
    // the commands from the start. Both cars must drive the same trajectory.
    let cmd = |k: usize| [1.0f32, if k < 20 { 0.5 } else { -0.5 }];
    let mut moved = false;
    for t in 0..40 {
        let sa = a.step(&if t < 3 { [-1.0, 0.0] } else { cmd(t - 3) }).unwrap();
        let sb = b.step(&cmd(t)).unwrap();
        assert_eq!(sa.obs, sb.obs, "step {t}");
        moved |= sb.obs[100] > 0.1;
    }
    assert!(moved);
}

#[test]
fn randomisation_draws_parameters_per_episode_from_the_seed() {
    let sim = || agvrl_sim::SimConfig {
        scene: agvrl_sim::SceneSource::Builtin("oval".into()),
        ..Default::default()
    };
    let mut v = SimVehicle::new(sim(), SpawnMode::Random, Randomisation::sim2real()).unwrap();
    v.reset(1).unwrap();
    let p1 = v.sim().car(0).params();
    v.reset(2).unwrap();
    let p2 = v.sim().car(0).params();
    v.reset(1).unwrap();
    assert_eq!(v.sim().car(0).params(), p1);
    assert_ne!(p1, p2);
    let nominal = v.sim().nominal_params();
    assert!((p1.drive.c_t / nominal.drive.c_t - 1.0).abs() <= 0.1);
    assert!(p1.steering_offset_rad.abs() <= 0.02);
}

#[test]
fn time_limit_passes_termination_through() {
    let cfg = EnvConfig {
        spawn: SpawnMode::Fixed,
        ..quick_cfg()
    };
    let inner = {
        let sim = agvrl_sim::SimConfig {
            scene: agvrl_sim::SceneSource::Builtin("oval".into()),
            ..Default::default()
        };
        TaskEnv::new(
            SimVehicle::new(sim, cfg.spawn, cfg.randomisation).unwrap(),
            Racing::new(RacingConfig::default(), 0.36),
        )
    };
    let mut env = TimeLimit::new(inner, 100_000);
    env.reset(Some(0)).unwrap();
    let _ = env.inner().task().observation_space();
    loop {
        let st = env.step(&[1.0, 0.0]).unwrap();
        if st.done() {
            assert!(st.terminated && !st.truncated);
            break;
        }
    }
}

/// An env whose critic values count the episode's steps; episodes last three steps.
struct CountingCritic(u32);

impl Env for CountingCritic {
    fn observation_space(&self) -> agvrl_envs::BoxSpace {
        agvrl_envs::BoxSpace::uniform(1, 0.0, 10.0)
    }
    fn action_space(&self) -> agvrl_envs::BoxSpace {
        agvrl_envs::BoxSpace::uniform(1, -1.0, 1.0)
    }
    fn reset(&mut self, _: Option<u64>) -> Result<(Vec<f32>, Info), EnvError> {
        self.0 = 0;
        let info = Info {
            critic_obs: Some(vec![0.0]),
            ..Info::default()
        };
        Ok((vec![0.0], info))
    }
    fn step(&mut self, _: &[f32]) -> Result<Step, EnvError> {
        self.0 += 1;
        Ok(Step {
            obs: vec![self.0 as f32],
            reward: 0.0,
            terminated: self.0 == 3,
            truncated: false,
            info: Info {
                critic_obs: Some(vec![self.0 as f32]),
                ..Info::default()
            },
        })
    }
    fn dt_s(&self) -> f64 {
        0.1
    }
    fn critic_obs_dim(&self) -> usize {
        1
    }
}

/// Where a vector env auto-resets, the ended episode's critic values move to
/// `final_critic_obs` beside `final_obs`, and `critic_obs` is the new episode's first.
#[test]
fn an_auto_reset_keeps_the_final_critic_values_beside_the_final_observation() {
    let mut v = VecEnv::new(vec![CountingCritic(0), CountingCritic(0)], 1).unwrap();
    assert_eq!(v.critic_obs_dim(), 1);
    let (_, infos) = v.reset(Some(0)).unwrap();
    assert_eq!(infos[0].critic_obs, Some(vec![0.0]));
    for t in 1..=3 {
        let st = v.step(&[0.0, 0.0]).unwrap();
        let info = &st.infos[1];
        if t < 3 {
            assert_eq!(
                (info.critic_obs.clone(), info.final_critic_obs.clone()),
                (Some(vec![t as f32]), None)
            );
        } else {
            assert_eq!(info.final_obs, Some(vec![3.0]));
            assert_eq!(info.final_critic_obs, Some(vec![3.0]));
            assert_eq!(info.critic_obs, Some(vec![0.0]));
        }
    }
}
