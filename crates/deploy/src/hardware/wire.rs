//! Faults on the wire between the simulated robot and a car's stack (`agvrl-drive --serve-sim
//! ENV --realtime --faults SPEC`). This kernel has no `netem`, so the sender injects them: each
//! sensor message the robot publishes goes through a [`Wire`] that drops, delays, duplicates
//! or holds it back before it reaches DDS, so the faults really travel over the network.

use super::msg;
use crate::record::Sensor;
use agvrl_rl::rng::Rng;
use std::fmt;
use std::str::FromStr;
use std::time::{Duration, Instant};

/// The sensor `s` names in a fault spec.
fn sensor_named(s: &str) -> Result<Sensor, String> {
    Ok(match s {
        "scan" => Sensor::Scan,
        "imu" => Sensor::Imu,
        "odom" => Sensor::Odom,
        "navsat" => Sensor::NavSat,
        "image" => Sensor::Image,
        _ => return Err(format!("unknown sensor '{s}' (scan, imu, odom, navsat, image)")),
    })
}

/// What goes wrong on the wire; the default is a perfect wire.
///
/// Written as comma-separated `key=value` pairs, e.g.
/// `loss=0.1,delay_ms=50,jitter_ms=20,duplicate=0.05,reorder=0.1,outage=300+30,mute=imu@300,clock_step=0.5@300,seed=1`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WireFaults {
    /// Probability that a message is lost.
    pub loss: f64,
    /// Added latency of every message, ms.
    pub delay_ms: f64,
    /// Each message's latency varies uniformly by up to this either way, ms (never below 0).
    pub jitter_ms: f64,
    /// Probability that a message is sent twice (the copy with a latency of its own).
    pub duplicate: f64,
    /// Probability that a message is held back one control period, so the next overtakes it.
    pub reorder: f64,
    /// From tick `.0`, for `.1` ticks, nothing is sent; then everything comes back.
    pub outage: Option<(u64, u64)>,
    /// From tick `.1` on, sensor `.0` sends nothing while the others go on.
    pub mute: Option<(Sensor, u64)>,
    /// From tick `.0` on, every stamp is `.1` seconds off (a sensor clock that steps).
    pub clock_step: Option<(u64, f64)>,
    /// Seed of the fault draws.
    pub seed: u64,
}

impl WireFaults {
    /// Whether any fault is set.
    pub fn any(&self) -> bool {
        *self
            != Self {
                seed: self.seed,
                ..Self::default()
            }
    }

    /// The stamp offset at `tick`, seconds.
    pub fn clock_offset_s(&self, tick: u64) -> f64 {
        self.clock_step.filter(|(at, _)| tick >= *at).map_or(0.0, |(_, s)| s)
    }
}

impl FromStr for WireFaults {
    type Err = String;
    fn from_str(spec: &str) -> Result<Self, String> {
        let mut f = Self::default();
        for pair in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| format!("--faults: '{pair}' is not KEY=VALUE"))?;
            let num = |v: &str| -> Result<f64, String> {
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| format!("--faults {key}: '{v}' is not a number"))
            };
            let tick = |v: &str| -> Result<u64, String> {
                v.parse::<u64>()
                    .map_err(|_| format!("--faults {key}: '{v}' is not a tick count"))
            };
            let prob = |v: &str| -> Result<f64, String> {
                let p = num(v)?;
                if (0.0..=1.0).contains(&p) {
                    Ok(p)
                } else {
                    Err(format!("--faults {key}: {p} is not a probability in [0, 1]"))
                }
            };
            match key {
                "loss" => f.loss = prob(value)?,
                "duplicate" => f.duplicate = prob(value)?,
                "reorder" => f.reorder = prob(value)?,
                "delay_ms" | "jitter_ms" => {
                    let ms = num(value)?;
                    if ms < 0.0 {
                        return Err(format!("--faults {key}: {ms} is negative"));
                    }
                    if key == "delay_ms" {
                        f.delay_ms = ms;
                    } else {
                        f.jitter_ms = ms;
                    }
                }
                "outage" => {
                    let (from, len) = value
                        .split_once('+')
                        .ok_or_else(|| format!("--faults outage: '{value}' is not FROM+TICKS"))?;
                    f.outage = Some((tick(from)?, tick(len)?));
                }
                "mute" => {
                    let (sensor, from) = value
                        .split_once('@')
                        .ok_or_else(|| format!("--faults mute: '{value}' is not SENSOR@TICK"))?;
                    f.mute = Some((
                        sensor_named(sensor).map_err(|e| format!("--faults mute: {e}"))?,
                        tick(from)?,
                    ));
                }
                "clock_step" => {
                    let (s, at) = value
                        .split_once('@')
                        .ok_or_else(|| format!("--faults clock_step: '{value}' is not SECONDS@TICK"))?;
                    f.clock_step = Some((tick(at)?, num(s)?));
                }
                "seed" => f.seed = tick(value)?,
                _ => {
                    return Err(format!(
                        "--faults: unknown key '{key}' (loss, delay_ms, jitter_ms, duplicate, reorder, outage, mute, clock_step, seed)"
                    ));
                }
            }
        }
        Ok(f)
    }
}

impl fmt::Display for WireFaults {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "loss={},delay_ms={},jitter_ms={},duplicate={},reorder={},seed={}",
            self.loss, self.delay_ms, self.jitter_ms, self.duplicate, self.reorder, self.seed
        )?;
        if let Some((from, n)) = self.outage {
            write!(f, ",outage={from}+{n}")?;
        }
        if let Some((s, from)) = self.mute {
            write!(f, ",mute={}@{from}", format!("{s:?}").to_lowercase())?;
        }
        if let Some((at, s)) = self.clock_step {
            write!(f, ",clock_step={s}@{at}")?;
        }
        Ok(())
    }
}

/// A sensor message on its way.
#[derive(Clone, Debug)]
pub enum Outgoing {
    /// LaserScan.
    Scan(msg::LaserScan),
    /// Imu.
    Imu(msg::Imu),
    /// Odometry.
    Odom(Box<msg::Odometry>),
    /// NavSatFix.
    NavSat(msg::NavSatFix),
    /// Image.
    Image(msg::Image),
}

impl Outgoing {
    fn sensor(&self) -> Sensor {
        match self {
            Self::Scan(_) => Sensor::Scan,
            Self::Imu(_) => Sensor::Imu,
            Self::Odom(_) => Sensor::Odom,
            Self::NavSat(_) => Sensor::NavSat,
            Self::Image(_) => Sensor::Image,
        }
    }
}

/// What the wire did so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WireStats {
    /// Messages handed to the wire.
    pub offered: u64,
    /// Messages that went out (copies included).
    pub sent: u64,
    /// Lost at random.
    pub lost: u64,
    /// Withheld by an outage or a muted sensor.
    pub withheld: u64,
    /// Extra copies sent.
    pub duplicated: u64,
    /// Held back a period.
    pub held_back: u64,
}

/// The wire: messages in, messages out when their time comes.
pub struct Wire {
    faults: WireFaults,
    period: Duration,
    rng: Rng,
    /// (release time, sequence number, message), in no order.
    pending: Vec<(Instant, u64, Outgoing)>,
    seq: u64,
    stats: WireStats,
}

impl Wire {
    /// A wire with `faults` for a robot with control period `period_s`.
    pub fn new(faults: WireFaults, period_s: f64) -> Self {
        Self {
            rng: Rng::new(faults.seed),
            faults,
            period: Duration::from_secs_f64(period_s),
            pending: Vec::new(),
            seq: 0,
            stats: WireStats::default(),
        }
    }

    /// The faults.
    pub fn faults(&self) -> &WireFaults {
        &self.faults
    }

    /// What the wire did so far.
    pub fn stats(&self) -> WireStats {
        self.stats
    }

    /// Hand `m` (published at robot tick `tick`) to the wire at `now`.
    pub fn send(&mut self, tick: u64, now: Instant, m: Outgoing) {
        let f = &self.faults;
        self.stats.offered += 1;
        let out = f.outage.is_some_and(|(from, n)| tick >= from && tick - from < n);
        let muted = f.mute.is_some_and(|(s, from)| s == m.sensor() && tick >= from);
        if out || muted {
            self.stats.withheld += 1;
            return;
        }
        if self.rng.uniform() < f.loss {
            self.stats.lost += 1;
            return;
        }
        let copies = if self.rng.uniform() < f.duplicate { 2 } else { 1 };
        self.stats.duplicated += copies - 1;
        for copy in 0..copies {
            let jitter = f.jitter_ms * (2.0 * self.rng.uniform() - 1.0);
            let mut delay = Duration::from_secs_f64((f.delay_ms + jitter).max(0.0) / 1e3);
            if copy == 0 && self.rng.uniform() < f.reorder {
                delay += self.period;
                self.stats.held_back += 1;
            }
            self.seq += 1;
            self.pending.push((now + delay, self.seq, m.clone()));
        }
    }

    /// The messages due by `now`, in the order they leave.
    pub fn due(&mut self, now: Instant) -> Vec<Outgoing> {
        let mut due: Vec<(Instant, u64, Outgoing)> = Vec::new();
        let mut i = 0;
        while i < self.pending.len() {
            if self.pending[i].0 <= now {
                due.push(self.pending.swap_remove(i));
            } else {
                i += 1;
            }
        }
        due.sort_by_key(|(t, seq, _)| (*t, *seq));
        self.stats.sent += due.len() as u64;
        due.into_iter().map(|(_, _, m)| m).collect()
    }

    /// When the next message leaves.
    pub fn next_release(&self) -> Option<Instant> {
        self.pending.iter().map(|p| p.0).min()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fault_spec_reads_back_and_bad_ones_are_named() {
        let f: WireFaults = "loss=0.1,delay_ms=50,jitter_ms=20,duplicate=0.05,reorder=0.1,outage=300+30,mute=imu@300,clock_step=0.5@300,seed=3"
            .parse()
            .unwrap();
        assert_eq!(f.to_string().parse::<WireFaults>().unwrap(), f);
        assert_eq!(f.outage, Some((300, 30)));
        assert_eq!(f.mute, Some((Sensor::Imu, 300)));
        assert_eq!(f.clock_offset_s(299), 0.0);
        assert_eq!(f.clock_offset_s(300), 0.5);
        assert!(!WireFaults::default().any() && f.any());
        for (bad, says) in [
            ("loss=2", "probability"),
            ("delay_ms=-1", "negative"),
            ("mute=lidar@3", "unknown sensor"),
            ("outage=3", "FROM+TICKS"),
            ("lag=3", "unknown key"),
            ("loss", "KEY=VALUE"),
        ] {
            let e = bad.parse::<WireFaults>().unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    fn scan(k: u32) -> Outgoing {
        let mut m = msg::LaserScan::default();
        m.header.stamp.sec = k as i32;
        Outgoing::Scan(m)
    }

    fn sec(m: &Outgoing) -> i32 {
        match m {
            Outgoing::Scan(s) => s.header.stamp.sec,
            _ => unreachable!(),
        }
    }

    #[test]
    fn the_wire_delays_drops_copies_and_reorders_as_told() {
        let t0 = Instant::now();
        let ms = |n: u64| Duration::from_millis(n);
        // Delay only: nothing before 50 ms, everything after, in order.
        let mut w = Wire::new("delay_ms=50".parse().unwrap(), 1.0 / 30.0);
        for k in 0..3 {
            w.send(k, t0 + ms(10 * k), scan(k as u32));
        }
        assert!(w.due(t0 + ms(49)).is_empty());
        assert_eq!(w.due(t0 + ms(75)).iter().map(sec).collect::<Vec<_>>(), vec![0, 1, 2]);
        // An outage withholds everything in it; a muted sensor only itself.
        let mut w = Wire::new("outage=2+3,mute=imu@0".parse().unwrap(), 1.0 / 30.0);
        for k in 0..8 {
            w.send(k, t0, scan(k as u32));
            w.send(k, t0, Outgoing::Imu(msg::Imu::default()));
        }
        assert_eq!(
            w.due(t0)
                .iter()
                .filter(|m| matches!(m, Outgoing::Scan(_)))
                .map(sec)
                .collect::<Vec<_>>(),
            vec![0, 1, 5, 6, 7]
        );
        assert_eq!(w.stats().withheld, 3 + 8);
        // Certain duplication and reordering: two copies each, the first a period late.
        let mut w = Wire::new("duplicate=1,reorder=1".parse().unwrap(), 0.1);
        w.send(0, t0, scan(0));
        w.send(1, t0 + ms(50), scan(1));
        assert_eq!(w.due(t0 + ms(60)).iter().map(sec).collect::<Vec<_>>(), vec![0, 1]);
        assert_eq!(w.due(t0 + ms(160)).iter().map(sec).collect::<Vec<_>>(), vec![0, 1]);
        assert_eq!(w.stats().duplicated, 2);
        // Loss 0.3 of 2000: the share lost is near 0.3.
        let mut w = Wire::new("loss=0.3,seed=7".parse().unwrap(), 0.1);
        for k in 0..2000 {
            w.send(k, t0, scan(0));
        }
        let lost = w.stats().lost as f64 / 2000.0;
        assert!((lost - 0.3).abs() < 0.04, "{lost}");
    }
}
