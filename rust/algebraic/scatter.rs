//! The scatter matrix `Σ d dᵀ` of the design rows `d = [x², y², z², 2xy, 2xz, 2yz, 2x, 2y, 2z,
//! 1]` (or `[x², y², z², 2x, 2y, 2z, 1]` for the axis-aligned quadric) of the normalised points.
//!
//! Each entry `d_a d_b` is a small integer times a monomial `xᵃ yᵇ zᶜ` of degree at most 4, and
//! the 55 entries of the 10 x 10 matrix are only 35 distinct moments `Σ xᵃ yᵇ zᶜ` (15 of degree
//! 4, 10 of degree 3, 6 of degree 2, 3 of degree 1 and the count; the 7 x 7 one needs 24 of
//! them). So the pass over the points sums the moments, each one fused multiply-add of two
//! lower-degree monomials a point, and the matrix is spelt out from them once at the end
//! ([`expand`]): about half the per-point work of summing the 55 products `d_a d_b`.

use super::Norm;
use crate::kernel::LANES;
use crate::simd::{arr3, dispatch, Simd};
use nalgebra::SMatrix;

/// `Σ d dᵀ` over the design rows `d` of the normalised points (`M` = 10 or 7).
pub(super) fn scatter<const M: usize>(
    points: &[[f64; 3]],
    norm: Norm,
    parallel: bool,
) -> SMatrix<f64, M, M> {
    let part = |c: &[[f64; 3]]| dispatch!(|simd| moments::<_, M>(simd, c, norm));
    let sums = if parallel && points.len() > crate::kernel::PARALLEL_ABOVE {
        let parts = crate::pool::map_chunks(points, crate::kernel::CHUNK, part);
        crate::kernel::in_order(
            parts,
            || [0.0; MOMENTS],
            |a, b| std::array::from_fn(|i| a[i] + b[i]),
        )
    } else {
        part(points)
    };
    expand::<M>(&sums, points.len() as f64)
}

/// The moments summed per point: degree 1 (3), 2 (6), 3 (10) and 4 (15), in that order. The
/// count needs no sum: it is the number of points.
const MOMENTS: usize = 34;

/// Exponents of the squares and products of the coordinates, in the order of the summed
/// degree-2 moments: `xx, yy, zz, xy, xz, yz`. The squares come first because the axis-aligned
/// quadric needs the products only as degree-2 moments.
const E2: [[usize; 3]; 6] = [
    [2, 0, 0],
    [0, 2, 0],
    [0, 0, 2],
    [1, 1, 0],
    [1, 0, 1],
    [0, 1, 1],
];

/// The degree-3 moments as (degree-2 monomial, coordinate) pairs: every one has a square
/// factor except `xyz` (which only the full quadric needs).
const P3: [(usize, usize); 10] = [
    (0, 0),
    (0, 1),
    (0, 2),
    (1, 0),
    (1, 1),
    (1, 2),
    (2, 0),
    (2, 1),
    (2, 2),
    (3, 2),
];

/// The degree-4 moments as (square, degree-2 monomial) pairs, by square: those of `xx` and `yy`
/// (11) are summed in one sweep and those of `zz` (4) in another, so that the accumulators and
/// the loaded squares fit in the 16 vector registers. The axis-aligned quadric needs only
/// square x square.
const P4: [(usize, usize); 15] = [
    (0, 0),
    (0, 1),
    (0, 2),
    (0, 3),
    (0, 4),
    (0, 5),
    (1, 1),
    (1, 2),
    (1, 3),
    (1, 4),
    (1, 5),
    (2, 2),
    (2, 3),
    (2, 4),
    (2, 5),
];

/// Where the degree-4 moments of `zz` start in [`P4`].
const P4_ZZ: usize = 11;

/// The design rows as (exponents, factor): `d_a = factor · xᵃ yᵇ zᶜ`.
const fn design_rows<const M: usize>() -> [([usize; 3], f64); M] {
    let mut rows = [([0; 3], 1.0); M];
    let mut k = 0;
    while k < 3 {
        rows[k].0[k] = 2; // x², y², z²
        rows[M - 4 + k].0[k] = 1; // 2x, 2y, 2z
        rows[M - 4 + k].1 = 2.0;
        k += 1;
    }
    if M == 10 {
        rows[3] = ([1, 1, 0], 2.0);
        rows[4] = ([1, 0, 1], 2.0);
        rows[5] = ([0, 1, 1], 2.0);
    }
    rows
}

/// Exponents of the moment summed at each index of the sums (see [`MOMENTS`]), then of the
/// count (index [`MOMENTS`]).
const fn exponents() -> [[usize; 3]; MOMENTS + 1] {
    let mut e = [[0; 3]; MOMENTS + 1];
    let mut k = 0;
    while k < 3 {
        e[k][k] = 1;
        k += 1;
    }
    let mut t = 0;
    while t < 6 {
        e[3 + t] = E2[t];
        t += 1;
    }
    t = 0;
    while t < 10 {
        let (i, k) = P3[t];
        e[9 + t] = E2[i];
        e[9 + t][k] += 1;
        t += 1;
    }
    t = 0;
    while t < 15 {
        let (i, j) = P4[t];
        let mut k = 0;
        while k < 3 {
            e[19 + t][k] = E2[i][k] + E2[j][k];
            k += 1;
        }
        t += 1;
    }
    e
}

/// For each entry of the scatter matrix, the index of its moment (see [`exponents`]) and the
/// product of the two rows' factors: worked out at compile time, so that spelling out the
/// matrix is a multiply per entry.
const fn layout<const M: usize>() -> [[(usize, f64); M]; M] {
    let rows = design_rows::<M>();
    let e = exponents();
    let mut out = [[(0, 0.0); M]; M];
    let mut a = 0;
    while a < M {
        let mut b = 0;
        while b < M {
            let (ea, fa) = rows[a];
            let (eb, fb) = rows[b];
            let mut i = 0;
            while !(e[i][0] == ea[0] + eb[0]
                && e[i][1] == ea[1] + eb[1]
                && e[i][2] == ea[2] + eb[2])
            {
                i += 1; // out of bounds (a compile error) if a moment were missing
            }
            out[a][b] = (i, fa * fb);
            b += 1;
        }
        a += 1;
    }
    out
}

/// The scatter matrix from the moment sums and the count.
fn expand<const M: usize>(sums: &[f64; MOMENTS], count: f64) -> SMatrix<f64, M, M> {
    let layout = const { layout::<M>() };
    let value = |i: usize| if i < MOMENTS { sums[i] } else { count };
    SMatrix::<f64, M, M>::from_fn(|a, b| {
        let (i, f) = layout[a][b];
        f * value(i)
    })
}

/// Groups of [`LANES`] points per block. A block is swept once per set of moments that fits in
/// the registers: the first sweep normalises its points and keeps them, their squares and
/// products in a stack buffer (9 vectors a group), and the later sweeps read them while their
/// moments' accumulators stay in registers. The 34 accumulators do not fit in 16 registers, and
/// accumulators in memory would cost a load and a store per update; a block spreads one load
/// and store of each over 8 groups. (Longer blocks save little more, and the buffer must be
/// zeroed once per call.)
const BLOCK: usize = 8;

/// The per-point moment sums (see [`MOMENTS`]) of the normalised points, lanes not yet added.
struct Sums<S: Simd> {
    d1: [S::V; 3],
    d2: [S::V; 6],
    d3: [S::V; 10],
    d4: [S::V; 15],
}

/// The first sweep for one group `x`: its normalised coordinates into `q`, their squares and
/// products into `m2` (the squares only for the axis-aligned quadric), and the degree-1 and
/// degree-2 sums.
#[inline(always)]
fn first<S: Simd, const M: usize>(
    s: S,
    x: [S::V; 3],
    mean: &[S::V; 3],
    inv: S::V,
    q: &mut [S::V; 3],
    m2: &mut [S::V; 6],
    d1: &mut [S::V; 3],
    d2: &mut [S::V; 6],
) {
    let v = arr3!(|k| s.mul(s.sub(x[k], mean[k]), inv));
    for k in 0..3 {
        d1[k] = s.add(d1[k], v[k]);
        m2[k] = s.mul(v[k], v[k]);
        d2[k] = s.add(d2[k], m2[k]);
    }
    let pairs = [(0, 1), (0, 2), (1, 2)];
    for (t, &(i, j)) in pairs.iter().enumerate() {
        if M == 10 {
            m2[3 + t] = s.mul(v[i], v[j]);
            d2[3 + t] = s.add(d2[3 + t], m2[3 + t]);
        } else {
            d2[3 + t] = s.fma(v[i], v[j], d2[3 + t]);
        }
    }
    *q = v;
}

/// Adds the moments of the `G` groups `groups` to `sums`.
#[inline(always)]
fn block<S: Simd, const M: usize, const G: usize>(
    s: S,
    groups: &[[[f64; 3]; LANES]; G],
    mean: &[S::V; 3],
    inv: S::V,
    q: &mut [[S::V; 3]; BLOCK],
    m2: &mut [[S::V; 6]; BLOCK],
    sums: &mut Sums<S>,
) {
    let full = M == 10;
    let (mut d1, mut d2) = (sums.d1, sums.d2);
    // a loop, not unrolled: unrolled, the compiler hoists the loads of all the groups and
    // spills them
    for g in 0..G {
        let x = s.load_xyz(&groups[g]);
        first::<S, M>(s, x, mean, inv, &mut q[g], &mut m2[g], &mut d1, &mut d2);
    }
    (sums.d1, sums.d2) = (d1, d2);
    // The sums wait in memory between the sweeps (a load and a store each per block), so that
    // each sweep has the registers for its own; left to itself the compiler keeps some of
    // another sweep's sums in registers and spills the current ones instead.
    std::hint::black_box(&mut *sums);
    let mut d3 = sums.d3;
    for g in 0..G {
        for (t, &(i, k)) in P3.iter().enumerate() {
            if full || i < 3 {
                d3[t] = s.fma(m2[g][i], q[g][k], d3[t]);
            }
        }
    }
    sums.d3 = d3;
    std::hint::black_box(&mut *sums);
    // the axis-aligned quadric's 6 (square x square) fit in one sweep
    let split = if full { P4_ZZ } else { P4.len() };
    let mut d4 = sums.d4;
    for g in 0..G {
        for (t, &(i, j)) in P4[..split].iter().enumerate() {
            if full || j < 3 {
                d4[t] = s.fma(m2[g][i], m2[g][j], d4[t]);
            }
        }
    }
    sums.d4 = d4;
    if full {
        std::hint::black_box(&mut *sums);
        let mut d4 = sums.d4;
        for g in 0..G {
            for (t, &(i, j)) in P4.iter().enumerate().skip(P4_ZZ) {
                d4[t] = s.fma(m2[g][i], m2[g][j], d4[t]);
            }
        }
        sums.d4 = d4;
    }
    std::hint::black_box(&mut *sums);
}

/// The moment sums (see [`MOMENTS`]) of the normalised points.
#[inline(always)]
fn moments<S: Simd, const M: usize>(s: S, points: &[[f64; 3]], norm: Norm) -> [f64; MOMENTS] {
    let mean = arr3!(|k| s.splat(norm.mean[k]));
    let inv = s.splat(norm.inv_scale);
    let mut sums = Sums::<S> {
        d1: [s.zero(); 3],
        d2: [s.zero(); 6],
        d3: [s.zero(); 10],
        d4: [s.zero(); 15],
    };
    // the block's normalised points, squares and products: zeroed once per call
    let mut q = [[s.zero(); 3]; BLOCK];
    let mut m2 = [[s.zero(); 6]; BLOCK];
    let (blocks, rest) = points.as_chunks::<{ LANES * BLOCK }>();
    for b in blocks {
        let (groups, _) = b.as_chunks::<LANES>();
        let groups: &[[[f64; 3]; LANES]; BLOCK] = groups.try_into().unwrap();
        block::<S, M, BLOCK>(s, groups, &mean, inv, &mut q, &mut m2, &mut sums);
    }
    if !rest.is_empty() {
        // the last < 32 points, padded with the mean: that normalises to exactly 0, which adds
        // nothing to any moment (the count is the number of points, not a sum), so no weights
        let mut pad = [[norm.mean[0], norm.mean[1], norm.mean[2]]; LANES * BLOCK];
        pad[..rest.len()].copy_from_slice(rest);
        let (groups, _) = pad.as_chunks::<LANES>();
        let mut left = groups[..rest.len().div_ceil(LANES)].as_ref();
        // in blocks of 4, 2 and 1 groups: each block loads and stores every accumulator once
        while let Some((g, tail)) = left.split_first_chunk::<4>() {
            block::<S, M, 4>(s, g, &mean, inv, &mut q, &mut m2, &mut sums);
            left = tail;
        }
        if let Some((g, tail)) = left.split_first_chunk::<2>() {
            block::<S, M, 2>(s, g, &mean, inv, &mut q, &mut m2, &mut sums);
            left = tail;
        }
        if let Some((g, _)) = left.split_first_chunk::<1>() {
            block::<S, M, 1>(s, g, &mean, inv, &mut q, &mut m2, &mut sums);
        }
    }
    // the lanes of four sums at a time: one transpose and three adds (each sum added in the
    // order of `Simd::sum`), where a sum at a time, written as a chain of iterators, cost ~20
    let mut all = [s.zero(); MOMENTS + 2];
    all[..3].copy_from_slice(&sums.d1);
    all[3..9].copy_from_slice(&sums.d2);
    all[9..19].copy_from_slice(&sums.d3);
    all[19..MOMENTS].copy_from_slice(&sums.d4);
    let mut out = [0.0; MOMENTS + 2];
    for (o, v) in out.chunks_exact_mut(LANES).zip(all.chunks_exact(LANES)) {
        let t = s.transpose([v[0], v[1], v[2], v[3]]);
        o.copy_from_slice(&s.to_array(s.add(s.add(t[0], t[1]), s.add(t[2], t[3]))));
    }
    std::array::from_fn(|i| out[i])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::Portable;
    use nalgebra::Vector3;

    /// xorshift64*: uniform numbers in [0, 1).
    fn uniform(state: &mut u64) -> f64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// `Σ d dᵀ` summed row by row in plain scalar code, and `Σ |d| |d|ᵀ` (the size of the
    /// round-off to allow for each entry).
    fn reference<const M: usize>(
        points: &[[f64; 3]],
        norm: Norm,
    ) -> ([[f64; M]; M], [[f64; M]; M]) {
        let (mut s, mut a) = ([[0.0; M]; M], [[0.0; M]; M]);
        for p in points {
            let q: [f64; 3] = std::array::from_fn(|k| (p[k] - norm.mean[k]) * norm.inv_scale);
            let d: [f64; M] = std::array::from_fn(|i| {
                let (e, f) = design_rows::<M>()[i];
                f * q[0].powi(e[0] as i32) * q[1].powi(e[1] as i32) * q[2].powi(e[2] as i32)
            });
            for i in 0..M {
                for j in 0..M {
                    s[i][j] += d[i] * d[j];
                    a[i][j] += (d[i] * d[j]).abs();
                }
            }
        }
        (s, a)
    }

    fn check<const M: usize>(n: usize, seed: u64) {
        let mut state = 0x9e37_79b9_7f4a_7c15 ^ seed;
        // an offset far from the origin and unequal axes, as raw sensor readings
        let points: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                let u: [f64; 3] = std::array::from_fn(|_| 2.0 * uniform(&mut state) - 1.0);
                [
                    400.0 + 16000.0 * u[0],
                    -230.0 + 17000.0 * u[1],
                    97.0 + 15000.0 * u[2],
                ]
            })
            .collect();
        let norm = Norm {
            mean: Vector3::new(350.0, -200.0, 120.0),
            inv_scale: 1.0 / 16000.0,
        };
        let (want, size) = reference::<M>(&points, norm);
        let portable = expand::<M>(&moments::<_, M>(Portable, &points, norm), n as f64);
        for (name, got) in [
            ("dispatched", scatter::<M>(&points, norm, true)),
            ("portable", portable),
        ] {
            for i in 0..M {
                for j in 0..M {
                    let err = (got[(i, j)] - want[i][j]).abs();
                    assert!(
                        err <= 1e-14 * size[i][j] + 1e-300,
                        "{name} M={M} n={n} ({i}, {j}): {} vs {}",
                        got[(i, j)],
                        want[i][j]
                    );
                }
            }
        }
    }

    #[test]
    fn scatter_matches_the_scalar_sum_of_the_design_rows() {
        // empty, a partial group alone, around the group (4) and block (128) sizes, and above
        // the parallel split
        let sizes = [
            0, 1, 3, 4, 5, 7, 8, 13, 28, 31, 32, 33, 63, 64, 65, 200, 1001,
        ];
        for (seed, &n) in sizes.iter().enumerate() {
            check::<10>(n, seed as u64);
            check::<7>(n, seed as u64);
        }
        let big = crate::kernel::PARALLEL_ABOVE + 4 * crate::kernel::CHUNK + 7;
        check::<10>(big, 99);
        check::<7>(big, 98);
    }
}
