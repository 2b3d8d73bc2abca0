//! Work shared between the calling thread and the rayon pool.
//!
//! rayon's parallel iterators, called from a thread outside the pool, hand the whole job to
//! the pool and park the caller until it is done: a pool asleep since the last call wakes a
//! thread (tens of microseconds here), and the caller is woken again at the end. A fit runs
//! several passes over its points, each such a call. [`map_indexed`] has the caller compute
//! from the start instead, while the pool's threads join in as they wake; each takes the next
//! index not yet taken. The values come back in index order, so what a caller makes of them
//! does not depend on which thread computed which. [`in_rounds`] does the same for work in
//! rounds, each round's tasks after the round before, in one job for all of them.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

/// `[f(0), f(1), ..., f(n - 1)]`, computed by the calling thread and the pool's threads.
pub(crate) fn map_indexed<T: Send + Sync>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let slots: Vec<OnceLock<T>> = (0..n).map(|_| OnceLock::new()).collect();
    in_rounds(1, n, &|_, i| {
        let _ = slots[i].set(f(i));
    });
    // every index below n was taken once, and its value set before the rounds ended (a panic
    // in `f` would have ended them by a panic)
    slots.into_iter().filter_map(OnceLock::into_inner).collect()
}

/// Runs `run(g, i)` for every task `i < per` of every round `g < rounds`, on the calling
/// thread and the pool's threads: each takes the next task not yet taken, and a task of round
/// `g` starts when every task of round `g - 1` has ended (a thread that takes one early
/// waits, spinning, for them). One job for all the rounds: a rayon job per round parks the
/// caller for each, and the Allan cascade's push, a round per 0.5 ms of work, ran on about
/// one core in one call of two after the process had been idle for 60 ms or more (3 x 1e6
/// octave taus: 25-35 ms, with as much CPU time as wall time, against 13-17 ms right after
/// another call).
pub(crate) fn in_rounds(rounds: usize, per: usize, run: &(dyn Fn(usize, usize) + Sync)) {
    let total = rounds * per;
    let next = AtomicUsize::new(0);
    let done: Vec<AtomicUsize> = (0..rounds).map(|_| AtomicUsize::new(0)).collect();
    // counted as ended even when it panics, so that no thread waits for it for ever (the
    // panic then ends the scope)
    struct Ended<'a>(&'a AtomicUsize);
    impl Drop for Ended<'_> {
        fn drop(&mut self) {
            self.0.fetch_add(1, Ordering::Release);
        }
    }
    let work = || loop {
        let t = next.fetch_add(1, Ordering::Relaxed);
        if t >= total {
            break;
        }
        let (g, i) = (t / per, t % per);
        if g > 0 {
            // every task of the round before was taken before this one: wait for them to end
            let mut spins = 0u32;
            while done[g - 1].load(Ordering::Acquire) < per {
                if spins < 100 {
                    std::hint::spin_loop();
                    spins += 1;
                } else {
                    std::thread::yield_now();
                }
            }
        }
        let _ended = Ended(&done[g]);
        run(g, i);
    };
    rayon::in_place_scope(|scope| {
        for _ in 1..rayon::current_num_threads().min(per) {
            scope.spawn(|_| work());
        }
        work();
    });
}

/// `f` of each chunk of `chunk` items of `items` (the last may be shorter), in order; see
/// [`map_indexed`].
pub(crate) fn map_chunks<U: Sync, T: Send + Sync>(
    items: &[U],
    chunk: usize,
    f: impl Fn(&[U]) -> T + Sync,
) -> Vec<T> {
    let chunk = chunk.max(1);
    map_indexed(items.len().div_ceil(chunk), |i| {
        f(&items[i * chunk..((i + 1) * chunk).min(items.len())])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_come_back_in_order_whatever_thread_made_them() {
        let items: Vec<u64> = (0..10_007).collect();
        let sums = map_chunks(&items, 100, |c| c.iter().sum::<u64>());
        assert_eq!(sums.len(), 101);
        let want: Vec<u64> = items.chunks(100).map(|c| c.iter().sum()).collect();
        assert_eq!(sums, want);
        assert!(map_indexed(0, |i| i).is_empty());
        assert_eq!(map_indexed(1, |i| i + 5), vec![5]);
    }

    #[test]
    fn a_round_starts_when_the_round_before_has_ended() {
        let (rounds, per) = (30, 4);
        for threads in [1, 2, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let ended: Vec<AtomicUsize> = (0..rounds).map(|_| AtomicUsize::new(0)).collect();
            let early = AtomicUsize::new(0);
            pool.install(|| {
                in_rounds(rounds, per, &|g, i| {
                    if g > 0 && ended[g - 1].load(Ordering::SeqCst) != per {
                        early.fetch_add(1, Ordering::SeqCst);
                    }
                    if i == 0 {
                        // the first task of a round is the slowest: the others end first
                        std::thread::sleep(std::time::Duration::from_micros(300));
                    }
                    ended[g].fetch_add(1, Ordering::SeqCst);
                })
            });
            assert_eq!(early.into_inner(), 0, "{threads} threads");
            assert!(ended.iter().all(|e| e.load(Ordering::SeqCst) == per));
        }
    }
}
