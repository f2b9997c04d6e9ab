//! agvrl: train autonomous ground vehicle policies with deep RL, evaluate them, look at what the
//! car sees, and measure speed. `cargo run --release` with no arguments trains the default
//! racing policy (configs/default.toml).

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    // A closed stdout (`agvrl policy F | head`) ends the process quietly, as it ends `cat`, not
    // with a panic from `println!`. Sockets are unaffected: std sends with MSG_NOSIGNAL.
    #[cfg(unix)]
    // SAFETY: before any other thread exists; SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    std::process::exit(agvrl::cli::main_with(std::env::args_os()));
}
