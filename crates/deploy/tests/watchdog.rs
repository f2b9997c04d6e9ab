//! The drive loop's watchdog and policy checks on the simulated car: stale and NaN frames stop the
//! car and driving resumes, a policy for another task refuses to start.

use agvrl_deploy::{DeployError, DriveConfig, DriveLoop, Event};
use agvrl_envs::api::{Control, EnvError, MapInfo, SensorFrame, Vehicle};
use agvrl_envs::{EnvConfig, VecEnv, make, make_task, make_vehicle};
use agvrl_rl::{Policy, Ppo, PpoConfig, default_device};

/// An untrained policy with the spaces of `id`.
fn policy_for(id: &str) -> Policy {
    let env = make(id, &EnvConfig::default()).unwrap();
    let dev = default_device();
    Ppo::new(PpoConfig::default(), VecEnv::new(vec![env], 1).unwrap(), &dev, 0)
        .unwrap()
        .policy(&dev)
}

/// A vehicle whose sensors freeze (stale frames) between two tick counts, or report NaN ranges.
struct Faulty {
    inner: Box<dyn Vehicle>,
    ticks: u64,
    freeze: std::ops::Range<u64>,
    nan: std::ops::Range<u64>,
    last: Option<SensorFrame>,
}

impl Vehicle for Faulty {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        self.inner.reset(seed)
    }
    fn actuate(&mut self, c: Control) -> Result<(), EnvError> {
        self.ticks += 1;
        self.inner.actuate(c)
    }
    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        let mut f = self.inner.sense()?;
        if self.freeze.contains(&self.ticks) {
            return Ok(self.last.clone().unwrap_or(f));
        }
        if self.nan.contains(&self.ticks)
            && let Some(s) = f.scan.as_mut()
        {
            s.ranges[10] = f32::NAN;
        }
        self.last = Some(f.clone());
        Ok(f)
    }
    fn control_period_s(&self) -> f64 {
        self.inner.control_period_s()
    }
    fn steering_limit_rad(&self) -> f64 {
        self.inner.steering_limit_rad()
    }
    fn map(&self) -> Option<&MapInfo> {
        self.inner.map()
    }
}

fn faulty_loop(
    freeze: std::ops::Range<u64>,
    nan: std::ops::Range<u64>,
) -> DriveLoop<Faulty, Box<dyn agvrl_envs::task::Task>> {
    let cfg = EnvConfig::default();
    let inner = make_vehicle("racing-oval", &cfg).unwrap();
    let task = make_task("racing-oval", &cfg, inner.steering_limit_rad()).unwrap();
    let v = Faulty {
        inner,
        ticks: 0,
        freeze,
        nan,
        last: None,
    };
    DriveLoop::new(v, task, policy_for("racing-oval"), DriveConfig::default(), 0).unwrap()
}

#[test]
fn stale_scans_stop_the_car_within_two_periods_and_driving_resumes() {
    // Sensors freeze from tick 10 to 19: the frame sensed at tick 10 is the tick-9 frame.
    let mut lp = faulty_loop(10..20, 0..0);
    let mut first_stop = None;
    for k in 0..30u64 {
        let t = lp.tick().unwrap();
        match &t.event {
            Some(Event::Stale { age_s }) => {
                assert!(k >= 10, "tick {k} stopped on fresh data");
                first_stop.get_or_insert(k);
                assert_eq!(
                    t.control,
                    Control::default(),
                    "a safe stop is zero throttle, straight wheels"
                );
                assert!(*age_s > 2.0 / 30.0);
            }
            Some(e) => panic!("unexpected event {e:?}"),
            None => assert!(!(12..20).contains(&k), "tick {k} drove on stale data"),
        }
    }
    let s = first_stop.expect("the watchdog never fired");
    // The data goes stale at tick 10; two periods later at the latest the car is stopped.
    assert!(s <= 12, "first safe stop at tick {s}");
    let t = lp.tick().unwrap();
    assert!(t.event.is_none(), "fresh data again: driving resumes");
}

#[test]
fn nan_ranges_never_reach_the_policy() {
    let mut lp = faulty_loop(0..0, 5..8);
    for k in 0..12u64 {
        let t = lp.tick().unwrap();
        if (5..8).contains(&k) {
            assert_eq!(t.event, Some(Event::NotFinite { sensor: "scan" }), "tick {k}");
            assert_eq!(t.control, Control::default());
        } else {
            assert!(t.event.is_none(), "tick {k}: {:?}", t.event);
        }
    }
}

#[test]
fn a_policy_for_another_task_refuses_to_start() {
    let cfg = EnvConfig::default();
    let v = make_vehicle("racing-oval", &cfg).unwrap();
    let task = make_task("racing-oval", &cfg, v.steering_limit_rad()).unwrap();
    match DriveLoop::new(v, task, policy_for("pendulum"), DriveConfig::default(), 0) {
        Err(DeployError::Mismatch(m)) => assert!(m.to_string().contains("observation"), "{m}"),
        Err(e) => panic!("wrong error {e}"),
        Ok(_) => panic!("a pendulum policy must not drive a car"),
    }
}
