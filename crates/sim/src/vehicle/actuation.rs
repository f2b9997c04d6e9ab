//! The paper's actuation (section 5): AutoVRL's wheel-speed model and the Ackermann split of
//! the steering angle between the front wheels. (How an action becomes a control is the task
//! layer's: agvrl-envs' `ActionMapping`.)

use serde::{Deserialize, Serialize};

pub use crate::msg::Control;

/// AutoVRL's wheel-speed model, integrated once per control period:
/// `w <- max(0, w + t_s (c_t T - w (c_d w + c_r)))`, w in rad/s.
///
/// With `brake > 0` the drive behaves like a speed-controlled ESC (what a VESC does with the
/// speed a ROS 2 drive command asks for): above the throttle's steady speed it slows at
/// `brake` rad/s^2 (or faster, by drag) down to that speed, instead of AutoVRL's coasting,
/// which needs metres to stop. Accelerating is AutoVRL's model either way.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DriveModel {
    /// Throttle gain, rad/s^2.
    pub c_t: f64,
    /// Quadratic drag, 1/rad.
    pub c_d: f64,
    /// Linear resistance, 1/s.
    pub c_r: f64,
    /// Braking deceleration of the wheel, rad/s^2 (0: coast, as AutoVRL).
    #[serde(default)]
    pub brake: f64,
}

impl DriveModel {
    /// Next wheel speed (rad/s) after `t_s` seconds at throttle `throttle` in [-1, 1].
    /// Reverse mirrors the forward model; a car rolling the other way than the throttle asks
    /// first slows to a stop (as an ESC does before it changes direction).
    pub fn advance(&self, w: f64, throttle: f64, t_s: f64) -> f64 {
        if w < 0.0 || (w == 0.0 && throttle < 0.0) {
            return -self.advance_forward(-w, (-throttle).max(0.0), t_s);
        }
        self.advance_forward(w, throttle.max(0.0), t_s)
    }

    fn advance_forward(&self, w: f64, throttle: f64, t_s: f64) -> f64 {
        let dw = self.c_t * throttle - w * (self.c_d * w + self.c_r);
        let coast = (w + t_s * dw).max(0.0);
        if self.brake > 0.0 {
            let target = self.steady_state(throttle);
            if w > target {
                return coast.min(w - t_s * self.brake).max(target);
            }
        }
        coast
    }

    /// Steady-state wheel speed at throttle `throttle`, rad/s: the positive root of
    /// `c_d w^2 + c_r w - c_t T = 0`.
    pub fn steady_state(&self, throttle: f64) -> f64 {
        let c = self.c_t * throttle;
        if self.c_d == 0.0 {
            return c / self.c_r;
        }
        (-self.c_r + (self.c_r * self.c_r + 4.0 * self.c_d * c).sqrt()) / (2.0 * self.c_d)
    }
}

/// Angles (left, right) of the two steered wheels for a centre angle `delta` (rad, + = left).
/// Ackermann: both wheels point at the same turning centre, `tan(delta_i) = L / (R - w/2)` for
/// the inner wheel, `L / (R + w/2)` for the outer, with `R = L / tan(delta)`; else both get delta.
pub fn ackermann_split(delta: f64, wheelbase_m: f64, track_m: f64, ackermann: bool) -> (f64, f64) {
    if !ackermann || delta.abs() < 1e-9 {
        return (delta, delta);
    }
    let r = wheelbase_m / delta.tan();
    let left = (wheelbase_m / (r - track_m / 2.0)).atan();
    let right = (wheelbase_m / (r + track_m / 2.0)).atan();
    (left, right)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drive_model_converges_to_autovrl_terminal_speed() {
        let m = DriveModel {
            c_t: 20.0,
            c_d: 0.01,
            c_r: 0.2,
            brake: 0.0,
        };
        let mut w = 0.0;
        for _ in 0..600 {
            w = m.advance(w, 1.0, 1.0 / 30.0);
        }
        // Facts file: terminal w = 35.8 rad/s.
        assert!((w - 35.83).abs() < 0.01, "w = {w}");
        assert!((m.steady_state(1.0) - w).abs() < 1e-6);
        assert_eq!(m.advance(1.0, 0.0, 10.0), 0.0, "coasting never reverses");
    }

    #[test]
    fn reverse_mirrors_forward_and_stops_before_changing_direction() {
        let m = DriveModel {
            c_t: 20.0,
            c_d: 0.01,
            c_r: 0.2,
            brake: 60.0,
        };
        let dt = 1.0 / 30.0;
        let (mut f, mut r) = (0.0, 0.0);
        for _ in 0..600 {
            f = m.advance(f, 0.4, dt);
            r = m.advance(r, -0.4, dt);
            assert_eq!(r, -f);
        }
        assert!((r + m.steady_state(0.4)).abs() < 1e-3, "reverse top speed: {r}");
        // Rolling forward with reverse asked: braked to a stop, never through zero in one period.
        let w = m.advance(10.0, -1.0, dt);
        assert_eq!(w, m.advance(10.0, 0.0, dt));
        assert!(w > 0.0);
        assert_eq!(m.advance(1.0, -1.0, dt), 0.0);
        assert!(m.advance(0.0, -1.0, dt) < 0.0);
        // And rolling backward with forward throttle: braked to a stop first.
        assert_eq!(m.advance(-1.0, 1.0, dt), 0.0);
    }

    #[test]
    fn brake_slows_at_its_rate_down_to_the_throttles_steady_speed() {
        let coast = DriveModel {
            c_t: 20.0,
            c_d: 0.01,
            c_r: 0.2,
            brake: 0.0,
        };
        let braked = DriveModel { brake: 60.0, ..coast };
        let dt = 1.0 / 30.0;
        let w0 = coast.steady_state(1.0);
        // Released throttle: coasting loses c_d w^2 + c_r w (20 rad/s^2 at top speed) per
        // second; the brake takes 60 rad/s^2 and stops in w0 / 60 s.
        let (mut wc, mut wb) = (w0, w0);
        let mut stop_steps = None;
        for k in 1..=60 {
            wc = coast.advance(wc, 0.0, dt);
            wb = braked.advance(wb, 0.0, dt);
            if wb == 0.0 && stop_steps.is_none() {
                stop_steps = Some(k);
            }
        }
        assert_eq!(stop_steps, Some((w0 / 60.0 / dt).ceil() as usize));
        assert!(wc > 5.0, "coasting is slow: w = {wc} after 2 s");
        // Half throttle: the brake stops at the steady speed of 0.5, not below.
        let half = coast.steady_state(0.5);
        let mut w = w0;
        for _ in 0..60 {
            w = braked.advance(w, 0.5, dt);
        }
        assert!((w - half).abs() < 1e-9, "{w} vs {half}");
        // Accelerating is the same model with or without the brake.
        assert_eq!(braked.advance(3.0, 1.0, dt), coast.advance(3.0, 1.0, dt));
    }

    #[test]
    fn inner_wheel_steers_more() {
        for delta in [0.05, 0.2, 0.36, -0.05, -0.36] {
            let (l, r) = ackermann_split(delta, 0.33, 0.314, true);
            let (inner, outer) = if delta > 0.0 { (l, r) } else { (r, l) };
            assert!(
                inner.abs() > delta.abs() && outer.abs() < delta.abs(),
                "delta {delta}: {l} {r}"
            );
            // Both wheels' normals meet at the same turning centre on the rear axle line.
            let centre_l = 0.33 / l.tan() + 0.157;
            let centre_r = 0.33 / r.tan() - 0.157;
            assert!((centre_l - centre_r).abs() < 1e-9);
        }
        assert_eq!(ackermann_split(0.2, 0.33, 0.314, false), (0.2, 0.2));
    }
}
