//! agvrl's side of the Stable-Baselines3 parity check on Pendulum: train, then score 200-step
//! deterministic episodes from the 100 shared start states (SB3's side:
//! `pendulum_parity.py --algo ALGO --seeds ...`, same names and output).
//!
//! `cargo run --release -p agvrl-rl --example parity -- [ppo_zoo|ppo_zoo_gaussian|sac] [seeds, e.g. 0,1,2,3,4] [--trace]`
//!
//! `--trace` prints one line per PPO update (the figures SB3 logs under `train/`).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let trace = args.iter().any(|a| a == "--trace");
    // `--dump-grads FILE [sde|gaussian] [seed] [--no-shuffle] [--after STEPS]`: a rollout, one
    // minibatch's loss and gradients at the weights after its update, and what that update
    // reported (tools/parity/sb3_gradient_check.py replays it in SB3); `--after` trains that
    // many env steps first, so the probe sees late training (small std, saturated latents).
    #[cfg(not(feature = "parity"))]
    if args.iter().any(|a| a == "--dump-grads") {
        return Err("--dump-grads needs the parity hooks: add --features parity".into());
    }
    #[cfg(feature = "parity")]
    if let Some(i) = args.iter().position(|a| a == "--dump-grads") {
        let path = args.get(i + 1).ok_or("--dump-grads FILE")?;
        let sde = args.get(i + 2).is_none_or(|s| s != "gaussian");
        let seed: u64 = args.get(i + 3).map_or(Ok(0), |s| s.parse())?;
        let cfg = agvrl_rl::learning::zoo_pendulum_ppo_config(sde);
        let envs = agvrl_rl::learning::pendulum_envs(4)?;
        let mut ppo = agvrl_rl::Ppo::new(cfg, envs, &agvrl_rl::default_device(), seed)?;
        if let Some(k) = args.iter().position(|a| a == "--after") {
            let steps: u64 = args.get(k + 1).ok_or("--after STEPS")?.parse()?;
            ppo.learn(steps, &mut |_| agvrl_rl::Control::Continue)?;
        }
        ppo.set_minibatch_shuffle(!args.iter().any(|a| a == "--no-shuffle"));
        let probe = ppo.gradient_probe()?;
        std::fs::write(path, serde_json::to_string(&probe)?)?;
        println!(
            "wrote {path}: first update approx_kl={:.5} clip_fraction={:.4} std={:.4}",
            probe.update_approx_kl, probe.update_clip_fraction, probe.update_std
        );
        return Ok(());
    }
    let pos: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let algo = pos.first().map_or("ppo_zoo", |s| s.as_str());
    let seeds: Vec<u64> = match pos.get(1) {
        Some(s) => s.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?,
        None => vec![0, 1, 2, 3, 4],
    };
    let mut scores = vec![];
    for &seed in &seeds {
        let t = std::time::Instant::now();
        let (steps, score) = match algo {
            "sac" => (20_000, agvrl_rl::learning::sac_parity(seed, 20_000)?),
            "ppo_zoo" | "ppo_zoo_gaussian" => {
                let mut on_update = |p: &agvrl_rl::Progress<'_>| {
                    if trace {
                        let l = &p.losses;
                        println!(
                            "update seed={seed} steps={} approx_kl={:.5} clip_fraction={:.4} pg_loss={:.5} value_loss={:.4} explained_variance={:.4} std={:.4} grad_norm={:.4} mean_return={:.1}",
                            p.steps,
                            l.approx_kl,
                            l.clip_fraction,
                            l.policy,
                            l.value,
                            l.explained_variance,
                            l.std,
                            l.grad_norm,
                            p.mean_return().unwrap_or(f64::NAN)
                        );
                    }
                };
                let sde = algo == "ppo_zoo";
                (
                    100_000,
                    agvrl_rl::learning::ppo_parity(sde, seed, 100_000, &mut on_update)?,
                )
            }
            other => return Err(format!("unknown algo '{other}' (ppo_zoo, ppo_zoo_gaussian, sac)").into()),
        };
        println!(
            "peer=agvrl algo={algo} seed={seed} steps={steps} mean_return={score:.2} wall_s={:.0}",
            t.elapsed().as_secs_f64()
        );
        scores.push(score);
    }
    let mean = scores.iter().sum::<f64>() / scores.len() as f64;
    println!("peer=agvrl algo={algo} seeds={} mean_return={mean:.2}", scores.len());
    Ok(())
}
