//! Many data sets at once (a production line: thousands of boards), in parallel with rayon.
//!
//! Each set is fitted on its own with the options given (see `ellipsoid`); the sets run in
//! parallel and each fit runs single-threaded, without the coverage diagnostics (a batch
//! reports no warnings). A bad set yields its own error and does not spoil the others.

use crate::ellipsoid::{fit_ellipsoid, EllipsoidFit, FitOptions};
use crate::error::{CalError, Result};
use rayon::prelude::*;

/// Fits every set in `sets`; the result has one entry per set, in order.
///
/// ```
/// use triaxcal::batch::fit_batch;
/// use triaxcal::ellipsoid::{FitOptions, Model};
/// let good = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
/// let bad = [[f64::NAN, 0.0, 0.0]; 6];
/// let out = fit_batch(&[&good[..], &bad[..]], &FitOptions { model: Model::Sphere, ..Default::default() });
/// assert!(out[0].is_ok() && out[1].is_err());
/// ```
pub fn fit_batch(sets: &[&[[f64; 3]]], opts: &FitOptions) -> Vec<Result<EllipsoidFit>> {
    let inner = FitOptions {
        parallel: false,
        diagnostics: false,
        ..*opts
    };
    let one = |s: &&[[f64; 3]]| {
        std::panic::catch_unwind(|| fit_ellipsoid(s, &inner)).unwrap_or_else(|_| {
            Err(CalError::InvalidArgument(
                "internal error while fitting this set (please report it with the data)".into(),
            ))
        })
    };
    let points: usize = sets.iter().map(|s| s.len()).sum();
    if points <= SEQUENTIAL_POINTS {
        // a few sets: handing them to the thread pool and waiting for it costs more than
        // fitting them on this thread
        return sets.iter().map(one).collect();
    }
    if sets.len() > POOL_SETS {
        // a large batch: the wait for the pool is nothing beside it, and rayon's split into
        // ranges measured faster here (10,000 sets of 200 points: 28.3-28.8 ms, against
        // 29.5-32.0 ms shared as below)
        return sets.par_iter().map(one).collect();
    }
    // the calling thread fits sets from the start, and the pool's threads join in as they
    // wake, each taking the next run of sets not yet taken (runs of a few sets: taken a set
    // at a time, 10,000 sets took 17 % longer)
    let per = (sets.len() / (8 * rayon::current_num_threads())).clamp(1, 64);
    crate::pool::map_chunks(sets, per, |c| c.iter().map(one).collect::<Vec<_>>())
        .into_iter()
        .flatten()
        .collect()
}

/// Batches of more sets than this go to the pool whole (see [`fit_batch`]).
const POOL_SETS: usize = 1_000;

/// Batches of at most this many points in all are fitted on the calling thread alone (a set
/// of 200 points takes about 6 us; a thread of the pool asleep since the last call takes tens
/// of us to wake, and the call waits for it even when the calling thread has fitted every
/// set). Measured with sets of 200 points, median of 41 calls 0.5 ms apart (in a tight loop):
/// 15 sets, 90 us on the calling thread alone, 90-103 us with the pool (54 us); 20 sets,
/// 118 us and 92-99 us (78 us); 10 sets, 64 us and 76-81 us (54 us).
pub const SEQUENTIAL_POINTS: usize = 3_000;

#[cfg(test)]
mod tests {
    use super::*;

    /// 60 points on an ellipsoid with offset `(k, -k, 2k)`.
    fn set(k: usize) -> Vec<[f64; 3]> {
        let k = k as f64;
        let w = nalgebra::Matrix3::new(1.2, 0.05, 0.0, 0.05, 0.9, -0.02, 0.0, -0.02, 1.0);
        crate::ellipsoid::tests::ellipsoid_points([k, -k, 2.0 * k], w, 1.0, 60)
    }

    #[test]
    fn every_path_returns_each_sets_own_fit_in_order() {
        // the calling thread alone (300 points), shared with the pool (3,600), the pool alone
        for count in [5, 60, POOL_SETS + 7] {
            let mut sets: Vec<Vec<[f64; 3]>> = (0..count).map(set).collect();
            sets[3][0][1] = f64::NAN;
            let refs: Vec<&[[f64; 3]]> = sets.iter().map(|s| &s[..]).collect();
            let opts = FitOptions::default();
            let out = fit_batch(&refs, &opts);
            assert_eq!(out.len(), count);
            let inner = FitOptions {
                parallel: false,
                diagnostics: false,
                ..opts
            };
            for (k, got) in out.iter().enumerate() {
                if k == 3 {
                    assert!(got.is_err(), "{count}: set 3 has a NaN");
                    continue;
                }
                let want = fit_ellipsoid(&sets[k], &inner).unwrap();
                let got = got.as_ref().unwrap();
                assert_eq!(got.offset, want.offset, "{count}: set {k}");
                assert_eq!(got.matrix, want.matrix, "{count}: set {k}");
            }
        }
    }
}
