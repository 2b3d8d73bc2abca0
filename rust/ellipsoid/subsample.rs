//! The subsample a large input is solved on first, and the larger curvature sample of
//! [`super::refine::polish_once`]: they depend on the set of points, not on their order.

/// The hash below which a point is taken into a subsample of about `size` of `n` points.
pub(super) fn hash_cut(size: usize, n: usize) -> u64 {
    ((size as f64 / n as f64) * 18_446_744_073_709_551_616.0) as u64
}

/// A subsample of about `size` points that depends only on the *set* of points, not on their
/// order: a point is taken when a hash of its coordinates falls below [`hash_cut`] (`picked`:
/// those points, taken in the scan of [`fit_ellipsoid`], in their order). Heavily repeated
/// data (few distinct values: a tiled pattern) would give a few values many times over; then
/// one point is drawn at a fixed pseudo-random position inside each of `size` equal blocks
/// instead (no period in the data can line up with that pick). The second value says whether
/// the points were taken by their hash.
pub(super) fn subsample(
    points: &[[f64; 3]],
    size: usize,
    picked: Vec<[f64; 3]>,
) -> (Vec<[f64; 3]>, bool) {
    let n = points.len();
    if distinct_at_least(&picked, MIN_DISTINCT.min(size / 2)) && picked.len() >= size / 2 {
        return (picked, true);
    }
    let nb = size.min(n).max(1);
    let blocks = (0..nb)
        .map(|b| {
            let lo = b * n / nb;
            let hi = (b + 1) * n / nb;
            let r = splitmix64(b as u64 ^ 0x7472_6961_7863_616c) % (hi - lo) as u64;
            points[lo + r as usize]
        })
        .collect();
    (blocks, false)
}

/// A subsample by content needs at least this many distinct points (else it is drawn by
/// position, see [`subsample`]).
pub(super) const MIN_DISTINCT: usize = 2000;

/// A hash of a point's bits (multiplicative hashing, twice: the high bits depend on all the
/// bits of all three coordinates).
#[inline(always)]
pub(super) fn point_hash(p: &[f64; 3]) -> u64 {
    let h = p[0].to_bits() ^ p[1].to_bits().rotate_left(21) ^ p[2].to_bits().rotate_left(42);
    let h = h.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    (h ^ (h >> 32)).wrapping_mul(0xd6e8_feb8_6659_fd93)
}

/// Calls `f(p, point_hash(p))` for each point `p` of `points` (in order) whose hash is below
/// `cut`: the hashes of four points at a time, then one test for all four (most groups have
/// no point below the cut, and a test per point was a branch per point).
pub(super) fn below_cut(points: &[[f64; 3]], cut: u64, mut f: impl FnMut(&[f64; 3], u64)) {
    let (groups, rest) = points.as_chunks::<4>();
    for g in groups {
        let h: [u64; 4] = std::array::from_fn(|j| point_hash(&g[j]));
        if h.iter().any(|&hj| hj < cut) {
            for (p, hj) in g.iter().zip(h) {
                if hj < cut {
                    f(p, hj);
                }
            }
        }
    }
    for p in rest {
        let h = point_hash(p);
        if h < cut {
            f(p, h);
        }
    }
}

/// Whether `points` hold at least `want` distinct values, estimated by linear counting over a
/// 65,536-bit map of their hashes (exact enough for the few thousand this is asked about).
pub(super) fn distinct_at_least(points: &[[f64; 3]], want: usize) -> bool {
    const BITS: usize = 1 << 16;
    let mut map = vec![0u64; BITS / 64];
    for p in points {
        let h = (point_hash(p) >> 16) as usize & (BITS - 1);
        map[h / 64] |= 1 << (h % 64);
    }
    let empty = BITS - map.iter().map(|w| w.count_ones() as usize).sum::<usize>();
    let estimate = if empty == 0 {
        f64::INFINITY
    } else {
        -(BITS as f64) * (empty as f64 / BITS as f64).ln()
    };
    estimate >= want as f64
}

/// SplitMix64: a well-mixed 64-bit hash of `x`.
#[inline(always)]
pub(super) fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}
