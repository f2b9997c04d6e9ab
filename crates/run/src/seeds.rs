//! Which seed each use of a run's seed gets, in one place.
//!
//! Every evaluation episode also draws from the held-out half of the seed space
//! (`agvrl_envs::heldout`, set by `EnvConfig::held_out`), so no base below can give an
//! evaluation an episode or a layout that training drew.

/// The seeds a run derives from its `seed`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Seeds {
    run: u64,
}

impl Seeds {
    /// The seeds of a run whose `seed` is `run`.
    pub fn of(run: u64) -> Self {
        Self { run }
    }

    /// The learner's seed and the training envs' episode seeds.
    pub fn training(self) -> u64 {
        self.run
    }

    /// The layout seed of procedural training env `env`.
    pub fn training_layout(self, env: usize) -> u64 {
        self.run.wrapping_mul(1_000_003).wrapping_add(env as u64)
    }

    /// Base of the evaluation `agvrl train` runs at the end (episode k resets with base + k).
    pub fn run_evaluation(self) -> u64 {
        self.run + 1_000_000
    }

    /// Base of `agvrl eval --run` without `--seed`: other episodes than the run's own evaluation.
    pub fn eval_command(self) -> u64 {
        self.run + 2_000_000
    }

    /// Base of the validation episodes that decide whether a run of several `attempts` is kept.
    pub fn validation(self) -> u64 {
        self.run + 3_000_000
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_s_uses_of_its_seed_never_share_a_base() {
        for run in [0, 1, 7, 999_999] {
            let s = Seeds::of(run);
            let bases = [s.training(), s.run_evaluation(), s.eval_command(), s.validation()];
            // 1,000 episodes from each base stay apart.
            for (i, a) in bases.iter().enumerate() {
                for b in &bases[i + 1..] {
                    assert!(a.abs_diff(*b) >= 1_000_000, "{run}: {bases:?}");
                }
            }
            assert_ne!(s.training_layout(0), s.training_layout(1));
        }
        assert_eq!(Seeds::of(3).run_evaluation(), 1_000_003);
        assert_eq!(Seeds::of(3).eval_command(), 2_000_003);
        assert_eq!(Seeds::of(3).validation(), 3_000_003);
    }
}
