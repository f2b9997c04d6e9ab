//! Arc geometry: the rear axle's poses along the Ackermann arc of a steering, and whether the
//! body (with margin) and the LiDAR's clearance at a pose keep off a set of points. Walking an
//! arc pose by pose gives how far a path stays free; the car's shape comes from its settings.

use super::SafetyFilterConfig;

/// Spacing of the poses checked along a path, metres.
pub(super) const PATH_STEP_M: f32 = 0.04;

impl SafetyFilterConfig {
    /// Poses every `PATH_STEP_M` along the arc of steering `delta`, forward (`sign` 1) or in
    /// reverse (-1), up to `limit`: the distance before the first pose `clear` rejects, or
    /// `limit`.
    pub(super) fn walk_arc(&self, delta: f32, limit: f32, sign: f32, clear: impl Fn(Pose) -> bool) -> f32 {
        let k = delta.tan() / self.wheelbase_m;
        let n = (limit / PATH_STEP_M).ceil().max(1.0) as usize;
        for i in 1..=n {
            let s = (i as f32 * PATH_STEP_M).min(limit);
            if !clear(arc_pose(k, sign * s)) {
                return (s - PATH_STEP_M).max(0.0);
            }
        }
        limit
    }

    /// A box (min, max corners, in the car's frame) holding every point that can fail the check
    /// of `pose` ([`Self::points_clear`]): the body's rectangle with margin, and the LiDAR's
    /// sector of radius `clearance_m` over its fan (a disk for a fan of 90 degrees or more),
    /// widened by 1 mm for rounding.
    pub(super) fn pose_box(&self, pose: Pose, fan: Fan) -> ([f32; 2], [f32; 2]) {
        use std::f32::consts::FRAC_PI_2;
        let cfg = self;
        let m = cfg.body_margin_m;
        let Pose { x, y, sin: s, cos: c } = pose;
        let (mut lo, mut hi) = ([f32::MAX; 2], [f32::MIN; 2]);
        let mut add = |px: f32, py: f32| {
            lo = [lo[0].min(px), lo[1].min(py)];
            hi = [hi[0].max(px), hi[1].max(py)];
        };
        for bx in [-cfg.rear_m - m, cfg.front_m + m] {
            for by in [-cfg.half_width_m - m, cfg.half_width_m + m] {
                add(x + c * bx - s * by, y + s * bx + c * by);
            }
        }
        let (ax, ay) = (x + c * cfg.lidar_x_m, y + s * cfg.lidar_x_m);
        let r = fan.clearance_m;
        if fan.half_rad >= FRAC_PI_2 {
            add(ax - r, ay - r);
            add(ax + r, ay + r);
        } else {
            add(ax, ay);
            // The arc's ends, at headings th -+ fan.
            let (sf, cf) = (fan.sin, fan.cos);
            add(ax + r * (c * cf + s * sf), ay + r * (s * cf - c * sf));
            add(ax + r * (c * cf - s * sf), ay + r * (s * cf + c * sf));
            // The circle's extremes along the axes that lie within the fan (an axis within
            // the fan makes an angle of at most the fan with the heading; the slack only
            // widens the box).
            for (ex, ey) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)] {
                if ex * c + ey * s >= cf - 1e-4 {
                    add(ax + r * ex, ay + r * ey);
                }
            }
        }
        let pad = 1e-3;
        ([lo[0] - pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad])
    }

    /// Whether the body (with margin) at `pose` touches none of `points` and the LiDAR keeps
    /// `fan.clearance_m` from those in its fan.
    pub(super) fn points_clear<'a>(
        &self,
        points: impl IntoIterator<Item = &'a [f32; 2]>,
        pose: Pose,
        fan: Fan,
    ) -> bool {
        let cfg = self;
        let Pose { x, y, sin: s, cos: c } = pose;
        let m = cfg.body_margin_m;
        let tan_fan = fan.tan;
        let c2 = fan.clearance_m * fan.clearance_m;
        for &[px, py] in points {
            let (dx, dy) = (px - x, py - y);
            let bx = c * dx + s * dy;
            let by = -s * dx + c * dy;
            if bx >= -cfg.rear_m - m && bx <= cfg.front_m + m && by.abs() <= cfg.half_width_m + m {
                return false;
            }
            let lx = bx - cfg.lidar_x_m;
            if lx * lx + by * by < c2 && (by.abs() <= lx * tan_fan || tan_fan.is_infinite()) {
                return false;
            }
        }
        true
    }
}

/// A rear-axle pose in the car's frame: position, and its heading's sine and cosine.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pose {
    x: f32,
    y: f32,
    sin: f32,
    cos: f32,
}

impl Pose {
    #[cfg(test)]
    fn new(x: f32, y: f32, th: f32) -> Self {
        let (sin, cos) = th.sin_cos();
        Self { x, y, sin, cos }
    }
}

/// The LiDAR's clearance in a check: `clearance_m` within `half_rad` of its heading (the
/// sine, cosine and tangent of `half_rad` computed once per path, not per pose).
#[derive(Clone, Copy, Debug)]
pub(super) struct Fan {
    half_rad: f32,
    clearance_m: f32,
    sin: f32,
    cos: f32,
    /// Infinite for a fan of 90 degrees or more.
    tan: f32,
}

impl Fan {
    pub(super) fn new(half_rad: f32, clearance_m: f32) -> Self {
        let (sin, cos) = half_rad.sin_cos();
        let tan = if half_rad < std::f32::consts::FRAC_PI_2 {
            half_rad.tan()
        } else {
            f32::INFINITY
        };
        Self {
            half_rad,
            clearance_m,
            sin,
            cos,
            tan,
        }
    }
}

/// The rear axle's pose after driving `s` metres (negative: reversing) on an arc of curvature
/// `k`, from the origin heading along x.
fn arc_pose(k: f32, s: f32) -> Pose {
    if k.abs() < 1e-6 {
        Pose {
            x: s,
            y: 0.0,
            sin: 0.0,
            cos: 1.0,
        }
    } else {
        let (sin, cos) = (k * s).sin_cos();
        Pose {
            x: sin / k,
            y: (1.0 - cos) / k,
            sin,
            cos,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::safety::memory::PointGrid;
    use crate::task::safety::tests::on;

    /// The grid only skips points that cannot fail a pose's check: for clusters of points
    /// (walls, a corner), poses anywhere around them at any heading, both clearances and four
    /// fans, a check over the grid's points in the pose's box agrees with one over every point.
    #[test]
    fn a_pose_check_over_the_grid_agrees_with_one_over_every_point() {
        let f = on();
        let mut x = 0.123f64;
        let mut next = || {
            x = (x * 3.99 * (1.0 - x)).clamp(1e-6, 1.0 - 1e-6);
            x as f32
        };
        let mut grid = PointGrid::default();
        let (mut checks, mut blocked) = (0, 0);
        for _ in 0..40 {
            // A few walls of 5 cm points, some far off the rest.
            let mut pts = Vec::new();
            for _ in 0..(1 + (next() * 5.0) as usize) {
                let (x0, y0, a) = (8.0 * next() - 4.0, 8.0 * next() - 4.0, 6.3 * next());
                for k in 0..(next() * 80.0) as usize {
                    let t = 0.05 * k as f32;
                    pts.push([x0 + t * a.cos(), y0 + t * a.sin()]);
                }
            }
            grid.rebuild(&pts);
            assert_eq!(grid.points.len(), pts.len());
            for _ in 0..200 {
                let (px, py, th) = (10.0 * next() - 5.0, 10.0 * next() - 5.0, 6.3 * next() - 3.15);
                for clearance in [f.cfg.clearance_m, f.cfg.reverse_clearance_m] {
                    for fan in [std::f32::consts::FRAC_PI_4, 1.2, 1.8, std::f32::consts::PI] {
                        let (pose, fan) = (Pose::new(px, py, th), Fan::new(fan, clearance));
                        let all = f.cfg.points_clear(&pts, pose, fan);
                        let (lo, hi) = f.cfg.pose_box(pose, fan);
                        let near = grid.within(lo, hi);
                        assert_eq!(f.cfg.points_clear(near, pose, fan), all, "pose {px} {py} {th}");
                        checks += 1;
                        blocked += usize::from(!all);
                    }
                }
            }
        }
        // Both outcomes are exercised.
        assert!(
            blocked > checks / 20 && blocked < checks - checks / 20,
            "{blocked} of {checks} blocked"
        );
        grid.rebuild(&[]);
        assert_eq!(grid.within([-1.0; 2], [1.0; 2]).count(), 0);
    }
}
