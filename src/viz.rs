//! Recordings for the rerun viewer: the scene, the vehicle and its path, LiDAR rays (red hits,
//! green misses, as the paper's figure), camera images, and reward / speed / steering / throttle
//! on a `step` timeline.

use crate::episode::{StepView, speed_mps};
use agvrl_sim::Sim;
use anyhow::{Context, Result};
use rapier3d::prelude::{Pose, Rotation, SharedShape};
use rerun::RecordingStream;
use std::path::PathBuf;

pub use crate::sink::{BagView, Sink, sink_of};

/// Logs episodes into one recording.
pub struct Recorder {
    rec: RecordingStream,
    file: Option<(PathBuf, PathBuf)>,
    scene_logged: bool,
    /// Semantic class id of each scene object (segmentation pixel value - 1).
    class_of: Vec<u16>,
    trail: Vec<[f32; 3]>,
    /// Each car's path in a race.
    trails: Vec<Vec<[f32; 3]>>,
    step: i64,
    /// Log camera images every this many steps (they are large).
    pub image_every: u64,
}

fn q_of(r: Rotation) -> rerun::Quaternion {
    rerun::Quaternion::from_xyzw([r.x, r.y, r.z, r.w])
}

fn color(c: [f32; 3]) -> rerun::Color {
    let u = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    rerun::Color::from_rgb(u(c[0]), u(c[1]), u(c[2]))
}

/// rerun's cylinders stand on z, parry's on y.
fn y_up_to_z_up(pose: &Pose) -> rerun::Quaternion {
    q_of(pose.rotation * Rotation::from_rotation_x(-std::f32::consts::FRAC_PI_2))
}

/// The car's path so far under `world/trajectory`.
fn log_trail(rec: &RecordingStream, trail: &[[f32; 3]]) -> Result<()> {
    rec.log(
        "world/trajectory",
        &rerun::LineStrips3D::new([trail.to_vec()]).with_colors([rerun::Color::from_rgb(255, 200, 0)]),
    )?;
    Ok(())
}

/// A scan under `base`: rays from `origin` to `ends` (red hits, green misses, as the paper's
/// figure) in `base/rays`, the hits in `base/scan`.
fn log_scan(rec: &RecordingStream, base: &str, origin: [f32; 3], ends: &[[f32; 3]], hit: &[bool]) -> Result<()> {
    let red = rerun::Color::from_rgb(255, 40, 40);
    let colors = hit
        .iter()
        .map(|&h| if h { red } else { rerun::Color::from_rgb(40, 220, 40) });
    rec.log(
        format!("{base}/rays"),
        &rerun::LineStrips3D::new(ends.iter().map(|e| [origin, *e]))
            .with_colors(colors)
            .with_radii([0.004]),
    )?;
    let hits = ends.iter().zip(hit).filter(|(_, h)| **h).map(|(e, _)| *e);
    rec.log(
        format!("{base}/scan"),
        &rerun::Points3D::new(hits).with_radii([0.03]).with_colors([red]),
    )?;
    Ok(())
}

/// How a recording opens in the viewer: the scene and the car large, the LiDAR and the camera
/// beside them, the time series below.
/// A depth-only camera (the camera racing policy's) opens on its depth tab.
fn layout(depth_first: bool) -> rerun::blueprint::Blueprint {
    use rerun::blueprint::{Blueprint, Horizontal, Spatial2DView, Spatial3DView, Tabs, TimeSeriesView, Vertical};
    let scene = Spatial3DView::new("scene").with_origin("world");
    let lidar = Spatial3DView::new("LiDAR")
        .with_origin("world")
        .with_contents(["world/lidar/**", "world/vehicle/**"]);
    // The first tab is the one shown.
    let rgb = Spatial2DView::new("camera").with_origin("camera/rgb").into();
    let depth = Spatial2DView::new("depth").with_origin("camera/depth").into();
    let seg = Spatial2DView::new("segmentation")
        .with_origin("camera/segmentation")
        .into();
    let camera = Tabs::new(if depth_first {
        [depth, rgb, seg]
    } else {
        [rgb, depth, seg]
    });
    let side = Vertical::new([lidar.into(), camera.into()]);
    let plots = Horizontal::new(
        ["reward", "speed_mps", "steering_rad", "throttle", "min_range_m"]
            .map(|p| TimeSeriesView::new(p).with_origin(format!("plots/{p}")).into()),
    );
    let top = Horizontal::new([scene.into(), side.into()]).with_column_shares([3.0, 1.0]);
    Blueprint::new(Vertical::new([top.into(), plots.into()]).with_row_shares([3.0, 1.0]))
}

impl Recorder {
    /// Open a recording named `name` of an env with camera `camera`.
    pub fn new(sink: Sink, name: &str, camera: Option<&agvrl_sim::sensors::CameraConfig>) -> Result<Self> {
        let builder = rerun::RecordingStreamBuilder::new("agvrl")
            .recording_name(name)
            .with_blueprint(layout(camera.is_some_and(|c| c.depth_only)));
        let (rec, file) = match sink {
            Sink::File(path) => {
                let tmp = path.with_extension("rrd.tmp");
                let rec = builder
                    .save(&tmp)
                    .with_context(|| format!("cannot write {}", tmp.display()))?;
                (rec, Some((tmp, path)))
            }
            Sink::Viewer => (
                builder
                    .spawn()
                    .context("cannot spawn the rerun viewer (install it: pip install rerun-sdk==0.36.3)")?,
                None,
            ),
        };
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        Ok(Self {
            rec,
            file,
            scene_logged: false,
            class_of: Vec::new(),
            trail: Vec::new(),
            trails: Vec::new(),
            step: 0,
            image_every: 3,
        })
    }

    fn log_shape(&self, path: &str, shape: &SharedShape, pose: &Pose, c: [f32; 3]) -> Result<()> {
        let t = pose.translation;
        let center = [t.x, t.y, t.z];
        if let Some(comp) = shape.as_compound() {
            for (k, (p, s)) in comp.shapes().iter().enumerate() {
                self.log_shape(&format!("{path}/{k}"), s, &(*pose * *p), c)?;
            }
        } else if let Some(b) = shape.as_cuboid() {
            let h = b.half_extents;
            self.rec.log_static(
                path,
                &rerun::Boxes3D::from_centers_and_half_sizes([center], [[h.x, h.y, h.z]])
                    .with_quaternions([q_of(pose.rotation)])
                    .with_colors([color(c)])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?;
        } else if let Some(cy) = shape.as_cylinder() {
            self.rec.log_static(
                path,
                &rerun::Cylinders3D::from_lengths_and_radii([2.0 * cy.half_height], [cy.radius])
                    .with_centers([center])
                    .with_quaternions([y_up_to_z_up(pose)])
                    .with_colors([color(c)])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?;
        } else if let Some(b) = shape.as_ball() {
            self.rec.log_static(
                path,
                &rerun::Ellipsoids3D::from_centers_and_radii([center], [b.radius])
                    .with_colors([color(c)])
                    .with_fill_mode(rerun::FillMode::Solid),
            )?;
        } else if let Some(cv) = shape.as_convex_polyhedron() {
            let (v, idx) = cv.to_trimesh();
            self.mesh(path, v.into_iter().map(|p| *pose * p), idx, c)?;
        } else if let Some(tm) = shape.as_trimesh() {
            self.mesh(path, tm.vertices().iter().map(|p| *pose * *p), tm.indices().to_vec(), c)?;
        } else {
            let a = shape.compute_aabb(pose);
            let (lo, hi) = (a.mins, a.maxs);
            self.rec.log_static(
                path,
                &rerun::Boxes3D::from_mins_and_sizes([[lo.x, lo.y, lo.z]], [[hi.x - lo.x, hi.y - lo.y, hi.z - lo.z]])
                    .with_colors([color(c)]),
            )?;
        }
        Ok(())
    }

    fn mesh(
        &self,
        path: &str,
        v: impl Iterator<Item = rapier3d::prelude::Vector>,
        idx: Vec<[u32; 3]>,
        c: [f32; 3],
    ) -> Result<()> {
        let pos: Vec<[f32; 3]> = v.map(|p| [p.x, p.y, p.z]).collect();
        self.rec.log_static(
            path,
            &rerun::Mesh3D::new(pos)
                .with_triangle_indices(idx)
                .with_albedo_factor(color(c).0),
        )?;
        Ok(())
    }

    /// The static scene, the vehicle's body and the segmentation classes (once).
    pub fn scene(&mut self, sim: &Sim) -> Result<()> {
        if self.scene_logged {
            return Ok(());
        }
        self.scene_logged = true;
        self.scene_objects(sim)?;
        self.vehicle_body(sim)
    }

    /// The ground, the scene's objects and the segmentation classes.
    fn scene_objects(&mut self, sim: &Sim) -> Result<()> {
        let scene = sim.scene();
        let g = &scene.file.ground;
        self.rec.log_static(
            "world/scene/ground",
            &rerun::Boxes3D::from_centers_and_half_sizes(
                [[0.0, 0.0, -0.01]],
                [[g.size_m[0] / 2.0, g.size_m[1] / 2.0, 0.01]],
            )
            .with_colors([color(g.color)])
            .with_fill_mode(rerun::FillMode::Solid),
        )?;
        let mut classes: Vec<&str> = scene.objects.iter().map(|o| o.class.as_str()).collect();
        classes.sort_unstable();
        classes.dedup();
        self.class_of = scene
            .objects
            .iter()
            .map(|o| classes.iter().position(|c| *c == o.class).map_or(0, |k| k as u16 + 1))
            .collect();
        let mut ctx = vec![(0u16, "ground/sky".to_string(), rerun::Rgba32::from_rgb(90, 90, 90))];
        for (k, name) in classes.iter().enumerate() {
            let c = scene
                .objects
                .iter()
                .find(|o| o.class == *name)
                .and_then(|o| o.shapes.first())
                .map_or([0.5; 3], |s| s.color);
            let col = color(c);
            let [r, g, b, _] = col.to_array();
            ctx.push((k as u16 + 1, name.to_string(), rerun::Rgba32::from_rgb(r, g, b)));
        }
        self.rec.log_static(
            "camera/segmentation",
            &rerun::AnnotationContext::new(ctx.iter().map(|(id, n, c)| (*id, n.as_str(), *c))),
        )?;
        for obj in &scene.objects {
            for (k, s) in obj.shapes.iter().enumerate() {
                self.log_shape(
                    &format!("world/scene/{}_{}/{k}", obj.model, obj.id),
                    &s.shape,
                    &s.pose,
                    s.color,
                )?;
            }
        }
        Ok(())
    }

    /// The car in its own frame under `world/vehicle`: a chassis spanning the wheels, and the
    /// wheels.
    fn vehicle_body(&mut self, sim: &Sim) -> Result<()> {
        let v = sim.vehicle();
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for w in &v.wheels {
            lo = [lo[0].min(w.center_b.x), lo[1].min(w.center_b.y)];
            hi = [hi[0].max(w.center_b.x), hi[1].max(w.center_b.y)];
        }
        if let Some(w) = v.wheels.first() {
            let z = w.center_b.z + w.radius_m;
            self.rec.log_static(
                "world/vehicle/chassis",
                &rerun::Boxes3D::from_centers_and_half_sizes(
                    [[(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, z]],
                    [[
                        (hi[0] - lo[0]) / 2.0 + w.radius_m,
                        (hi[1] - lo[1]) / 2.0 - w.width_m / 2.0,
                        0.04,
                    ]],
                )
                .with_colors([rerun::Color::from_rgb(30, 90, 200)])
                .with_fill_mode(rerun::FillMode::Solid),
            )?;
            self.log_wheels("world/vehicle/wheels", v)?;
        }
        Ok(())
    }

    /// Log one step (a new episode starts at `v.step == 0`).
    pub fn step(&mut self, v: &StepView<'_>) -> Result<()> {
        self.scene(v.sim)?;
        let rec = &self.rec;
        rec.set_time_sequence("step", self.step);
        rec.set_time_sequence("episode", v.episode as i64);
        self.step += 1;
        let pose = v.sim.car(0).pose();
        let t = pose.position_m;
        rec.log(
            "world/vehicle",
            &rerun::Transform3D::from_translation_rotation(t, rerun::Quaternion::from_xyzw(pose.orientation_xyzw)),
        )?;
        if v.step == 0 {
            self.trail.clear();
        }
        self.trail.push([t[0], t[1], 0.02]);
        // The whole trail every half second keeps the file linear in the episode length.
        if v.step.is_multiple_of(15) || v.done {
            log_trail(rec, &self.trail)?;
        }
        if let Some(scan) = &v.frame.scan {
            log_scan(rec, "world/lidar", scan.origin_w, &scan.points_w, &scan.hit)?;
            rec.log("plots/min_range_m", &rerun::Scalars::single(scan.min_range() as f64))?;
        }
        if let Some(img) = &v.frame.image
            && img.width > 0
            && (v.step.is_multiple_of(self.image_every.max(1)) || v.done)
        {
            let res = [img.width, img.height];
            // A depth-only camera has no colour or segmentation.
            if !img.rgb.is_empty() {
                rec.log("camera/rgb", &rerun::Image::from_rgb24(img.rgb.clone(), res))?;
            }
            let depth: Vec<u8> = img.depth_m.iter().flat_map(|d| d.to_le_bytes()).collect();
            rec.log(
                "camera/depth",
                &rerun::DepthImage::from_data_type_and_bytes(depth, res, rerun::datatypes::ChannelDatatype::F32)
                    .with_meter(1.0),
            )?;
            if !img.segmentation.is_empty() {
                let seg: Vec<u8> = img
                    .segmentation
                    .iter()
                    .map(|&s| match s {
                        0 => 0,
                        id => self.class_of.get(id as usize - 1).copied().unwrap_or(0),
                    })
                    .flat_map(|c: u16| c.to_le_bytes())
                    .collect();
                rec.log(
                    "camera/segmentation",
                    &rerun::SegmentationImage::new(
                        seg,
                        rerun::components::ImageFormat::segmentation(res, rerun::datatypes::ChannelDatatype::U16),
                    ),
                )?;
            }
        }
        let a = v.frame.applied;
        rec.log("plots/reward", &rerun::Scalars::single(v.reward))?;
        rec.log("plots/speed_mps", &rerun::Scalars::single(speed_mps(v.frame)))?;
        rec.log("plots/steering_rad", &rerun::Scalars::single(a.steering_rad))?;
        rec.log("plots/throttle", &rerun::Scalars::single(a.throttle))?;
        if v.done {
            let what = if v.terminated {
                "terminated (collision)"
            } else {
                "time limit"
            };
            rec.log(
                "log",
                &rerun::TextLog::new(format!("episode {} ended at step {}: {what}", v.episode, v.step)),
            )?;
        }
        Ok(())
    }

    /// A car's wheels in its own frame, under `path`.
    fn log_wheels(&self, path: &str, v: &agvrl_sim::vehicle::VehicleModel) -> Result<()> {
        let q = q_of(Rotation::from_rotation_x(-std::f32::consts::FRAC_PI_2));
        self.rec.log_static(
            path,
            &rerun::Cylinders3D::from_lengths_and_radii(
                v.wheels.iter().map(|w| w.width_m),
                v.wheels.iter().map(|w| w.radius_m),
            )
            .with_centers(v.wheels.iter().map(|w| [w.center_b.x, w.center_b.y, w.center_b.z]))
            .with_quaternions(v.wheels.iter().map(|_| q))
            .with_colors([rerun::Color::from_rgb(30, 30, 30)])
            .with_fill_mode(rerun::FillMode::Solid),
        )?;
        Ok(())
    }

    /// One step of race `race` (a race starts at `step == 0`): every car its own entity
    /// `world/car_<i>` (its collision shapes, the upper deck included, in its frame, and the
    /// wheels), its path `world/paths/car_<i>`, its LiDAR `world/lidar/car_<i>`, its speed in
    /// `plots/speed_mps/car_<i>`.
    pub fn race_step(
        &mut self,
        sim: &Sim,
        scans: &[Option<&agvrl_sim::msg::LaserScan>],
        race: usize,
        step: u64,
    ) -> Result<()> {
        let palette = [
            [0.12, 0.35, 0.85],
            [0.85, 0.2, 0.2],
            [0.1, 0.65, 0.3],
            [0.9, 0.6, 0.1],
            [0.55, 0.25, 0.75],
            [0.1, 0.7, 0.75],
            [0.4, 0.4, 0.4],
            [0.95, 0.4, 0.7],
        ];
        let n = sim.n_cars();
        if !self.scene_logged {
            self.scene_logged = true;
            self.scene_objects(sim)?;
            let v = sim.vehicle();
            for i in 0..n {
                let c = palette[i % palette.len()];
                for (k, s) in v.body_shapes.iter().enumerate() {
                    self.log_shape(&format!("world/car_{i}/body/{k}"), &s.shape, &s.pose, c)?;
                }
                self.log_wheels(&format!("world/car_{i}/wheels"), v)?;
            }
        }
        if step == 0 {
            self.trails = vec![Vec::new(); n];
        }
        let rec = &self.rec;
        rec.set_time_sequence("step", self.step);
        rec.set_time_sequence("race", race as i64);
        self.step += 1;
        for i in 0..n {
            let pose = sim.car(i).pose();
            let t = pose.position_m;
            rec.log(
                format!("world/car_{i}"),
                &rerun::Transform3D::from_translation_rotation(t, rerun::Quaternion::from_xyzw(pose.orientation_xyzw)),
            )?;
            if let Some(trail) = self.trails.get_mut(i) {
                trail.push([t[0], t[1], t[2] + 0.02]);
                rec.log(
                    format!("world/paths/car_{i}"),
                    &rerun::LineStrips3D::new([trail.clone()]).with_colors([color(palette[i % palette.len()])]),
                )?;
            }
            if let Some(Some(scan)) = scans.get(i) {
                log_scan(
                    rec,
                    &format!("world/lidar/car_{i}"),
                    scan.origin_w,
                    &scan.points_w,
                    &scan.hit,
                )?;
            }
            rec.log(
                format!("plots/speed_mps/car_{i}"),
                &rerun::Scalars::single(sim.car(i).forward_speed_mps() as f64),
            )?;
        }
        Ok(())
    }

    /// Flush; a file recording is renamed into place. Returns its path.
    pub fn finish(self) -> Result<Option<PathBuf>> {
        let file = self.file.clone();
        if let Err(e) = self.rec.flush_blocking() {
            // rerun's file writer names no cause; a full disk is the common one.
            let full = file.as_ref().is_some_and(|(tmp, _)| no_space_left(tmp));
            let e = anyhow::Error::new(e).context("flushing the rerun recording");
            return Err(match (full, &file) {
                (true, Some((tmp, _))) => e.context(format!("no space left on the device of {}", tmp.display())),
                _ => e,
            });
        }
        drop(self.rec);
        match file {
            Some((tmp, path)) => {
                std::fs::rename(&tmp, &path).with_context(|| format!("renaming to {}", path.display()))?;
                Ok(Some(path))
            }
            None => Ok(None),
        }
    }
}

/// Whether recordings can be made.
pub const ENABLED: bool = true;

/// A rosbag2 bag (`agvrl-drive --record`, `agvrl eval --record`, or a car log) as a recording:
/// the car's pose from Odometry, its path, the LiDAR scan placed by `/tf_static` (red hits, green
/// misses, as live recordings), the depth image, and the commands, actions, speed and the
/// watchdog's and filter's events on a `bag_time` timeline (from the first message). rerun reads
/// the raw MCAP too, but draws no LaserScan, Odometry or our ticks.
pub fn bag(sink: Sink, dir: &std::path::Path) -> Result<(Option<PathBuf>, BagView)> {
    use agvrl_deploy::bag::{decode, read_messages};
    use agvrl_deploy::hardware::msg;
    let (msgs, damage) = read_messages(dir)?;
    let has_image = msgs.iter().any(|m| m.ty == "sensor_msgs/msg/Image");
    let name = format!("bag {}", dir.display());
    let cam = has_image.then(|| agvrl_sim::sensors::CameraConfig {
        depth_only: true,
        ..Default::default()
    });
    let r = Recorder::new(sink, &name, cam.as_ref())?;
    let rec = &r.rec;
    let mut v = BagView {
        damage,
        ..BagView::default()
    };
    let t0 = msgs.iter().map(|m| m.log_ns).min().unwrap_or(0);
    let mut trail: Vec<[f32; 3]> = Vec::new();
    let f = |x: f64| x as f32;
    for m in &msgs {
        rec.set_duration_secs("bag_time", m.log_ns.saturating_sub(t0) as f64 * 1e-9);
        let bad = |e: String| anyhow::anyhow!("{}: a {} message on {}: {e}", dir.display(), m.ty, m.topic);
        match m.ty.as_str() {
            "tf2_msgs/msg/TFMessage" if m.topic == "/tf_static" => {
                let tf: msg::TFMessage = decode(&m.data).map_err(bad)?;
                for t in &tf.transforms {
                    let (p, q) = (t.transform.translation, t.transform.rotation);
                    rec.log_static(
                        format!("world/vehicle/{}", t.child_frame_id),
                        &rerun::Transform3D::from_translation_rotation(
                            [f(p.x), f(p.y), f(p.z)],
                            rerun::Quaternion::from_xyzw([f(q.x), f(q.y), f(q.z), f(q.w)]),
                        ),
                    )?;
                }
            }
            "nav_msgs/msg/Odometry" => {
                let o: msg::Odometry = decode(&m.data).map_err(bad)?;
                let (p, q) = (o.pose.pose.position, o.pose.pose.orientation);
                rec.log(
                    "world/vehicle",
                    &rerun::Transform3D::from_translation_rotation(
                        [f(p.x), f(p.y), f(p.z)],
                        rerun::Quaternion::from_xyzw([f(q.x), f(q.y), f(q.z), f(q.w)]),
                    ),
                )?;
                rec.log("plots/speed_mps", &rerun::Scalars::single(o.twist.twist.linear.x))?;
                trail.push([f(p.x), f(p.y), 0.02]);
                if v.poses.is_multiple_of(15) {
                    log_trail(rec, &trail)?;
                }
                v.poses += 1;
            }
            "sensor_msgs/msg/LaserScan" => {
                let s: msg::LaserScan = decode(&m.data).map_err(bad)?;
                let frame = if s.header.frame_id.is_empty() {
                    "laser".to_string()
                } else {
                    s.header.frame_id.clone()
                };
                let (mut ends, mut hit, mut min) = (Vec::new(), Vec::new(), f32::INFINITY);
                for (k, &r) in s.ranges.iter().enumerate() {
                    let a = s.angle_min + k as f32 * s.angle_increment;
                    let h = r.is_finite() && r >= s.range_min && r < s.range_max;
                    let d = if h { r } else { s.range_max };
                    if h {
                        min = min.min(r);
                    }
                    ends.push([d * a.cos(), d * a.sin(), 0.0]);
                    hit.push(h);
                }
                log_scan(rec, &format!("world/vehicle/{frame}"), [0.0; 3], &ends, &hit)?;
                if min.is_finite() {
                    rec.log("plots/min_range_m", &rerun::Scalars::single(min as f64))?;
                }
                v.scans += 1;
            }
            "sensor_msgs/msg/Image" => {
                let i: msg::Image = decode(&m.data).map_err(bad)?;
                let res = [i.width, i.height];
                let rows = i.height as usize * i.step as usize;
                let packed = |px: usize| -> Option<Vec<u8>> {
                    let row = i.width as usize * px;
                    (i.is_bigendian == 0 && i.data.len() >= rows && i.step as usize >= row).then(|| {
                        i.data
                            .chunks(i.step.max(1) as usize)
                            .take(i.height as usize)
                            .flat_map(|r| r[..row].iter().copied())
                            .collect()
                    })
                };
                use rerun::datatypes::ChannelDatatype as C;
                let image = match i.encoding.as_str() {
                    "32FC1" => {
                        packed(4).map(|b| rerun::DepthImage::from_data_type_and_bytes(b, res, C::F32).with_meter(1.0))
                    }
                    "16UC1" => packed(2)
                        .map(|b| rerun::DepthImage::from_data_type_and_bytes(b, res, C::U16).with_meter(1000.0)),
                    _ => None,
                };
                match image {
                    Some(img) => {
                        rec.log("camera/depth", &img)?;
                        v.images += 1;
                    }
                    None => v.skipped += 1,
                }
            }
            "agvrl_msgs/msg/Tick" => {
                let t: msg::Tick = decode(&m.data).map_err(bad)?;
                rec.log("plots/throttle", &rerun::Scalars::single(t.throttle))?;
                rec.log("plots/steering_rad", &rerun::Scalars::single(t.steering_rad))?;
                for (k, a) in t.action.iter().enumerate() {
                    rec.log(format!("plots/action/{k}"), &rerun::Scalars::single(*a as f64))?;
                }
                if !t.event.is_empty() {
                    rec.log(
                        "log",
                        &rerun::TextLog::new(format!("tick {}: watchdog {}", t.tick, t.event))
                            .with_level(rerun::TextLogLevel::WARN),
                    )?;
                }
                if !matches!(t.intervention.as_str(), "" | "none") {
                    rec.log(
                        "log",
                        &rerun::TextLog::new(format!("tick {}: filter {}", t.tick, t.intervention)),
                    )?;
                }
                v.ticks += 1;
            }
            _ => v.skipped += 1,
        }
    }
    if trail.len() > 1 {
        log_trail(rec, &trail)?;
    }
    Ok((r.finish()?, v))
}

/// Whether the file system holding `path` has no block left for an unprivileged writer.
fn no_space_left(path: &std::path::Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(path.as_os_str().as_bytes()) else {
        return false;
    };
    // SAFETY: a NUL-terminated path and a zeroed statvfs the call fills.
    unsafe {
        let mut st: libc::statvfs = std::mem::zeroed();
        libc::statvfs(c.as_ptr(), &mut st) == 0 && st.f_bavail == 0
    }
}
