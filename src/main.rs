//! agvrl: train autonomous ground vehicle policies with deep RL, evaluate them, look at what the
//! car sees, and measure speed. `cargo run --release` with no arguments trains the default
//! racing policy (configs/default.toml).

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    std::process::exit(agvrl::cli::main_with(std::env::args_os()));
}
