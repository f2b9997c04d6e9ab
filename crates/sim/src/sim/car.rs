//! One car of a world, read-only: [`Sim::car`]. Every reading comes back as the crate's own
//! types (`msg`, [`PlanarPose`], arrays); rapier's stay inside the crate.

use super::{CarContact, PlanarPose, Sim, VehicleParams};
use crate::msg::{GpsReading, ImuReading, Pose3};
use crate::sensors::camera::RenderedFrame;
use crate::vehicle::Control;
use rapier3d::prelude::*;

/// Car `index` of a [`Sim`].
#[derive(Clone, Copy)]
pub struct CarView<'a> {
    pub(super) sim: &'a Sim,
    pub(super) i: usize,
}

/// A rapier pose as the crate's own.
pub(crate) fn pose3(p: &Pose) -> Pose3 {
    Pose3 {
        position_m: p.translation.to_array(),
        orientation_xyzw: p.rotation.to_array(),
    }
}

/// The crate's own pose as rapier's.
pub(crate) fn pose_of(p: &Pose3) -> Pose {
    Pose::from_parts(
        Vector::from_array(p.position_m),
        Rotation::from_array(p.orientation_xyzw),
    )
}

impl CarView<'_> {
    /// The car's index in its world.
    pub fn index(&self) -> usize {
        self.i
    }

    fn base(&self) -> Pose {
        self.sim.base_pose(self.i)
    }

    /// Planar pose of the base frame.
    pub fn pose2(&self) -> PlanarPose {
        let p = self.base();
        let fwd = p.rotation * Vector::X;
        PlanarPose {
            x_m: p.translation.x,
            y_m: p.translation.y,
            yaw_rad: fwd.y.atan2(fwd.x),
        }
    }

    /// World pose of the base frame.
    pub fn pose(&self) -> Pose3 {
        pose3(&self.base())
    }

    /// Linear velocity of the base origin over the last physics substep, world frame, m/s.
    pub fn linvel_w(&self) -> [f32; 3] {
        self.sim.cars[self.i].vel_w.0.to_array()
    }

    /// Angular velocity of the base over the last physics substep, world frame, rad/s.
    pub fn angvel_w(&self) -> [f32; 3] {
        self.sim.cars[self.i].vel_w.1.to_array()
    }

    /// Speed along the heading, m/s (negative when rolling backwards).
    pub fn forward_speed_mps(&self) -> f32 {
        self.sim.cars[self.i].vel_w.0.dot(self.base().rotation * Vector::X)
    }

    /// Yaw rate, rad/s.
    pub fn yaw_rate_radps(&self) -> f32 {
        self.sim.cars[self.i].vel_w.1.dot(self.base().rotation * Vector::Z)
    }

    /// Whether the car is on its side or roof (body z more than 60 degrees from world z).
    pub fn flipped(&self) -> bool {
        (self.base().rotation * Vector::Z).z < 0.5
    }

    /// Whether the car is parked (see [`Sim::park`]).
    pub fn parked(&self) -> bool {
        self.sim.cars[self.i].parked
    }

    /// Its parameters in force (domain randomisation).
    pub fn params(&self) -> VehicleParams {
        self.sim.cars[self.i].params
    }

    /// The control in force (throttle, centre steering angle after limits and offset; with a
    /// steering rate limit, the angle the wheels reached by the end of the period).
    pub fn control(&self) -> Control {
        self.sim.cars[self.i].control
    }

    /// Steering angles of the left and right front wheels, rad.
    pub fn wheel_angles_rad(&self) -> (f64, f64) {
        self.sim.cars[self.i].wheel_angles
    }

    /// The drive model's wheel speed, rad/s.
    pub fn wheel_speed_radps(&self) -> f64 {
        self.sim.cars[self.i].wheel_speed
    }

    /// Scene objects it touched in the last physics step (walls included, ground excluded);
    /// empty right after a reset. (Refreshing contacts at reset with rapier's collision-only
    /// pass would drop the multibody car from the solver's islands.)
    pub fn contacts(&self) -> Vec<u32> {
        self.sim.contacts(self.i)
    }

    /// The other cars it touched in the last physics step, each once, with the deepest contact
    /// point.
    pub fn car_contacts(&self) -> Vec<CarContact> {
        self.sim.car_contacts(self.i)
    }

    /// The LiDAR's world pose.
    pub fn lidar_pose(&self) -> Pose3 {
        pose3(&(self.base() * self.sim.model.lidar_b))
    }

    /// The camera's world pose, when the vehicle has a camera link.
    pub fn camera_pose(&self) -> Option<Pose3> {
        self.sim.camera_pose(self.i).map(|p| pose3(&p))
    }

    /// Its camera frame (the scene and the other cars), when a camera is configured and the
    /// vehicle has a camera link.
    pub fn camera_frame(&self) -> Option<RenderedFrame> {
        self.sim.camera_frame(self.i)
    }

    /// Its GPS reading.
    pub fn gps(&self) -> GpsReading {
        crate::sensors::gps::read(&self.sim.cfg.settings.gps, &self.base())
    }

    /// Its IMU reading (accelerations over the last control period).
    pub fn imu(&self) -> ImuReading {
        let c = &self.sim.cars[self.i];
        c.imu.read(&self.base(), c.vel_w.0, c.vel_w.1)
    }
}
