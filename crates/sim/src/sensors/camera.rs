//! A synthetic pinhole camera (the paper's camera section): view and projection matrices as
//! PyBullet's computeViewMatrix / computeProjectionMatrixFOV build them, and an RGB image, a
//! linear depth buffer (metres along the optical axis) and a segmentation mask (object ids and
//! semantic classes) by ray casting the static scene on the CPU: no GPU, no display,
//! deterministic, rows in parallel.
//!
//! Speed: rays walk a 2D grid of the scene's colliders (objects stand on the ground, so a ray's
//! footprint crosses few cells) and stop at the first cell boundary beyond their nearest hit;
//! the ground is the plane z = 0 inside the ground's extent, with the scene's decals on it.

use crate::msg::CameraFrame;
use crate::scene::Scene;
use crate::world::{Movers, StaticEntry, StaticIndex};
use rapier3d::prelude::*;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Camera settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Vertical field of view, degrees.
    pub fov_deg: f32,
    /// Near clipping distance, metres.
    pub near_m: f32,
    /// Far clipping distance, metres (depth of sky pixels).
    pub far_m: f32,
    /// Render depth only, as a depth camera gives it (no colour, no segmentation: the frame's
    /// `rgb` and `segmentation` are empty), for observations that take depth alone.
    pub depth_only: bool,
}

impl Default for CameraConfig {
    /// 160x120, 80 degrees (AutoVRL's XTENTH-CAR camera), 0.01-100 m.
    fn default() -> Self {
        Self {
            width: 160,
            height: 120,
            fov_deg: 80.0,
            near_m: 0.01,
            far_m: 100.0,
            depth_only: false,
        }
    }
}

impl CameraConfig {
    /// Check the settings.
    pub fn validate(&self) -> Result<(), crate::InvalidSetting> {
        if self.width == 0 || self.height == 0 || self.width > 8192 || self.height > 8192 {
            return Err(crate::InvalidSetting::new(
                "camera",
                format!("camera size {}x{} must be in 1..=8192", self.width, self.height),
            ));
        }
        if !(self.fov_deg > 0.0 && self.fov_deg < 179.0) {
            return Err(crate::InvalidSetting::new(
                "camera",
                format!("camera fov_deg must be in (0, 179), got {}", self.fov_deg),
            ));
        }
        if !(self.near_m > 0.0 && self.far_m > self.near_m && self.far_m.is_finite()) {
            return Err(crate::InvalidSetting::new(
                "camera",
                "camera needs 0 < near_m < far_m < inf",
            ));
        }
        Ok(())
    }
}

/// Semantic classes of segmentation pixels.
pub mod class {
    /// Nothing hit.
    pub const SKY: u8 = 0;
    /// The ground.
    pub const GROUND: u8 = 1;
    /// A road decal.
    pub const ROAD: u8 = 2;
    /// A lane marking decal.
    pub const LANE_MARKING: u8 = 3;
    /// Walls (boundary, track).
    pub const WALL: u8 = 4;
    /// Trees.
    pub const TREE: u8 = 5;
    /// Rocks.
    pub const ROCK: u8 = 6;
    /// Buildings.
    pub const BUILDING: u8 = 7;
    /// Cars.
    pub const CAR: u8 = 8;
    /// People (search subjects).
    pub const PERSON: u8 = 9;
    /// Anything else.
    pub const OTHER: u8 = 255;
    /// Names, by class id (index), for annotation contexts.
    pub const NAMES: [(u8, &str); 11] = [
        (SKY, "sky"),
        (GROUND, "ground"),
        (ROAD, "road"),
        (LANE_MARKING, "lane_marking"),
        (WALL, "wall"),
        (TREE, "tree"),
        (ROCK, "rock"),
        (BUILDING, "building"),
        (CAR, "car"),
        (PERSON, "person"),
        (OTHER, "other"),
    ];

    /// The class id of a scene class name.
    pub fn of(name: &str) -> u8 {
        NAMES.iter().find(|(_, n)| *n == name).map(|(c, _)| *c).unwrap_or(OTHER)
    }
}

/// PyBullet's computeViewMatrix: a column-major 4x4 world-to-camera matrix (OpenGL: the camera
/// looks along its -z).
pub fn compute_view_matrix(eye: [f32; 3], target: [f32; 3], up: [f32; 3]) -> [f32; 16] {
    let (e, t, u) = (
        Vector::from_array(eye),
        Vector::from_array(target),
        Vector::from_array(up),
    );
    let f = (t - e).normalize();
    let s = f.cross(u).normalize();
    let u = s.cross(f);
    [
        s.x,
        u.x,
        -f.x,
        0.0,
        s.y,
        u.y,
        -f.y,
        0.0,
        s.z,
        u.z,
        -f.z,
        0.0,
        -s.dot(e),
        -u.dot(e),
        f.dot(e),
        1.0,
    ]
}

/// PyBullet's computeProjectionMatrixFOV: a column-major OpenGL perspective matrix.
pub fn compute_projection_matrix_fov(fov_deg: f32, aspect: f32, near: f32, far: f32) -> [f32; 16] {
    let y = 1.0 / (fov_deg.to_radians() / 2.0).tan();
    let mut m = [0.0; 16];
    m[0] = y / aspect;
    m[5] = y;
    m[10] = (far + near) / (near - far);
    m[11] = -1.0;
    m[14] = 2.0 * far * near / (near - far);
    m
}

/// A frame with the semantic class of every pixel alongside the object ids.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderedFrame {
    /// RGB, depth and object ids (depth alone with `depth_only`).
    pub frame: CameraFrame,
    /// Semantic class per pixel (`class::*`; empty with `depth_only`).
    pub classes: Vec<u8>,
}

struct Grid {
    origin: [f32; 2],
    cell: f32,
    nx: i32,
    ny: i32,
    cells: Vec<Vec<u32>>,
}

impl Grid {
    fn cell(&self, i: i32, j: i32) -> &[u32] {
        &self.cells[(i * self.ny + j) as usize]
    }

    fn contains(&self, i: i32, j: i32) -> bool {
        (i as u32) < self.nx as u32 && (j as u32) < self.ny as u32
    }
}

struct Decal {
    centre: [f32; 2],
    axis: [f32; 2],
    half: [f32; 2],
    color: [f32; 3],
    class: u8,
}

/// `1 / d` per component, a huge finite value where `d` is 0, so that the slab test below never
/// multiplies 0 by infinity.
fn slab_recip(d: Vector) -> Vector {
    let r = |x: f32| if x == 0.0 { 1e30 } else { 1.0 / x };
    Vector::new(r(d.x), r(d.y), r(d.z))
}

/// Whether `o + t d`, `0 <= t <= max_t`, meets `aabb` (slabs, with `inv = slab_recip(d)`).
fn crosses_box(o: Vector, inv: Vector, aabb: &Aabb, max_t: f32) -> bool {
    let (a, b) = ((aabb.mins - o) * inv, (aabb.maxs - o) * inv);
    let enter = a.min(b).max_element().max(0.0);
    let exit = a.max(b).min_element().min(max_t);
    enter <= exit
}

/// `x.floor() as i32` without the libm call a build for baseline x86-64 makes of `floor`
/// (grid coordinates are far inside i32's range).
fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x { i - 1 } else { i }
}

/// What every ray of a frame shares: the eye and its grid cell (computed once a frame).
struct Eye {
    o: Vector,
    /// The eye's grid cell.
    cell: [i32; 2],
    /// Distance to the next cell boundary in grid units, towards + and towards -, per axis.
    frac_pos: [f32; 2],
    frac_neg: [f32; 2],
    inside: bool,
}

/// A renderer bound to one scene.
pub struct Camera {
    cfg: CameraConfig,
    grid: Grid,
    classes: Vec<u8>,
    ground_half: [f32; 2],
    ground_color: [f32; 3],
    decals: Vec<Decal>,
    /// The top of the tallest object, metres.
    top_z: f32,
}

const SKY_RGB: [f32; 3] = [0.62, 0.76, 0.92];
/// Direction towards the sun (unit), for Lambert shading.
const SUN: [f32; 3] = [0.35, 0.25, 0.90];

impl Camera {
    /// Prepare a camera for `scene` (whose colliders are `statics`).
    pub fn new(cfg: CameraConfig, scene: &Scene, statics: &StaticIndex) -> Self {
        let [gx, gy] = scene.file.ground.size_m;
        let cell = 1.0f32;
        let (half_x, half_y) = (gx / 2.0 + 1.0, gy / 2.0 + 1.0);
        let mut lo = [-half_x, -half_y];
        let mut hi = [half_x, half_y];
        for e in statics.entries.iter().filter(|e| e.object_id.is_some()) {
            lo = [lo[0].min(e.aabb.mins.x), lo[1].min(e.aabb.mins.y)];
            hi = [hi[0].max(e.aabb.maxs.x), hi[1].max(e.aabb.maxs.y)];
        }
        let nx = ((hi[0] - lo[0]) / cell).ceil().max(1.0) as i32;
        let ny = ((hi[1] - lo[1]) / cell).ceil().max(1.0) as i32;
        let mut cells = vec![Vec::new(); (nx * ny) as usize];
        for (k, e) in statics
            .entries
            .iter()
            .enumerate()
            .filter(|(_, e)| e.object_id.is_some())
        {
            let i0 = ((e.aabb.mins.x - lo[0]) / cell).floor().max(0.0) as i32;
            let i1 = (((e.aabb.maxs.x - lo[0]) / cell).floor() as i32).min(nx - 1);
            let j0 = ((e.aabb.mins.y - lo[1]) / cell).floor().max(0.0) as i32;
            let j1 = (((e.aabb.maxs.y - lo[1]) / cell).floor() as i32).min(ny - 1);
            for i in i0..=i1 {
                for j in j0..=j1 {
                    cells[(i * ny + j) as usize].push(k as u32);
                }
            }
        }
        let classes = statics
            .entries
            .iter()
            .map(|e| match e.object_id {
                Some(id) => scene
                    .objects
                    .get(id as usize)
                    .map(|o| class::of(&o.class))
                    .unwrap_or(class::OTHER),
                None => class::GROUND,
            })
            .collect();
        let decals = scene
            .file
            .decals
            .iter()
            .map(|d| {
                let (s, c) = d.yaw_deg.to_radians().sin_cos();
                Decal {
                    centre: [d.x_m, d.y_m],
                    axis: [c, s],
                    half: [d.size_m[0] / 2.0, d.size_m[1] / 2.0],
                    color: d.color,
                    class: class::of(&d.class),
                }
            })
            .collect();
        Self {
            cfg,
            grid: Grid {
                origin: lo,
                cell,
                nx,
                ny,
                cells,
            },
            classes,
            ground_half: [gx / 2.0, gy / 2.0],
            ground_color: scene.file.ground.color,
            decals,
            top_z: statics
                .entries
                .iter()
                .filter(|e| e.object_id.is_some())
                .fold(f32::NEG_INFINITY, |z, e| z.max(e.aabb.maxs.z)),
        }
    }

    /// Settings.
    pub fn config(&self) -> &CameraConfig {
        &self.cfg
    }

    /// Render from a camera at `pose_w` looking along its x axis with z up (the ROS link
    /// convention of a camera mount).
    pub fn render(&self, statics: &StaticIndex, pose_w: &Pose) -> RenderedFrame {
        self.render_with(statics, &Movers::default(), None, pose_w)
    }

    /// Render the static scene and the cars' shapes but car `own`'s (class `car`,
    /// segmentation 0).
    pub fn render_with(
        &self,
        statics: &StaticIndex,
        movers: &Movers,
        own: Option<u32>,
        pose_w: &Pose,
    ) -> RenderedFrame {
        let eye = pose_w.translation;
        let fwd = pose_w.rotation * Vector::X;
        let up = pose_w.rotation * Vector::Z;
        let right = fwd.cross(up).normalize();
        let (w, h) = (self.cfg.width as usize, self.cfg.height as usize);
        let tan_y = (self.cfg.fov_deg.to_radians() / 2.0).tan();
        let tan_x = tan_y * w as f32 / h as f32;
        // Pixel (u, v)'s unit ray and its length: unnormalised, the ray's component along the
        // optical axis is 1, so the ray parameter at a hit over the length is the depth. Its
        // column and row terms are computed once a frame.
        let across: Vec<Vector> = (0..w)
            .map(|u| fwd + right * ((2.0 * (u as f32 + 0.5) / w as f32 - 1.0) * tan_x))
            .collect();
        let rise = |v: usize| up * ((1.0 - 2.0 * (v as f32 + 0.5) / h as f32) * tan_y);
        let ray = |a: &Vector, r: Vector| {
            let dir = *a + r;
            let len = dir.length();
            (dir / len, len)
        };
        let n = w * h;
        let mut depth = vec![0f32; n];
        let eye_g = self.eye(eye);
        let frame = |rgb, segmentation, depth_m| CameraFrame {
            width: self.cfg.width,
            height: self.cfg.height,
            rgb,
            depth_m,
            segmentation,
        };
        if self.cfg.depth_only {
            depth.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
                let r = rise(v);
                for (z, a) in row.iter_mut().zip(&across) {
                    let (d, len) = ray(a, r);
                    let (t, _, _) = self.nearest(statics, movers, own, &eye_g, d, self.cfg.far_m * len);
                    *z = (t / len).clamp(self.cfg.near_m, self.cfg.far_m);
                }
            });
            return RenderedFrame {
                frame: frame(vec![], vec![], depth),
                classes: vec![],
            };
        }
        let mut rgb = vec![0u8; 3 * n];
        let mut seg = vec![0u32; n];
        let mut cls = vec![0u8; n];
        rgb.par_chunks_mut(3 * w)
            .zip(depth.par_chunks_mut(w))
            .zip(seg.par_chunks_mut(w))
            .zip(cls.par_chunks_mut(w))
            .enumerate()
            .for_each(|(v, (((rgb_row, depth_row), seg_row), cls_row))| {
                let r = rise(v);
                for (u, a) in across.iter().enumerate() {
                    let (d, len) = ray(a, r);
                    let (t, color, id, c) = self.shade(statics, movers, own, &eye_g, d, self.cfg.far_m * len);
                    let z = (t / len).clamp(self.cfg.near_m, self.cfg.far_m);
                    depth_row[u] = z;
                    seg_row[u] = id;
                    cls_row[u] = c;
                    for k in 0..3 {
                        rgb_row[3 * u + k] = (color[k].clamp(0.0, 1.0) * 255.0).round() as u8;
                    }
                }
            });
        RenderedFrame {
            frame: frame(rgb, seg, depth),
            classes: cls,
        }
    }

    /// The first surface along `o + t d` (`d` unit) before `max_t`: its distance, the entry hit
    /// (a static one, or after them another car's shape) and its normal, or whether it is the
    /// ground.
    fn nearest(
        &self,
        statics: &StaticIndex,
        movers: &Movers,
        own: Option<u32>,
        eye: &Eye,
        d: Vector,
        max_t: f32,
    ) -> (f32, Option<(usize, Vector)>, bool) {
        let o = eye.o;
        // The ground plane bounds the walk.
        let mut best = max_t;
        let mut hit: Option<(usize, Vector)> = None;
        let mut ground = false;
        if d.z < -1e-6 && o.z > 0.0 {
            let t = -o.z / d.z;
            let p = o + d * t;
            if t < best && p.x.abs() <= self.ground_half[0] && p.y.abs() <= self.ground_half[1] {
                best = t;
                ground = true;
            }
        }
        // A ray rising above the tallest object meets nothing more: the walk stops there.
        let mut reach = best;
        if d.z > 1e-6 {
            reach = reach.min(((self.top_z - o.z) / d.z).max(0.0));
        }
        // Only rays that meet an entry need the slabs' reciprocals.
        let mut inv = None;
        // The last entries tested: one that missed misses in every further cell (the reach only
        // shrinks), and a long wall spans many cells.
        let mut seen = [u32::MAX; 8];
        let mut next = 0;
        self.walk(
            eye,
            d,
            &mut reach,
            |k, t_max| {
                if seen.contains(&k) {
                    return None;
                }
                seen[next % seen.len()] = k;
                next += 1;
                let e = &statics.entries[k as usize];
                // The box first: most rays pass above or beside most of a cell's entries.
                let inv = *inv.get_or_insert_with(|| slab_recip(d));
                if !crosses_box(o, inv, &e.aabb, t_max) {
                    return None;
                }
                e.fast.cast_normal(o, d, t_max).map(|(t, n)| (t, n, k as usize))
            },
            &mut hit,
        );
        if hit.is_some() {
            best = reach;
        }
        for (m, e) in movers.seen(own) {
            let inv = *inv.get_or_insert_with(|| slab_recip(d));
            if !crosses_box(o, inv, &e.aabb, best) {
                continue;
            }
            if let Some((t, n)) = e.fast.cast_normal(o, d, best)
                && t < best
            {
                best = t;
                hit = Some((statics.entries.len() + m, n));
                ground = false;
            }
        }
        (best, hit, ground)
    }

    /// (distance, colour, object id + 1, class) of the first surface along `o + t d`.
    fn shade(
        &self,
        statics: &StaticIndex,
        movers: &Movers,
        own: Option<u32>,
        eye: &Eye,
        d: Vector,
        max_t: f32,
    ) -> (f32, [f32; 3], u32, u8) {
        let sun = Vector::from_array(SUN).normalize();
        let o = eye.o;
        let (best, hit, ground) = self.nearest(statics, movers, own, eye, d, max_t);
        if let Some((k, n)) = hit {
            let (e, class): (&StaticEntry, u8) = match k.checked_sub(statics.entries.len()) {
                None => (&statics.entries[k], self.classes[k]),
                Some(m) => (&movers.entries[m], class::CAR),
            };
            let lambert = 0.35 + 0.65 * n.dot(sun).max(0.0);
            let c = e.color.map(|v| v * lambert);
            return (best, c, e.object_id.map(|i| i + 1).unwrap_or(0), class);
        }
        if ground {
            let p = o + d * best;
            let (mut color, mut c) = (self.ground_color, class::GROUND);
            for dc in &self.decals {
                let (dx, dy) = (p.x - dc.centre[0], p.y - dc.centre[1]);
                let (a, b) = (dx * dc.axis[0] + dy * dc.axis[1], -dx * dc.axis[1] + dy * dc.axis[0]);
                if a.abs() <= dc.half[0] && b.abs() <= dc.half[1] {
                    color = dc.color;
                    c = dc.class;
                }
            }
            let lambert = 0.35 + 0.65 * sun.z;
            return (best, color.map(|v| v * lambert), 0, c);
        }
        (max_t, SKY_RGB, 0, class::SKY)
    }

    /// The eye at `o`: its grid cell and the distances to the cell's boundaries, as `walk`
    /// would compute them for every ray.
    fn eye(&self, o: Vector) -> Eye {
        let g = &self.grid;
        let (px, py) = ((o.x - g.origin[0]) / g.cell, (o.y - g.origin[1]) / g.cell);
        let (i, j) = (floor_i(px), floor_i(py));
        let (fx, fy) = (floor_i(px) as f32, floor_i(py) as f32);
        Eye {
            o,
            cell: [i, j],
            frac_pos: [fx + 1.0 - px, fy + 1.0 - py],
            frac_neg: [px - fx, py - fy],
            inside: (0..g.nx).contains(&i) && (0..g.ny).contains(&j),
        }
    }

    /// Visit the grid cells along the ray's ground track, nearest first, testing their entries;
    /// stops once the nearest hit lies before the next cell.
    fn walk(
        &self,
        eye: &Eye,
        d: Vector,
        best: &mut f32,
        mut test: impl FnMut(u32, f32) -> Option<(f32, Vector, usize)>,
        hit: &mut Option<(usize, Vector)>,
    ) {
        let g = &self.grid;
        let o = eye.o;
        let [mut i, mut j] = eye.cell;
        let step_i = if d.x > 0.0 { 1 } else { -1 };
        let step_j = if d.y > 0.0 { 1 } else { -1 };
        let inv_x = if d.x.abs() > 1e-9 {
            g.cell / d.x.abs()
        } else {
            f32::INFINITY
        };
        let inv_y = if d.y.abs() > 1e-9 {
            g.cell / d.y.abs()
        } else {
            f32::INFINITY
        };
        let frac = |p: f32, s: i32| {
            let f = floor_i(p) as f32;
            if s > 0 { f + 1.0 - p } else { p - f }
        };
        let pick = |k: usize, s: i32| if s > 0 { eye.frac_pos[k] } else { eye.frac_neg[k] };
        let mut t_x = pick(0, step_i) * inv_x;
        let mut t_y = pick(1, step_j) * inv_y;
        // A camera outside the grid: jump to where the ray enters it.
        if !eye.inside {
            let lo = Vector::new(g.origin[0], g.origin[1], f32::MIN);
            let hi = Vector::new(
                g.origin[0] + g.nx as f32 * g.cell,
                g.origin[1] + g.ny as f32 * g.cell,
                f32::MAX,
            );
            let inv = d.recip();
            let (a, b) = ((lo - o) * inv, (hi - o) * inv);
            let enter = a.min(b).max_element().max(0.0);
            let exit = a.max(b).min_element();
            if enter > exit || enter >= *best {
                return;
            }
            let p = o + d * (enter + 1e-4);
            let (qx, qy) = ((p.x - g.origin[0]) / g.cell, (p.y - g.origin[1]) / g.cell);
            i = floor_i(qx).clamp(0, g.nx - 1);
            j = floor_i(qy).clamp(0, g.ny - 1);
            t_x = enter + frac(qx, step_i) * inv_x;
            t_y = enter + frac(qy, step_j) * inv_y;
        }
        while g.contains(i, j) {
            for &k in g.cell(i, j) {
                if let Some((t, n, idx)) = test(k, *best)
                    && t < *best
                {
                    *best = t;
                    *hit = Some((idx, n));
                }
            }
            let t_next = t_x.min(t_y);
            if *best <= t_next {
                return;
            }
            if t_x < t_y {
                t_x += inv_x;
                i += step_i;
            } else {
                t_y += inv_y;
                j += step_j;
            }
        }
    }
}
