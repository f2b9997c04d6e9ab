//! Deploy figures for `agvrl bench`: watchdog + observation + inference latency per tick,
//! CPU and memory of `agvrl-drive` driving at 30 Hz in real time, its binary size, and the
//! ROS 2 loopback rate.

use agvrl_deploy::stats::quantile;
use agvrl_deploy::{DriveConfig, DriveLoop};
use agvrl_envs::{EnvConfig, Vehicle, make_task, make_vehicle};
use agvrl_rl::Policy;
use std::path::PathBuf;
use std::time::Instant;

/// The shipped racing policy (`assets/policies/racing-oval-ppo.agvrl`) in this source tree.
fn shipped_policy() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/policies/racing-oval-ppo.agvrl"
    ))
}

/// Bytes of an ELF64 file's sections that are loaded into memory (what `strip` keeps, near
/// enough: the release profile adds line tables, which are not loaded). None if not ELF64 LE.
fn elf_loaded_bytes(b: &[u8]) -> Option<u64> {
    let u16_at = |o: usize| Some(u16::from_le_bytes(b.get(o..o + 2)?.try_into().ok()?));
    let u32_at = |o: usize| Some(u32::from_le_bytes(b.get(o..o + 4)?.try_into().ok()?));
    let u64_at = |o: usize| Some(u64::from_le_bytes(b.get(o..o + 8)?.try_into().ok()?));
    if b.get(0..4)? != b"\x7fELF" || *b.get(4)? != 2 || *b.get(5)? != 1 {
        return None;
    }
    let (shoff, shentsize, shnum) = (u64_at(0x28)? as usize, u16_at(0x3a)? as usize, u16_at(0x3c)? as usize);
    let mut total = 0;
    for i in 0..shnum {
        let h = shoff + i * shentsize;
        let (kind, flags, size) = (u32_at(h + 4)?, u64_at(h + 8)?, u64_at(h + 32)?);
        // SHF_ALLOC, and not SHT_NOBITS (.bss takes no file space).
        if flags & 2 != 0 && kind != 8 {
            total += size;
        }
    }
    Some(total)
}

fn kv(k: &str, v: impl std::fmt::Display) -> (String, String) {
    (k.to_string(), v.to_string())
}

/// The deploy figures as `key=value` pairs (`quick`: fewer ticks, a smoke test).
pub(super) fn run(quick: bool) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let policy = shipped_policy();
    // Latency: the simulated car as fast as it goes, the shipped policy.
    let lat = (|| -> Result<Vec<f64>, String> {
        let cfg = EnvConfig::default();
        let v = make_vehicle("racing-oval", &cfg).map_err(|e| e.to_string())?;
        let t = make_task("racing-oval", &cfg, v.steering_limit_rad()).map_err(|e| e.to_string())?;
        let p = Policy::load(&policy).map_err(|e| e.to_string())?;
        let mut lp = DriveLoop::new(v, t, p, DriveConfig::default(), 0).map_err(|e| e.to_string())?;
        let n = if quick { 100 } else { 2000 };
        (0..n)
            .map(|_| lp.tick().map(|t| t.infer_us).map_err(|e| e.to_string()))
            .collect()
    })();
    match lat {
        Ok(us) => {
            out.push(kv("deploy_infer_us_p50", format!("{:.1}", quantile(&us, 0.5))));
            out.push(kv("deploy_infer_us_p99", format!("{:.1}", quantile(&us, 0.99))));
        }
        Err(e) => out.push(kv("deploy_infer_error", e.replace(char::is_whitespace, "_"))),
    }
    // The binaries as shipped (tools/build-drive.sh), where built: static, LTO, stripped.
    let exe_dir = std::env::current_exe().ok().and_then(|p| p.parent().map(PathBuf::from));
    let mut shipped_here = None;
    if let Some(root) = exe_dir.as_deref().and_then(|d| d.parent()) {
        for (arch, bin) in shipped_binaries(root) {
            match std::fs::metadata(&bin) {
                Ok(m) => {
                    out.push(kv(
                        &format!("deploy_shipped_{arch}_mb"),
                        format!("{:.1}", m.len() as f64 / 1e6),
                    ));
                    if arch == std::env::consts::ARCH {
                        shipped_here = Some(bin);
                    }
                }
                Err(_) => out.push(kv(
                    &format!("deploy_shipped_{arch}_mb"),
                    format!("not_built(tools/build-drive.sh_{arch})"),
                )),
            }
        }
    }
    // CPU and RSS: agvrl-drive itself at 30 Hz real time, the shipped build where there is one.
    let built = exe_dir.map(|d| d.join("agvrl-drive")).filter(|p| p.exists());
    if let Some(drive) = &built {
        if let Ok(m) = std::fs::metadata(drive) {
            out.push(kv("deploy_binary_mb", format!("{:.1}", m.len() as f64 / 1e6)));
        }
        if let Some(b) = std::fs::read(drive).ok().and_then(|b| elf_loaded_bytes(&b)) {
            out.push(kv("deploy_binary_loaded_mb", format!("{:.1}", b as f64 / 1e6)));
        }
    }
    match shipped_here.map(|b| (b, "shipped")).or(built.map(|b| (b, "release"))) {
        Some((drive, which)) => {
            out.push(kv("deploy_30hz_binary", which));
            let steps = if quick { "30" } else { "300" };
            let res = std::process::Command::new(&drive)
                .args([
                    "--policy",
                    &policy.to_string_lossy(),
                    "--realtime",
                    "--quiet",
                    "--steps",
                    steps,
                ])
                .output();
            match res {
                Ok(o) if o.status.success() => {
                    let text = String::from_utf8_lossy(&o.stdout);
                    let summary = text.lines().last().unwrap_or("");
                    for key in ["cpu_pct", "rss_mb", "wall_s"] {
                        if let Some(v) = summary
                            .split_whitespace()
                            .find_map(|f| f.strip_prefix(&format!("{key}=")))
                        {
                            out.push(kv(&format!("deploy_30hz_{key}"), v));
                        }
                    }
                }
                Ok(o) => out.push(kv(
                    "deploy_30hz_error",
                    String::from_utf8_lossy(&o.stderr)
                        .trim()
                        .replace(char::is_whitespace, "_"),
                )),
                Err(e) => out.push(kv("deploy_30hz_error", e.to_string().replace(char::is_whitespace, "_"))),
            }
        }
        None => out.push(kv(
            "deploy_binary_mb",
            "not_built(cargo build --release -p agvrl-deploy)",
        )),
    }
    out.extend(loopback(quick));
    out
}

/// Where tools/build-drive.sh puts agvrl-drive for each architecture, given the x86_64 target
/// directory (`CARGO_TARGET_DIR`; aarch64 has its own beside it).
fn shipped_binaries(target_root: &std::path::Path) -> [(&'static str, PathBuf); 2] {
    let mut a64 = target_root.as_os_str().to_owned();
    a64.push("-aarch64");
    [
        (
            "x86_64",
            target_root.join("x86_64-unknown-linux-gnu/deploy/agvrl-drive"),
        ),
        (
            "aarch64",
            PathBuf::from(a64).join("aarch64-unknown-linux-gnu/deploy/agvrl-drive"),
        ),
    ]
}

/// Ticks per second of the drive loop against the sim-backed robot over DDS on loopback
/// (lockstep: each tick is a full command -> simulate -> sensors round trip).
fn loopback(quick: bool) -> Vec<(String, String)> {
    use agvrl_deploy::hardware::{Faults, Pace, Ros2Config, Ros2Vehicle, SimRobot};
    let r = (|| -> Result<(f64, f64, f64), String> {
        let cfg = Ros2Config {
            // A domain of its own, away from ROS 2's default 0.
            domain_id: 200 + (std::process::id() % 30) as u16,
            ..Ros2Config::default()
        };
        let env_cfg = EnvConfig::default();
        let mut robot =
            SimRobot::new("racing-oval", &env_cfg, cfg.clone(), 0, Faults::default()).map_err(|e| e.to_string())?;
        let h = robot.handle();
        let th = std::thread::spawn(move || robot.run(Pace::Lockstep, 0));
        let res = (|| {
            let v = Ros2Vehicle::new(cfg.clone(), true, None).map_err(|e| e.to_string())?;
            let t = make_task("racing-oval", &env_cfg, cfg.drive.steering_limit_rad).map_err(|e| e.to_string())?;
            let p = Policy::load(&shipped_policy()).map_err(|e| e.to_string())?;
            let mut lp = DriveLoop::new(v, t, p, DriveConfig::default(), 0).map_err(|e| e.to_string())?;
            let n = if quick { 60 } else { 900 };
            let t0 = Instant::now();
            let mut tick_us = Vec::with_capacity(n);
            for _ in 0..n {
                let t1 = Instant::now();
                lp.tick().map_err(|e| e.to_string())?;
                tick_us.push(t1.elapsed().as_secs_f64() * 1e6);
            }
            Ok((
                n as f64 / t0.elapsed().as_secs_f64(),
                quantile(&tick_us, 0.5),
                quantile(&tick_us, 0.99),
            ))
        })();
        h.stop();
        let _ = th.join();
        res
    })();
    match r {
        Ok((rate, p50, p99)) => vec![
            kv("deploy_ros2_lockstep_ticks_per_s", format!("{rate:.0}")),
            kv("deploy_ros2_tick_us_p50", format!("{p50:.0}")),
            kv("deploy_ros2_tick_us_p99", format!("{p99:.0}")),
        ],
        Err(e) => vec![kv("deploy_ros2_error", e.replace(char::is_whitespace, "_"))],
    }
}

#[cfg(test)]
mod tests {
    use super::elf_loaded_bytes;

    #[test]
    fn elf_loaded_size_of_this_test_binary() {
        let b = std::fs::read(std::env::current_exe().unwrap()).unwrap();
        let n = elf_loaded_bytes(&b).unwrap();
        assert!(n > 100_000 && n < b.len() as u64, "{n} of {}", b.len());
        assert_eq!(elf_loaded_bytes(b"not an ELF file at all"), None);
    }
}
