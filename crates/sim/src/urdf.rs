//! URDF reading shared by objects and vehicles: link frames at the zero configuration, collision
//! shapes (primitives, and meshes as convex hulls) and colours. Parsing goes through the urdf-rs
//! that rapier3d-urdf re-exports; every error names the file.

use crate::SimError;
use crate::assets::{AssetSource, join_rel};
use rapier3d::prelude::*;
use rapier3d_urdf::urdf_rs;
use std::collections::HashMap;

/// A parsed URDF with each link's pose relative to the root link (all joints at zero).
#[derive(Clone, Debug)]
pub struct UrdfModel {
    /// Asset-relative path, for messages and mesh lookup.
    pub rel_path: String,
    /// The parsed file.
    pub robot: urdf_rs::Robot,
    /// Name of the root link (the one that is no joint's child).
    pub root: String,
    /// Pose of each link in the root frame at zero joint positions.
    pub link_pose: HashMap<String, Pose>,
}

/// One collision shape of a model, in the model's root frame.
#[derive(Clone)]
pub struct ShapeSpec {
    /// The shape.
    pub shape: SharedShape,
    /// Pose in the root frame.
    pub pose: Pose,
    /// Link the shape belongs to.
    pub link: String,
    /// RGB colour from the link's first visual material, in [0, 1].
    pub color: [f32; 3],
}

/// Convert a URDF origin (xyz, fixed-axis roll-pitch-yaw) into a pose.
pub fn pose_from_urdf(p: &urdf_rs::Pose) -> Pose {
    let [x, y, z] = p.xyz.0;
    let [r, pi, ya] = p.rpy.0;
    let rot = Rotation::from_rotation_z(ya as f32)
        * Rotation::from_rotation_y(pi as f32)
        * Rotation::from_rotation_x(r as f32);
    Pose::from_parts(Vector::new(x as f32, y as f32, z as f32), rot)
}

impl UrdfModel {
    /// Read and parse `rel` from `src`.
    pub fn read(src: &AssetSource, rel: &str) -> Result<Self, SimError> {
        let text = src.read(rel)?;
        Self::parse(src, rel, &text)
    }

    /// Parse URDF text that came from `rel`.
    pub fn parse(src: &AssetSource, rel: &str, text: &str) -> Result<Self, SimError> {
        let err = |msg: String| SimError::Urdf {
            path: src.display_path(rel),
            msg,
        };
        let robot = urdf_rs::read_from_string(text).map_err(|e| err(e.to_string()))?;
        if robot.links.is_empty() {
            return Err(err("no <link> elements".into()));
        }
        let children: std::collections::HashSet<&str> = robot.joints.iter().map(|j| j.child.link.as_str()).collect();
        let roots: Vec<&str> = robot
            .links
            .iter()
            .map(|l| l.name.as_str())
            .filter(|n| !children.contains(n))
            .collect();
        let root = match roots.as_slice() {
            [r] => r.to_string(),
            [] => return Err(err("no root link (every link is some joint's child: a cycle)".into())),
            many => return Err(err(format!("several root links: {}", many.join(", ")))),
        };
        let names: std::collections::HashSet<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
        for j in &robot.joints {
            for l in [&j.parent.link, &j.child.link] {
                if !names.contains(l.as_str()) {
                    return Err(err(format!("joint '{}' names unknown link '{l}'", j.name)));
                }
            }
        }
        let mut link_pose = HashMap::new();
        link_pose.insert(root.clone(), Pose::IDENTITY);
        let mut frontier = vec![root.clone()];
        while let Some(parent) = frontier.pop() {
            let parent_pose = link_pose[&parent];
            for j in robot.joints.iter().filter(|j| j.parent.link == parent) {
                if link_pose.contains_key(&j.child.link) {
                    return Err(err(format!("link '{}' is reached twice (a cycle)", j.child.link)));
                }
                link_pose.insert(j.child.link.clone(), parent_pose * pose_from_urdf(&j.origin));
                frontier.push(j.child.link.clone());
            }
        }
        Ok(Self {
            rel_path: rel.to_string(),
            robot,
            root,
            link_pose,
        })
    }

    /// The link named `name`.
    pub fn link(&self, name: &str) -> Result<&urdf_rs::Link, SimError> {
        self.robot
            .links
            .iter()
            .find(|l| l.name == name)
            .ok_or_else(|| SimError::Invalid {
                context: self.rel_path.clone(),
                msg: format!("no link named '{name}'"),
            })
    }

    /// The joint named `name`.
    pub fn joint(&self, name: &str) -> Result<&urdf_rs::Joint, SimError> {
        self.robot
            .joints
            .iter()
            .find(|j| j.name == name)
            .ok_or_else(|| SimError::Invalid {
                context: self.rel_path.clone(),
                msg: format!("no joint named '{name}'"),
            })
    }

    /// RGB colour of a link: its first visual's material, looked up among the file's named
    /// materials when the visual gives only a name. Grey when none.
    pub fn link_color(&self, link: &urdf_rs::Link) -> [f32; 3] {
        for v in &link.visual {
            if let Some(m) = &v.material {
                let c = m.color.clone().or_else(|| {
                    self.robot
                        .materials
                        .iter()
                        .find(|n| n.name == m.name)
                        .and_then(|n| n.color.clone())
                });
                if let Some(c) = c {
                    let [r, g, b, _] = c.rgba.0;
                    return [r as f32, g as f32, b as f32];
                }
            }
        }
        [0.6, 0.6, 0.6]
    }

    /// Collision shapes of the links accepted by `keep`, in the root frame, scaled per axis by
    /// `scale` (exact for meshes and for primitives aligned with the root axes).
    pub fn collision_shapes(
        &self,
        src: &AssetSource,
        scale: Vector,
        keep: impl Fn(&str) -> bool,
    ) -> Result<Vec<ShapeSpec>, SimError> {
        let mut out = Vec::new();
        for link in self.robot.links.iter().filter(|l| keep(&l.name)) {
            let link_pose = self.link_pose.get(&link.name).copied().unwrap_or(Pose::IDENTITY);
            let color = self.link_color(link);
            for c in &link.collision {
                let local = link_pose * pose_from_urdf(&c.origin);
                let (shape, pose) = self.shape(src, &c.geometry, local, scale)?;
                out.push(ShapeSpec {
                    shape,
                    pose,
                    link: link.name.clone(),
                    color,
                });
            }
        }
        Ok(out)
    }

    fn shape(
        &self,
        src: &AssetSource,
        g: &urdf_rs::Geometry,
        pose: Pose,
        scale: Vector,
    ) -> Result<(SharedShape, Pose), SimError> {
        let bad = |msg: String| SimError::Urdf {
            path: src.display_path(&self.rel_path),
            msg,
        };
        // Scale factor along each of the shape's local axes.
        let axis_scale = |i: usize| -> f32 {
            let d = pose.rotation * Vector::ith(i, 1.0);
            (d * scale).length()
        };
        let scaled_pose = Pose::from_parts(pose.translation * scale, pose.rotation);
        let positive = |v: f64, what: &str| -> Result<f32, SimError> {
            if v.is_finite() && v > 0.0 {
                Ok(v as f32)
            } else {
                Err(bad(format!("{what} must be positive, got {v}")))
            }
        };
        Ok(match g {
            urdf_rs::Geometry::Box { size } => {
                let [x, y, z] = size.0;
                let h = Vector::new(
                    positive(x, "box size")? / 2.0 * axis_scale(0),
                    positive(y, "box size")? / 2.0 * axis_scale(1),
                    positive(z, "box size")? / 2.0 * axis_scale(2),
                );
                (SharedShape::cuboid(h.x, h.y, h.z), scaled_pose)
            }
            urdf_rs::Geometry::Cylinder { radius, length } => {
                let r = positive(*radius, "cylinder radius")? * 0.5 * (axis_scale(0) + axis_scale(1));
                let hh = positive(*length, "cylinder length")? / 2.0 * axis_scale(2);
                // URDF cylinders run along z, rapier's along y.
                let rot = scaled_pose.rotation * Rotation::from_rotation_x(std::f32::consts::FRAC_PI_2);
                (
                    SharedShape::cylinder(hh, r),
                    Pose::from_parts(scaled_pose.translation, rot),
                )
            }
            urdf_rs::Geometry::Capsule { radius, length } => {
                let r = positive(*radius, "capsule radius")? * 0.5 * (axis_scale(0) + axis_scale(1));
                let hh = positive(*length, "capsule length")? / 2.0 * axis_scale(2);
                (SharedShape::capsule_z(hh, r), scaled_pose)
            }
            urdf_rs::Geometry::Sphere { radius } => {
                let r = positive(*radius, "sphere radius")? * (axis_scale(0) + axis_scale(1) + axis_scale(2)) / 3.0;
                (SharedShape::ball(r), scaled_pose)
            }
            urdf_rs::Geometry::Mesh {
                filename,
                scale: mscale,
            } => {
                let rel = join_rel(&self.rel_path, filename.trim_start_matches("package://"));
                let text = src.read(&rel).map_err(|e| SimError::Mesh {
                    path: src.display_path(&rel),
                    msg: e.to_string(),
                })?;
                let ms = mscale.map(|s| s.0).unwrap_or([1.0, 1.0, 1.0]);
                let ms = Vector::new(ms[0] as f32, ms[1] as f32, ms[2] as f32);
                // Hull in the model root frame so the per-axis scale is exact.
                let pts: Vec<Vector> = parse_obj_vertices(&text)
                    .map_err(|msg| SimError::Mesh {
                        path: src.display_path(&rel),
                        msg,
                    })?
                    .into_iter()
                    .map(|v| (pose * (v * ms)) * scale)
                    .collect();
                let hull = SharedShape::convex_hull(&pts).ok_or_else(|| SimError::Mesh {
                    path: src.display_path(&rel),
                    msg: format!("no convex hull from {} vertices (degenerate mesh)", pts.len()),
                })?;
                (hull, Pose::IDENTITY)
            }
        })
    }
}

/// Vertices (`v x y z` lines) of a Wavefront OBJ file, in file order. Only the point cloud
/// is needed (every mesh becomes its convex hull), and the meshes are embedded assets:
/// rapier3d-urdf's mesh loading reads from disk paths, and mesh-loader's OBJ reader returns
/// face-expanded vertices in another order (a hull built from them is not bit-identical, which
/// would move every committed search figure), so the parser is these twenty lines.
pub fn parse_obj_vertices(text: &str) -> Result<Vec<Vector>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() != Some("v") {
            continue;
        }
        let xyz: Vec<f32> = it
            .take(3)
            .map(|s| s.parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("line {}: {e}", i + 1))?;
        if xyz.len() != 3 || xyz.iter().any(|v| !v.is_finite()) {
            return Err(format!("line {}: a vertex needs three finite numbers", i + 1));
        }
        out.push(Vector::new(xyz[0], xyz[1], xyz[2]));
    }
    if out.len() < 4 {
        return Err(format!("{} vertices; a convex hull needs at least 4", out.len()));
    }
    Ok(out)
}
