//! The streaming passes of the geometric ellipsoid fit: per point, the residual and its
//! Jacobian row, summed into `JᵀJ`, `Jᵀr` and a few scalars; optionally the coverage of the
//! sphere by the calibrated directions.
//!
//! Notation (see `ellipsoid` for the model): normalised point `q = (p - mean) / scale`,
//! `u = q - offset`, `v = W u`, `n = ‖v‖`. The plain residual is `r₀ = n - 1`; the noise-bias
//! direction is `c = tr W² + ûᵀW²û` with `ûᵀW²û = ‖W v‖² / n²`. The debiased residual of the
//! fit is `r = r₀ - h c` (`h = σ²/2`), and because `h` enters linearly, one pass that sums
//! `Jᵀr₀`, `Jᵀc`, `Σ r₀²`, `Σ r₀ c`, `Σ c²` gives `Jᵀr` and `Σ r²` for *any* `h` afterwards:
//! the noise level can be estimated from the same pass that uses it.
//!
//! Jacobian row, labelled by parameter (W symmetric):
//! - `offset_*`: `-(W v)ᵀ / n`
//! - `k` (sphere): `v·u / n`
//! - `diag_a`: `v_a u_a / n`
//! - `offdiag_ab`: `(v_a u_b + v_b u_a) / n`
//!
//! The model follows from the number of parameters `P` (4 sphere, 6 axis, 9 full). Points go
//! through in groups of [`LANES`] as structure-of-arrays temporaries with per-lane
//! accumulators, which the compiler turns into SIMD arithmetic. Multiply-adds go through
//! [`Arith`]: the AVX2 build (see `simd`) uses fused multiply-adds, the portable build plain
//! ones (so that it never calls a software `fma`).

use crate::simd::{arr3, dispatch, Simd};

/// Points per group (one AVX2 register of doubles per quantity).
pub(crate) const LANES: usize = 4;

/// Points per rayon task.
pub(crate) const CHUNK: usize = 4096;

/// A pass runs on several threads only above this many points: below it, the cost of waking
/// the pool exceeds the gain.
pub(crate) const PARALLEL_ABOVE: usize = 3 * CHUNK;

/// Adds per-chunk results `parts` (in the order of their chunks) in an order fixed whatever
/// the number of threads that computed them: halves, quarters and eighths of the chunks, each
/// eighth summed left to right from zero, then pairwise back up. That is the tree rayon's
/// `reduce` (and `sum`) takes on a pool of one thread called from outside it, so results are
/// those of a one-thread pool; on more threads its tree follows the work stealing, and float
/// sums differed in the last bits from one run of the same fit to the next.
pub(crate) fn in_order<T>(parts: Vec<T>, zero: impl Fn() -> T, add: impl Fn(T, T) -> T) -> T {
    fn tree<T>(
        parts: &mut std::vec::IntoIter<T>,
        len: usize,
        depth: u32,
        zero: &impl Fn() -> T,
        add: &impl Fn(T, T) -> T,
    ) -> T {
        if depth == 0 || len < 2 {
            return parts.by_ref().take(len).fold(zero(), add);
        }
        let mid = len / 2;
        let left = tree(parts, mid, depth - 1, zero, add);
        let right = tree(parts, len - mid, depth - 1, zero, add);
        add(left, right)
    }
    let len = parts.len();
    tree(&mut parts.into_iter(), len, 3, &zero, &add)
}

/// The fixed inputs of one pass.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Setup {
    /// Mean subtracted from the points.
    pub mean: [f64; 3],
    /// Multiplies `p - mean`.
    pub inv_scale: f64,
    /// Offset, normalised coordinates.
    pub offset: [f64; 3],
    /// `W`, symmetric, normalised coordinates.
    pub w: [[f64; 3]; 3],
    /// `tr W²`.
    pub trw2: f64,
}

/// What a pass sums. A pass that wants the coverage and neither `JᵀJ` nor the noise sums is a
/// coverage-only pass: its `Jᵀr₀`, `Σ r₀²` and `Σ ûᵀW²û` stay zero.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) struct Want {
    /// `JᵀJ` (the expensive part: `P(P+1)/2` multiply-adds per point).
    pub jtj: bool,
    /// `Jᵀc`, `Σ r₀c`, `Σ c²` (needed when the residual is debiased).
    pub debias: bool,
    /// Coverage: `Σ d dᵀ` of the unit directions `d = v / n` and face counts.
    pub coverage: bool,
}

/// Sums over the points of one pass (upper triangle of `jtj`; unused parts stay zero).
#[derive(Clone, Debug)]
pub(crate) struct Sums<const P: usize> {
    pub jtj: [[f64; P]; P],
    pub jtr0: [f64; P],
    pub jtc: [f64; P],
    pub r0r0: f64,
    pub r0c: f64,
    pub cc: f64,
    /// `Σ ûᵀW²û`: the noise variance estimate is `Σ r² / wq`.
    pub wq: f64,
    /// `Σ d dᵀ` of unit directions: xx yy zz xy xz yz.
    pub dd: [f64; 6],
    /// Directions closest to +X, -X, +Y, -Y, +Z, -Z.
    pub faces: [f64; 6],
    /// Points counted (a zero-length `v` has no direction).
    pub count: f64,
}

impl<const P: usize> Sums<P> {
    pub(crate) fn zero() -> Self {
        Sums {
            jtj: [[0.0; P]; P],
            jtr0: [0.0; P],
            jtc: [0.0; P],
            r0r0: 0.0,
            r0c: 0.0,
            cc: 0.0,
            wq: 0.0,
            dd: [0.0; 6],
            faces: [0.0; 6],
            count: 0.0,
        }
    }

    fn add(mut self, o: Self) -> Self {
        for i in 0..P {
            for j in i..P {
                self.jtj[i][j] += o.jtj[i][j];
            }
            self.jtr0[i] += o.jtr0[i];
            self.jtc[i] += o.jtc[i];
        }
        self.r0r0 += o.r0r0;
        self.r0c += o.r0c;
        self.cc += o.cc;
        self.wq += o.wq;
        for k in 0..6 {
            self.dd[k] += o.dd[k];
            self.faces[k] += o.faces[k];
        }
        self.count += o.count;
        self
    }

    /// `Jᵀr` for the residual `r₀ - h c`.
    pub(crate) fn jtr(&self, h: f64) -> [f64; P] {
        let mut g = self.jtr0;
        if h != 0.0 {
            for i in 0..P {
                g[i] -= h * self.jtc[i];
            }
        }
        g
    }

    /// `Σ (r₀ - h c)²`.
    pub(crate) fn cost(&self, h: f64) -> f64 {
        if h == 0.0 {
            self.r0r0
        } else {
            (self.r0r0 - 2.0 * h * self.r0c + h * h * self.cc).max(0.0)
        }
    }
}

/// Entries of the packed upper triangle of a `P x P` matrix (at most 9 x 9).
const PACKED: usize = 45;

/// Index of `(a, b)`, `a <= b`, in the packed upper triangle of a `P x P` matrix.
#[inline(always)]
const fn packed(p: usize, a: usize, b: usize) -> usize {
    a * p - a * a.saturating_sub(1) / 2 - if a > 0 { a } else { 0 } + b
}

/// Lane-wise accumulators of one thread other than `JᵀJ` (`S::V` holds one value per lane).
/// Kept small: a zeroed struct above 2 KiB costs a `rep stosb`, which instruction counts see
/// as one instruction per byte.
struct Lanes<S: Simd, const P: usize> {
    jtr0: [S::V; P],
    jtc: [S::V; P],
    r0r0: S::V,
    r0c: S::V,
    cc: S::V,
    wq: S::V,
    dd: [S::V; 6],
    faces: [S::V; 6],
    count: S::V,
}

impl<S: Simd, const P: usize> Lanes<S, P> {
    #[inline(always)]
    fn zero(s: S) -> Self {
        let z = s.zero();
        Lanes {
            jtr0: [z; P],
            jtc: [z; P],
            r0r0: z,
            r0c: z,
            cc: z,
            wq: z,
            dd: [z; 6],
            faces: [z; 6],
            count: z,
        }
    }

    #[inline(always)]
    fn sum(&self, s: S, jtj: &[S::V; PACKED], want: Want) -> Sums<P> {
        let mut out = Sums::zero();
        for i in 0..P {
            if want.jtj {
                for j in i..P {
                    out.jtj[i][j] = s.sum(jtj[packed(P, i, j)]);
                }
            }
            out.jtr0[i] = s.sum(self.jtr0[i]);
            if want.debias {
                out.jtc[i] = s.sum(self.jtc[i]);
            }
        }
        out.r0r0 = s.sum(self.r0r0);
        out.r0c = s.sum(self.r0c);
        out.cc = s.sum(self.cc);
        out.wq = s.sum(self.wq);
        if want.coverage {
            for k in 0..6 {
                out.dd[k] = s.sum(self.dd[k]);
                out.faces[k] = s.sum(self.faces[k]);
            }
            out.count = s.sum(self.count);
        }
        out
    }
}

/// Groups of [`LANES`] points whose Jacobian rows are computed before they are summed into
/// `JᵀJ`, so that each row of `JᵀJ` is summed with its accumulators in registers.
const BLOCK: usize = 8;

/// One group's Jacobian rows (one vector per parameter), plain residual and noise direction.
struct Rows<S: Simd, const P: usize> {
    j: [S::V; P],
    r0: S::V,
    c: S::V,
}

/// One group of [`LANES`] points (`x`: their x, y, z; `wt`: 1 for a point, 0 for padding, or
/// `None` for a full group): its Jacobian rows, `r₀` and `c`; adds its scalar sums (unless
/// `!scalars`: a coverage-only pass) and coverage to `acc`.
#[inline(always)]
fn group<S: Simd, const P: usize, const DEB: bool, const COV: bool>(
    s: S,
    k: &Consts<S>,
    x: [S::V; 3],
    wt: Option<S::V>,
    acc: &mut Lanes<S, P>,
    scalars: bool,
) -> Rows<S, P> {
    let w = &k.w;
    let u = arr3!(|i| s.fma(s.sub(x[i], k.mean[i]), k.inv_scale, k.neg_offset[i]));
    let v = arr3!(|i| s.fma(w[i][2], u[2], s.fma(w[i][1], u[1], s.mul(w[i][0], u[0]))));
    let wv = arr3!(|i| s.fma(w[i][2], v[2], s.fma(w[i][1], v[1], s.mul(w[i][0], v[0]))));
    let nn = s.fma(v[2], v[2], s.fma(v[1], v[1], s.mul(v[0], v[0])));
    let n = s.sqrt(nn);
    let one = k.one;
    let mut iv = s.and(s.gt(n, s.zero()), s.div(one, n));
    let mut r0 = s.sub(n, one);
    if let Some(wt) = wt {
        iv = s.mul(iv, wt);
        r0 = s.mul(r0, wt);
    }
    // Jacobian row; vi = v / n is also the unit direction
    let vi = arr3!(|i| s.mul(v[i], iv));
    let niv = s.sub(s.zero(), iv);
    let mut j = [s.zero(); P];
    for i in 0..3 {
        j[i] = s.mul(wv[i], niv); // offset_x, offset_y, offset_z
    }
    if P == 4 {
        j[3] = s.fma(vi[2], u[2], s.fma(vi[1], u[1], s.mul(vi[0], u[0]))); // k (sphere)
    } else {
        for a in 0..3 {
            j[3 + a] = s.mul(vi[a], u[a]); // diag_x, diag_y, diag_z
        }
        if P == 9 {
            j[6] = s.fma(vi[0], u[1], s.mul(vi[1], u[0])); // offdiag_xy
            j[7] = s.fma(vi[0], u[2], s.mul(vi[2], u[0])); // offdiag_xz
            j[8] = s.fma(vi[1], u[2], s.mul(vi[2], u[1])); // offdiag_yz
        }
    }
    let wq = s.fma(j[2], j[2], s.fma(j[1], j[1], s.mul(j[0], j[0])));
    if scalars {
        acc.wq = s.add(acc.wq, wq);
        acc.r0r0 = s.fma(r0, r0, acc.r0r0);
    }
    let mut c = s.zero();
    if DEB {
        c = s.add(k.trw2, wq);
        if let Some(wt) = wt {
            c = s.mul(c, wt);
        }
        acc.r0c = s.fma(r0, c, acc.r0c);
        acc.cc = s.fma(c, c, acc.cc);
    }
    if COV {
        let d = vi;
        acc.dd[0] = s.fma(d[0], d[0], acc.dd[0]);
        acc.dd[1] = s.fma(d[1], d[1], acc.dd[1]);
        acc.dd[2] = s.fma(d[2], d[2], acc.dd[2]);
        acc.dd[3] = s.fma(d[0], d[1], acc.dd[3]);
        acc.dd[4] = s.fma(d[0], d[2], acc.dd[4]);
        acc.dd[5] = s.fma(d[1], d[2], acc.dd[5]);
        // the face each direction is closest to (ties go to the lower axis): masks, then 1.0
        let on = s.and(s.gt(iv, s.zero()), one);
        let (ax, ay, az) = (s.abs(d[0]), s.abs(d[1]), s.abs(d[2]));
        let is_x = s.and(s.ge(ax, ay), s.ge(ax, az));
        let is_y = s.andnot(is_x, s.ge(ay, az));
        let fx = s.and(is_x, on);
        let fy = s.and(is_y, on);
        let fz = s.andnot(is_y, s.andnot(is_x, on));
        let zero = s.zero();
        let (px, py, pz) = (s.ge(d[0], zero), s.ge(d[1], zero), s.ge(d[2], zero));
        acc.faces[0] = s.add(acc.faces[0], s.and(px, fx));
        acc.faces[1] = s.add(acc.faces[1], s.andnot(px, fx));
        acc.faces[2] = s.add(acc.faces[2], s.and(py, fy));
        acc.faces[3] = s.add(acc.faces[3], s.andnot(py, fy));
        acc.faces[4] = s.add(acc.faces[4], s.and(pz, fz));
        acc.faces[5] = s.add(acc.faces[5], s.andnot(pz, fz));
        acc.count = s.add(acc.count, on);
    }
    Rows { j, r0, c }
}

/// Adds the `G` groups `rows` to `Jᵀr₀` (and `Jᵀc`, and `JᵀJ`): for each row `a` of `JᵀJ`
/// the accumulators of that row stay in registers across the groups.
#[inline(always)]
fn sum_block<S: Simd, const P: usize, const G: usize, const JTJ: bool, const DEB: bool>(
    s: S,
    rows: &[Rows<S, P>; G],
    acc: &mut Lanes<S, P>,
    jtj: &mut [S::V; PACKED],
) {
    macro_rules! row {
        ($a:literal) => {
            if $a < P {
                let mut jr = s.zero();
                let mut jc = s.zero();
                let mut rowv = [s.zero(); P];
                for g in 0..G {
                    let ja = rows[g].j[$a];
                    jr = s.fma(ja, rows[g].r0, jr);
                    if DEB {
                        jc = s.fma(ja, rows[g].c, jc);
                    }
                    if JTJ {
                        for b in $a..P {
                            rowv[b] = s.fma(ja, rows[g].j[b], rowv[b]);
                        }
                    }
                }
                acc.jtr0[$a] = s.add(acc.jtr0[$a], jr);
                if DEB {
                    acc.jtc[$a] = s.add(acc.jtc[$a], jc);
                }
                if JTJ {
                    for b in $a..P {
                        let i = packed(P, $a, b);
                        jtj[i] = s.add(jtj[i], rowv[b]);
                    }
                }
            }
        };
    }
    row!(0);
    row!(1);
    row!(2);
    row!(3);
    row!(4);
    row!(5);
    row!(6);
    row!(7);
    row!(8);
}

/// The pass's constants as vectors.
struct Consts<S: Simd> {
    mean: [S::V; 3],
    inv_scale: S::V,
    neg_offset: [S::V; 3],
    w: [[S::V; 3]; 3],
    trw2: S::V,
    one: S::V,
}

#[inline(always)]
fn run<S: Simd, const P: usize, const JTJ: bool, const DEB: bool, const COV: bool>(
    s: S,
    points: &[[f64; 3]],
    setup: &Setup,
) -> Sums<P> {
    let k = Consts::<S> {
        mean: arr3!(|i| s.splat(setup.mean[i])),
        inv_scale: s.splat(setup.inv_scale),
        neg_offset: arr3!(|i| s.splat(-setup.offset[i])),
        w: arr3!(|i| arr3!(|j| s.splat(setup.w[i][j]))),
        trw2: s.splat(setup.trw2),
        one: s.splat(1.0),
    };
    let mut acc = Lanes::<S, P>::zero(s);
    let mut jtj = [s.zero(); PACKED];
    // a coverage-only pass (the one `finish` makes) computes `v / ‖v‖` and nothing of the
    // Jacobian: the work left out (`W v`, the rows, `Jᵀr₀`) is about half of the pass, and
    // the coverage sums are the same operations in the same order as in any other pass
    let scalars = JTJ || DEB || !COV;
    let (groups, rest) = points.as_chunks::<LANES>();
    let (blocks, tail) = groups.as_chunks::<BLOCK>();
    for b in blocks {
        macro_rules! g {
            ($g:literal) => {
                group::<S, P, DEB, COV>(s, &k, s.load_xyz(&b[$g]), None, &mut acc, scalars)
            };
        }
        let rows = [g!(0), g!(1), g!(2), g!(3), g!(4), g!(5), g!(6), g!(7)];
        if scalars {
            sum_block::<S, P, BLOCK, JTJ, DEB>(s, &rows, &mut acc, &mut jtj);
        }
    }
    for grp in tail {
        let rows = [group::<S, P, DEB, COV>(
            s,
            &k,
            s.load_xyz(grp),
            None,
            &mut acc,
            scalars,
        )];
        if scalars {
            sum_block::<S, P, 1, JTJ, DEB>(s, &rows, &mut acc, &mut jtj);
        }
    }
    if !rest.is_empty() {
        let mut wt = [0.0; LANES];
        wt[..rest.len()].fill(1.0);
        let mut grp = [rest[0]; LANES];
        grp[..rest.len()].copy_from_slice(rest);
        let wt = Some(s.vector(wt));
        let rows = [group::<S, P, DEB, COV>(
            s,
            &k,
            s.load_xyz(&grp),
            wt,
            &mut acc,
            scalars,
        )];
        if scalars {
            sum_block::<S, P, 1, JTJ, DEB>(s, &rows, &mut acc, &mut jtj);
        }
    }
    acc.sum(
        s,
        &jtj,
        Want {
            jtj: JTJ,
            debias: DEB,
            coverage: COV,
        },
    )
}

/// One pass over `points` on the calling thread.
pub(crate) fn pass_serial<const P: usize>(points: &[[f64; 3]], s: &Setup, want: Want) -> Sums<P> {
    macro_rules! go {
        ($j:literal, $d:literal, $c:literal) => {
            dispatch!(|simd| run::<_, P, $j, $d, $c>(simd, points, s))
        };
    }
    match (want.jtj, want.debias, want.coverage) {
        (true, true, true) => go!(true, true, true),
        (true, true, false) => go!(true, true, false),
        (true, false, true) => go!(true, false, true),
        (true, false, false) => go!(true, false, false),
        (false, true, true) => go!(false, true, true),
        (false, true, false) => go!(false, true, false),
        (false, false, true) => go!(false, false, true),
        (false, false, false) => go!(false, false, false),
    }
}

/// One pass over `points`, on the rayon pool when `parallel` and there are enough of them.
pub(crate) fn pass<const P: usize>(
    points: &[[f64; 3]],
    s: &Setup,
    want: Want,
    parallel: bool,
) -> Sums<P> {
    if parallel && points.len() > PARALLEL_ABOVE {
        let parts = crate::pool::map_chunks(points, CHUNK, |c| pass_serial::<P>(c, s, want));
        in_order(parts, Sums::zero, Sums::add)
    } else {
        pass_serial::<P>(points, s, want)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> Vec<[f64; 3]> {
        let mut x = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n)
            .map(|_| {
                let (a, b, c) = (next(), next(), next());
                let r = (a * a + b * b + c * c).sqrt().max(1e-9);
                [
                    3.0 * a / r + 0.1,
                    2.5 * b / r - 0.2,
                    2.0 * c / r + 0.01 * next(),
                ]
            })
            .collect()
    }

    fn setup() -> Setup {
        let w = [[0.35, 0.01, -0.02], [0.01, 0.42, 0.03], [-0.02, 0.03, 0.5]];
        let trw2 = (0..3)
            .map(|i| (0..3).map(|k| w[i][k] * w[k][i]).sum::<f64>())
            .sum();
        Setup {
            mean: [0.1, -0.2, 0.0],
            inv_scale: 1.0,
            offset: [0.01, 0.02, -0.03],
            w,
            trw2,
        }
    }

    fn bits(a: &Sums<9>) -> Vec<u64> {
        let mut v: Vec<f64> = a.jtj.iter().flatten().copied().collect();
        v.extend(a.jtr0.iter().chain(&a.jtc).chain(&a.dd).chain(&a.faces));
        v.extend([a.r0r0, a.r0c, a.cc, a.wq, a.count]);
        v.iter().map(|x| x.to_bits()).collect()
    }

    #[test]
    fn a_parallel_pass_sums_the_same_bits_on_any_number_of_threads() {
        // 37 chunks: more than the eighths of `in_order`, an odd count, a short last chunk
        let pts = cloud(36 * CHUNK + 123);
        let want = Want {
            jtj: true,
            debias: true,
            coverage: true,
        };
        let s = setup();
        let outside = bits(&pass::<9>(&pts, &s, want, true));
        for threads in [1, 2, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for _ in 0..5 {
                let inside = pool.install(|| bits(&pass::<9>(&pts, &s, want, true)));
                assert_eq!(inside, outside, "{threads} threads");
            }
        }
    }

    #[test]
    fn in_order_sums_halves_quarters_and_eighths() {
        // with values whose sums round differently in different orders
        let parts: Vec<f64> = (0..11)
            .map(|i| 1.0 + f64::EPSILON * (i as f64) * 0.75)
            .collect();
        let fold = |p: &[f64]| p.iter().fold(0.0, |a, b| a + b);
        let eighths = [&parts[0..1], &parts[1..2], &parts[2..3], &parts[3..5]];
        let rest = [&parts[5..6], &parts[6..8], &parts[8..9], &parts[9..11]];
        let left = (fold(eighths[0]) + fold(eighths[1])) + (fold(eighths[2]) + fold(eighths[3]));
        let right = (fold(rest[0]) + fold(rest[1])) + (fold(rest[2]) + fold(rest[3]));
        let got = in_order(parts.clone(), || 0.0, |a, b| a + b);
        assert_eq!(got.to_bits(), (left + right).to_bits());
        assert_eq!(in_order(Vec::<f64>::new(), || 0.0, |a, b| a + b), 0.0);
        assert_eq!(in_order(vec![2.5], || 0.0, |a, b| a + b), 2.5);
    }

    #[test]
    fn a_coverage_only_pass_gives_the_coverage_of_a_full_pass() {
        for n in [0, 3, 4, 31, 32, 33, 1000, 4099] {
            let pts = cloud(n);
            let s = setup();
            let full = pass_serial::<9>(
                &pts,
                &s,
                Want {
                    jtj: true,
                    debias: true,
                    coverage: true,
                },
            );
            let only = pass_serial::<9>(
                &pts,
                &s,
                Want {
                    jtj: false,
                    debias: false,
                    coverage: true,
                },
            );
            let b = |a: &Sums<9>| {
                a.dd.iter()
                    .chain(&a.faces)
                    .chain([&a.count])
                    .map(|x| x.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(b(&only), b(&full), "{n} points");
            assert_eq!(full.count, n as f64);
            assert!(only.jtr0.iter().all(|&x| x == 0.0) && only.r0r0 == 0.0 && only.wq == 0.0);
        }
    }
}
