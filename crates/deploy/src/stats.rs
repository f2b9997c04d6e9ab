//! What `agvrl-drive` reports about its own process (Linux /proc), and the quantiles of its
//! latencies.

pub use agvrl_run::stats::quantile;

/// CPU time (user + system) of this process, seconds (/proc/self/stat).
pub fn cpu_time_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // USER_HZ is 100 on every Linux ABI /proc reports in.
    Some(ticks / 100.0)
}

/// Resident set size of this process, MB (/proc/self/status VmRSS).
pub fn rss_mb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// How a drive stopped and went on, from its ticks: what a fault on the wire did to the car.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stops {
    /// Ticks seen.
    pub ticks: u64,
    /// Ticks that acted on the policy (no watchdog event).
    pub driving: u64,
    /// Times the car went from driving to a zero command.
    pub stops: u64,
    /// Longest time from the newest frame a driving tick acted on to the first zero command
    /// after it, seconds (the drive's clock).
    pub stop_after_frame_s_max: f64,
    /// Longest age of the frame the first driving tick after a stop acted on, seconds: how long
    /// after the data came back the car drove again.
    pub resume_s_max: f64,
    /// Driving ticks that acted on a frame stamped before one acted on earlier (must stay 0).
    pub stamp_back: u64,
    last_acted_s: Option<f64>,
    stopped: bool,
}

impl Stops {
    /// Take in one tick.
    pub fn add(&mut self, t: &crate::Tick) {
        self.ticks += 1;
        if t.event.is_none() {
            self.driving += 1;
            if self.last_acted_s.is_some_and(|s| t.stamp_s < s) {
                self.stamp_back += 1;
            }
            if self.stopped {
                self.resume_s_max = self.resume_s_max.max(t.now_s - t.stamp_s);
                self.stopped = false;
            }
            self.last_acted_s = Some(t.stamp_s);
        } else if !self.stopped {
            self.stopped = true;
            self.stops += 1;
            if let Some(s) = self.last_acted_s {
                self.stop_after_frame_s_max = self.stop_after_frame_s_max.max(t.now_s - s);
            }
        }
    }

    /// Share of ticks that drove.
    pub fn driving_share(&self) -> f64 {
        self.driving as f64 / self.ticks.max(1) as f64
    }

    /// ` driving_share=... stops=... ` for a summary line.
    pub fn summary(&self) -> String {
        format!(
            " driving_share={:.3} stops={} stop_after_frame_ms_max={:.1} resume_ms_max={:.1} stamp_back={}",
            self.driving_share(),
            self.stops,
            1e3 * self.stop_after_frame_s_max,
            1e3 * self.resume_s_max,
            self.stamp_back
        )
    }
}

/// Quantiles of a latency stream in constant memory, so a car that drives for days holds no
/// growing list: log-spaced bins 1 % wide from 0.1 us to about 100 s, and the exact maximum.
#[derive(Clone, Debug)]
pub struct Latencies {
    bins: Vec<u64>,
    n: u64,
    max: f64,
}

impl Default for Latencies {
    fn default() -> Self {
        Self {
            bins: vec![0; Self::BINS],
            n: 0,
            max: f64::NAN,
        }
    }
}

impl Latencies {
    const LOW_US: f64 = 0.1;
    const RATIO: f64 = 1.01;
    const BINS: usize = 2084;

    fn bin(us: f64) -> usize {
        if us.is_nan() || us <= Self::LOW_US {
            return 0;
        }
        (((us / Self::LOW_US).ln() / Self::RATIO.ln()) as usize + 1).min(Self::BINS - 1)
    }

    /// Take in one latency, us.
    pub fn add(&mut self, us: f64) {
        self.bins[Self::bin(us)] += 1;
        self.n += 1;
        self.max = self.max.max(us);
    }

    /// The nearest-rank `q` quantile (as [`quantile`]), to 1 %: the geometric middle of its bin
    /// (NaN when empty).
    pub fn quantile(&self, q: f64) -> f64 {
        if self.n == 0 {
            return f64::NAN;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (i, &c) in self.bins.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return if i == 0 {
                    Self::LOW_US
                } else {
                    (Self::LOW_US * Self::RATIO.powf(i as f64 - 0.5)).min(self.max)
                };
            }
        }
        self.max
    }

    /// The largest latency taken in (NaN when empty).
    pub fn max(&self) -> f64 {
        self.max
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latency_quantiles_in_constant_memory_are_within_one_percent_of_the_exact_ones() {
        // A skewed stream: most ticks fast, a tail of slow ones, spanning five decades.
        let mut x = 0.37f64;
        let mut v = Vec::new();
        let mut l = Latencies::default();
        for _ in 0..20_000 {
            x = 3.97 * x * (1.0 - x);
            let us = 20.0 * (1.0 + 9.0 * x).powi(5);
            v.push(us);
            l.add(us);
        }
        for q in [0.01, 0.5, 0.9, 0.99, 0.999, 1.0] {
            let (exact, approx) = (quantile(&v, q), l.quantile(q));
            assert!((approx / exact - 1.0).abs() < 0.01, "q {q}: {approx} vs {exact}");
        }
        assert_eq!(l.max(), v.iter().copied().fold(f64::MIN, f64::max));
        assert!(Latencies::default().quantile(0.5).is_nan());
    }
}
