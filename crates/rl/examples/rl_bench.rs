//! Speed figures: `cargo run --release -p agvrl-rl --example rl_bench -- [quick] [flex|ndarray]`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "quick");
    let backend = match args.iter().find(|a| *a == "flex" || *a == "ndarray") {
        Some(b) => agvrl_rl::CpuBackend::parse(b)?,
        None => agvrl_rl::CpuBackend::default(),
    };
    for line in agvrl_rl::bench::run_on(backend, quick)? {
        println!("{line}");
    }
    Ok(())
}
