//! The edit queue with back-pressure: while one edit computes, a newer move of the same
//! gesture replaces the pending one instead of queueing behind it, so a slow computation
//! never builds a backlog and the edit that runs next is always the newest.
//!
//! Only the queue's last job can absorb a newer one with the same key; jobs of other keys
//! (and keyless jobs: undo, a command) keep their order, so coalescing never reorders edits.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};

/// A job that may absorb a newer job of the same gesture.
pub trait Coalesce: Sized {
    /// The gesture this job belongs to, if it may be coalesced.
    fn key(&self) -> Option<u64>;
    /// Absorb `newer` (same key), which arrived later; give it back if it is of another
    /// kind (it is then queued behind).
    ///
    /// # Errors
    /// `newer` itself when it cannot be absorbed.
    fn absorb(&mut self, newer: Self) -> Result<(), Self>;
}

/// A multi-producer, single-consumer queue that coalesces.
#[derive(Debug)]
pub struct Queue<J> {
    state: Mutex<State<J>>,
    ready: Condvar,
}

#[derive(Debug)]
struct State<J> {
    jobs: VecDeque<J>,
    closed: bool,
    coalesced: u64,
}

impl<J: Coalesce> Default for Queue<J> {
    fn default() -> Self {
        Self::new()
    }
}

impl<J: Coalesce> Queue<J> {
    /// An empty queue.
    #[must_use]
    pub fn new() -> Self {
        Self {
            state: Mutex::new(State {
                jobs: VecDeque::new(),
                closed: false,
                coalesced: 0,
            }),
            ready: Condvar::new(),
        }
    }

    /// Add `job`; if the last pending job has the same key, it absorbs `job` instead.
    pub fn push(&self, job: J) {
        let mut s = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match (job.key(), s.jobs.back_mut()) {
            (Some(k), Some(last)) if last.key() == Some(k) => match last.absorb(job) {
                Ok(()) => s.coalesced += 1,
                Err(job) => s.jobs.push_back(job),
            },
            _ => s.jobs.push_back(job),
        }
        self.ready.notify_one();
    }

    /// The next job, waiting for one; `None` once closed and drained.
    pub fn pop(&self) -> Option<J> {
        let mut s = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            if let Some(j) = s.jobs.pop_front() {
                return Some(j);
            }
            if s.closed {
                return None;
            }
            s = self
                .ready
                .wait(s)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }

    /// Take the first pending job `matches` accepts out of the queue (a job cancelled before
    /// it started), keeping the order of the others.
    pub fn remove(&self, matches: impl Fn(&J) -> bool) -> Option<J> {
        let mut s = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let i = s.jobs.iter().position(matches)?;
        s.jobs.remove(i)
    }

    /// Stop: `pop` returns the remaining jobs, then `None`.
    pub fn close(&self) {
        let mut s = self
            .state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        s.closed = true;
        self.ready.notify_all();
    }

    /// How many jobs were absorbed by a pending one so far.
    #[must_use]
    pub fn coalesced(&self) -> u64 {
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .coalesced
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::time::Duration;

    /// A drag to an absolute position (key: gesture), or a slow keyless edit.
    #[derive(Debug)]
    enum Fake {
        Slow,
        Drag { gesture: u64, to: i64 },
    }

    impl Coalesce for Fake {
        fn key(&self) -> Option<u64> {
            match self {
                Fake::Slow => None,
                Fake::Drag { gesture, .. } => Some(*gesture),
            }
        }
        fn absorb(&mut self, newer: Self) -> Result<(), Self> {
            *self = newer;
            Ok(())
        }
    }

    /// A slow edit is running while 200 drags arrive: the worker runs the slow edit and then
    /// one drag, the last one; nothing queues up.
    #[test]
    fn burst_during_slow_edit_runs_only_the_newest_drag() {
        let q = Arc::new(Queue::new());
        let (started_tx, started_rx) = std::sync::mpsc::channel();
        let worker = {
            let q = Arc::clone(&q);
            std::thread::spawn(move || {
                let mut ran = Vec::new();
                let mut position = 0;
                while let Some(j) = q.pop() {
                    match j {
                        Fake::Slow => {
                            started_tx.send(()).unwrap();
                            std::thread::sleep(Duration::from_millis(150));
                            ran.push("slow");
                        }
                        Fake::Drag { to, .. } => {
                            position = to;
                            ran.push("drag");
                        }
                    }
                }
                (ran, position)
            })
        };
        q.push(Fake::Slow);
        started_rx.recv().unwrap();
        for to in 1..=200 {
            q.push(Fake::Drag { gesture: 9, to });
        }
        q.close();
        let (ran, position) = worker.join().unwrap();
        assert_eq!(ran, ["slow", "drag"]);
        assert_eq!(position, 200);
        assert_eq!(q.coalesced(), 199);
    }

    /// Coalescing never crosses another job: drags before and after an undo both run.
    #[test]
    fn coalescing_keeps_the_order_of_other_jobs() {
        let q = Queue::new();
        q.push(Fake::Drag { gesture: 1, to: 1 });
        q.push(Fake::Drag { gesture: 1, to: 2 });
        q.push(Fake::Slow);
        q.push(Fake::Drag { gesture: 1, to: 3 });
        q.push(Fake::Drag { gesture: 2, to: 4 });
        q.close();
        let mut got = Vec::new();
        while let Some(j) = q.pop() {
            got.push(match j {
                Fake::Slow => -1,
                Fake::Drag { to, .. } => to,
            });
        }
        assert_eq!(got, [2, -1, 3, 4]);
    }

    /// A pending job can be taken out; the others keep their order.
    #[test]
    fn removing_a_pending_job_keeps_the_others_in_order() {
        let q = Queue::new();
        q.push(Fake::Drag { gesture: 1, to: 1 });
        q.push(Fake::Slow);
        q.push(Fake::Drag { gesture: 2, to: 2 });
        q.push(Fake::Drag { gesture: 3, to: 3 });
        let gone = q.remove(|j| matches!(j, Fake::Drag { gesture: 2, .. }));
        assert!(matches!(gone, Some(Fake::Drag { to: 2, .. })));
        assert!(
            q.remove(|j| matches!(j, Fake::Drag { gesture: 9, .. }))
                .is_none()
        );
        q.close();
        let mut got = Vec::new();
        while let Some(j) = q.pop() {
            got.push(match j {
                Fake::Slow => -1,
                Fake::Drag { to, .. } => to,
            });
        }
        assert_eq!(got, [1, -1, 3]);
    }
}
