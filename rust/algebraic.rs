//! The starting point of the geometric fit: the algebraic (least-squares quadric) fit, itself
//! seeded by the linear sphere fit through the same moments.
//!
//! The quadric `qᵀ M q + 2 bᵀ q + c = 0` is the smallest eigenvector of the scatter matrix of
//! the design rows `[x², y², z², 2xy, 2xz, 2yz, 2x, 2y, 2z, 1]` (cross terms dropped for the
//! axis and sphere models). It minimises an algebraic error, which noise biases by O(σ²); the
//! geometric refinement in `ellipsoid` removes that.

use crate::kernel::{Arith, Fused, Separate, LANES};
use crate::simd;
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
    let lin = nalgebra::Matrix4::from_fn(|i, j| s[(l + i, l + j)]);
    // the design rows hold 2x, 2y, 2z: the unknowns are c (x2) and d
    let rhs = nalgebra::Vector4::from_fn(|i, _| s[(l + i, 0)] + s[(l + i, 1)] + s[(l + i, 2)]);
    lin.cholesky().map(|c| c.solve(&rhs))
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
    let o = mq.try_inverse()? * (-b);
    let k = o.dot(&(mq * o)) - c;
    if !(k > 0.0) {
        return None;
    }
    let e = SymmetricEigen::new(mq / k);
    if e.eigenvalues.iter().any(|&l| !(l > 0.0) || !l.is_finite()) {
        return None;
    }
    let sq = Matrix3::from_diagonal(&e.eigenvalues.map(f64::sqrt));
    Some((o, e.eigenvectors * sq * e.eigenvectors.transpose()))
}

/// The design row of a normalised point (`M` = 10: full quadric; 7: axis-aligned).
#[inline(always)]
fn row<const M: usize>(x: f64, y: f64, z: f64) -> [f64; M] {
    let mut r = [0.0; M];
    r[0] = x * x;
    r[1] = y * y;
    r[2] = z * z;
    if M == 10 {
        r[3] = 2.0 * x * y;
        r[4] = 2.0 * x * z;
        r[5] = 2.0 * y * z;
    }
    r[M - 4] = 2.0 * x;
    r[M - 3] = 2.0 * y;
    r[M - 2] = 2.0 * z;
    r[M - 1] = 1.0;
    r
}

/// `Σ d dᵀ` over the design rows `d` of the normalised points.
fn scatter<const M: usize>(points: &[[f64; 3]], norm: Norm, parallel: bool) -> SMatrix<f64, M, M> {
    let part = |c: &[[f64; 3]]| scatter_serial::<M>(c, norm);
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

fn scatter_serial<const M: usize>(points: &[[f64; 3]], norm: Norm) -> [[f64; M]; M] {
    #[cfg(target_arch = "x86_64")]
    if simd::has_avx2_fma() {
        return simd::avx2_call!(scatter_avx2::<M>(points, norm));
    }
    scatter_lanes::<Separate, M>(points, norm)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn scatter_avx2<const M: usize>(points: &[[f64; 3]], norm: Norm) -> [[f64; M]; M] {
    scatter_lanes::<Fused, M>(points, norm)
}

/// Lane-wise upper triangle of `Σ d dᵀ`.
#[inline(always)]
fn scatter_lanes<A: Arith, const M: usize>(points: &[[f64; 3]], norm: Norm) -> [[f64; M]; M] {
    let mut acc = [[[0.0f64; LANES]; M]; M];
    let m = [norm.mean.x, norm.mean.y, norm.mean.z];
    let s = norm.inv_scale;
    let mut add = |g: &[[f64; 3]], wt: &[f64; LANES]| {
        let mut d = [[0.0f64; LANES]; M];
        for l in 0..LANES {
            let p = g[l.min(g.len() - 1)];
            let r = row::<M>((p[0] - m[0]) * s, (p[1] - m[1]) * s, (p[2] - m[2]) * s);
            for a in 0..M {
                d[a][l] = r[a] * wt[l];
            }
        }
        for a in 0..M {
            for b in a..M {
                for l in 0..LANES {
                    acc[a][b][l] = A::fma(d[a][l], d[b][l], acc[a][b][l]);
                }
            }
        }
    };
    let groups = points.chunks_exact(LANES);
    let rest = groups.remainder();
    for g in groups {
        add(g, &[1.0; LANES]);
    }
    if !rest.is_empty() {
        let mut wt = [0.0; LANES];
        wt[..rest.len()].fill(1.0);
        add(rest, &wt);
    }
    let mut out = [[0.0; M]; M];
    for a in 0..M {
        for b in a..M {
            let v = &acc[a][b];
            out[a][b] = (v[0] + v[1]) + (v[2] + v[3]);
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
    let chol = (s + SMatrix::<f64, M, M>::identity() * shift).cholesky();
    let Some(chol) = chol else {
        let e = SymmetricEigen::new(DMatrix::from_fn(M, M, |i, j| s[(i, j)]));
        let i = e.eigenvalues.imin();
        return Some(SVector::<f64, M>::from_fn(|k, _| e.eigenvectors[(k, i)]));
    };
    for _ in 0..50 {
        let mut w = chol.solve(&v);
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
