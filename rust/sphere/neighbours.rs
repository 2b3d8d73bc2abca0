//! The error sums at the 26 neighbours of a centre in one pass over the points, four points
//! per vector: the inner loop of the descent.

use super::*;

/// The 26 neighbour offsets in units of the step, in a fixed order: x-major, then y, then z,
/// from -1 to +1, skipping the centre. Ties between neighbours go to the first in this order.
pub const NEIGHBOURS: [[i8; 3]; 26] = {
    let mut out = [[0i8; 3]; 26];
    let mut n = 0;
    let mut i = -1i8;
    while i <= 1 {
        let mut j = -1i8;
        while j <= 1 {
            let mut k = -1i8;
            while k <= 1 {
                if !(i == 0 && j == 0 && k == 0) {
                    out[n] = [i, j, k];
                    n += 1;
                }
                k += 1;
            }
            j += 1;
        }
        i += 1;
    }
    out
};

/// Partial sums for the 26 neighbours of one centre.
///
/// For a point with `q = p - c`, `s = |q|² - R²` and `(a, b, c) = 2h q`, the error at the
/// neighbour `c + h (i, j, k)` is `s - (i a + j b + k c) + h² (i² + j² + k²)`. A point whose
/// error keeps one sign over the whole neighbourhood (`|s|` larger than the most the
/// neighbourhood can change it) adds a term that is linear in `(i, j, k)`: such points are
/// summed as moments, and only points near the sphere's surface are evaluated 26 times.
#[derive(Clone, Copy)]
pub(super) struct NeighbourSums {
    direct: [f64; 26],
    // moments of the points of stable sign, each already multiplied by that sign:
    // sum of s, of a, of b, of c, and the count (signed)
    m: [f64; 5],
}

impl NeighbourSums {
    fn zero() -> Self {
        NeighbourSums {
            direct: [0.0; 26],
            m: [0.0; 5],
        }
    }
    fn add(mut self, o: Self) -> Self {
        for t in 0..26 {
            self.direct[t] += o.direct[t];
        }
        for t in 0..5 {
            self.m[t] += o.m[t];
        }
        self
    }
    fn totals(&self, h2: f64) -> [f64; 26] {
        let mut out = [0.0; 26];
        for (t, d) in NEIGHBOURS.iter().enumerate() {
            let (i, j, k) = (d[0] as f64, d[1] as f64, d[2] as f64);
            let n = i * i + j * j + k * k;
            out[t] = self.direct[t] + self.m[0] - i * self.m[1] - j * self.m[2] - k * self.m[3]
                + h2 * n * self.m[4];
        }
        out
    }
}

pub(super) fn neighbour_sums(points: &[[f64; 3]], c: [f64; 3], r2: f64, h: f64) -> [f64; 26] {
    let h2 = h * h;
    let part = |chunk: &[[f64; 3]]| dispatch!(|simd| neighbour_part(simd, chunk, c, r2, h));
    let sums = if points.len() < PARALLEL_FROM {
        part(points)
    } else {
        let parts = points.par_chunks(CHUNK).map(part).collect();
        crate::kernel::in_order(parts, NeighbourSums::zero, NeighbourSums::add)
    };
    sums.totals(h2)
}

/// Points of [`neighbour_part`] examined between two passes over the points near the sphere.
pub(super) const BLOCK: usize = 128;

/// The points near the sphere found in a block, one `[e0, a, b, c]` each: `e0 = |q|² - R²`
/// and `(a, b, c) = 2h q` (see [`NeighbourSums`]). Room for a block and the up to three points
/// a block leaves over for the next.
pub(super) struct Near {
    v: [[f64; 4]; BLOCK + 8],
    n: usize,
}

/// [`NeighbourSums`] of `points` about the centre `c`, four points per vector: points far from
/// the sphere (their error keeps its sign over the whole neighbourhood) add to the moments; the
/// others are set aside and evaluated at all 26 neighbours after each block.
#[inline(always)]
pub(super) fn neighbour_part<S: Simd>(
    s: S,
    points: &[[f64; 3]],
    c: [f64; 3],
    r2: f64,
    h: f64,
) -> NeighbourSums {
    let h2 = h * h;
    let cv = arr3!(|k| s.splat(c[k]));
    let (r2v, h2x2, low, one) = (
        s.splat(r2),
        s.splat(2.0 * h),
        s.splat(-3.0 * h2),
        s.splat(1.0),
    );
    // moments of the points of stable sign, signed: e0, a, b, c, count
    let mut m = [s.zero(); 5];
    let mut direct = [s.zero(); 26];
    let mut near = Near {
        v: [[0.0; 4]; BLOCK + 8],
        n: 0,
    };
    let (groups, rest) = points.as_chunks::<4>();
    for block in groups.chunks(BLOCK / 4) {
        for g in block {
            let x = s.load_xyz(g);
            let q = arr3!(|k| s.sub(x[k], cv[k]));
            let e0 = s.sub(s.fma(q[2], q[2], s.fma(q[1], q[1], s.mul(q[0], q[0]))), r2v);
            let v = [e0, s.mul(h2x2, q[0]), s.mul(h2x2, q[1]), s.mul(h2x2, q[2])];
            let reach = s.add(s.add(s.abs(v[1]), s.abs(v[2])), s.abs(v[3]));
            // positive everywhere in the neighbourhood (h² n >= 0 only adds), or negative
            let pos = s.gt(e0, reach);
            let neg = s.gt(s.sub(low, reach), e0);
            for t in 0..4 {
                m[t] = s.add(m[t], s.sub(s.and(pos, v[t]), s.and(neg, v[t])));
            }
            m[4] = s.add(m[4], s.sub(s.and(pos, one), s.and(neg, one)));
            let unstable = !(s.sign_bits(pos) | s.sign_bits(neg)) & 0xF;
            if unstable != 0 {
                // one point per vector; each written, kept only if near the sphere
                let rows = s.transpose(v);
                for (l, r) in rows.iter().enumerate() {
                    near.v[near.n] = s.to_array(*r);
                    near.n += ((unstable >> l) & 1) as usize;
                }
            }
        }
        near_sums(s, &mut near, h2, &mut direct);
    }
    let mut acc = NeighbourSums::zero();
    for t in 0..5 {
        acc.m[t] = s.sum(m[t]);
    }
    for t in 0..26 {
        acc.direct[t] = s.sum(direct[t]);
    }
    // the points after the last group of four, and what the blocks left over: one at a time
    let mut left: Vec<[f64; 4]> = near.v[..near.n].to_vec();
    for p in rest {
        let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        let e0 = x * x + y * y + z * z - r2;
        let v = [e0, 2.0 * h * x, 2.0 * h * y, 2.0 * h * z];
        let reach = v[1].abs() + v[2].abs() + v[3].abs();
        if e0 > reach {
            for t in 0..4 {
                acc.m[t] += v[t];
            }
            acc.m[4] += 1.0;
        } else if e0 < -reach - 3.0 * h2 {
            for t in 0..4 {
                acc.m[t] -= v[t];
            }
            acc.m[4] -= 1.0;
        } else {
            left.push(v);
        }
    }
    for v in left {
        for (t, d) in NEIGHBOURS.iter().enumerate() {
            let (i, j, k) = (d[0] as f64, d[1] as f64, d[2] as f64);
            let e = v[0] - i * v[1] - j * v[2] - k * v[3] + h2 * (i * i + j * j + k * k);
            acc.direct[t] += e.abs();
        }
    }
    acc
}

/// Adds the errors of the points set aside in `near`, at the 26 neighbours, to `direct`, four
/// points at a time; the up to three left over move to the front of `near`.
#[inline(always)]
pub(super) fn near_sums<S: Simd>(s: S, near: &mut Near, h2: f64, direct: &mut [S::V; 26]) {
    let full = near.n / 4 * 4;
    // one plane of neighbours (i = -1, 0, 1) at a time: its nine sums stay in registers
    near_plane::<S, 0>(s, near, full, h2, direct);
    near_plane::<S, 1>(s, near, full, h2, direct);
    near_plane::<S, 2>(s, near, full, h2, direct);
    near.v.copy_within(full..near.n, 0);
    near.n -= full;
}

/// The sums of [`near_sums`] for the neighbours with `i = I - 1`.
#[inline(always)]
pub(super) fn near_plane<S: Simd, const I: usize>(
    s: S,
    near: &Near,
    full: usize,
    h2: f64,
    direct: &mut [S::V; 26],
) {
    let h2v = s.splat(h2);
    // the plane's sums: index 3 (j + 1) + (k + 1), the centre's slot (4) unused
    let mut acc = [s.zero(); 9];
    let (groups, _) = near.v[..full].as_chunks::<4>();
    for g in groups {
        let [e0, a, b, cc] = s.transpose(g.map(|r| s.vector(r)));
        // e(i, j, k) = e0 - i a - j b - k c + h² (i² + j² + k²), built one axis at a time
        let xi = match I {
            0 => s.add(s.add(e0, h2v), a),
            1 => e0,
            _ => s.sub(s.add(e0, h2v), a),
        };
        let xh = s.add(xi, h2v);
        let ey = [s.add(xh, b), xi, s.sub(xh, b)];
        for (jj, &yj) in ey.iter().enumerate() {
            let yh = s.add(yj, h2v);
            let ez = [s.add(yh, cc), yj, s.sub(yh, cc)];
            for (kk, &e) in ez.iter().enumerate() {
                if I == 1 && jj == 1 && kk == 1 {
                    continue; // the centre
                }
                acc[3 * jj + kk] = s.add(acc[3 * jj + kk], s.abs(e));
            }
        }
    }
    for (m, a) in acc.iter().enumerate() {
        if I == 1 && m == 4 {
            continue;
        }
        let t = 9 * I + m;
        let t = if t > 13 { t - 1 } else { t };
        direct[t] = s.add(direct[t], *a);
    }
}
