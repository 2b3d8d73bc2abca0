//! The starting point of the geometric fit: the algebraic (least-squares quadric) fit, itself
//! seeded by the linear sphere fit through the same moments.
//!
//! The quadric `qᵀ M q + 2 bᵀ q + c = 0` is the smallest eigenvector of the scatter matrix of
//! the design rows `[x², y², z², 2xy, 2xz, 2yz, 2x, 2y, 2z, 1]` (cross terms dropped for the
//! axis and sphere models). It minimises an algebraic error, which noise biases by O(σ²); the
//! geometric refinement in `ellipsoid` removes that.

use crate::kernel::LANES;
use crate::linalg;
use crate::simd::{arr3, dispatch, Simd};
use nalgebra::{DMatrix, Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};
use rayon::prelude::*;

/// Normalised coordinates `q = (p - mean) * inv_scale`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Norm {
    pub mean: Vector3<f64>,
    pub inv_scale: f64,
}

/// Algebraic fit on normalised coordinates: `(offset, W)` with `‖W (q - offset)‖ = 1`.
///
/// `full` fits the 10-term quadric, otherwise the axis-aligned 7-term one. `sphere_only`
/// returns the linear sphere fit through the same moments. `None` when the quadric is not an
/// ellipsoid (or no sphere fits).
pub(crate) fn start(
    points: &[[f64; 3]],
    norm: Norm,
    full: bool,
    sphere_only: bool,
    parallel: bool,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    if full {
        let s = scatter::<10>(points, norm, parallel);
        if sphere_only {
            return sphere_of(&s);
        }
        let v = smallest_eigenvector_of(s)?;
        let mq = Matrix3::new(v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2]);
        quadric_to_ellipsoid(mq, Vector3::new(v[6], v[7], v[8]), v[9])
    } else {
        let s = scatter::<7>(points, norm, parallel);
        if sphere_only {
            return sphere_of(&s);
        }
        let v = smallest_eigenvector_of(s)?;
        let mq = Matrix3::from_diagonal(&Vector3::new(v[0], v[1], v[2]));
        quadric_to_ellipsoid(mq, Vector3::new(v[3], v[4], v[5]), v[6])
    }
}

/// The linear sphere fit `|q|² = 2 c·q + d` from the design scatter: `(c, I / radius)`.
pub(crate) fn sphere_of<const M: usize>(
    s: &SMatrix<f64, M, M>,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    let sol = sphere_solve(s)?;
    let c = Vector3::new(sol[0], sol[1], sol[2]);
    let r2 = sol[3] + c.norm_squared();
    (r2 > 0.0 && r2.is_finite()).then(|| (c, Matrix3::identity() / r2.sqrt()))
}

/// Solves the sphere's normal equations from the scatter of the design rows (rows x², y², z²
/// sum to |q|²; the last four rows are 2x, 2y, 2z and 1).
fn sphere_solve<const M: usize>(s: &SMatrix<f64, M, M>) -> Option<nalgebra::Vector4<f64>> {
    let l = M - 4;
    let lin: [[f64; 4]; 4] = std::array::from_fn(|i| std::array::from_fn(|j| s[(l + i, l + j)]));
    // the design rows hold 2x, 2y, 2z: the unknowns are c (x2) and d
    let mut lin = lin;
    let mut x: [f64; 4] = std::array::from_fn(|i| s[(l + i, 0)] + s[(l + i, 1)] + s[(l + i, 2)]);
    linalg::spd_solve_in_place(&mut lin, &mut x).then(|| nalgebra::Vector4::from(x))
}

/// `qᵀ M q + 2 bᵀ q + c = 0` to `(offset, W)` with `‖W (q - offset)‖ = 1`.
fn quadric_to_ellipsoid(
    mq: Matrix3<f64>,
    b: Vector3<f64>,
    c: f64,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    // make the quadratic part positive (the eigenvector's sign is arbitrary)
    let (mq, b, c) = if mq.trace() < 0.0 {
        (-mq, -b, -c)
    } else {
        (mq, b, c)
    };
    let arr: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| mq[(i, j)]));
    let inv = linalg::inverse3(&arr)?;
    let o = Vector3::from_fn(|i, _| -(inv[i][0] * b.x + inv[i][1] * b.y + inv[i][2] * b.z));
    let k = o.dot(&(mq * o)) - c;
    if !(k > 0.0) {
        return None;
    }
    let a = mq / k;
    let arr: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
    // an ellipsoid only if `a` is positive definite: a 3 x 3 Cholesky factorisation tells as
    // much as the signs of its eigenvalues, for a tenth of the cost (no acos / cos)
    linalg::cholesky(&arr)?;
    let w = linalg::sqrtm3(&arr)?;
    Some((o, Matrix3::from_fn(|i, j| w[i][j])))
}

/// `Σ d dᵀ` over the design rows `d` of the normalised points.
fn scatter<const M: usize>(points: &[[f64; 3]], norm: Norm, parallel: bool) -> SMatrix<f64, M, M> {
    let part = |c: &[[f64; 3]]| dispatch!(|simd| scatter_lanes::<_, M>(simd, c, norm));
    let acc = if parallel && points.len() > crate::kernel::PARALLEL_ABOVE {
        points.par_chunks(crate::kernel::CHUNK).map(part).reduce(
            || [[0.0; M]; M],
            |mut a, b| {
                for i in 0..M {
                    for j in i..M {
                        a[i][j] += b[i][j];
                    }
                }
                a
            },
        )
    } else {
        part(points)
    };
    SMatrix::<f64, M, M>::from_fn(|i, j| if i <= j { acc[i][j] } else { acc[j][i] })
}

/// Groups per block of the scatter (see `kernel`'s blocks).
const BLOCK: usize = 8;

/// The design rows of a group: `x², y², z², [2xy, 2xz, 2yz,] 2x, 2y, 2z, 1` (times `wt`).
#[inline(always)]
fn design<S: Simd, const M: usize>(
    s: S,
    x: [S::V; 3],
    mean: &[S::V; 3],
    inv: S::V,
    wt: S::V,
) -> [S::V; M] {
    let q = arr3!(|k| s.mul(s.sub(x[k], mean[k]), inv));
    let q2 = arr3!(|k| s.mul(s.add(q[k], q[k]), wt)); // 2x, 2y, 2z (weighted)
    let mut d = [s.zero(); M];
    for k in 0..3 {
        d[k] = s.mul(s.mul(q[k], q[k]), wt);
    }
    if M == 10 {
        d[3] = s.mul(q[0], q2[1]);
        d[4] = s.mul(q[0], q2[2]);
        d[5] = s.mul(q[1], q2[2]);
    }
    d[M - 4] = q2[0];
    d[M - 3] = q2[1];
    d[M - 2] = q2[2];
    d[M - 1] = wt;
    d
}

/// Entries of the packed upper triangle of the (at most 10 x 10) scatter matrix.
const PACKED: usize = 55;

/// Index of `(a, b)`, `a <= b`, in the packed upper triangle of an `m x m` matrix.
#[inline(always)]
const fn packed(m: usize, a: usize, b: usize) -> usize {
    a * m - a * a.saturating_sub(1) / 2 - if a > 0 { a } else { 0 } + b
}

/// Adds the `G` design rows `rows` to `acc`, one row of the scatter matrix at a time (its
/// accumulators in registers).
#[inline(always)]
fn add_rows<S: Simd, const M: usize, const G: usize>(
    s: S,
    rows: &[[S::V; M]; G],
    acc: &mut [S::V; PACKED],
) {
    macro_rules! row {
        ($a:literal) => {
            if $a < M {
                let mut row = [s.zero(); M];
                for d in rows.iter() {
                    for b in $a..M {
                        row[b] = s.fma(d[$a], d[b], row[b]);
                    }
                }
                for b in $a..M {
                    let i = packed(M, $a, b);
                    acc[i] = s.add(acc[i], row[b]);
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
    row!(9);
}

/// Upper triangle of `Σ d dᵀ` over the design rows of the points.
#[inline(always)]
fn scatter_lanes<S: Simd, const M: usize>(s: S, points: &[[f64; 3]], norm: Norm) -> [[f64; M]; M] {
    let mut acc = [s.zero(); PACKED];
    let mean = arr3!(|k| s.splat(norm.mean[k]));
    let inv = s.splat(norm.inv_scale);
    let one = s.splat(1.0);
    let (groups, rest) = points.as_chunks::<LANES>();
    let (blocks, tail) = groups.as_chunks::<BLOCK>();
    for b in blocks {
        macro_rules! d {
            ($g:literal) => {
                design::<S, M>(s, s.load_xyz(&b[$g]), &mean, inv, one)
            };
        }
        let rows = [d!(0), d!(1), d!(2), d!(3), d!(4), d!(5), d!(6), d!(7)];
        add_rows::<S, M, BLOCK>(s, &rows, &mut acc);
    }
    for grp in tail {
        let rows = [design::<S, M>(s, s.load_xyz(grp), &mean, inv, one)];
        add_rows::<S, M, 1>(s, &rows, &mut acc);
    }
    if !rest.is_empty() {
        let mut wt = [0.0; LANES];
        wt[..rest.len()].fill(1.0);
        let mut grp = [rest[0]; LANES];
        grp[..rest.len()].copy_from_slice(rest);
        let rows = [design::<S, M>(
            s,
            s.load_xyz(&grp),
            &mean,
            inv,
            s.vector(wt),
        )];
        add_rows::<S, M, 1>(s, &rows, &mut acc);
    }
    let mut out = [[0.0; M]; M];
    for a in 0..M {
        for b in a..M {
            out[a][b] = s.sum(acc[packed(M, a, b)]);
        }
    }
    out
}

/// Smallest eigenvector of the symmetric positive semi-definite `s`: inverse iteration on the
/// slightly shifted Cholesky factor, seeded with the linear sphere fit from the same moments.
fn smallest_eigenvector_of<const M: usize>(s: SMatrix<f64, M, M>) -> Option<SVector<f64, M>> {
    let l = M - 4;
    let mut v = SVector::<f64, M>::zeros();
    match sphere_solve(&s) {
        Some(sol) => {
            // |q|² - 2c·q - d = 0: coefficient 1 on x², y², z², -c on 2x.., -d on 1
            for i in 0..3 {
                v[i] = 1.0;
                v[l + i] = -sol[i];
            }
            v[M - 1] = -sol[3];
        }
        None => v.fill(1.0),
    }
    v /= v.norm();
    let shift = 1e-13 * s.trace();
    // the scatter is exactly symmetric: its column-major storage reads as the row-major array
    let mut chol: [[f64; M]; M] = s.data.0;
    for i in 0..M {
        chol[i][i] += shift;
    }
    if !linalg::cholesky_in_place(&mut chol) {
        let e = SymmetricEigen::new(DMatrix::from_fn(M, M, |i, j| s[(i, j)]));
        let i = e.eigenvalues.imin();
        return Some(SVector::<f64, M>::from_fn(|k, _| e.eigenvectors[(k, i)]));
    }
    for _ in 0..50 {
        let mut x: [f64; M] = v.data.0[0];
        linalg::cholesky_solve_in_place(&chol, &mut x);
        let mut w = SVector::<f64, M>::from(x);
        let n = w.norm();
        if !(n > 0.0 && n.is_finite()) {
            return None;
        }
        w /= n;
        if w.dot(&v) < 0.0 {
            w = -w;
        }
        let change = (w - v).norm_squared();
        v = w;
        if change < 1e-26 {
            break;
        }
    }
    Some(v)
}
