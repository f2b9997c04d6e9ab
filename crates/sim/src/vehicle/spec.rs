//! A vehicle is data: a URDF plus a TOML beside it naming the driven and steered joints, the
//! sensor links and the actuation constants. `VehicleModel::load` turns both into geometry the
//! dynamics modes share.

use crate::SimError;
use crate::assets::{AssetSource, join_rel};
use crate::urdf::{ShapeSpec, UrdfModel};
use rapier3d::prelude::*;
use serde::{Deserialize, Serialize};

/// The TOML beside a vehicle URDF.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// URDF file, relative to this TOML.
    pub urdf: String,
    /// Link the LiDAR rays start from.
    pub lidar_link: String,
    /// Link of the camera's optical centre.
    pub camera_link: Option<String>,
    /// Tyre friction coefficient (multiplied with the ground's).
    #[serde(default = "one")]
    pub tyre_friction: f32,
    /// Wheel-speed model and motor limits.
    pub drive: DriveSpec,
    /// Steering limits and geometry.
    pub steering: SteeringSpec,
    /// Tyres with cornering stiffness (ray-cast mode). Without it the tyres follow rapier's
    /// ray-cast side friction, which has no slip angle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tyre: Option<TyreSpec>,
    /// The wheels.
    #[serde(rename = "wheel")]
    pub wheels: Vec<WheelSpec>,
}

fn one() -> f32 {
    1.0
}

/// AutoVRL's wheel-speed model `w' = c_t T - w (c_d w + c_r)` (w in rad/s) and motor limits.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DriveSpec {
    /// Throttle gain C_T, rad/s^2 per unit throttle.
    pub c_t: f64,
    /// Quadratic drag C_d, 1/rad.
    pub c_d: f64,
    /// Linear rolling resistance C_r, 1/s.
    pub c_r: f64,
    /// Maximum torque of each driven wheel's motor, N m.
    pub max_torque_nm: f64,
}

/// Steering limits.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SteeringSpec {
    /// Largest steering angle of the virtual centre wheel, rad.
    pub max_rad: f64,
    /// Split the angle between the front wheels by Ackermann geometry (else both get it).
    pub ackermann: bool,
    /// Fastest the virtual centre wheel turns, rad/s; unset, the wheels take each commanded
    /// angle at once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_rate_radps: Option<f64>,
}

/// The single-track model's linear tyre (f1tenth_gym's `vehicle_dynamics_st`): each wheel's side
/// force is `mu * C_S * F_z * alpha` for a slip angle `alpha`, up to what the friction circle
/// leaves beside the drive force.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TyreSpec {
    /// Cornering stiffness coefficient of the steered wheels, 1/rad (side force per unit load
    /// and friction, per radian of slip).
    pub cornering_stiffness_front: f64,
    /// The same for the fixed wheels, 1/rad.
    pub cornering_stiffness_rear: f64,
}

/// One wheel: its spinning joint, optionally the hinge that steers it, and whether it is driven.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WheelSpec {
    /// The continuous joint the wheel spins on (axis = the wheel's axle).
    pub joint: String,
    /// The revolute joint (axis z) that steers this wheel, if any.
    pub steer_joint: Option<String>,
    /// Whether the drive motor turns this wheel.
    pub drive: bool,
}

/// Geometry of one wheel in the base frame.
#[derive(Clone, Debug)]
pub struct WheelGeom {
    /// Centre of the wheel in the base frame, metres.
    pub center_b: Vector,
    /// Radius, metres.
    pub radius_m: f32,
    /// Width, metres.
    pub width_m: f32,
    /// Steered wheel on the left (+1), right (-1), or not steered (0).
    pub steer_side: i8,
    /// Driven by the motor.
    pub driven: bool,
    /// Link carrying the wheel.
    pub link: String,
    /// Spinning joint.
    pub joint: String,
    /// Steering joint.
    pub steer_joint: Option<String>,
}

/// A loaded vehicle: spec, URDF and the derived geometry.
#[derive(Clone)]
pub struct VehicleModel {
    /// Name (file stem).
    pub name: String,
    /// The TOML spec.
    pub spec: VehicleSpec,
    /// The URDF.
    pub urdf: UrdfModel,
    /// Wheels, in spec order.
    pub wheels: Vec<WheelGeom>,
    /// Distance between the steered and the fixed axle, metres.
    pub wheelbase_m: f32,
    /// Distance between the steered wheels' centres, metres.
    pub front_track_m: f32,
    /// Total mass, kg.
    pub mass_kg: f32,
    /// Mass properties of the whole car in the base frame (rigid, wheels included).
    pub mass_props: MassProperties,
    /// LiDAR pose in the base frame.
    pub lidar_b: Pose,
    /// Camera pose in the base frame, when the vehicle has one.
    pub camera_b: Option<Pose>,
    /// Collision shapes of every link but the wheels, in the base frame.
    pub body_shapes: Vec<ShapeSpec>,
    /// Mass properties of each link in its own frame, from the URDF's inertials.
    pub link_mprops: std::collections::HashMap<String, MassProperties>,
}

impl VehicleModel {
    /// The LiDAR's mount in the base frame (`base_link` -> `laser`).
    pub fn lidar_mount(&self) -> crate::msg::Pose3 {
        crate::sim::pose3(&self.lidar_b)
    }

    /// The camera's mount in the base frame, when the vehicle has one.
    pub fn camera_mount(&self) -> Option<crate::msg::Pose3> {
        self.camera_b.as_ref().map(crate::sim::pose3)
    }

    /// The box the body (every link but the wheels) fills in the base frame, as its lowest and
    /// highest corner (x ahead, y left, z up; metres): `None` for a vehicle of wheels alone.
    pub fn body_bounds_m(&self) -> Option<([f32; 3], [f32; 3])> {
        let boxes = self.body_shapes.iter().map(|s| s.shape.compute_aabb(&s.pose));
        let b = boxes.reduce(|a, b| a.merged(&b))?;
        Some((b.mins.to_array(), b.maxs.to_array()))
    }

    /// Load `<name>.toml` (and its URDF) from `vehicles/` of `src`.
    pub fn builtin(src: &AssetSource, name: &str) -> Result<Self, SimError> {
        let rel = format!("vehicles/{name}.toml");
        if src.read(&rel).is_err() {
            return Err(SimError::Invalid {
                context: "vehicle".into(),
                msg: format!(
                    "unknown vehicle '{name}'; built-in vehicles: {}",
                    src.list("vehicles", "toml").join(", ")
                ),
            });
        }
        Self::load(src, &rel)
    }

    /// Load the vehicle TOML at `rel` in `src`.
    pub fn load(src: &AssetSource, rel: &str) -> Result<Self, SimError> {
        let text = src.read(rel)?;
        let spec: VehicleSpec = toml::from_str(&text).map_err(|e| SimError::Toml {
            path: src.display_path(rel),
            msg: e.to_string(),
        })?;
        let urdf = UrdfModel::read(src, &join_rel(rel, &spec.urdf))?;
        let name = rel
            .rsplit('/')
            .next()
            .unwrap_or(rel)
            .trim_end_matches(".toml")
            .to_string();
        let invalid = |msg: String| SimError::Invalid {
            context: src.display_path(rel).display().to_string(),
            msg,
        };
        if spec.wheels.len() < 3 {
            return Err(invalid(format!(
                "a car needs at least 3 wheels, the spec lists {}",
                spec.wheels.len()
            )));
        }
        let d = spec.drive;
        if !(d.c_t > 0.0 && d.c_d >= 0.0 && d.c_r >= 0.0 && d.max_torque_nm > 0.0) {
            return Err(invalid(
                "drive constants must be c_t > 0, c_d >= 0, c_r >= 0, max_torque_nm > 0".into(),
            ));
        }
        if !(spec.steering.max_rad > 0.0 && spec.steering.max_rad < 1.5) {
            return Err(invalid(format!(
                "steering.max_rad must be in (0, 1.5), got {}",
                spec.steering.max_rad
            )));
        }
        if let Some(t) = spec.tyre
            && !(t.cornering_stiffness_front > 0.0 && t.cornering_stiffness_rear > 0.0)
        {
            return Err(invalid(format!(
                "tyre cornering stiffnesses must be > 0, got front {} and rear {}",
                t.cornering_stiffness_front, t.cornering_stiffness_rear
            )));
        }
        if let Some(r) = spec.steering.max_rate_radps
            && !(r.is_finite() && r > 0.0)
        {
            return Err(invalid(format!(
                "steering.max_rate_radps must be finite and > 0, got {r}"
            )));
        }
        let mut wheels = Vec::new();
        for w in &spec.wheels {
            let joint = urdf.joint(&w.joint)?;
            let link = urdf.link(&joint.child.link)?;
            let (r, width, off) = link
                .collision
                .iter()
                .find_map(|c| match c.geometry {
                    rapier3d_urdf::urdf_rs::Geometry::Cylinder { radius, length } => Some((
                        radius as f32,
                        length as f32,
                        crate::urdf::pose_from_urdf(&c.origin).translation,
                    )),
                    _ => None,
                })
                .ok_or_else(|| invalid(format!("wheel link '{}' needs a cylinder collision shape", link.name)))?;
            let center_b = urdf.link_pose[&link.name] * off;
            let steer_side = match &w.steer_joint {
                Some(s) => {
                    urdf.joint(s)?;
                    if center_b.y >= 0.0 { 1 } else { -1 }
                }
                None => 0,
            };
            wheels.push(WheelGeom {
                center_b,
                radius_m: r,
                width_m: width,
                steer_side,
                driven: w.drive,
                link: link.name.clone(),
                joint: w.joint.clone(),
                steer_joint: w.steer_joint.clone(),
            });
        }
        let steered: Vec<&WheelGeom> = wheels.iter().filter(|w| w.steer_side != 0).collect();
        let fixed: Vec<&WheelGeom> = wheels.iter().filter(|w| w.steer_side == 0).collect();
        if steered.is_empty() || fixed.is_empty() {
            return Err(invalid("need at least one steered and one fixed wheel".into()));
        }
        let mean_x = |ws: &[&WheelGeom]| ws.iter().map(|w| w.center_b.x).sum::<f32>() / ws.len() as f32;
        let wheelbase_m = (mean_x(&steered) - mean_x(&fixed)).abs();
        let ys: Vec<f32> = steered.iter().map(|w| w.center_b.y).collect();
        let front_track_m = ys.iter().cloned().fold(f32::MIN, f32::max) - ys.iter().cloned().fold(f32::MAX, f32::min);
        if wheelbase_m < 0.05 {
            return Err(invalid(format!(
                "wheelbase {wheelbase_m} m: steered and fixed wheels share an axle"
            )));
        }

        let mut mass_props = MassProperties::default();
        let mut link_mprops = std::collections::HashMap::new();
        for l in &urdf.robot.links {
            let i = &l.inertial;
            let m = i.mass.value as f32;
            if m <= 0.0 {
                continue;
            }
            let ip = &i.inertia;
            let mat = Matrix::from_cols(
                Vector::new(ip.ixx as f32, ip.ixy as f32, ip.ixz as f32),
                Vector::new(ip.ixy as f32, ip.iyy as f32, ip.iyz as f32),
                Vector::new(ip.ixz as f32, ip.iyz as f32, ip.izz as f32),
            );
            let origin = crate::urdf::pose_from_urdf(&i.origin);
            let r = Matrix::from_quat(origin.rotation);
            let local = MassProperties::with_inertia_matrix(origin.translation, m, r * mat * r.transpose());
            mass_props += local.transform_by(&urdf.link_pose[&l.name]);
            link_mprops.insert(l.name.clone(), local);
        }
        if mass_props.mass() <= 0.0 {
            return Err(invalid("the URDF has no mass (add <inertial> elements)".into()));
        }
        let lidar_b = *urdf
            .link_pose
            .get(&spec.lidar_link)
            .ok_or_else(|| invalid(format!("no lidar link '{}'", spec.lidar_link)))?;
        let camera_b = match &spec.camera_link {
            Some(c) => Some(
                *urdf
                    .link_pose
                    .get(c)
                    .ok_or_else(|| invalid(format!("no camera link '{c}'")))?,
            ),
            None => None,
        };
        let wheel_links: Vec<String> = wheels.iter().map(|w| w.link.clone()).collect();
        let body_shapes = urdf.collision_shapes(src, Vector::ONE, |l| !wheel_links.iter().any(|w| w == l))?;
        Ok(Self {
            name,
            mass_kg: mass_props.mass(),
            spec,
            urdf,
            wheels,
            wheelbase_m,
            front_track_m,
            mass_props,
            lidar_b,
            camera_b,
            body_shapes,
            link_mprops,
        })
    }

    /// Wheel radius of the driven wheels, metres (the radius the drive model's w refers to).
    pub fn drive_radius_m(&self) -> f32 {
        let d: Vec<f32> = self.wheels.iter().filter(|w| w.driven).map(|w| w.radius_m).collect();
        if d.is_empty() {
            self.wheels[0].radius_m
        } else {
            d.iter().sum::<f32>() / d.len() as f32
        }
    }

    /// Top speed of the drive model on flat ground, m/s: the steady wheel speed at full
    /// throttle times the driven wheels' radius (tyre slip makes the simulated car about 2 %
    /// slower).
    pub fn top_speed_mps(&self) -> f32 {
        let d = self.spec.drive;
        let model = crate::vehicle::actuation::DriveModel {
            c_t: d.c_t,
            c_d: d.c_d,
            c_r: d.c_r,
            brake: 0.0,
        };
        model.steady_state(1.0) as f32 * self.drive_radius_m()
    }

    /// Height of the base frame above flat ground when the car rests on its wheels, metres.
    pub fn rest_height_m(&self) -> f32 {
        self.wheels
            .iter()
            .map(|w| w.radius_m - w.center_b.z)
            .fold(0.0, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The racecar's body is three boxes straight from its URDF: the chassis (0.4 x 0.16 x
    /// 0.04 m at (0.16, 0, 0.03)), the LiDAR (0.1 m cube at (0.265, 0, 0.075)) and the camera
    /// (0.033 x 0.175 x 0.03 m at (0.39, 0, 0.04)); the wheels are not part of it.
    #[test]
    fn the_body_bounds_are_the_union_of_the_urdfs_body_boxes() {
        let model = VehicleModel::builtin(&AssetSource::Embedded, "racecar").unwrap();
        let (lo, hi) = model.body_bounds_m().expect("the racecar has a body");
        let want = ([-0.04, -0.0875, 0.01], [0.4065, 0.0875, 0.125]);
        for k in 0..3 {
            assert!(
                (lo[k] - want.0[k]).abs() < 1e-5,
                "lowest corner {lo:?}, want {:?}",
                want.0
            );
            assert!(
                (hi[k] - want.1[k]).abs() < 1e-5,
                "highest corner {hi:?}, want {:?}",
                want.1
            );
        }
    }
}
