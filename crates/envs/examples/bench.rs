//! `cargo run --release -p agvrl-envs --example bench [quick]`: the envs' speed figures.
fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    for line in agvrl_envs::bench::run(quick) {
        println!("{line}");
    }
}
