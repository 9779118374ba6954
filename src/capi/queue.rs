//! A device's queue: the work of the `Async` calls, run in order on one worker thread,
//! as OIDN's CPU engine runs its queue. The worker starts with the first queued job and
//! stops when the device goes, after finishing what is queued.
//!
//! The first error a job returns is kept until a sync point takes it ([`Queue::take_error`];
//! OIDN's "async error", which temcSyncDevice and the blocking calls report).

use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;

use super::objects::{Failure, Outcome};
use super::{TEMC_ERROR_OUT_OF_MEMORY, TEMC_ERROR_UNKNOWN};

/// Work queued on a device. It holds (by `Arc`) every object it uses, so releasing their
/// handles meanwhile is safe.
pub(crate) type Job = Box<dyn FnOnce() -> Outcome<()> + Send>;

#[derive(Default)]
struct Jobs {
    waiting: VecDeque<Job>,
    /// A job is running (popped from `waiting`, not finished).
    running: bool,
    /// The device is going: the worker ends once `waiting` is empty.
    shutdown: bool,
    /// The first error of a job since the last sync point.
    error: Option<Failure>,
}

#[derive(Default)]
struct Shared {
    jobs: Mutex<Jobs>,
    /// Signalled when a job is queued or finishes, and at shutdown.
    changed: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Jobs> {
        // Every update of `Jobs` is a single assignment or push/pop, so a poisoned lock
        // still holds a consistent queue.
        self.jobs.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The next job, or None when the queue is shut down and empty.
    fn next(&self) -> Option<Job> {
        let mut jobs = self.lock();
        loop {
            if let Some(job) = jobs.waiting.pop_front() {
                jobs.running = true;
                return Some(job);
            }
            if jobs.shutdown {
                return None;
            }
            jobs = self.changed.wait(jobs).unwrap_or_else(|e| e.into_inner());
        }
    }

    fn finish(&self, result: Outcome<()>) {
        let mut jobs = self.lock();
        jobs.running = false;
        if let Err(e) = result {
            // As OIDN's setAsyncError: later errors are dropped until a sync takes this one.
            jobs.error.get_or_insert(e);
        }
        drop(jobs);
        self.changed.notify_all();
    }

    fn work(&self) {
        while let Some(job) = self.next() {
            // The job (and the objects it holds) is dropped inside this call, before
            // `finish` tells waiters that the queue moved on.
            let result = catch_unwind(AssertUnwindSafe(job)).unwrap_or_else(|_| {
                Err(Failure::new(TEMC_ERROR_UNKNOWN, "internal error (panic)"))
            });
            self.finish(result);
        }
    }
}

/// One device's FIFO of asynchronous work.
#[derive(Default)]
pub(crate) struct Queue {
    shared: Arc<Shared>,
    worker: Mutex<Option<JoinHandle<()>>>,
}

impl Queue {
    fn worker(&self) -> MutexGuard<'_, Option<JoinHandle<()>>> {
        self.worker.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether the caller is this queue's worker (a job, or a progress monitor it runs),
    /// which must not wait for the queue: it would wait for itself.
    fn on_worker(&self) -> bool {
        let me = std::thread::current().id();
        self.worker()
            .as_ref()
            .is_some_and(|w| w.thread().id() == me)
    }

    /// Queues `job` after everything queued before it; returns at once.
    pub fn push(&self, job: Job) -> Outcome<()> {
        let mut worker = self.worker();
        if worker.is_none() {
            let shared = self.shared.clone();
            let handle = std::thread::Builder::new()
                .name("temc-queue".into())
                .spawn(move || shared.work())
                .map_err(|e| {
                    Failure::new(
                        TEMC_ERROR_OUT_OF_MEMORY,
                        format!("cannot start the device's queue thread: {e}"),
                    )
                })?;
            *worker = Some(handle);
        }
        self.shared.lock().waiting.push_back(job);
        self.shared.changed.notify_all();
        Ok(())
    }

    /// Waits until every job queued so far has finished.
    pub fn wait_idle(&self) {
        if self.on_worker() {
            return;
        }
        let jobs = self.shared.lock();
        let _idle = self
            .shared
            .changed
            .wait_while(jobs, |j| j.running || !j.waiting.is_empty())
            .unwrap_or_else(|e| e.into_inner());
    }

    /// Takes the first error of the jobs finished since the last call.
    pub fn take_error(&self) -> Option<Failure> {
        self.shared.lock().error.take()
    }
}

impl Drop for Queue {
    fn drop(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.changed.notify_all();
        let worker = self.worker().take();
        if let Some(w) = worker {
            // The worker drops the objects its jobs hold; if it dropped the device's last
            // reference, it is the thread running this: it ends by itself after this job.
            if w.thread().id() != std::thread::current().id() {
                let _ = w.join();
            }
        }
    }
}
