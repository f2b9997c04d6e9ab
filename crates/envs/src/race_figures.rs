//! The race figures a racing engineer reads (docs/racing.md, "Race figures"): encounters, passes
//! and at-fault incidents, decided per ordered pair of cars from their distances along the
//! centre line (continuous across the lap line), their at-fault contacts and their crashes.
//!
//! - An *encounter* of car i with car j starts when i is 0-3 m behind j, and ends when i falls
//!   more than 5 m behind, when either car crashes, when i passes j (or leads for 2 s after a
//!   contact it caused: no pass), or when the race ends. Once i leads by 0.5 m the 2 s hold
//!   decides, however far ahead it pulls meanwhile.
//! - A *pass* ends an encounter: i at least 0.5 m ahead of j for 2 s, with no contact i caused
//!   from 2 s before it drew ahead until then, and j not crashed.

/// An encounter starts within this distance behind the other car, metres.
pub const ENCOUNTER_BEHIND_M: f64 = 3.0;
/// An encounter ends when the gap passes this distance either way, metres.
pub const ENCOUNTER_END_M: f64 = 5.0;
/// A pass needs the passing car this far ahead, metres,
pub const PASS_LEAD_M: f64 = 0.5;
/// for this long, seconds, with no contact it caused in as long before it drew ahead.
pub const PASS_HOLD_S: f64 = 2.0;

/// One car's state at a step, as the race figures read it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CarAt {
    /// Distance raced along the centre line, metres (continuous across the lap line).
    pub distance_m: f64,
    /// Still racing (not crashed).
    pub running: bool,
    /// When it last caused a contact (its front hit another car), seconds.
    pub last_fault_s: Option<f64>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Encounter {
    active: bool,
    /// Since when the car behind at the start leads by [`PASS_LEAD_M`], seconds.
    lead_since_s: Option<f64>,
}

/// Encounters and passes of every ordered pair of cars in one race.
#[derive(Clone, Debug, Default)]
pub struct PassBook {
    n: usize,
    /// `pairs[i * n + j]`: car i's encounter with car j (i behind at its start).
    pairs: Vec<Encounter>,
    encounters: Vec<u32>,
    passes: Vec<u32>,
}

impl PassBook {
    /// A book for `n` cars, before the start.
    pub fn new(n: usize) -> Self {
        Self {
            n,
            pairs: vec![Encounter::default(); n * n],
            encounters: vec![0; n],
            passes: vec![0; n],
        }
    }

    /// Take the cars' state at time `now_s`.
    pub fn update(&mut self, now_s: f64, cars: &[CarAt]) {
        debug_assert_eq!(cars.len(), self.n);
        for i in 0..self.n {
            for j in (0..self.n).filter(|&j| j != i) {
                let (a, b) = (&cars[i], &cars[j]);
                let gap = a.distance_m - b.distance_m;
                let e = &mut self.pairs[i * self.n + j];
                if !e.active {
                    if a.running && b.running && (-ENCOUNTER_BEHIND_M..=0.0).contains(&gap) {
                        *e = Encounter {
                            active: true,
                            lead_since_s: None,
                        };
                        self.encounters[i] += 1;
                    }
                    continue;
                }
                if !(a.running && b.running) || gap < -ENCOUNTER_END_M {
                    *e = Encounter::default();
                    continue;
                }
                if gap < PASS_LEAD_M {
                    e.lead_since_s = None;
                    continue;
                }
                // Leading: the hold decides, however far ahead the car pulls meanwhile.
                let since = *e.lead_since_s.get_or_insert(now_s);
                if now_s - since >= PASS_HOLD_S - 1e-9 {
                    let clean = a.last_fault_s.is_none_or(|t| t < since - PASS_HOLD_S);
                    self.passes[i] += u32::from(clean);
                    *e = Encounter::default();
                }
            }
        }
    }

    /// Encounters each car had (as the car behind).
    pub fn encounters(&self) -> &[u32] {
        &self.encounters
    }

    /// Passes each car made.
    pub fn passes(&self) -> &[u32] {
        &self.passes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.1;

    /// Run a scripted gap (car 0 minus car 1, metres) per step of 0.1 s with car 1 at 10 m;
    /// car 0 caused a contact at `fault_s` if set; car 1 crashes at `crash_s` if set.
    fn script(gaps: &[f64], fault_s: Option<f64>, crash_s: Option<f64>) -> PassBook {
        let mut book = PassBook::new(2);
        for (k, g) in gaps.iter().enumerate() {
            let t = k as f64 * DT;
            let cars = [
                CarAt {
                    distance_m: 10.0 + g,
                    running: true,
                    last_fault_s: fault_s.filter(|&f| f <= t),
                },
                CarAt {
                    distance_m: 10.0,
                    running: crash_s.is_none_or(|c| t < c),
                    last_fault_s: None,
                },
            ];
            book.update(t, &cars);
        }
        book
    }

    /// From `from` to `to` metres in `steps` steps, then held at `to` for `hold` steps.
    fn ramp(from: f64, to: f64, steps: usize, hold: usize) -> Vec<f64> {
        let mut v: Vec<f64> = (0..steps)
            .map(|k| from + (to - from) * k as f64 / steps as f64)
            .collect();
        v.extend(std::iter::repeat_n(to, hold));
        v
    }

    #[test]
    fn a_pass_held_for_two_seconds_counts_once() {
        let book = script(&ramp(-2.0, 1.0, 20, 60), None, None);
        assert_eq!(book.encounters(), &[1, 1], "car 1 then rides 1 m behind car 0");
        assert_eq!(book.passes(), &[1, 0]);
    }

    #[test]
    fn falling_back_before_two_seconds_is_no_pass() {
        let mut gaps = ramp(-2.0, 1.0, 20, 15);
        gaps.extend(ramp(1.0, -2.0, 10, 30));
        let book = script(&gaps, None, None);
        assert_eq!(book.passes()[0], 0);
        assert_eq!(book.encounters()[0], 1, "one encounter, still on");
        // Car 1, passed for 1.5 s, leads again by 2 m for 3 s: its pass back counts.
        assert_eq!(book.passes()[1], 1);
    }

    #[test]
    fn a_pass_after_a_contact_it_caused_is_no_pass() {
        // Ahead from step 20 (2.0 s); the contact at 0.5 s lies within the 2 s before.
        let book = script(&ramp(-2.0, 1.0, 20, 60), Some(0.5), None);
        assert_eq!(book.passes(), &[0, 0]);
        assert_eq!(book.encounters()[0], 1);
        // A contact longer ago does not count against it.
        let mut gaps = vec![-2.0; 40];
        gaps.extend(ramp(-2.0, 1.0, 20, 60));
        let book = script(&gaps, Some(0.5), None);
        assert_eq!(book.passes(), &[1, 0]);
    }

    #[test]
    fn passing_a_crashed_car_is_no_pass_and_ends_the_encounter() {
        let book = script(&ramp(-2.0, 1.0, 20, 60), None, Some(1.0));
        assert_eq!(book.passes(), &[0, 0]);
        assert_eq!(book.encounters(), &[1, 0]);
    }

    #[test]
    fn an_encounter_ends_beyond_five_metres_and_starts_again_within_three() {
        let mut gaps = ramp(-2.0, -6.0, 10, 5);
        gaps.extend(ramp(-6.0, -1.0, 10, 5));
        let book = script(&gaps, None, None);
        assert_eq!(book.encounters(), &[2, 0]);
        // Far behind, nothing starts.
        let book = script(&[-4.0; 50], None, None);
        assert_eq!(book.encounters(), &[0, 0]);
    }

    #[test]
    fn a_pass_that_pulls_away_fast_still_counts() {
        // 0.5 m ahead at 1.0 s and 9 m ahead 2 s later.
        let book = script(&ramp(-2.0, 9.0, 40, 10), None, None);
        assert_eq!(book.passes(), &[1, 0]);
    }
}
