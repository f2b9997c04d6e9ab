//! Classical racing drivers: scripted controllers that map what the car senses to a [`Control`],
//! as a policy does, so that evaluation, races, the deploy loop and Python can drive with them
//! (and compare a learned policy against them) through one trait, [`Driver`].
//!
//! ```text
//! VehicleModel + brake_mps2 -> CarLimits
//! Track | raceline CSV -> RacePath (closed polyline + speed profile from CarLimits)
//! SensorFrame.gps + .imu, RacePath -> PurePursuit -> Control
//! SensorFrame.scan (+ .imu)        -> FollowTheGap -> Control
//! ```
//!
//! Both drivers turn a target speed into a throttle the same way ([`CarLimits::throttle`]): the
//! throttle whose steady speed it is, plus a proportional term on the measured speed.

mod follow_gap;
mod limits;
mod pure_pursuit;
mod raceline;

pub use follow_gap::{FollowTheGap, FollowTheGapSettings};
pub use limits::CarLimits;
pub use pure_pursuit::{PurePursuit, PurePursuitSettings};
pub use raceline::{RacePath, parse_raceline};

use crate::api::{Control, MapInfo, SensorFrame};

/// A scripted driver: maps what the car senses (and, for pure pursuit, its pose and the track)
/// to a control, like a policy, one control period at a time.
pub trait Driver: Send {
    /// Start an episode from its first frame: forget the previous one, and build what the
    /// driver needs from the episode's map (a real car has none).
    fn reset(&mut self, frame: &SensorFrame, map: Option<&MapInfo>);
    /// The control for the period that starts with `frame`.
    fn control(&mut self, frame: &SensorFrame, map: Option<&MapInfo>) -> Control;
    /// How many points of its raceline the driver moved to fit the car on the last reset's
    /// track (pure pursuit with a raceline, on a map whose track knows its clearance); None
    /// where no fit ran.
    fn raceline_points_moved(&self) -> Option<usize> {
        None
    }
}

/// Which classical racer: the names commands and settings use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RacerKind {
    /// [`PurePursuit`]: needs the pose and the track (or a raceline).
    PurePursuit,
    /// [`FollowTheGap`]: the LiDAR alone.
    FollowTheGap,
}

impl RacerKind {
    /// Every kind, in the order commands list them.
    pub const ALL: [Self; 2] = [Self::PurePursuit, Self::FollowTheGap];

    /// `pure-pursuit` or `follow-the-gap`.
    pub fn name(self) -> &'static str {
        match self {
            Self::PurePursuit => "pure-pursuit",
            Self::FollowTheGap => "follow-the-gap",
        }
    }

    /// The kind named `name`.
    pub fn of(name: &str) -> Result<Self, crate::EnvError> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| crate::EnvError::Config(format!("unknown racer '{name}': pure-pursuit or follow-the-gap")))
    }
}

/// A racer as `KIND[@SCALE]` names it (`pure-pursuit@0.75`: pure pursuit at 0.75 of its speed
/// profile; no `@SCALE`: 1).
pub fn parse_racer(text: &str) -> Result<(RacerKind, f64), crate::EnvError> {
    let bad = |m: &str| crate::EnvError::Config(format!("racer '{text}': {m}"));
    let (kind, scale) = match text.split_once('@') {
        Some((k, s)) => (
            k,
            s.parse::<f64>().map_err(|_| bad("the scale after @ is not a number"))?,
        ),
        None => (text, 1.0),
    };
    let kind = RacerKind::of(kind).map_err(|_| bad("the kind is pure-pursuit or follow-the-gap"))?;
    if !(scale.is_finite() && scale > 0.0 && scale <= 1.0) {
        return Err(bad("the speed scale must be in (0, 1]"));
    }
    Ok((kind, scale))
}

/// The racer `kind` for the car of `cfg` at `speed_scale` (of pure pursuit's speed profile, of
/// follow-the-gap's top speed); pure pursuit drives `raceline` (a raceline or centre-line CSV's
/// text) when given, else the track's centre line.
pub fn make_racer(
    kind: RacerKind,
    cfg: &crate::EnvConfig,
    speed_scale: f64,
    raceline: Option<&str>,
) -> Result<Box<dyn Driver>, crate::EnvError> {
    let model = cfg.sim.vehicle_model()?;
    let limits = CarLimits::of(&model, cfg.sim.brake_mps2);
    Ok(match kind {
        RacerKind::PurePursuit => {
            let path = raceline
                .map(|text| RacePath::from_csv(text, &limits, speed_scale))
                .transpose()
                .map_err(|e| crate::EnvError::Config(format!("raceline: {e}")))?;
            let settings = PurePursuitSettings {
                speed_scale,
                ..Default::default()
            };
            Box::new(PurePursuit::new(settings, limits, path)?)
        }
        RacerKind::FollowTheGap => {
            let settings = FollowTheGapSettings {
                speed_scale,
                ..Default::default()
            };
            Box::new(FollowTheGap::new(settings, limits)?)
        }
    })
}

/// Forward speed from the IMU's body-frame velocity, m/s, when the frame carries one.
pub(crate) fn measured_speed_mps(frame: &SensorFrame) -> Option<f64> {
    frame.imu.as_ref().map(|imu| imu.lin_vel_b[0]).filter(|v| v.is_finite())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::CarLimits;

    /// The shipped car's limits on a drive that brakes at `brake_mps2`.
    pub(crate) fn xtenth(brake_mps2: f64) -> CarLimits {
        let model = agvrl_sim::SimSettings::default().vehicle_model().unwrap();
        CarLimits::of(&model, brake_mps2)
    }

    /// `n` points evenly round a circle of radius `r` about the origin, counter-clockwise.
    pub(crate) fn circle(r: f64, n: usize) -> Vec<[f32; 2]> {
        (0..n)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                [(r * a.cos()) as f32, (r * a.sin()) as f32]
            })
            .collect()
    }
}
