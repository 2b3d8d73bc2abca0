//! The starting point of the geometric fit: the algebraic (least-squares quadric) fit, itself
//! seeded by the linear sphere fit through the same moments.
//!
//! The quadric `qᵀ M q + 2 bᵀ q + c = 0` is the smallest eigenvector of the scatter matrix of
//! the design rows `[x², y², z², 2xy, 2xz, 2yz, 2x, 2y, 2z, 1]` (cross terms dropped for the
//! axis and sphere models). It minimises an algebraic error, which noise biases by O(σ²); the
//! geometric refinement in `ellipsoid` removes that.

use crate::linalg;
use nalgebra::{DMatrix, Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};

mod scatter;

use scatter::scatter;

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
    let mut last = f64::INFINITY;
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
        // converged; or converging so fast (the change shrinks by the same factor each step)
        // that the next change would be below that: the step that only confirms it is left out
        if change < 1e-26 || change * change < 1e-26 * last {
            break;
        }
        last = change;
    }
    Some(v)
}
