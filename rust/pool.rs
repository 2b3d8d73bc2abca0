//! Work shared between the calling thread and the rayon pool.
//!
//! rayon's parallel iterators, called from a thread outside the pool, hand the whole job to
//! the pool and park the caller until it is done: a pool asleep since the last call wakes a
//! thread (tens of microseconds here), and the caller is woken again at the end. A fit runs
//! several passes over its points, each such a call. [`map_indexed`] has the caller compute
//! from the start instead, while the pool's threads join in as they wake; each takes the next
//! index not yet taken. The values come back in index order, so what a caller makes of them
//! does not depend on which thread computed which. [`in_chains`] does the same for chains of
//! tasks that wait for each other, in one job for all of them.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, OnceLock};

/// `[f(0), f(1), ..., f(n - 1)]`, computed by the calling thread and the pool's threads.
pub(crate) fn map_indexed<T: Send + Sync>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let slots: Vec<OnceLock<T>> = (0..n).map(|_| OnceLock::new()).collect();
    let next = AtomicUsize::new(0);
    let work = || loop {
        let i = next.fetch_add(1, Ordering::Relaxed);
        if i >= n {
            break;
        }
        let _ = slots[i].set(f(i));
    };
    rayon::in_place_scope(|scope| {
        for _ in 1..rayon::current_num_threads().min(n) {
            scope.spawn(|_| work());
        }
        work();
    });
    // every index below n was taken once, and its value set before the scope ended (a panic
    // in `f` would have ended it by a panic)
    slots.into_iter().filter_map(OnceLock::into_inner).collect()
}

/// Runs the tasks of several chains on the calling thread and the pool's threads, in one job:
/// chain `c`'s tasks `0..lens[c]` in order, never two of a chain at once, and task `j` of
/// chain `c` only once `ready(c, j, ended)` holds, `ended(c')` being how many tasks of chain
/// `c'` have ended. A thread takes, of the chains whose next task may start and is not
/// running, the one whose task has the lowest `rank(c, j)` (the lower chain on a tie), and
/// waits, spinning and then yielding, while there is none. One job for all the tasks: a
/// rayon job per step parks the caller for each, and the Allan cascade's push, a step per
/// 0.5 ms of work, then ran on about one core in one call of two after the process had been
/// idle for 60 ms or more. And no barrier between steps: with the Allan cascade's tasks in
/// rounds, each round's after every task of the round before, a thread waited for tasks it
/// did not need (3 x 1e6 octave taus, two threads, medians of 25 calls in six interleaved
/// runs: 11.1-12.1 ms in rounds, 9.9-11.1 ms in chains). Unless `parallel`, the calling
/// thread runs every task itself, in the same order of ranks.
///
/// Panics if no task can start while none is running and tasks remain (rules that can
/// never be met).
pub(crate) fn in_chains(
    parallel: bool,
    lens: &[usize],
    ready: &(dyn Fn(usize, usize, &[usize]) -> bool + Sync),
    rank: &(dyn Fn(usize, usize) -> usize + Sync),
    run: &(dyn Fn(usize, usize) + Sync),
) {
    // per chain: whether a task of it is running, and how many of its tasks have ended
    struct State {
        running: Vec<bool>,
        ended: Vec<usize>,
        left: usize,
    }
    let state = Mutex::new(State {
        running: vec![false; lens.len()],
        ended: vec![0; lens.len()],
        left: lens.iter().sum(),
    });
    // marks the task ended even when it panics, so that no thread waits for it for ever
    // (the panic then ends the scope)
    struct Ended<'a>(&'a Mutex<State>, usize);
    impl Drop for Ended<'_> {
        fn drop(&mut self) {
            let mut s = lock(self.0);
            s.running[self.1] = false;
            s.ended[self.1] += 1;
            s.left -= 1;
        }
    }
    let work = || {
        let mut spins = 0u32;
        loop {
            let task = {
                let mut s = lock(&state);
                if s.left == 0 {
                    break;
                }
                let mut best: Option<(usize, usize, usize)> = None;
                for (c, &len) in lens.iter().enumerate() {
                    let j = s.ended[c];
                    if s.running[c] || j >= len || !ready(c, j, &s.ended) {
                        continue;
                    }
                    let r = rank(c, j);
                    if best.is_none_or(|(b, _, _)| r < b) {
                        best = Some((r, c, j));
                    }
                }
                assert!(
                    best.is_some() || s.running.iter().any(|&r| r),
                    "no task of the chains can start"
                );
                if let Some((_, c, _)) = best {
                    s.running[c] = true;
                }
                best
            };
            match task {
                Some((_, c, j)) => {
                    spins = 0;
                    let _ended = Ended(&state, c);
                    run(c, j);
                }
                None if spins < 100 => {
                    std::hint::spin_loop();
                    spins += 1;
                }
                None => std::thread::yield_now(),
            }
        }
    };
    if !parallel {
        return work();
    }
    rayon::in_place_scope(|scope| {
        for _ in 1..rayon::current_num_threads().min(lens.len()) {
            scope.spawn(|_| work());
        }
        work();
    });
}

/// Locks `m`, going on after a panic of the thread that held it (which is then on its way
/// to the caller).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
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

    /// Two chains of a pipeline like the Allan cascade's: chain 1's task `j` reads what
    /// chain 0's task `j` made, and chain 0's task `j` reuses the buffer chain 1's task
    /// `j - 2` read; plus a free chain.
    fn pipeline_rules(c: usize, j: usize, ended: &[usize]) -> bool {
        match c {
            0 => ended[1] + 1 >= j,
            1 => ended[0] > j,
            _ => true,
        }
    }

    #[test]
    fn a_task_starts_only_when_its_rules_allow_and_chains_keep_their_order() {
        let n = 20;
        for threads in [1, 2, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let ended: Vec<AtomicUsize> = (0..3).map(|_| AtomicUsize::new(0)).collect();
            let running: Vec<AtomicUsize> = (0..3).map(|_| AtomicUsize::new(0)).collect();
            let broken = AtomicUsize::new(0);
            pool.install(|| {
                in_chains(
                    true,
                    &[n, n, n],
                    &pipeline_rules,
                    &|c, j| 2 * j + usize::from(c == 1),
                    &|c, j| {
                        let now: Vec<usize> =
                            ended.iter().map(|e| e.load(Ordering::SeqCst)).collect();
                        // in order, alone in its chain, and only when the rules allow
                        let alone = running[c].fetch_add(1, Ordering::SeqCst) == 0;
                        if now[c] != j || !alone || !pipeline_rules(c, j, &now) {
                            broken.fetch_add(1, Ordering::SeqCst);
                        }
                        if j % 3 == c {
                            // some tasks slower than the others
                            std::thread::sleep(std::time::Duration::from_micros(300));
                        }
                        running[c].fetch_sub(1, Ordering::SeqCst);
                        ended[c].fetch_add(1, Ordering::SeqCst);
                    },
                )
            });
            assert_eq!(broken.into_inner(), 0, "{threads} threads");
            assert!(ended.iter().all(|e| e.load(Ordering::SeqCst) == n));
        }
    }

    #[test]
    fn one_thread_runs_the_tasks_in_the_order_of_their_ranks() {
        let want = vec![(0, 0), (1, 0), (0, 1), (1, 1), (0, 2), (1, 2)];
        let run = |parallel: bool| {
            let order = Mutex::new(Vec::new());
            let caller = std::thread::current().id();
            let elsewhere = AtomicUsize::new(0);
            in_chains(
                parallel,
                &[3, 3],
                &pipeline_rules,
                &|c, j| 2 * j + usize::from(c == 1),
                &|c, j| {
                    if std::thread::current().id() != caller {
                        elsewhere.fetch_add(1, Ordering::SeqCst);
                    }
                    order.lock().unwrap().push((c, j));
                },
            );
            (order.into_inner().unwrap(), elsewhere.into_inner())
        };
        // a pool of one thread
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(pool.install(|| run(true)).0, want);
        // not parallel, in a pool of several: the calling thread alone
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        assert_eq!(pool.install(|| run(false)), (want, 0));
    }

    #[test]
    fn rules_that_can_never_be_met_panic_instead_of_hanging() {
        let never = std::panic::catch_unwind(|| {
            in_chains(true, &[2, 2], &|c, _, _| c == 0, &|_, j| j, &|_, _| {});
        });
        assert!(never.is_err());
        // a task that panics ends the call by its panic, with no thread left waiting for it
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            pool.install(|| {
                in_chains(true, &[5, 5], &pipeline_rules, &|_, j| j, &|c, j| {
                    assert!(!(c == 0 && j == 2), "a failing task");
                })
            })
        }));
        assert!(panicked.is_err());
    }
}
