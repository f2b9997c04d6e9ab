//! The oval race track's geometry as the racing task reads it: progress along the centre line
//! and the lateral offset. Plain numbers: the simulator's scene file describes the walls, and
//! `SimVehicle` hands the task this from it.

use serde::{Deserialize, Serialize};

/// An oval (stadium) race track: straights along y joined by semicircles centred at
/// (0, +-straight/2). Plain geometry for progress along the centre line.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OvalTrack {
    /// Length of each straight, metres.
    pub straight_m: f32,
    /// Radius of the inner wall's lane-side face, metres.
    pub inner_radius_m: f32,
    /// Radius of the outer wall's lane-side face, metres.
    pub outer_radius_m: f32,
}

impl OvalTrack {
    /// Radius of the centre line, metres.
    pub fn centre_radius_m(&self) -> f32 {
        0.5 * (self.inner_radius_m + self.outer_radius_m)
    }

    /// Length of the centre line, metres.
    pub fn lap_length_m(&self) -> f32 {
        2.0 * self.straight_m + 2.0 * std::f32::consts::PI * self.centre_radius_m()
    }

    /// Arc length (metres, in [0, lap)) of the centre-line point nearest to (x, y), measured
    /// clockwise seen from above (AutoVRL's direction) from the top end of the +x straight
    /// (x = R, y = +straight/2).
    pub fn centreline_s(&self, x: f32, y: f32) -> f32 {
        use std::f32::consts::PI;
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        if y.abs() <= h {
            if x >= 0.0 {
                h - y
            } else {
                self.straight_m + PI * r + (y + h)
            }
        } else if y < -h {
            let a = (-(y + h)).atan2(x).clamp(0.0, PI);
            self.straight_m + a * r
        } else {
            let a = (y - h).atan2(-x).clamp(0.0, PI);
            2.0 * self.straight_m + PI * r + a * r
        }
    }

    /// The centre-line point at arc length `s` and the racing direction there (unit x, y).
    pub fn centreline_at(&self, s: f32) -> ([f32; 2], [f32; 2]) {
        use std::f32::consts::PI;
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        let s = s.rem_euclid(self.lap_length_m());
        let arc = PI * r;
        if s < self.straight_m {
            ([r, h - s], [0.0, -1.0])
        } else if s < self.straight_m + arc {
            let a = (s - self.straight_m) / r;
            ([r * a.cos(), -h - r * a.sin()], [-a.sin(), -a.cos()])
        } else if s < 2.0 * self.straight_m + arc {
            ([-r, -h + (s - self.straight_m - arc)], [0.0, 1.0])
        } else {
            let a = (s - 2.0 * self.straight_m - arc) / r;
            ([-r * a.cos(), h + r * a.sin()], [a.sin(), a.cos()])
        }
    }

    /// Signed distance from the centre line, metres (positive towards the outer wall).
    pub fn lateral_offset_m(&self, x: f32, y: f32) -> f32 {
        let h = self.straight_m / 2.0;
        let r = self.centre_radius_m();
        if y.abs() <= h {
            x.abs() - r
        } else {
            let cy = if y > 0.0 { h } else { -h };
            (x * x + (y - cy).powi(2)).sqrt() - r
        }
    }
}
