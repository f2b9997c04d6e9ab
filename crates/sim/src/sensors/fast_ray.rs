//! Closed-form ray casts against the static scene's shapes, in the world frame. parry casts
//! rays at cylinders and convex hulls by GJK iterations; a LiDAR casts thousands per second at
//! the same fixed shapes, so they are turned once into planes (boxes, hulls) or an analytic
//! cylinder. Other shapes fall back to parry.

use rapier3d::prelude::*;

/// A static shape prepared for fast ray casts.
#[derive(Clone)]
pub enum FastRay {
    /// A convex solid as the intersection of half-spaces `n . x <= d` (world frame).
    Planes(Vec<(Vector, f32)>),
    /// A box as three pairs of opposite half-spaces `n . x <= d+` and `-n . x <= d-` (world
    /// frame): the planes a cuboid's `Planes` would hold, in the same order, each pair's dot
    /// products taken once (negating a dot product is exact, so the casts agree to the bit).
    Cuboid([(Vector, f32, f32); 3]),
    /// A finite cylinder (world frame): centre, unit axis, radius, half height.
    Cylinder {
        /// Centre.
        c: Vector,
        /// Unit axis.
        a: Vector,
        /// Radius.
        r: f32,
        /// Half height.
        h: f32,
    },
    /// Anything else: parry's cast.
    Parry(SharedShape, Pose),
}

impl FastRay {
    /// Prepare `shape` at `pose`.
    pub fn new(shape: &SharedShape, pose: &Pose) -> Self {
        if let Some(c) = shape.as_cuboid() {
            let he = c.half_extents;
            let pair = |i: usize| {
                let n = pose.rotation * Vector::ith(i, 1.0);
                let d = n.dot(pose.translation);
                (n, d + he[i], -d + he[i])
            };
            return FastRay::Cuboid([pair(0), pair(1), pair(2)]);
        }
        if let Some(p) = shape.as_convex_polyhedron() {
            let pts: Vec<Vector> = p.points().iter().map(|v| pose * *v).collect();
            let planes = p
                .faces()
                .iter()
                .map(|f| {
                    let n = pose.rotation * f.normal;
                    let d = pts.iter().map(|q| n.dot(*q)).fold(f32::MIN, f32::max);
                    (n, d)
                })
                .collect();
            return FastRay::Planes(planes);
        }
        if let Some(c) = shape.as_cylinder() {
            return FastRay::Cylinder {
                c: pose.translation,
                a: pose.rotation * Vector::Y,
                r: c.radius,
                h: c.half_height,
            };
        }
        FastRay::Parry(shape.clone(), *pose)
    }

    /// Time of impact and outward surface normal (zero when the ray starts inside).
    pub fn cast_normal(&self, o: Vector, d: Vector, max_t: f32) -> Option<(f32, Vector)> {
        match self {
            FastRay::Planes(planes) => {
                let (mut t0, mut t1) = (0.0f32, max_t);
                let mut n0 = Vector::ZERO;
                for (n, off) in planes {
                    if clip_plane(n.dot(d), off - n.dot(o), &mut t0, &mut t1)? {
                        n0 = *n;
                    }
                }
                Some((t0, n0))
            }
            FastRay::Cuboid(pairs) => {
                let (mut t0, mut t1) = (0.0f32, max_t);
                let mut n0 = Vector::ZERO;
                for &(n, off_pos, off_neg) in pairs {
                    let nd = n.dot(d);
                    let no = n.dot(o);
                    // The planes (n, off_pos) and (-n, off_neg), in this order, as `Planes`
                    // takes them: (-n).d = -nd and off_neg - (-n).o = off_neg + no exactly.
                    for (denom, dist, sign) in [(nd, off_pos - no, 1.0f32), (-nd, off_neg + no, -1.0)] {
                        if clip_plane(denom, dist, &mut t0, &mut t1)? {
                            n0 = n * sign;
                        }
                    }
                }
                Some((t0, n0))
            }
            FastRay::Cylinder { c, a, r, h } => {
                let t = cast_cylinder(o - *c, d, *a, *r, *h, max_t)?;
                let p = o + d * t - *c;
                let along = p.dot(*a);
                let n = if along.abs() >= *h - 1e-4 {
                    *a * along.signum()
                } else {
                    (p - *a * along).normalize_or_zero()
                };
                Some((t, n))
            }
            FastRay::Parry(s, p) => s
                .cast_ray_and_get_normal(p, &Ray::new(o, d), max_t, true)
                .map(|h| (h.time_of_impact, h.normal)),
        }
    }

    /// Time of impact in [0, max_t] of the solid shape along `o + t d` (unit `d`), if any.
    #[inline]
    pub fn cast(&self, o: Vector, d: Vector, max_t: f32) -> Option<f32> {
        match self {
            FastRay::Parry(s, p) => s.cast_ray(p, &Ray::new(o, d), max_t, true),
            FastRay::Cuboid(pairs) => cast_cuboid(pairs, o, d, max_t),
            _ => self.cast_normal(o, d, max_t).map(|(t, _)| t),
        }
    }
}

/// `cast_normal`'s `Cuboid` arm without the normal: the same operations in the same order.
#[inline]
fn cast_cuboid(pairs: &[(Vector, f32, f32); 3], o: Vector, d: Vector, max_t: f32) -> Option<f32> {
    let (mut t0, mut t1) = (0.0f32, max_t);
    for &(n, off_pos, off_neg) in pairs {
        let nd = n.dot(d);
        let no = n.dot(o);
        for (denom, dist) in [(nd, off_pos - no), (-nd, off_neg + no)] {
            clip_plane(denom, dist, &mut t0, &mut t1)?;
        }
    }
    Some(t0)
}

/// One plane of a slab clip along the ray (`denom` = n.d, `dist` = offset - n.o): narrows
/// [t0, t1]. `None` when the ray misses the convex shape; `Some(true)` when this plane became
/// the entry plane.
#[inline(always)]
fn clip_plane(denom: f32, dist: f32, t0: &mut f32, t1: &mut f32) -> Option<bool> {
    let mut entered = false;
    if denom.abs() < 1e-12 {
        if dist < 0.0 {
            return None;
        }
    } else {
        let t = dist / denom;
        if denom > 0.0 {
            *t1 = t1.min(t);
        } else if t > *t0 {
            *t0 = t;
            entered = true;
        }
        if *t0 > *t1 {
            return None;
        }
    }
    Some(entered)
}

fn cast_cylinder(o: Vector, d: Vector, a: Vector, r: f32, h: f32, max_t: f32) -> Option<f32> {
    // Split into the axial coordinate and the radial plane.
    let (oa, da) = (o.dot(a), d.dot(a));
    let (orad, drad) = (o - a * oa, d - a * da);
    // Slab of the caps.
    let (mut t0, mut t1) = (0.0f32, max_t);
    if da.abs() < 1e-12 {
        if oa.abs() > h {
            return None;
        }
    } else {
        let (ta, tb) = ((-h - oa) / da, (h - oa) / da);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    // Infinite cylinder |orad + t drad| <= r.
    let qa = drad.dot(drad);
    let qb = orad.dot(drad);
    let qc = orad.dot(orad) - r * r;
    if qa < 1e-12 {
        if qc > 0.0 {
            return None;
        }
    } else {
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        t0 = t0.max((-qb - s) / qa);
        t1 = t1.min((-qb + s) / qa);
    }
    (t0 <= t1).then_some(t0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_forms_agree_with_parry() {
        let shapes = [
            (
                SharedShape::cuboid(0.5, 1.0, 0.3),
                Pose::from_parts(Vector::new(2.0, 1.0, 0.2), Rotation::from_rotation_z(0.7)),
            ),
            (
                SharedShape::cylinder(0.8, 0.3),
                Pose::from_parts(Vector::new(-1.0, 2.0, 0.5), Rotation::from_rotation_x(1.5707964)),
            ),
            (
                SharedShape::convex_hull(&[
                    Vector::new(0.0, 0.0, 0.0),
                    Vector::new(1.0, 0.2, 0.0),
                    Vector::new(0.3, 1.1, 0.1),
                    Vector::new(0.4, 0.4, 1.2),
                    Vector::new(0.9, 0.9, 0.7),
                ])
                .unwrap(),
                Pose::from_translation(Vector::new(0.5, -2.0, -0.3)),
            ),
        ];
        let o = Vector::new(0.1, -0.2, 0.3);
        // Length of the ray's chord through the solid, by casting back from beyond it (the
        // origin is outside every shape); no way back out is no evidence of a graze.
        let chord = |cast: &dyn Fn(Vector, Vector) -> Option<f32>, d: Vector, t_in: f32| {
            let far = 40.0;
            cast(o + d * far, -d).map_or(f32::INFINITY, |t_back| far - t_back - t_in)
        };
        let mut grazing = 0;
        for (i, (shape, pose)) in shapes.iter().enumerate() {
            let (mut hits, mut misses) = (0, 0);
            let fast = FastRay::new(shape, pose);
            assert!(!matches!(fast, FastRay::Parry(..)), "shape {i} must take a closed form");
            let by_parry = |o: Vector, d: Vector| shape.cast_ray(pose, &Ray::new(o, d), 40.0, true);
            let by_fast = |o: Vector, d: Vector| fast.cast(o, d, 40.0);
            for k in 0..720 {
                let a = k as f32 * std::f32::consts::TAU / 720.0;
                let d = Vector::new(a.cos(), a.sin(), 0.05 * (k as f32 * 0.37).sin()).normalize();
                let want = shape.cast_ray(pose, &Ray::new(o, d), 20.0, true);
                let got = fast.cast(o, d, 20.0);
                match (want, got) {
                    (Some(w), Some(g)) => {
                        hits += 1;
                        assert!((w - g).abs() < 1e-3, "shape {i} ray {k}: parry {w} vs {g}");
                    }
                    (None, None) => misses += 1,
                    // Hit against miss only where the ray grazes the surface: the side that
                    // hits finds a chord of almost no length.
                    (Some(t), None) | (None, Some(t)) => {
                        grazing += 1;
                        let c = if want.is_some() {
                            chord(&by_parry, d, t)
                        } else {
                            chord(&by_fast, d, t)
                        };
                        assert!(
                            c < 1e-2,
                            "shape {i} ray {k}: parry {want:?} vs {got:?}, through {c} m of solid"
                        );
                    }
                }
            }
            assert!(hits > 20 && misses > 20, "shape {i}: hits {hits}, misses {misses}");
        }
        assert!(grazing <= 4, "{grazing} rays disagree on hit or miss");
    }
}
