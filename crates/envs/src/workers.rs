//! The one worker pool: persistent helper threads that VecEnv's rounds and the learners'
//! gradient steps (SAC's blocks, PPO's image minibatches) spread their work over.
//!
//! A round of env steps or a gradient step forks and joins within tens of microseconds to a
//! few milliseconds. On a virtual machine, waking a parked thread costs tens of microseconds
//! each time, and a fresh thread per fork also starts with cold caches and GEMM packing
//! buffers; so the helpers live as long as the pool, and both sides wait for each other by
//! spinning for a few tens of microseconds, then yielding for a while, before they park.
//! Yielding, unlike a spin, hands the core to any other runnable thread at once.
//!
//! A VecEnv and its learner share one pool ([`crate::VecEnv::workers`]): their work
//! alternates, so one set of helpers serves both.

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// How long a waiting side yields before it parks: longer than the gap between the forks of
/// one gradient step or two env rounds, shorter than anything a person would notice as a busy
/// core.
const YIELD_FOR: Duration = Duration::from_millis(2);

/// How long a waiting side spins before it yields: a VecEnv round's steps take tens of
/// microseconds, and a yield is a system call that can cost a microsecond each time.
const SPIN_FOR: Duration = Duration::from_micros(50);

type Job = Box<dyn FnOnce() + Send>;

static NEXT_POOL: AtomicU64 = AtomicU64::new(1);

thread_local! {
    /// The pool this thread is a helper of (0: none).
    static HELPER_OF: Cell<u64> = const { Cell::new(0) };
}

/// `n` helper threads; [`Workers::run`] spreads jobs over them and the calling thread.
pub struct Workers {
    id: u64,
    senders: Vec<Sender<Job>>,
    handles: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for Workers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workers").field("helpers", &self.len()).finish()
    }
}

/// Take the next message: spin for [`SPIN_FOR`], then yield until [`YIELD_FOR`], then block.
fn wait<T>(rx: &Receiver<T>) -> Option<T> {
    let start = Instant::now();
    loop {
        match rx.try_recv() {
            Ok(v) => return Some(v),
            Err(TryRecvError::Disconnected) => return None,
            Err(TryRecvError::Empty) => {
                let waited = start.elapsed();
                if waited < SPIN_FOR {
                    std::hint::spin_loop();
                } else if waited < YIELD_FOR {
                    std::thread::yield_now();
                } else {
                    return rx.recv().ok();
                }
            }
        }
    }
}

impl Workers {
    /// Start `n` helpers (none when `n == 0`).
    pub fn new(n: usize) -> std::io::Result<Self> {
        let id = NEXT_POOL.fetch_add(1, Ordering::Relaxed);
        let mut senders = Vec::with_capacity(n);
        let mut handles = Vec::with_capacity(n);
        for i in 0..n {
            let (tx, rx) = mpsc::channel::<Job>();
            let handle = std::thread::Builder::new()
                .name(format!("agvrl-worker-{}", i + 1))
                .spawn(move || {
                    HELPER_OF.set(id);
                    while let Some(job) = wait(&rx) {
                        // A panicking job reads as `None` to its caller (its result channel is
                        // dropped); the helper stays for the next job.
                        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(job));
                    }
                })?;
            senders.push(tx);
            handles.push(handle);
        }
        Ok(Self { id, senders, handles })
    }

    /// Helper threads (the calling thread not counted).
    pub fn len(&self) -> usize {
        self.senders.len()
    }

    /// Whether the pool has no helpers (every job runs on the calling thread).
    pub fn is_empty(&self) -> bool {
        self.senders.is_empty()
    }

    /// Run `jobs` (at most `len() + 1`): job 0 on the calling thread, job `i` on helper
    /// `i - 1`; results in job order. A job that panics on a helper returns `None`. Jobs may
    /// borrow from the caller's stack: every job has returned or unwound before this returns
    /// (a panic in job 0 is resumed only once the helpers' jobs are done), so nothing a job
    /// borrows goes away while it runs. Called from one of this pool's own helpers (a job that
    /// forks again), the jobs run one after another on that helper: its queue would otherwise
    /// wait on itself.
    pub fn run<'s, T: Send + 's>(&self, jobs: Vec<Box<dyn FnOnce() -> T + Send + 's>>) -> Vec<Option<T>> {
        assert!(jobs.len() <= self.len() + 1, "more jobs than threads");
        let mut jobs = jobs.into_iter();
        if HELPER_OF.get() == self.id {
            let Some(first) = jobs.next() else {
                return vec![];
            };
            let first = std::panic::catch_unwind(std::panic::AssertUnwindSafe(first));
            let rest = jobs.map(|job| std::panic::catch_unwind(std::panic::AssertUnwindSafe(job)).ok());
            let rest: Vec<Option<T>> = rest.collect();
            return match first {
                Ok(v) => std::iter::once(Some(v)).chain(rest).collect(),
                Err(panic) => std::panic::resume_unwind(panic),
            };
        }
        let Some(first) = jobs.next() else {
            return vec![];
        };
        let receivers: Vec<Receiver<T>> = jobs
            .zip(&self.senders)
            .map(|(job, worker)| {
                let (tx, rx) = mpsc::channel();
                let job: Box<dyn FnOnce() + Send + 's> = Box::new(move || {
                    let _ = tx.send(job());
                });
                // SAFETY: only the lifetime changes. The job ends (its result sent, or its
                // channel dropped as it unwinds or is dropped unrun) before this function
                // returns: every receiver is waited on below, even when job 0 panics.
                let job: Job = unsafe { std::mem::transmute::<Box<dyn FnOnce() + Send + 's>, Job>(job) };
                // A helper that is gone drops the job unrun, leaving `rx` disconnected: `None`.
                let _ = worker.send(job);
                rx
            })
            .collect();
        let first = std::panic::catch_unwind(std::panic::AssertUnwindSafe(first));
        let rest: Vec<Option<T>> = receivers.iter().map(wait).collect();
        match first {
            Ok(v) => std::iter::once(Some(v)).chain(rest).collect(),
            Err(panic) => std::panic::resume_unwind(panic),
        }
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

    /// Borrowing jobs see the caller's data and return in order; a panic in the caller's own
    /// job reaches the caller, and the helpers run the next call's jobs.
    #[test]
    fn scoped_jobs_borrow_the_callers_data_and_a_panic_reaches_the_caller() {
        let workers = Workers::new(2).unwrap();
        let data: Vec<u64> = (0..300).collect();
        let sums = |w: &Workers| -> Vec<u64> {
            let jobs: Vec<Box<dyn FnOnce() -> u64 + Send + '_>> = data
                .chunks(100)
                .map(|c| Box::new(|| c.iter().sum::<u64>()) as Box<dyn FnOnce() -> u64 + Send + '_>)
                .collect();
            w.run(jobs).into_iter().map(Option::unwrap).collect()
        };
        assert_eq!(sums(&workers), [4950, 14950, 24950]);
        let done = std::sync::atomic::AtomicUsize::new(0);
        let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let count = || {
                done.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            };
            let jobs: Vec<Box<dyn FnOnce() + Send + '_>> = vec![Box::new(|| panic!("job 0 failed")), Box::new(count)];
            workers.run(jobs)
        }));
        assert!(caught.is_err());
        assert_eq!(
            done.load(std::sync::atomic::Ordering::SeqCst),
            1,
            "the helper's job ran"
        );
        assert_eq!(sums(&workers), [4950, 14950, 24950]);
    }

    /// A panicking job reads as `None` and the others still return; its helper serves the next
    /// call (the pool is shared by a VecEnv and
    /// its learner, so one failed env step must not take the learner's helpers with it).
    #[test]
    fn a_panicking_job_reads_as_none_and_its_helper_serves_the_next_call() {
        let workers = Workers::new(1).unwrap();
        let jobs: Vec<Box<dyn FnOnce() -> u32 + Send>> = vec![Box::new(|| 1), Box::new(|| panic!("job failed"))];
        assert_eq!(workers.run(jobs), vec![Some(1), None]);
        let me = std::thread::current().id();
        let jobs: Vec<Box<dyn FnOnce() -> bool + Send>> =
            vec![Box::new(|| true), Box::new(move || std::thread::current().id() != me)];
        assert_eq!(workers.run(jobs), vec![Some(true), Some(true)]);
    }

    /// A job on a helper that forks over the same pool gets its results: the nested jobs run
    /// on that helper instead of queueing behind the job that waits for them.
    #[test]
    fn a_job_that_forks_over_its_own_pool_finishes() {
        let workers = std::sync::Arc::new(Workers::new(1).unwrap());
        let (tx, rx) = mpsc::channel();
        let pool = workers.clone();
        std::thread::spawn(move || {
            let inner = pool.clone();
            let jobs: Vec<Box<dyn FnOnce() -> Vec<Option<u32>> + Send>> = vec![
                Box::new(|| vec![Some(0)]),
                Box::new(move || {
                    let nested: Vec<Box<dyn FnOnce() -> u32 + Send>> = vec![Box::new(|| 2), Box::new(|| 3)];
                    inner.run(nested)
                }),
            ];
            let _ = tx.send(pool.run(jobs));
        });
        let out = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the nested fork never returned");
        assert_eq!(out, vec![Some(vec![Some(0)]), Some(vec![Some(2), Some(3)])]);
    }
}
