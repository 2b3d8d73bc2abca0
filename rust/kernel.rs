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

use crate::simd;
use rayon::prelude::*;

/// Points per group (one AVX2 register of doubles per quantity).
pub(crate) const LANES: usize = 4;

/// Points per rayon task.
pub(crate) const CHUNK: usize = 4096;

/// A pass runs on several threads only above this many points: below it, the cost of waking
/// the pool exceeds the gain.
pub(crate) const PARALLEL_ABOVE: usize = 3 * CHUNK;

/// Multiply-add: fused on the AVX2 + FMA build, separate on the portable one.
pub(crate) trait Arith: Copy {
    /// `a * b + c`.
    fn fma(a: f64, b: f64, c: f64) -> f64;
}

/// Fused multiply-add (one rounding): compiled to `vfmadd` in the AVX2 + FMA build.
#[derive(Clone, Copy)]
pub(crate) struct Fused;

/// Separate multiply and add, for CPUs without FMA (where `mul_add` is a library call).
#[derive(Clone, Copy)]
pub(crate) struct Separate;

impl Arith for Fused {
    #[inline(always)]
    fn fma(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
}

impl Arith for Separate {
    #[inline(always)]
    fn fma(a: f64, b: f64, c: f64) -> f64 {
        a * b + c
    }
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

/// What a pass sums.
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

/// Lane-wise accumulators of one thread.
struct Lanes<const P: usize> {
    jtj: [[[f64; LANES]; P]; P],
    jtr0: [[f64; LANES]; P],
    jtc: [[f64; LANES]; P],
    r0r0: [f64; LANES],
    r0c: [f64; LANES],
    cc: [f64; LANES],
    wq: [f64; LANES],
    dd: [[f64; LANES]; 6],
    faces: [[f64; LANES]; 6],
    count: [f64; LANES],
}

impl<const P: usize> Lanes<P> {
    #[inline(always)]
    fn zero() -> Self {
        Lanes {
            jtj: [[[0.0; LANES]; P]; P],
            jtr0: [[0.0; LANES]; P],
            jtc: [[0.0; LANES]; P],
            r0r0: [0.0; LANES],
            r0c: [0.0; LANES],
            cc: [0.0; LANES],
            wq: [0.0; LANES],
            dd: [[0.0; LANES]; 6],
            faces: [[0.0; LANES]; 6],
            count: [0.0; LANES],
        }
    }

    #[inline(always)]
    fn sum(&self, want: Want) -> Sums<P> {
        let s = |a: &[f64; LANES]| (a[0] + a[1]) + (a[2] + a[3]);
        let mut out = Sums::zero();
        for i in 0..P {
            if want.jtj {
                for j in i..P {
                    out.jtj[i][j] = s(&self.jtj[i][j]);
                }
            }
            out.jtr0[i] = s(&self.jtr0[i]);
            if want.debias {
                out.jtc[i] = s(&self.jtc[i]);
            }
        }
        out.r0r0 = s(&self.r0r0);
        out.r0c = s(&self.r0c);
        out.cc = s(&self.cc);
        out.wq = s(&self.wq);
        if want.coverage {
            for k in 0..6 {
                out.dd[k] = s(&self.dd[k]);
                out.faces[k] = s(&self.faces[k]);
            }
            out.count = s(&self.count);
        }
        out
    }
}

/// One group of [`LANES`] points: `x[k][l]` is coordinate `k` of lane `l`; `wt[l]` is 1 for a
/// point and 0 for padding.
#[inline(always)]
fn group<A: Arith, const P: usize, const JTJ: bool, const DEB: bool, const COV: bool>(
    s: &Setup,
    x: &[[f64; LANES]; 3],
    wt: &[f64; LANES],
    acc: &mut Lanes<P>,
) {
    let w = &s.w;
    let mut u = [[0.0f64; LANES]; 3];
    for k in 0..3 {
        for l in 0..LANES {
            u[k][l] = A::fma(x[k][l] - s.mean[k], s.inv_scale, -s.offset[k]);
        }
    }
    let mut v = [[0.0f64; LANES]; 3];
    let mut wv = [[0.0f64; LANES]; 3];
    for i in 0..3 {
        for l in 0..LANES {
            v[i][l] = A::fma(
                w[i][2],
                u[2][l],
                A::fma(w[i][1], u[1][l], w[i][0] * u[0][l]),
            );
        }
    }
    for i in 0..3 {
        for l in 0..LANES {
            wv[i][l] = A::fma(
                w[i][2],
                v[2][l],
                A::fma(w[i][1], v[1][l], w[i][0] * v[0][l]),
            );
        }
    }
    let mut iv = [0.0f64; LANES];
    let mut r0 = [0.0f64; LANES];
    for l in 0..LANES {
        let nn = A::fma(
            v[2][l],
            v[2][l],
            A::fma(v[1][l], v[1][l], v[0][l] * v[0][l]),
        );
        let n = nn.sqrt();
        iv[l] = if n > 0.0 { wt[l] / n } else { 0.0 };
        r0[l] = (n - 1.0) * wt[l];
    }
    // Jacobian row; vi = v / n is also the unit direction
    let mut j = [[0.0f64; LANES]; P];
    let mut vi = [[0.0f64; LANES]; 3];
    for k in 0..3 {
        for l in 0..LANES {
            j[k][l] = -wv[k][l] * iv[l]; // offset_x, offset_y, offset_z
            vi[k][l] = v[k][l] * iv[l];
        }
    }
    if P == 4 {
        for l in 0..LANES {
            // k (sphere)
            j[3][l] = A::fma(
                vi[2][l],
                u[2][l],
                A::fma(vi[1][l], u[1][l], vi[0][l] * u[0][l]),
            );
        }
    } else {
        for a in 0..3 {
            for l in 0..LANES {
                j[3 + a][l] = vi[a][l] * u[a][l]; // diag_x, diag_y, diag_z
            }
        }
        if P == 9 {
            for l in 0..LANES {
                j[6][l] = A::fma(vi[0][l], u[1][l], vi[1][l] * u[0][l]); // offdiag_xy
                j[7][l] = A::fma(vi[0][l], u[2][l], vi[2][l] * u[0][l]); // offdiag_xz
                j[8][l] = A::fma(vi[1][l], u[2][l], vi[2][l] * u[1][l]); // offdiag_yz
            }
        }
    }
    let mut c = [0.0f64; LANES];
    for l in 0..LANES {
        let wq = A::fma(
            j[2][l],
            j[2][l],
            A::fma(j[1][l], j[1][l], j[0][l] * j[0][l]),
        );
        acc.wq[l] += wq;
        acc.r0r0[l] = A::fma(r0[l], r0[l], acc.r0r0[l]);
        if DEB {
            c[l] = (s.trw2 + wq) * wt[l];
            acc.r0c[l] = A::fma(r0[l], c[l], acc.r0c[l]);
            acc.cc[l] = A::fma(c[l], c[l], acc.cc[l]);
        }
    }
    for a in 0..P {
        for l in 0..LANES {
            acc.jtr0[a][l] = A::fma(j[a][l], r0[l], acc.jtr0[a][l]);
        }
        if DEB {
            for l in 0..LANES {
                acc.jtc[a][l] = A::fma(j[a][l], c[l], acc.jtc[a][l]);
            }
        }
        if JTJ {
            for b in a..P {
                for l in 0..LANES {
                    acc.jtj[a][b][l] = A::fma(j[a][l], j[b][l], acc.jtj[a][b][l]);
                }
            }
        }
    }
    if COV {
        let d = &vi;
        for l in 0..LANES {
            acc.dd[0][l] = A::fma(d[0][l], d[0][l], acc.dd[0][l]);
            acc.dd[1][l] = A::fma(d[1][l], d[1][l], acc.dd[1][l]);
            acc.dd[2][l] = A::fma(d[2][l], d[2][l], acc.dd[2][l]);
            acc.dd[3][l] = A::fma(d[0][l], d[1][l], acc.dd[3][l]);
            acc.dd[4][l] = A::fma(d[0][l], d[2][l], acc.dd[4][l]);
            acc.dd[5][l] = A::fma(d[1][l], d[2][l], acc.dd[5][l]);
            // the face the direction is closest to (ties go to the lower axis)
            let (ax, ay, az) = (d[0][l].abs(), d[1][l].abs(), d[2][l].abs());
            let on = if iv[l] > 0.0 { 1.0 } else { 0.0 };
            let is_x = ax >= ay && ax >= az;
            let is_y = !is_x && ay >= az;
            let is_z = !is_x && !is_y;
            let fx = if is_x { on } else { 0.0 };
            let fy = if is_y { on } else { 0.0 };
            let fz = if is_z { on } else { 0.0 };
            let (px, py, pz) = (d[0][l] >= 0.0, d[1][l] >= 0.0, d[2][l] >= 0.0);
            acc.faces[0][l] += if px { fx } else { 0.0 };
            acc.faces[1][l] += if px { 0.0 } else { fx };
            acc.faces[2][l] += if py { fy } else { 0.0 };
            acc.faces[3][l] += if py { 0.0 } else { fy };
            acc.faces[4][l] += if pz { fz } else { 0.0 };
            acc.faces[5][l] += if pz { 0.0 } else { fz };
            acc.count[l] += on;
        }
    }
}

#[inline(always)]
fn load(p: &[[f64; 3]]) -> [[f64; LANES]; 3] {
    let mut x = [[0.0f64; LANES]; 3];
    for l in 0..LANES {
        let q = p[l.min(p.len() - 1)];
        for k in 0..3 {
            x[k][l] = q[k];
        }
    }
    x
}

#[inline(always)]
fn run<A: Arith, const P: usize, const JTJ: bool, const DEB: bool, const COV: bool>(
    points: &[[f64; 3]],
    s: &Setup,
) -> Sums<P> {
    let mut acc = Lanes::<P>::zero();
    let groups = points.chunks_exact(LANES);
    let rest = groups.remainder();
    for g in groups {
        group::<A, P, JTJ, DEB, COV>(s, &load(g), &[1.0; LANES], &mut acc);
    }
    if !rest.is_empty() {
        let mut wt = [0.0; LANES];
        wt[..rest.len()].fill(1.0);
        group::<A, P, JTJ, DEB, COV>(s, &load(rest), &wt, &mut acc);
    }
    acc.sum(Want {
        jtj: JTJ,
        debias: DEB,
        coverage: COV,
    })
}

macro_rules! dispatch_flags {
    ($arith:ty, $points:expr, $s:expr, $want:expr) => {
        match ($want.jtj, $want.debias, $want.coverage) {
            (true, true, true) => run::<$arith, P, true, true, true>($points, $s),
            (true, true, false) => run::<$arith, P, true, true, false>($points, $s),
            (true, false, true) => run::<$arith, P, true, false, true>($points, $s),
            (true, false, false) => run::<$arith, P, true, false, false>($points, $s),
            (false, true, true) => run::<$arith, P, false, true, true>($points, $s),
            (false, true, false) => run::<$arith, P, false, true, false>($points, $s),
            (false, false, true) => run::<$arith, P, false, false, true>($points, $s),
            (false, false, false) => run::<$arith, P, false, false, false>($points, $s),
        }
    };
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn run_avx2<const P: usize>(points: &[[f64; 3]], s: &Setup, want: Want) -> Sums<P> {
    dispatch_flags!(Fused, points, s, want)
}

fn run_portable<const P: usize>(points: &[[f64; 3]], s: &Setup, want: Want) -> Sums<P> {
    dispatch_flags!(Separate, points, s, want)
}

/// One pass over `points` on the calling thread.
pub(crate) fn pass_serial<const P: usize>(points: &[[f64; 3]], s: &Setup, want: Want) -> Sums<P> {
    #[cfg(target_arch = "x86_64")]
    if simd::has_avx2_fma() {
        return simd::avx2_call!(run_avx2::<P>(points, s, want));
    }
    run_portable::<P>(points, s, want)
}

/// One pass over `points`, on the rayon pool when `parallel` and there are enough of them.
pub(crate) fn pass<const P: usize>(
    points: &[[f64; 3]],
    s: &Setup,
    want: Want,
    parallel: bool,
) -> Sums<P> {
    if parallel && points.len() > PARALLEL_ABOVE {
        points
            .par_chunks(CHUNK)
            .map(|c| pass_serial::<P>(c, s, want))
            .reduce(Sums::zero, Sums::add)
    } else {
        pass_serial::<P>(points, s, want)
    }
}
