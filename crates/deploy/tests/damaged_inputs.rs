//! Damaged inputs never panic: randomly damaged bags through the reader and the decoders, and the
//! fuzz targets' seeds and regressions replayed on stable.

use crate::{drive_cli, scratch, shipped_policy};

/// Random damage to a recorded bag (flipped bytes, cuts, both; 300 seeded cases) never panics
/// the reader or the message decoders: each case reads up to the damage or is refused with an
/// error, and every message that comes back decodes or is refused.
#[test]
fn damaged_bags_never_panic_the_reader_or_the_decoders() {
    use agvrl_deploy::bag;
    use rand::{RngExt, SeedableRng};
    let dir = scratch("fuzzbag");
    let d = dir.path().join("rec");
    let (ok, _, err) = drive_cli(&[
        "--policy".as_ref(),
        shipped_policy("racing-oval-camera").as_os_str(),
        "--steps".as_ref(),
        "20".as_ref(),
        "--quiet".as_ref(),
        "--record".as_ref(),
        d.as_os_str(),
    ]);
    assert!(ok, "{err}");
    let path = d.join(bag::MCAP_FILE);
    let good = std::fs::read(&path).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(7);
    let (mut refused, mut cut_short, mut bad_messages) = (0, 0, 0);
    for case in 0..300 {
        let mut b = good.clone();
        if case % 3 != 1 {
            for _ in 0..rng.random_range(1..9) {
                let i = rng.random_range(0..b.len());
                b[i] ^= 1 << rng.random_range(0..8);
            }
        }
        if case % 3 != 0 {
            b.truncate(rng.random_range(0..b.len()));
        }
        std::fs::write(&path, &b).unwrap();
        let r = std::panic::catch_unwind(|| match bag::read_messages(&d) {
            Ok((msgs, damage)) => (
                false,
                damage.is_some(),
                msgs.iter()
                    .filter(|m| agvrl_deploy::record::decode_json(m).is_err())
                    .count(),
            ),
            Err(_) => (true, false, 0),
        });
        let (r, c, m) = r.unwrap_or_else(|_| panic!("case {case} panicked"));
        refused += usize::from(r);
        cut_short += usize::from(c);
        bad_messages += m;
    }
    // The 200 cut files are noticed (refused, or read up to where they stop); flipped bytes
    // mostly are (a chunk's CRC), though a flip in an unchecked summary field may not be.
    assert!(refused + cut_short >= 200, "refused {refused}, cut short {cut_short}");
    eprintln!("refused {refused}, cut short {cut_short}, messages refused by a decoder {bad_messages}");
}

/// The fuzz targets' seeds and every input their runs kept (fuzz/seeds, fuzz/regressions; see
/// docs/reliability.md) go through the same bodies on stable: none panics. CI replays; it does
/// not fuzz.
#[test]
fn fuzz_regressions_replay_without_panic() {
    use agvrl_deploy::bag::fuzz;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    type Body = fn(&[u8]);
    let targets: [(&str, Body); 7] = [
        ("bag_reader", fuzz::read_and_decode),
        ("ros2_messages", fuzz::ros2_message),
        ("policy_file", agvrl_run::fuzz::policy_file),
        ("checkpoint", agvrl_rl::fuzz::checkpoint),
        ("run_toml", agvrl_run::fuzz::run_toml),
        ("asset_files", agvrl_sim::fuzz::asset_file),
        ("map_file", agvrl_sim::fuzz::map_file),
    ];
    // What the bodies write to the temp folder, they remove.
    let leftovers = || -> std::collections::BTreeSet<std::ffi::OsString> {
        std::fs::read_dir(std::env::temp_dir())
            .unwrap()
            .filter_map(|e| Some(e.ok()?.file_name()))
            .filter(|n| n.to_string_lossy().starts_with("agvrl-fuzz"))
            .collect()
    };
    let before = leftovers();
    let mut replayed = 0;
    for (target, body) in targets {
        for kind in ["seeds", "regressions"] {
            let Ok(dir) = std::fs::read_dir(root.join(kind).join(target)) else {
                continue;
            };
            for entry in dir {
                let path = entry.unwrap().path();
                let bytes = std::fs::read(&path).unwrap();
                body(&bytes);
                replayed += 1;
            }
        }
    }
    assert!(replayed >= 36, "the seeds are missing: {replayed} inputs");
    let left: Vec<_> = leftovers().difference(&before).cloned().collect();
    assert!(left.is_empty(), "the replays left {left:?} in the temp folder");
    // Seeds the decoders refuse would leave the fuzzer at the first check.
    for entry in std::fs::read_dir(root.join("seeds/policy_file")).unwrap() {
        let path = entry.unwrap().path();
        let bytes = agvrl_rl::fuzz::with_crc(&std::fs::read(&path).unwrap());
        agvrl_rl::PolicyData::from_bytes(&path, &bytes).unwrap();
    }
}
