use crate::api::{Control, EnvError, MapInfo, SensorFrame, Vehicle};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Sensor noise and actuation latency (standard deviations in SI units). All zero: off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseConfig {
    /// Gaussian LiDAR range noise, metres.
    pub lidar_sigma_m: f64,
    /// Probability that a ray returns nothing (reads range_max, hit = false).
    pub lidar_dropout: f64,
    /// Gyroscope white noise, rad/s.
    pub gyro_sigma_radps: f64,
    /// Gyroscope bias drawn per episode, rad/s (standard deviation).
    pub gyro_bias_radps: f64,
    /// Accelerometer white noise, m/s^2.
    pub accel_sigma_mps2: f64,
    /// Accelerometer bias drawn per episode, m/s^2 (standard deviation).
    pub accel_bias_mps2: f64,
    /// Velocity estimate noise, m/s.
    pub vel_sigma_mps: f64,
    /// GPS position noise, metres.
    pub gps_sigma_m: f64,
    /// Commands take effect this many control periods late.
    pub latency_steps: usize,
    /// Depth camera noise: Gaussian with a standard deviation of this times the depth squared
    /// (a stereo camera's error grows with the square of the distance), 1/m.
    pub depth_sigma_per_m: f64,
    /// Probability that a depth pixel has no reading (NaN, as a stereo camera's holes).
    pub depth_hole_prob: f64,
    /// Depth below this reads NaN (the camera's minimum range), metres.
    pub depth_min_m: f64,
}

impl NoiseConfig {
    /// The `sim2real` preset, sized for a YDLIDAR-class scanner (1 cm, 1 % dropouts), a
    /// consumer MEMS IMU, an RTK-grade GPS (2 cm) and a ZED 2 depth camera (under 1 % error at
    /// 3 m, 2 % holes, 0.3 m minimum range), with one period of command latency.
    pub fn sim2real() -> Self {
        Self {
            lidar_sigma_m: 0.01,
            lidar_dropout: 0.01,
            gyro_sigma_radps: 0.005,
            gyro_bias_radps: 0.002,
            accel_sigma_mps2: 0.05,
            accel_bias_mps2: 0.05,
            vel_sigma_mps: 0.02,
            gps_sigma_m: 0.02,
            latency_steps: 1,
            depth_sigma_per_m: 0.0033,
            depth_hole_prob: 0.02,
            depth_min_m: 0.3,
        }
    }

    /// Whether anything is switched on.
    pub fn is_off(&self) -> bool {
        *self == Self::default()
    }
}

/// A vehicle whose sensors are noisy and whose commands arrive late. Every draw comes from a
/// RNG seeded by `reset`, so noisy episodes replay exactly.
pub struct Noisy<V> {
    inner: V,
    cfg: NoiseConfig,
    rng: StdRng,
    queue: VecDeque<Control>,
    gyro_bias: [f64; 3],
    accel_bias: [f64; 3],
}

impl<V: Vehicle> Noisy<V> {
    /// Wrap `inner`.
    pub fn new(inner: V, cfg: NoiseConfig) -> Self {
        Self {
            inner,
            cfg,
            rng: StdRng::seed_from_u64(0),
            queue: VecDeque::new(),
            gyro_bias: [0.0; 3],
            accel_bias: [0.0; 3],
        }
    }

    /// The wrapped vehicle.
    pub fn inner(&self) -> &V {
        &self.inner
    }

    fn gauss(&mut self, sigma: f64) -> f64 {
        if sigma > 0.0 {
            Normal::new(0.0, sigma).map(|n| n.sample(&mut self.rng)).unwrap_or(0.0)
        } else {
            0.0
        }
    }

    fn corrupt(&mut self, mut f: SensorFrame) -> SensorFrame {
        let c = self.cfg;
        if let Some(scan) = f.scan.as_mut() {
            for i in 0..scan.ranges.len() {
                if c.lidar_dropout > 0.0 && self.rng.random::<f64>() < c.lidar_dropout {
                    scan.ranges[i] = scan.range_max;
                    scan.hit[i] = false;
                } else if scan.hit[i] {
                    let r = scan.ranges[i] as f64 + self.gauss(c.lidar_sigma_m);
                    scan.ranges[i] = (r as f32).clamp(scan.range_min, scan.range_max);
                }
            }
        }
        if let Some(imu) = f.imu.as_mut() {
            for k in 0..3 {
                imu.ang_vel_b[k] += self.gyro_bias[k] + self.gauss(c.gyro_sigma_radps);
                imu.lin_acc_b[k] += self.accel_bias[k] + self.gauss(c.accel_sigma_mps2);
                imu.lin_vel_b[k] += self.gauss(c.vel_sigma_mps);
            }
        }
        if let Some(gps) = f.gps.as_mut() {
            for k in 0..2 {
                gps.position_m[k] += self.gauss(c.gps_sigma_m);
            }
        }
        if let Some(img) = f.image.as_mut()
            && (c.depth_sigma_per_m > 0.0 || c.depth_hole_prob > 0.0 || c.depth_min_m > 0.0)
        {
            for z in img.depth_m.iter_mut() {
                let hole = c.depth_hole_prob > 0.0 && self.rng.random::<f64>() < c.depth_hole_prob;
                let noisy = *z as f64 + self.gauss(c.depth_sigma_per_m * (*z as f64).powi(2));
                *z = if hole || noisy < c.depth_min_m {
                    f32::NAN
                } else {
                    noisy as f32
                };
            }
        }
        f
    }
}

impl<V: Vehicle> Vehicle for Noisy<V> {
    fn reset(&mut self, seed: u64) -> Result<SensorFrame, EnvError> {
        // A stream of its own, so noise does not shift the vehicle's spawn draws.
        self.rng = StdRng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
        self.queue.clear();
        for k in 0..3 {
            self.gyro_bias[k] = self.gauss(self.cfg.gyro_bias_radps);
            self.accel_bias[k] = self.gauss(self.cfg.accel_bias_mps2);
        }
        let f = self.inner.reset(seed)?;
        Ok(self.corrupt(f))
    }

    fn actuate(&mut self, control: Control) -> Result<(), EnvError> {
        self.queue.push_back(control);
        let applied = if self.queue.len() > self.cfg.latency_steps {
            self.queue.pop_front().unwrap_or_default()
        } else {
            Control::default()
        };
        self.inner.actuate(applied)
    }

    fn sense(&mut self) -> Result<SensorFrame, EnvError> {
        let f = self.inner.sense()?;
        Ok(self.corrupt(f))
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
