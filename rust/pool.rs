//! Work shared between the calling thread and the rayon pool.
//!
//! rayon's parallel iterators, called from a thread outside the pool, hand the whole job to
//! the pool and park the caller until it is done: a pool asleep since the last call wakes a
//! thread (tens of microseconds here), and the caller is woken again at the end. A fit runs
//! several passes over its points, each such a call. [`map_indexed`] has the caller compute
//! from the start instead, while the pool's threads join in as they wake; each takes the next
//! index not yet taken. The values come back in index order, so what a caller makes of them
//! does not depend on which thread computed which.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

/// `[f(0), f(1), ..., f(n - 1)]`, computed by the calling thread and the pool's threads.
pub(crate) fn map_indexed<T: Send + Sync>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let slots: Vec<OnceLock<T>> = (0..n).map(|_| OnceLock::new()).collect();
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
    // in `f` would have ended the scope by a panic)
    slots.into_iter().filter_map(OnceLock::into_inner).collect()
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
}
