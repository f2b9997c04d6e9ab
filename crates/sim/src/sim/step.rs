//! One control period: each car's actuation (throttle through the drive model, steering through
//! its limits, rate and Ackermann split), the physics substeps (through rapier, or in free
//! flight while no car touches anything), then each car's velocities and IMU.

use super::{Sim, body_params};
use crate::SimError;
use crate::vehicle::{Control, ackermann_split};
use rapier3d::prelude::*;

impl Sim {
    /// Apply `control` for one control period: advance the wheel-speed model, split the
    /// steering, and run the physics substeps.
    pub fn step(&mut self, control: Control) -> Result<(), SimError> {
        self.step_cars(&[control])
    }

    /// Apply one control per car for one control period. Every car's wheels act, then the
    /// world takes one physics step, substep by substep.
    pub fn step_cars(&mut self, controls: &[Control]) -> Result<(), SimError> {
        self.check_count(controls.len(), "controls")?;
        let t = self.cfg.settings.control_period_s;
        let ack = self
            .cfg
            .settings
            .ackermann
            .unwrap_or(self.model.spec.steering.ackermann);
        let max = self.model.spec.steering.max_rad;
        let rate = self.model.spec.steering.max_rate_radps;
        for (car, control) in self.cars.iter_mut().zip(controls) {
            if car.parked {
                continue;
            }
            let c = Control {
                throttle: if control.throttle.is_finite() {
                    control.throttle.clamp(-1.0, 1.0)
                } else {
                    0.0
                },
                steering_rad: if control.steering_rad.is_finite() {
                    control.steering_rad
                } else {
                    0.0
                },
            };
            let delta = (c.steering_rad + car.params.steering_offset_rad).clamp(-max, max);
            car.wheel_speed = car.params.drive.advance(car.wheel_speed, c.throttle, t);
            car.steer_target_rad = delta;
            if rate.is_none() {
                car.steer_rad = delta;
                car.wheel_angles = ackermann_split(
                    delta,
                    self.model.wheelbase_m as f64,
                    self.model.front_track_m as f64,
                    ack,
                );
            }
            car.control = Control {
                throttle: c.throttle,
                steering_rad: delta,
            };
        }
        // The first step after a reset runs through rapier: it applies the reset's mass and pose.
        let free = self.cfg.settings.free_flight && self.steps > 0 && self.free_of_contacts(t as f32);
        self.free_steps += u64::from(free);
        let mut before = vec![Pose::IDENTITY; self.cars.len()];
        for _ in 0..self.cfg.settings.substeps {
            for (i, car) in self.cars.iter_mut().enumerate() {
                before[i] = *self.world.pw.bodies[car.body.base()].position();
                if car.parked && car.body.is_raycast() {
                    continue;
                }
                if let Some(rate) = rate {
                    let turn = rate * t / self.cfg.settings.substeps as f64;
                    car.steer_rad += (car.steer_target_rad - car.steer_rad).clamp(-turn, turn);
                    car.wheel_angles = ackermann_split(
                        car.steer_rad,
                        self.model.wheelbase_m as f64,
                        self.model.front_track_m as f64,
                        ack,
                    );
                    car.control.steering_rad = car.steer_rad;
                }
                let steer = (car.wheel_angles.0 as f32, car.wheel_angles.1 as f32);
                car.body.drive(
                    &mut self.world,
                    &mut car.near,
                    &self.model,
                    car.wheel_speed as f32,
                    steer,
                    body_params(&car.params),
                );
            }
            if free {
                for car in self.cars.iter().filter(|c| !c.parked) {
                    car.body.fly(&mut self.world);
                }
            } else {
                self.world.pw.step();
            }
        }
        self.time_s += t;
        self.steps += 1;
        // Velocities of the base origin over the last substep: the motion the pose really made.
        // (rapier's body velocity is the centre of mass's, and in ray-cast mode it carries the
        // gravity increment that the next suspension impulse cancels.)
        let h = self.world.pw.integration_parameters.dt;
        for (i, car) in self.cars.iter_mut().enumerate() {
            let after = *self.world.pw.bodies[car.body.base()].position();
            let lin = (after.translation - before[i].translation) / h;
            let (axis, angle) = (after.rotation * before[i].rotation.inverse()).to_axis_angle();
            let ang = if angle.is_finite() && axis.is_finite() {
                axis * (angle / h)
            } else {
                Vector::ZERO
            };
            if !(after.is_finite() && lin.is_finite() && ang.is_finite()) {
                return Err(SimError::NotFinite(format!(
                    "state of car {i} after step {}",
                    self.steps
                )));
            }
            car.vel_w = (lin, ang);
            car.imu.update(lin, ang, t as f32);
        }
        self.place_shapes();
        Ok(())
    }

    /// Whether the coming control period can skip rapier's pipeline: no car may touch the
    /// scene, and the cars' widened boxes must stay apart (see `Body::free_reach`).
    fn free_of_contacts(&self, period_s: f32) -> bool {
        let Some(boxes) = self
            .cars
            .iter()
            .map(|c| c.body.free_reach(&self.world, period_s, c.parked))
            .collect::<Option<Vec<Aabb>>>()
        else {
            return false;
        };
        boxes
            .iter()
            .enumerate()
            .all(|(i, a)| boxes[i + 1..].iter().all(|b| !a.intersects(b)))
    }
}
