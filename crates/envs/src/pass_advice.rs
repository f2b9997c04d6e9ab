//! Passing advice: how a car closing on another should pass it with a lateral gap between the
//! two bodies, worked out from both cars' places on the track (which the policy never sees). A
//! race env in training reports it as the corrected action
//! (`RaceSettings::pass_advice_margin_m`), for PPO's correction term to learn; there it is
//! never applied. A passer ([`crate::passer`]) applies it.
//!
//! The advice sends the car along a line beside the other car before the two bodies overlap,
//! and where no such line fits between the walls, it follows. Once the bodies overlap the
//! training advice says nothing: the other car is then beside the car, out of its scan, and a
//! policy cannot learn from advice whose reason it does not see. The passer's advice
//! ([`advise_passing`]) holds the line until the car is past.

/// How far ahead the advice looks: a car ahead closer than this many seconds at the closing
/// speed counts as about to overlap.
pub const HORIZON_S: f32 = 1.0;

/// Room a passing line keeps from the wall, metres (beyond the body's half width).
pub const WALL_MARGIN_M: f32 = 0.1;

/// Following, the gap kept from this car's front to the other car's rear, metres, and the
/// speed added per metre beyond it (taken off per metre short of it), 1/s.
pub const FOLLOW_GAP_M: f32 = 0.4;
/// See [`FOLLOW_GAP_M`].
pub const FOLLOW_GAIN_PER_S: f32 = 1.0;

/// The car and the one ahead of it, on the track.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// The other car's base ahead of this one's along the centre line, metres.
    pub ahead_m: f32,
    /// This car's offset from the centre line, metres, positive on the right of the racing
    /// direction.
    pub offset_m: f32,
    /// The other car's offset, as `offset_m`.
    pub other_offset_m: f32,
    /// This car's forward speed, m/s.
    pub speed_mps: f32,
    /// The other car's forward speed, m/s.
    pub other_speed_mps: f32,
    /// From the centre line to the walls at this car's place, metres.
    pub half_width_m: f32,
}

/// Both cars' body: its length and half width, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Body {
    /// Rear end to front end.
    pub length_m: f32,
    /// Half the body's width.
    pub half_width_m: f32,
}

/// What to do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Advice {
    /// Drive along the line this far from the centre line, metres (positive right).
    Line(f32),
    /// Do not close in: drive at this speed, m/s.
    Follow(f32),
}

/// The advice for a car closing on `p`'s other car; None when the other car is behind, out of
/// reach, or pulling away.
pub fn advise(p: &Pair, body: &Body, margin_m: f32) -> Option<Advice> {
    let reach = body.length_m + HORIZON_S * p.speed_mps.max(0.0);
    if !(p.ahead_m > 0.0 && p.ahead_m < reach) {
        return None;
    }
    let closing = p.speed_mps - p.other_speed_mps;
    if p.ahead_m < body.length_m || closing < 0.05 {
        return None;
    }
    Some(decide(p, body, &Lines::of(p, body, margin_m, None)))
}

/// The advice a passer applies ([`crate::passer`]): as [`advise`], and on along the passing
/// line while the bodies overlap and until the other car's base is `hold_m` behind this car's
/// rear, so the car does not cut back across the other car's front. From straight behind it
/// passes on side `right` when given (the side of a pass under way), so a pass does not swap
/// sides as the other car's place wavers about this car's.
pub fn advise_passing(p: &Pair, body: &Body, margin_m: f32, hold_m: f32, right: Option<bool>) -> Option<Advice> {
    let reach = body.length_m + HORIZON_S * p.speed_mps.max(0.0);
    if !(p.ahead_m > -(body.length_m + hold_m) && p.ahead_m < reach) {
        return None;
    }
    let lines = Lines::of(p, body, margin_m, right);
    if p.ahead_m < body.length_m {
        let limit = lines.limit.max(0.0);
        return Some(Advice::Line(lines.near.clamp(-limit, limit)));
    }
    if p.speed_mps - p.other_speed_mps < 0.05 {
        return None;
    }
    Some(decide(p, body, &lines))
}

/// The passing lines on either side of the other car, and the farthest a centre may stand out.
struct Lines {
    near: f32,
    far: f32,
    limit: f32,
    side: f32,
}

impl Lines {
    fn of(p: &Pair, body: &Body, margin_m: f32, kept: Option<bool>) -> Self {
        // Centre to centre beside the other car.
        let apart = 2.0 * body.half_width_m + margin_m;
        let side = p.offset_m - p.other_offset_m;
        // The side the car is on; straight behind, the side kept, else the one with more room.
        let right = if side.abs() < 0.05 {
            kept.unwrap_or(p.other_offset_m < 0.0)
        } else {
            side > 0.0
        };
        let line = |right: bool| {
            let to = if right {
                p.other_offset_m + apart
            } else {
                p.other_offset_m - apart
            };
            // Already wider than that: keep the line it is on.
            if right { to.max(p.offset_m) } else { to.min(p.offset_m) }
        };
        Self {
            near: line(right),
            far: line(!right),
            limit: p.half_width_m - body.half_width_m - WALL_MARGIN_M,
            side,
        }
    }
}

/// The near line where it fits, else the far one from straight behind, else following.
fn decide(p: &Pair, body: &Body, l: &Lines) -> Advice {
    let fits = |o: f32| o.abs() <= l.limit;
    if fits(l.near) {
        Advice::Line(l.near)
    } else if fits(l.far) && l.side.abs() < 2.0 * body.half_width_m {
        Advice::Line(l.far)
    } else {
        let clear = p.ahead_m - body.length_m;
        let v = p.other_speed_mps + FOLLOW_GAIN_PER_S * (clear - FOLLOW_GAP_M);
        Advice::Follow(v.clamp(0.0, p.speed_mps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BODY: Body = Body {
        length_m: 0.6,
        half_width_m: 0.19,
    };

    fn pair(ahead_m: f32, offset_m: f32, other_offset_m: f32) -> Pair {
        Pair {
            ahead_m,
            offset_m,
            other_offset_m,
            speed_mps: 1.8,
            other_speed_mps: 1.3,
            half_width_m: 1.25,
        }
    }

    /// A car closing on one ahead from its left is sent along a line two half widths and the
    /// margin to the other car's left; one already wider keeps its own line.
    #[test]
    fn a_car_closing_in_is_sent_along_a_line_the_margin_beside_the_other() {
        let m = 0.25;
        let Some(Advice::Line(o)) = advise(&pair(1.0, -0.1, 0.2), &BODY, m) else {
            panic!("a line expected")
        };
        assert!((o - (0.2 - 0.38 - m)).abs() < 1e-6, "{o}");
        assert_eq!(advise(&pair(1.0, 0.9, 0.1), &BODY, m), Some(Advice::Line(0.9)));
    }

    /// Straight behind, the car goes to the side with more room; with room on neither side it
    /// follows, slower when closer than the gap it keeps; once the bodies overlap, nothing.
    #[test]
    fn with_no_room_beside_a_car_behind_follows_and_alongside_it_is_not_advised() {
        let m = 0.25;
        let Some(Advice::Line(o)) = advise(&pair(1.0, 0.3, 0.3), &BODY, m) else {
            panic!("a line expected")
        };
        assert!((o - (0.3 - 0.63)).abs() < 1e-6, "more room on the left: {o}");
        let narrow = Pair {
            half_width_m: 0.75,
            ..pair(1.0, 0.0, 0.0)
        };
        // 1.0 m base to base: 0.4 m from front to rear, the gap it keeps.
        assert_eq!(advise(&narrow, &BODY, m), Some(Advice::Follow(1.3)));
        let close = Pair { ahead_m: 0.8, ..narrow };
        let Some(Advice::Follow(v)) = advise(&close, &BODY, m) else {
            panic!("follow expected")
        };
        assert!((v - (1.3 - 0.2)).abs() < 1e-6, "0.2 m short of the gap: slower ({v})");
        let alongside = Pair {
            ahead_m: 0.3,
            offset_m: 0.3,
            ..narrow
        };
        assert_eq!(advise(&alongside, &BODY, m), None);
    }

    /// Nothing for a car behind, one too far ahead to reach within the horizon, or one that
    /// pulls away.
    #[test]
    fn no_advice_when_the_other_car_is_behind_far_ahead_or_faster() {
        let m = 0.25;
        assert_eq!(advise(&pair(-0.2, 0.0, 0.0), &BODY, m), None);
        assert_eq!(advise(&pair(3.0, 0.0, 0.0), &BODY, m), None);
        let faster = Pair {
            other_speed_mps: 1.9,
            ..pair(1.0, 0.0, 0.0)
        };
        assert_eq!(advise(&faster, &BODY, m), None);
    }

    /// The passer's advice goes on beside the other car and past it, on the side the car is
    /// on and inside the walls, until the other car's base is a car length and the hold behind;
    /// before the bodies overlap it is the training advice.
    #[test]
    fn a_passer_holds_its_line_beside_and_just_past_the_other_car() {
        let (m, hold) = (0.25, 0.3);
        for ahead in [0.3, 0.0, -0.85] {
            assert_eq!(
                advise_passing(&pair(ahead, -0.5, 0.0), &BODY, m, hold, None),
                Some(Advice::Line(-0.63)),
                "{ahead} m ahead"
            );
        }
        assert_eq!(advise_passing(&pair(-0.95, -0.5, 0.0), &BODY, m, hold, None), None);
        let narrow = Pair {
            half_width_m: 0.75,
            ..pair(0.2, -0.3, 0.0)
        };
        let Some(Advice::Line(o)) = advise_passing(&narrow, &BODY, m, hold, None) else {
            panic!("a line expected")
        };
        assert!((o + 0.46).abs() < 1e-6, "inside the walls: {o}");
        for p in [pair(1.0, -0.1, 0.2), pair(1.0, 0.3, 0.3), pair(3.0, 0.0, 0.0)] {
            assert_eq!(advise_passing(&p, &BODY, m, hold, None), advise(&p, &BODY, m), "{p:?}");
        }
    }

    /// From straight behind a pass under way keeps its side while the other car's place
    /// wavers across this car's: with the other car 1 cm to the left of it (which alone sends
    /// the car right), the kept left side is passed on.
    #[test]
    fn a_pass_from_straight_behind_keeps_its_side() {
        let (m, hold) = (0.25, 0.3);
        let p = pair(1.0, 0.0, -0.01);
        let Some(Advice::Line(free)) = advise_passing(&p, &BODY, m, hold, None) else {
            panic!("a line expected")
        };
        assert!(free > 0.0, "{free}");
        assert_eq!(advise_passing(&p, &BODY, m, hold, Some(true)), Some(Advice::Line(free)));
        let Some(Advice::Line(kept)) = advise_passing(&p, &BODY, m, hold, Some(false)) else {
            panic!("a line expected")
        };
        assert!((kept - (-0.01 - 0.38 - m)).abs() < 1e-6, "{kept}");
        // Off to one side, the car passes on the side it is on.
        let wide = pair(1.0, 0.3, 0.0);
        assert_eq!(
            advise_passing(&wide, &BODY, m, hold, Some(false)),
            advise_passing(&wide, &BODY, m, hold, None)
        );
    }
}
