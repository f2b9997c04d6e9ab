//! Persistent helper threads for a learner's gradient steps.
//!
//! A gradient step forks and joins twice (critic, actor) within a few milliseconds. On a
//! virtual machine, waking a parked thread costs tens of microseconds each time, and a fresh
//! thread per fork also starts with cold GEMM packing buffers; so the helpers live as long as
//! the learner, and both sides wait for each other by yielding for a short while before they
//! park. Yielding, unlike a pure spin, hands the core to any other runnable thread (a
//! VecEnv's worker) at once.

use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a waiting side yields before it parks: longer than the gap between the forks of
/// one gradient step, shorter than anything a person would notice as a busy core.
const YIELD_FOR: Duration = Duration::from_millis(2);

type Job = Box<dyn FnOnce() + Send>;

/// `n` helper threads; [`Workers::run`] spreads jobs over them and the calling thread.
pub(crate) struct Workers {
    senders: Vec<Sender<Job>>,
    handles: Vec<JoinHandle<()>>,
}

/// Take the next message, yielding for [`YIELD_FOR`] before blocking.
fn wait<T>(rx: &Receiver<T>) -> Option<T> {
    let start = Instant::now();
    loop {
        match rx.try_recv() {
            Ok(v) => return Some(v),
            Err(TryRecvError::Disconnected) => return None,
            Err(TryRecvError::Empty) if start.elapsed() < YIELD_FOR => std::thread::yield_now(),
            Err(TryRecvError::Empty) => return rx.recv().ok(),
        }
    }
}

impl Workers {
    /// Start `n` helpers (none when `n == 0`).
    pub(crate) fn new(n: usize) -> std::io::Result<Self> {
        let mut senders = Vec::with_capacity(n);
        let mut handles = Vec::with_capacity(n);
        for i in 0..n {
            let (tx, rx) = mpsc::channel::<Job>();
            let handle = std::thread::Builder::new()
                .name(format!("agvrl-learner-{}", i + 1))
                .spawn(move || {
                    while let Some(job) = wait(&rx) {
                        job();
                    }
                })?;
            senders.push(tx);
            handles.push(handle);
        }
        Ok(Self { senders, handles })
    }

    /// Helper threads (the calling thread not counted).
    pub(crate) fn len(&self) -> usize {
        self.senders.len()
    }

    /// Run `jobs` (at most `len() + 1`): job 0 on the calling thread, job `i` on helper
    /// `i - 1`; results in job order. A job that panics on a helper returns `None`.
    pub(crate) fn run<T: Send + 'static>(&self, jobs: Vec<Box<dyn FnOnce() -> T + Send>>) -> Vec<Option<T>> {
        assert!(jobs.len() <= self.len() + 1, "more jobs than threads");
        let mut jobs = jobs.into_iter();
        let Some(first) = jobs.next() else {
            return vec![];
        };
        let receivers: Vec<Receiver<T>> = jobs
            .zip(&self.senders)
            .map(|(job, worker)| {
                let (tx, rx) = mpsc::channel();
                // A helper that is gone leaves `rx` disconnected, read below as `None`.
                let _ = worker.send(Box::new(move || {
                    let _ = tx.send(job());
                }));
                rx
            })
            .collect();
        let mut out = vec![Some(first())];
        out.extend(receivers.iter().map(wait));
        out
    }
}

impl Drop for Workers {
    fn drop(&mut self) {
        self.senders.clear();
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jobs_return_in_order_and_run_on_distinct_threads() {
        let workers = Workers::new(2).unwrap();
        for round in 0..50u64 {
            let jobs: Vec<Box<dyn FnOnce() -> (u64, std::thread::ThreadId) + Send>> = (0..3u64)
                .map(|i| {
                    Box::new(move || (round * 10 + i, std::thread::current().id())) as Box<dyn FnOnce() -> _ + Send>
                })
                .collect();
            let out: Vec<_> = workers.run(jobs).into_iter().map(Option::unwrap).collect();
            assert_eq!(
                out.iter().map(|o| o.0).collect::<Vec<_>>(),
                [round * 10, round * 10 + 1, round * 10 + 2]
            );
            assert_eq!(out[0].1, std::thread::current().id());
            assert!(out[1].1 != out[0].1 && out[2].1 != out[0].1 && out[1].1 != out[2].1);
        }
    }

    #[test]
    fn a_panicking_job_reads_as_none_and_the_others_still_return() {
        let workers = Workers::new(1).unwrap();
        let jobs: Vec<Box<dyn FnOnce() -> u32 + Send>> = vec![Box::new(|| 1), Box::new(|| panic!("job failed"))];
        assert_eq!(workers.run(jobs), vec![Some(1), None]);
    }
}
