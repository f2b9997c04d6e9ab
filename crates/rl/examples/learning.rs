//! The learning checks on pendulum: `cargo run --release -p agvrl-rl --example learning -- [sac|ppo|ppo-gsde|ppo-gaussian|all] [steps] [seeds, e.g. 0,1,2]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("all");
    let steps: Option<u64> = args.get(2).map(|s| s.parse()).transpose()?;
    let seeds: Vec<u64> = match args.get(3) {
        Some(s) => s.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?,
        None => vec![0, 1, 2],
    };
    if which == "sac" || which == "all" {
        let steps = steps.unwrap_or(20_000);
        let mut rets = vec![];
        for &seed in &seeds {
            let t = std::time::Instant::now();
            let r = agvrl_rl::learning::pendulum_sac(seed, steps)?;
            println!(
                "algo=sac env=pendulum steps={steps} seed={seed} eval_return={r:.1} wall_s={:.0}",
                t.elapsed().as_secs_f64()
            );
            rets.push(r);
        }
        rets.sort_by(f64::total_cmp);
        println!("algo=sac median_eval_return={:.1} target>=-170", rets[rets.len() / 2]);
    }
    type Check = fn(u64, u64) -> agvrl_rl::Result<f64>;
    let ppo_checks: [(&str, Check); 2] = [
        ("gsde", agvrl_rl::learning::pendulum_ppo),
        ("gaussian", agvrl_rl::learning::pendulum_ppo_gaussian),
    ];
    for (name, run) in ppo_checks {
        if which != "all" && which != "ppo" && which != format!("ppo-{name}") {
            continue;
        }
        let steps = steps.unwrap_or(100_000);
        let mut rets = vec![];
        for &seed in &seeds {
            let t = std::time::Instant::now();
            let r = run(seed, steps)?;
            println!(
                "algo=ppo exploration={name} env=pendulum steps={steps} seed={seed} eval_return={r:.1} wall_s={:.0}",
                t.elapsed().as_secs_f64()
            );
            rets.push(r);
        }
        rets.sort_by(f64::total_cmp);
        println!(
            "algo=ppo exploration={name} median_eval_return={:.1} target>=-250",
            rets[rets.len() / 2]
        );
    }
    Ok(())
}
