//! End-to-end tests of the `agvrl` binary, one test binary with a module per topic; the helpers
//! here (running agvrl, scratch directories, its output, plots and recordings) serve several
//! topics.

mod command_line;
mod evaluation;
mod planners;
mod racing_against_others;
mod run_directories;
mod shipped_policies;
mod training;
mod trials;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn agvrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_agvrl"))
        .args(args)
        .output()
        .expect("run agvrl")
}

/// A test's scratch directory, removed when the test ends, whether it passed or not.
fn tmp(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("agvrl-e2e-{name}-"))
        .tempdir()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Every line of `text` as JSON (the `--progress json` output).
fn json_lines(text: &str) -> Vec<serde_json::Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON: {l:?}: {e}")))
        .collect()
}

/// Width, height and number of distinct colours of a PNG.
fn png_summary(p: &Path) -> (u32, u32, usize) {
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(p).unwrap()));
    let mut r = dec.read_info().unwrap();
    let mut buf = vec![0; r.output_buffer_size().unwrap()];
    let info = r.next_frame(&mut buf).unwrap();
    let px = info.color_type.samples();
    let colours: std::collections::HashSet<&[u8]> = buf[..info.buffer_size()].chunks(px).collect();
    (info.width, info.height, colours.len())
}

/// A recording is non-empty and, where the official `rerun` CLI of the same version is
/// installed (always in CI: .ci/run installs it), verifies and holds `entities`.
fn rrd_check(p: &Path, entities: &[&str]) {
    let len = std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    assert!(len > 1000, "{}: {len} bytes", p.display());
    let cli = Command::new("rerun").arg("--version").output();
    let Ok(v) = cli else {
        assert!(
            std::env::var("CI").is_err(),
            "CI must install the rerun CLI (pip install rerun-sdk==0.36.3)"
        );
        eprintln!("rerun CLI not found: skipping the viewer-side check of {}", p.display());
        return;
    };
    assert!(
        String::from_utf8_lossy(&v.stdout).contains("0.36.3"),
        "rerun CLI version: {}",
        stdout(&v)
    );
    let o = Command::new("rerun")
        .args(["rrd", "verify"])
        .arg(p)
        .env("RERUN_TELEMETRY_ENABLED", "false")
        .output()
        .unwrap();
    assert!(o.status.success(), "rerun rrd verify: {}{}", stdout(&o), stderr(&o));
    let o = Command::new("rerun")
        .args(["rrd", "print"])
        .arg(p)
        .env("RERUN_TELEMETRY_ENABLED", "false")
        .output()
        .unwrap();
    assert!(o.status.success(), "rerun rrd print: {}", stderr(&o));
    let text = stdout(&o) + &stderr(&o);
    for e in entities {
        assert!(
            text.contains(e),
            "{e} not in the recording:\n{}",
            &text[..text.len().min(3000)]
        );
    }
    // The recording carries the layout it opens with (src/viz.rs `layout`).
    for b in ["ViewBlueprint", "ContainerBlueprint"] {
        assert!(text.contains(b), "no {b} in the recording");
    }
}

fn tiny_config(dir: &Path) -> PathBuf {
    let p = dir.join("tiny.toml");
    std::fs::write(
        &p,
        "env = \"racing-oval\"\nalgo = \"ppo\"\nsteps = 512\nseed = 1\nn_envs = 2\nthreads = 1\neval_episodes = 1\n\
         [env_config]\nmax_steps = 100\n[ppo]\nn_steps = 128\nbatch_size = 64\nn_epochs = 2\n",
    )
    .unwrap();
    p
}

/// The value of the first `k=VALUE` line of `out`.
fn key<'a>(out: &'a str, k: &str) -> &'a str {
    out.lines()
        .find_map(|l| l.strip_prefix(k).and_then(|r| r.strip_prefix('=')))
        .unwrap_or_else(|| panic!("{k}= missing in:\n{out}"))
}
