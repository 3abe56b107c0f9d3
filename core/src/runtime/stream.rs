//! Items computed on a worker pool and consumed in order on the calling thread, with a
//! bounded lead: the runtime's layers.
//!
//! Workers take the next index as soon as they are free, so one slow layer holds up
//! only itself (fixed windows of layers waited for their slowest layer before the next
//! window could start, which left a core idle at the end of every window). A worker
//! does not start an index more than `ahead` past the last one consumed, so memory
//! holds at most `ahead` results whatever the pool's speed against the consumer's.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex, mpsc};

use crate::error::{Error, Result};

/// What the workers and the consumer share: the next index to take, how many are
/// consumed (with its condition variable), and whether to stop.
struct Gate {
    next: AtomicUsize,
    consumed: Mutex<usize>,
    moved: Condvar,
    stop: AtomicBool,
}

impl Gate {
    /// Waits until index `i` may start; `false` when the run stops instead.
    fn admit(&self, i: usize, ahead: usize) -> bool {
        let mut consumed = self.consumed.lock().unwrap_or_else(|e| e.into_inner());
        while i >= *consumed + ahead && !self.stop.load(Ordering::Acquire) {
            consumed = self.moved.wait(consumed).unwrap_or_else(|e| e.into_inner());
        }
        !self.stop.load(Ordering::Acquire)
    }

    fn advance(&self, consumed: usize) {
        *self.consumed.lock().unwrap_or_else(|e| e.into_inner()) = consumed;
        self.moved.notify_all();
    }

    fn halt(&self) {
        self.stop.store(true, Ordering::Release);
        // Taken so that no worker sits between its check and its wait.
        drop(self.consumed.lock().unwrap_or_else(|e| e.into_inner()));
        self.moved.notify_all();
    }
}

/// Stops the workers however the consumer leaves (an error, a panic).
struct HaltOnDrop<'a>(&'a Gate);

impl Drop for HaltOnDrop<'_> {
    fn drop(&mut self) {
        self.0.halt();
    }
}

/// Computes `compute(i)` for `i` in `0..count` on every thread of `pool` and hands the
/// results to `consume` in index order on the calling thread, at most `ahead` (at least
/// one) computed before they are consumed. The first error of `consume` stops the
/// workers and is returned; `compute` reports its errors through its result type.
pub fn ordered<T: Send>(
    pool: &rayon::ThreadPool,
    count: usize,
    ahead: usize,
    compute: impl Fn(usize) -> T + Sync,
    mut consume: impl FnMut(usize, T) -> Result<()>,
) -> Result<()> {
    let ahead = ahead.max(1);
    let gate = Gate {
        next: AtomicUsize::new(0),
        consumed: Mutex::new(0),
        moved: Condvar::new(),
        stop: AtomicBool::new(false),
    };
    let (tx, rx) = mpsc::channel::<(usize, T)>();
    std::thread::scope(|scope| -> Result<()> {
        let (gate, compute) = (&gate, &compute);
        let workers = scope.spawn(move || {
            pool.broadcast(|_| {
                let tx = tx.clone();
                loop {
                    let i = gate.next.fetch_add(1, Ordering::Relaxed);
                    if i >= count || !gate.admit(i, ahead) {
                        break;
                    }
                    if tx.send((i, compute(i))).is_err() {
                        break;
                    }
                }
            });
            // `tx` is dropped here: once every worker is done, the receiver ends.
        });
        let halt = HaltOnDrop(gate);
        let mut pending = BTreeMap::new();
        let mut consumed = 0;
        while consumed < count {
            let Ok((i, item)) = rx.recv() else { break };
            pending.insert(i, item);
            while let Some(item) = pending.remove(&consumed) {
                consume(consumed, item)?;
                consumed += 1;
                gate.advance(consumed);
            }
        }
        drop(halt);
        workers
            .join()
            .map_err(|_| Error::stage("runtime", "a worker thread stopped with a panic"))?;
        if consumed < count {
            return Err(Error::stage(
                "runtime",
                format!("the workers stopped after {consumed} of {count} layers"),
            ));
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    }

    #[test]
    fn results_arrive_in_order_with_a_bounded_lead() {
        for threads in [1, 2, 5] {
            let started = AtomicUsize::new(0);
            let mut seen = Vec::new();
            ordered(
                &pool(threads),
                200,
                3,
                |i| {
                    started.fetch_add(1, Ordering::SeqCst);
                    // Uneven work, so that later indices often finish first.
                    std::thread::sleep(std::time::Duration::from_micros(((i * 7919) % 13) as u64 * 50));
                    i * 2
                },
                |i, v| {
                    // Never more than `ahead` started beyond what is consumed.
                    let lead = started.load(Ordering::SeqCst) - i;
                    assert!(lead <= 3 + threads, "lead {lead} at {i}");
                    assert_eq!(v, i * 2);
                    seen.push(i);
                    Ok(())
                },
            )
            .unwrap();
            assert_eq!(seen, (0..200).collect::<Vec<_>>());
        }
    }

    #[test]
    fn a_consumer_error_stops_the_workers() {
        let computed = AtomicUsize::new(0);
        let r = ordered(
            &pool(2),
            10_000,
            4,
            |i| {
                computed.fetch_add(1, Ordering::SeqCst);
                i
            },
            |i, _| {
                if i == 10 {
                    Err(Error::stage("test", "stop"))
                } else {
                    Ok(())
                }
            },
        );
        assert!(r.unwrap_err().to_string().contains("stop"));
        assert!(computed.load(Ordering::SeqCst) < 100);
    }

    #[test]
    fn nothing_to_do_is_done() {
        ordered(&pool(2), 0, 4, |i| i, |_, _| panic!("no item")).unwrap();
    }
}
