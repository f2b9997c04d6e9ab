//! Generated env counts, thread counts, reset splits and actions.

use super::*;
use proptest::prelude::*;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Any thread count, and the first reset split over several masked calls in any
    /// order, give the bits of one thread and one reset (auto-resets included).
    #[test]
    fn a_vec_env_gives_the_same_bits_for_any_thread_count_and_any_split_of_resets(
        n in 1usize..6,
        threads in 1usize..5,
        groups in prop::collection::vec(0usize..3, 5),
        max_steps in 3u64..12,
        seed in 0u64..1000,
        actions in prop::collection::vec(-1.0f32..=1.0, 2 * 5 * 24),
    ) {
        let cfg = EnvConfig { max_steps, ..quick_cfg() };
        let mk = || (0..n).map(|_| make("search-urban-20", &cfg).unwrap()).collect::<Vec<_>>();
        let mut one = VecEnv::new(mk(), 1).unwrap();
        let mut many = VecEnv::new(mk(), threads).unwrap();
        let (o1, _) = one.reset(Some(seed)).unwrap();
        let mut rows = vec![vec![]; n];
        for g in [2, 0, 1] {
            let mask: Vec<bool> = (0..n).map(|i| groups[i] == g).collect();
            if !mask.contains(&true) {
                continue;
            }
            let seeds = (0..n as u64).map(|i| Some(seed + i)).collect();
            let (o, _) = many.reset_envs(seeds, Some(mask.clone())).unwrap();
            let dim = o.len() / n;
            for i in (0..n).filter(|&i| mask[i]) {
                rows[i] = o[i * dim..(i + 1) * dim].to_vec();
            }
        }
        prop_assert_eq!(bits(&o1), bits(&rows.concat()));
        for t in 0..24 {
            let a = &actions[t * 10..t * 10 + 2 * n];
            let (s1, s2) = (one.step(a).unwrap(), many.step(a).unwrap());
            prop_assert_eq!(bits(&s1.obs), bits(&s2.obs), "step {}", t);
            prop_assert_eq!(
                s1.rewards.iter().map(|r| r.to_bits()).collect::<Vec<_>>(),
                s2.rewards.iter().map(|r| r.to_bits()).collect::<Vec<_>>()
            );
            prop_assert_eq!(&s1.terminated, &s2.terminated);
            prop_assert_eq!(&s1.truncated, &s2.truncated);
        }
    }
}
