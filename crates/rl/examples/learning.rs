//! The learning checks on pendulum, scored on the 100 start states shared with Stable-Baselines3
//! (the figures `agvrl bench --only learning` prints, with any steps and seeds):
//! `cargo run --release -p agvrl-rl --example learning -- [sac|ppo|ppo-gsde|ppo-gaussian|all] [steps] [seeds, e.g. 0,1,2,3,4]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("all");
    let steps: Option<u64> = args.get(2).map(|s| s.parse()).transpose()?;
    let seeds: Vec<u64> = match args.get(3) {
        Some(s) => s.split(',').map(|x| x.parse()).collect::<Result<_, _>>()?,
        None => vec![0, 1, 2, 3, 4],
    };
    type Check = Box<dyn Fn(u64, u64) -> agvrl_rl::Result<f64>>;
    let checks: [(&str, u64, Check); 3] = [
        ("sac", 20_000, Box::new(agvrl_rl::learning::sac_parity)),
        (
            "ppo-gsde",
            100_000,
            Box::new(|seed, steps| agvrl_rl::learning::ppo_parity(true, seed, steps, &mut |_| {})),
        ),
        (
            "ppo-gaussian",
            100_000,
            Box::new(|seed, steps| agvrl_rl::learning::ppo_parity(false, seed, steps, &mut |_| {})),
        ),
    ];
    for (name, default_steps, run) in checks {
        if which != "all" && which != name && !(which == "ppo" && name.starts_with("ppo")) {
            continue;
        }
        let steps = steps.unwrap_or(default_steps);
        let mut rets = vec![];
        for &seed in &seeds {
            let t = std::time::Instant::now();
            let r = run(seed, steps)?;
            println!(
                "check={name} env=pendulum steps={steps} seed={seed} mean_return={r:.2} wall_s={:.0}",
                t.elapsed().as_secs_f64()
            );
            rets.push(r);
        }
        println!(
            "check={name} seeds={} mean_return={:.2} median_return={:.2}",
            rets.len(),
            rets.iter().sum::<f64>() / rets.len() as f64,
            {
                let mut s = rets.clone();
                s.sort_by(f64::total_cmp);
                s[s.len() / 2]
            }
        );
    }
    Ok(())
}
