use agvrl_rl::*;
fn main() {
    let dev = default_device();
    for threads in [1, 2] {
        let env = agvrl_envs::VecEnv::new(vec![bench::RandomEnv::new(100, 2)], 1).unwrap();
        let cfg = SacConfig {
            learning_starts: 256,
            buffer_size: 100_000,
            ..SacConfig::default()
        };
        let mut sac = Sac::new(cfg, env, &dev, 0).unwrap();
        sac.set_threads(threads);
        sac.learn(300, &mut |_| Control::Continue).unwrap();
        let t = std::time::Instant::now();
        sac.learn(200, &mut |_| Control::Continue).unwrap();
        println!(
            "threads={threads} updates_per_s={:.1}",
            200.0 / t.elapsed().as_secs_f64()
        );
    }
}
