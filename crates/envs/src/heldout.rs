//! The held-out protocol: the seed space is split in two halves by its top bit. Training
//! episodes (spawns, randomisation, noise, procedural layouts) draw from the lower half,
//! evaluation episodes from the upper half, so an evaluation episode or layout is never one a
//! policy trained on, whatever seeds either side was given.

/// The bit that marks an evaluation seed.
pub const EVAL_BIT: u64 = 1 << 63;

/// `seed` moved into the evaluation half (`held_out`) or the training half.
pub fn split(seed: u64, held_out: bool) -> u64 {
    if held_out { seed | EVAL_BIT } else { seed & !EVAL_BIT }
}

/// Whether `seed` lies in the evaluation half.
pub fn is_held_out(seed: u64) -> bool {
    seed & EVAL_BIT != 0
}

/// A layout seed drawn from an episode seed (SplitMix64's finaliser), in the episode seed's half.
pub fn layout_of_episode(episode_seed: u64) -> u64 {
    let mut z = episode_seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    split(z ^ (z >> 31), is_held_out(episode_seed))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_never_meet() {
        for s in [0, 1, 42, u64::MAX, EVAL_BIT, EVAL_BIT - 1, 0x1234_5678_9abc_def0] {
            assert!(is_held_out(split(s, true)));
            assert!(!is_held_out(split(s, false)));
            assert_ne!(split(s, true), split(s, false));
            assert!(is_held_out(layout_of_episode(split(s, true))));
            assert!(!is_held_out(layout_of_episode(split(s, false))));
        }
        // Different episodes get different layouts.
        assert_ne!(layout_of_episode(1), layout_of_episode(2));
    }
}
