//! What the drivers know of the car: its geometry, steering and drive, and the accelerations a
//! speed profile may ask of it.

use agvrl_sim::vehicle::VehicleModel;
use agvrl_sim::{DriveModel, InvalidSetting};

/// Standard gravity, m/s^2.
const GRAVITY_MPS2: f64 = 9.81;

/// Share of the tyres' grip a speed profile corners with: at 0.8 of the friction circle's radius
/// sideways, sqrt(1 - 0.8^2) = 0.6 of it is left for the drive and the brake, and the load moving
/// to the outer wheels (which lowers the grip of a tyre pair) does not put the car at the edge.
const LATERAL_GRIP_SHARE: f64 = 0.8;

/// The same for a car with slip-angle tyres (`[tyre]` in its TOML, the F1TENTH car): at 10 m/s
/// pure pursuit steers off its path by more than the path bends, and the load moving forward
/// when it brakes takes grip from the rear wheels; at 0.8 two of the six validation circuits
/// (BrandsHatch, Zandvoort) spun it into a wall, at 0.7 none.
const TYRE_LATERAL_GRIP_SHARE: f64 = 0.7;

/// The car as the drivers plan with it. Build it with [`CarLimits::of`]; the fields are public so
/// a real car's measured figures can replace the model's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarLimits {
    /// Top speed on flat ground, m/s: the drive's steady speed at full throttle.
    pub top_speed_mps: f64,
    /// Distance between the steered and the fixed axle, metres.
    pub wheelbase_m: f64,
    /// Largest steering angle of the virtual centre wheel, rad.
    pub max_steering_rad: f64,
    /// The wheel-speed model (w in rad/s), its `brake` in rad/s^2 as the simulator sets it.
    pub drive: DriveModel,
    /// Radius of the driven wheels, metres (speed = w * radius).
    pub drive_radius_m: f64,
    /// Largest lateral acceleration a speed profile corners with, m/s^2 (default
    /// 0.8 * tyre friction * g: see `LATERAL_GRIP_SHARE`).
    pub lateral_accel_mps2: f64,
    /// Braking deceleration of the drive's speed-controlled ESC, m/s^2 (the simulator's
    /// `brake_mps2`); 0: the car only coasts, slowed by the drive's drag.
    pub brake_mps2: f64,
    /// Half the car's width over its wheels, metres.
    pub half_width_m: f64,
    /// Position of the rear (fixed) axle along the base frame's x, metres: the point pure pursuit
    /// steers (0 when the base link sits on the rear axle, as on XTENTH-CAR).
    pub rear_axle_x_m: f64,
}

impl CarLimits {
    /// The limits of `model` on a drive that brakes at `brake_mps2` (the simulator's setting; 0
    /// coasts), cornering at 0.8 of the tyres' friction (the ground's taken as 1, as in every
    /// shipped scene).
    pub fn of(model: &VehicleModel, brake_mps2: f64) -> Self {
        let d = model.spec.drive;
        let drive_radius_m = model.drive_radius_m() as f64;
        let drive = DriveModel {
            c_t: d.c_t,
            c_d: d.c_d,
            c_r: d.c_r,
            brake: brake_mps2.max(0.0) / drive_radius_m,
        };
        let fixed: Vec<f64> = model
            .wheels
            .iter()
            .filter(|w| w.steer_side == 0)
            .map(|w| w.center_b.x as f64)
            .collect();
        let rear_axle_x_m = if fixed.is_empty() {
            0.0
        } else {
            fixed.iter().sum::<f64>() / fixed.len() as f64
        };
        let half_width_m = model
            .wheels
            .iter()
            .map(|w| (w.center_b.y.abs() + 0.5 * w.width_m) as f64)
            .fold(0.0, f64::max);
        let share = if model.spec.tyre.is_some() {
            TYRE_LATERAL_GRIP_SHARE
        } else {
            LATERAL_GRIP_SHARE
        };
        Self {
            top_speed_mps: drive.steady_state(1.0) * drive_radius_m,
            wheelbase_m: model.wheelbase_m as f64,
            max_steering_rad: model.spec.steering.max_rad,
            drive,
            drive_radius_m,
            lateral_accel_mps2: share * model.spec.tyre_friction as f64 * GRAVITY_MPS2,
            brake_mps2: brake_mps2.max(0.0),
            half_width_m,
            rear_axle_x_m,
        }
    }

    /// An error naming the first field a driver cannot plan with (not finite, or not positive
    /// where it divides).
    pub fn validate(&self) -> Result<(), InvalidSetting> {
        let positive = [
            ("top_speed_mps", self.top_speed_mps),
            ("wheelbase_m", self.wheelbase_m),
            ("max_steering_rad", self.max_steering_rad),
            ("drive_radius_m", self.drive_radius_m),
            ("lateral_accel_mps2", self.lateral_accel_mps2),
            ("drive.c_t", self.drive.c_t),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(InvalidSetting::new(
                    "car limits",
                    format!("car limits: {name} must be finite and > 0, got {v}"),
                ));
            }
        }
        let non_negative = [
            ("brake_mps2", self.brake_mps2),
            ("half_width_m", self.half_width_m),
            ("drive.c_d", self.drive.c_d),
            ("drive.c_r", self.drive.c_r),
            ("drive.brake", self.drive.brake),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(InvalidSetting::new(
                    "car limits",
                    format!("car limits: {name} must be finite and >= 0, got {v}"),
                ));
            }
        }
        if !self.rear_axle_x_m.is_finite() {
            return Err(InvalidSetting::new(
                "car limits",
                format!("car limits: rear_axle_x_m must be finite, got {}", self.rear_axle_x_m),
            ));
        }
        if self.drive.c_d == 0.0 && self.drive.c_r == 0.0 {
            return Err(InvalidSetting::new(
                "car limits",
                "car limits: drive.c_d and drive.c_r are both 0: the drive has no steady speed",
            ));
        }
        Ok(())
    }

    /// Curvature of the tightest circle the steering drives, 1/m.
    pub fn max_curvature_1pm(&self) -> f64 {
        self.max_steering_rad.tan() / self.wheelbase_m
    }

    /// The throttle whose steady speed is `speed_mps`, in [0, 1]: `T = w (c_d w + c_r) / c_t`
    /// with `w = v / r` (the drive model's equilibrium).
    pub fn throttle_for(&self, speed_mps: f64) -> f64 {
        let w = speed_mps.max(0.0) / self.drive_radius_m;
        (w * (self.drive.c_d * w + self.drive.c_r) / self.drive.c_t).clamp(0.0, 1.0)
    }

    /// The throttle that drives towards `target_mps`: [`Self::throttle_for`] the target, plus
    /// `gain_per_mps` per m/s the measured speed falls short of it (none without a measurement),
    /// in [0, 1]. The feedforward holds the target without a steady error; the proportional
    /// term reaches it sooner than the drive's own time constant, and a negative one brakes.
    pub fn throttle(&self, target_mps: f64, measured_mps: Option<f64>, gain_per_mps: f64) -> f64 {
        let feedback = measured_mps.map_or(0.0, |v| gain_per_mps * (target_mps - v));
        (self.throttle_for(target_mps) + feedback).clamp(0.0, 1.0)
    }

    /// Forward acceleration at full throttle at `speed_mps`, m/s^2 (the drive model's).
    pub fn accel_mps2(&self, speed_mps: f64) -> f64 {
        let w = speed_mps.max(0.0) / self.drive_radius_m;
        (self.drive_radius_m * (self.drive.c_t - w * (self.drive.c_d * w + self.drive.c_r))).max(0.0)
    }

    /// Deceleration the car can count on at `speed_mps`, m/s^2: the ESC's brake, or the drive's
    /// drag when that is stronger (coasting, `brake_mps2 = 0`, has only the drag), within the
    /// circle of radius [`Self::lateral_accel_mps2`] a speed profile keeps to: braking harder
    /// spins a car whose load moves forward onto its front wheels.
    pub fn decel_mps2(&self, speed_mps: f64) -> f64 {
        let w = speed_mps.max(0.0) / self.drive_radius_m;
        let drag = self.drive_radius_m * w * (self.drive.c_d * w + self.drive.c_r);
        drag.max(self.brake_mps2).min(self.lateral_accel_mps2)
    }

    /// Acceleration along the path the tyres allow while cornering at `lateral_mps2`, m/s^2:
    /// both share one circle of radius [`Self::lateral_accel_mps2`], so a car at the cornering
    /// limit neither brakes nor drives harder.
    pub fn along_while_cornering_mps2(&self, lateral_mps2: f64) -> f64 {
        (self.lateral_accel_mps2.powi(2) - lateral_mps2.powi(2)).max(0.0).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::tests::xtenth;

    #[test]
    fn the_xtenth_cars_limits_are_its_model() {
        let l = xtenth(0.0);
        assert!((l.top_speed_mps - 1.79).abs() < 0.01, "{l:?}");
        assert!((l.wheelbase_m - 0.33).abs() < 1e-6);
        assert_eq!(l.max_steering_rad, 0.36);
        assert!((l.drive_radius_m - 0.05).abs() < 1e-6);
        assert!((l.half_width_m - 0.192).abs() < 1e-6, "{}", l.half_width_m);
        assert_eq!(l.rear_axle_x_m, 0.0);
        assert!((l.lateral_accel_mps2 - 0.8 * 9.81).abs() < 1e-9);
        assert_eq!(l.drive.brake, 0.0);
        assert_eq!(xtenth(3.0).drive.brake, 3.0 / l.drive_radius_m);
        l.validate().unwrap();
    }

    #[test]
    fn the_throttle_for_a_speed_has_that_speed_as_its_steady_state() {
        let l = xtenth(0.0);
        for v in [0.0, 0.3, 1.0, 1.5, 1.78] {
            let t = l.throttle_for(v);
            let steady = l.drive.steady_state(t) * l.drive_radius_m;
            assert!((steady - v).abs() < 1e-9, "{v} m/s: throttle {t} holds {steady}");
        }
        assert_eq!(l.throttle_for(5.0), 1.0);
        assert!((l.throttle_for(l.top_speed_mps) - 1.0).abs() < 1e-9);
        // Feedback: short of the target adds throttle, over it takes some away.
        assert!(l.throttle(1.0, Some(0.5), 1.0) > l.throttle_for(1.0));
        assert!(l.throttle(1.0, Some(1.5), 1.0) < l.throttle_for(1.0));
        assert_eq!(l.throttle(1.0, None, 1.0), l.throttle_for(1.0));
    }

    #[test]
    fn acceleration_and_deceleration_are_the_drives() {
        let l = xtenth(0.0);
        // At rest the drive pushes with c_t r; at top speed it has nothing left.
        assert!((l.accel_mps2(0.0) - 20.0 * 0.05).abs() < 1e-6);
        assert!(l.accel_mps2(l.top_speed_mps).abs() < 1e-9);
        // Coasting from top speed loses what full throttle put in.
        assert!((l.decel_mps2(l.top_speed_mps) - 20.0 * 0.05).abs() < 1e-6);
        assert_eq!(l.decel_mps2(0.0), 0.0);
        assert_eq!(xtenth(3.0).decel_mps2(0.5), 3.0);
    }

    /// The F1TENTH car has slip-angle tyres: its profiles corner at 0.7 of its grip (XTENTH-CAR's
    /// at 0.8) and brake no harder than that circle's radius, whatever its ESC can; cornering
    /// leaves the rest of the circle along the path.
    #[test]
    fn the_f1tenth_car_corners_at_0_7_of_its_grip_and_brakes_within_that_circle() {
        let model = agvrl_sim::SimSettings {
            vehicle: "f1tenth".into(),
            ..Default::default()
        }
        .vehicle_model()
        .unwrap();
        let l = CarLimits::of(&model, 9.51);
        let grip = 1.0489 * GRAVITY_MPS2;
        assert!(
            (l.lateral_accel_mps2 - 0.7 * grip).abs() < 1e-5,
            "{}",
            l.lateral_accel_mps2
        );
        assert_eq!(l.decel_mps2(5.0), l.lateral_accel_mps2);
        assert_eq!(CarLimits::of(&model, 6.0).decel_mps2(5.0), 6.0);
        let r = l.lateral_accel_mps2;
        assert_eq!(l.along_while_cornering_mps2(0.0), r);
        assert_eq!(l.along_while_cornering_mps2(r), 0.0);
        assert_eq!(l.along_while_cornering_mps2(2.0 * r), 0.0);
        assert!((l.along_while_cornering_mps2(0.6 * r) - 0.8 * r).abs() < 1e-9);
    }

    #[test]
    fn limits_a_driver_cannot_plan_with_are_refused() {
        let bad = CarLimits {
            wheelbase_m: 0.0,
            ..xtenth(0.0)
        };
        let e = bad.validate().unwrap_err();
        assert!(e.message.contains("wheelbase_m"), "{e}");
        let bad = CarLimits {
            brake_mps2: f64::NAN,
            ..xtenth(0.0)
        };
        assert!(bad.validate().unwrap_err().message.contains("brake_mps2"));
    }
}
