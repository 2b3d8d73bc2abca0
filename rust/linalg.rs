//! Small dense linear algebra on fixed-size arrays, for the inner loops of the fits: Cholesky
//! factorisation, solves and the inverse of a symmetric positive-definite `N x N` matrix, and
//! the square root of a symmetric positive-definite 3 x 3 matrix.
//!
//! nalgebra does all of this too; these plain loops over `[[f64; N]; N]` compile to a few
//! hundred instructions for `N = 9`, several times fewer than the generic versions, which
//! matters when thousands of small fits run in a batch.

/// The lower Cholesky factor `L` (`A = L Lᵀ`) of the symmetric `a` (only its lower triangle is
/// read); `None` unless `a` is positive definite.
#[inline]
pub fn cholesky<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let mut l = [[0.0f64; N]; N];
    for j in 0..N {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if !(d > 0.0) || !d.is_finite() {
            return None;
        }
        let djj = d.sqrt();
        l[j][j] = djj;
        let inv = 1.0 / djj;
        for i in j + 1..N {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s * inv;
        }
    }
    Some(l)
}

/// Solves `L Lᵀ x = b` with the factor from [`cholesky`].
#[inline]
pub fn cholesky_solve<const N: usize>(l: &[[f64; N]; N], b: &[f64; N]) -> [f64; N] {
    let mut y = *b;
    for i in 0..N {
        let mut s = y[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    for i in (0..N).rev() {
        let mut s = y[i];
        for k in i + 1..N {
            s -= l[k][i] * y[k];
        }
        y[i] = s / l[i][i];
    }
    y
}

/// `A⁻¹` from the factor of [`cholesky`] (`A⁻¹ = L⁻ᵀ L⁻¹`).
#[inline]
pub fn cholesky_inverse<const N: usize>(l: &[[f64; N]; N]) -> [[f64; N]; N] {
    // M = L⁻¹ (lower triangular)
    let mut m = [[0.0f64; N]; N];
    for j in 0..N {
        m[j][j] = 1.0 / l[j][j];
        for i in j + 1..N {
            let mut s = 0.0;
            for k in j..i {
                s -= l[i][k] * m[k][j];
            }
            m[i][j] = s / l[i][i];
        }
    }
    // A⁻¹ = Mᵀ M
    let mut out = [[0.0f64; N]; N];
    for i in 0..N {
        for j in i..N {
            let mut s = 0.0;
            for k in j..N {
                s += m[k][i] * m[k][j];
            }
            out[i][j] = s;
            out[j][i] = s;
        }
    }
    out
}

/// The symmetric positive-definite square root of the symmetric positive-definite `a`, by the
/// Newton iteration `X ← (X + A X⁻¹) / 2` from `√(tr A / 3) I` (every iterate is a polynomial
/// in `A`, hence symmetric; convergence is quadratic). `None` when it does not converge (`a`
/// not positive definite, or its eigenvalues spread by more than about 10⁴).
pub fn sqrtm3(a: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let tr = a[0][0] + a[1][1] + a[2][2];
    if !(tr > 0.0) || !tr.is_finite() {
        return None;
    }
    let c = (tr / 3.0).sqrt();
    let mut x = [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, c]];
    for _ in 0..40 {
        let xi = inverse3(&x)?;
        let mut next = [[0.0; 3]; 3];
        let mut change = 0.0f64;
        let mut size = 0.0f64;
        for i in 0..3 {
            for j in 0..3 {
                let axi = a[i][0] * xi[0][j] + a[i][1] * xi[1][j] + a[i][2] * xi[2][j];
                next[i][j] = 0.5 * (x[i][j] + axi);
                change = change.max((next[i][j] - x[i][j]).abs());
                size = size.max(next[i][j].abs());
            }
        }
        // symmetrise (round-off only)
        for i in 0..3 {
            for j in i + 1..3 {
                let m = 0.5 * (next[i][j] + next[j][i]);
                next[i][j] = m;
                next[j][i] = m;
            }
        }
        x = next;
        if change <= 1e-15 * size {
            return Some(x);
        }
    }
    None
}

/// The inverse of a 3 x 3 matrix (adjugate over determinant); `None` when singular.
pub fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
    let c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
    let c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
    let det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
    if !(det != 0.0) || !det.is_finite() {
        return None;
    }
    let d = 1.0 / det;
    Some([
        [
            c00 * d,
            (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * d,
            (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * d,
        ],
        [
            c01 * d,
            (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * d,
            (m[0][2] * m[1][0] - m[0][0] * m[1][2]) * d,
        ],
        [
            c02 * d,
            (m[0][1] * m[2][0] - m[0][0] * m[2][1]) * d,
            (m[0][0] * m[1][1] - m[0][1] * m[1][0]) * d,
        ],
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, SMatrix};

    #[test]
    fn cholesky_solve_and_inverse_match_nalgebra() {
        let b = SMatrix::<f64, 5, 5>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 1.5);
        let a = b * b.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.5;
        let arr: [[f64; 5]; 5] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
        let l = cholesky(&arr).unwrap();
        let rhs = [1.0, -2.0, 0.5, 3.0, -1.0];
        let x = cholesky_solve(&l, &rhs);
        let want = a
            .cholesky()
            .unwrap()
            .solve(&nalgebra::SVector::<f64, 5>::from(rhs));
        let inv = cholesky_inverse(&l);
        let want_inv = a.try_inverse().unwrap();
        for i in 0..5 {
            assert!((x[i] - want[i]).abs() < 1e-12 * (1.0 + want[i].abs()));
            for j in 0..5 {
                assert!((inv[i][j] - want_inv[(i, j)]).abs() < 1e-12 * want_inv.norm());
            }
        }
        let not_pd = [[1.0, 2.0], [2.0, 1.0]];
        assert!(cholesky(&not_pd).is_none());
    }

    #[test]
    fn square_root_of_a_spd_matrix() {
        let a = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5);
        let arr = [[2.0, 0.3, -0.1], [0.3, 1.0, 0.2], [-0.1, 0.2, 0.5]];
        let r = sqrtm3(&arr).unwrap();
        let rm = Matrix3::from_fn(|i, j| r[i][j]);
        assert!((rm * rm - a).norm() < 1e-13, "{rm}");
        assert!((rm - rm.transpose()).norm() == 0.0);
        assert!(sqrtm3(&[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]).is_none());
    }
}
