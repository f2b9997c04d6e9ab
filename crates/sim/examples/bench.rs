//! `cargo run --release -p agvrl-sim --example bench [quick]`: the simulator's speed figures.
fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    for line in agvrl_sim::bench::run(quick) {
        println!("{line}");
    }
}
