//! IMU: velocities from the rigid body, accelerations by finite difference over the sample time
//! (as AutoVRL's paper does), reported as a real IMU does (specific force: +9.81 m/s^2 on body z
//! at rest).

use crate::msg::ImuReading;
use crate::world::GRAVITY_MPS2;
use rapier3d::prelude::*;

/// Velocity state the IMU differentiates.
#[derive(Clone, Copy, Debug, Default)]
pub struct ImuState {
    /// Linear velocity at the previous sample, world frame, m/s.
    pub prev_lin_w: Vector,
    /// Angular velocity at the previous sample, world frame, rad/s.
    pub prev_ang_w: Vector,
    /// Linear acceleration over the last sample period, world frame, m/s^2.
    pub lin_acc_w: Vector,
    /// Angular acceleration over the last sample period, world frame, rad/s^2.
    pub ang_acc_w: Vector,
}

impl ImuState {
    /// Record a new sample of the body's velocities taken `dt_s` after the previous one.
    pub fn update(&mut self, lin_w: Vector, ang_w: Vector, dt_s: f32) {
        self.lin_acc_w = (lin_w - self.prev_lin_w) / dt_s;
        self.ang_acc_w = (ang_w - self.prev_ang_w) / dt_s;
        self.prev_lin_w = lin_w;
        self.prev_ang_w = ang_w;
    }

    /// Restart at rest.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The reading for a body at `pose_w` moving with (`lin_w`, `ang_w`).
    pub fn read(&self, pose_w: &Pose, lin_w: Vector, ang_w: Vector) -> ImuReading {
        let inv = pose_w.rotation.inverse();
        let f = |v: Vector| v.as_dvec3().to_array();
        let specific_w = self.lin_acc_w + Vector::new(0.0, 0.0, GRAVITY_MPS2);
        ImuReading {
            orientation_xyzw: pose_w.rotation.as_dquat().to_array(),
            lin_vel_w: f(lin_w),
            lin_vel_b: f(inv * lin_w),
            ang_vel_w: f(ang_w),
            ang_vel_b: f(inv * ang_w),
            lin_acc_b: f(inv * specific_w),
            ang_acc_b: f(inv * self.ang_acc_w),
        }
    }
}
