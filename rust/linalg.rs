//! Small dense linear algebra on fixed-size arrays, for the inner loops of the fits: Cholesky
//! factorisation, solves and the inverse of a symmetric positive-definite `N x N` matrix, and
//! the square root of a symmetric positive-definite 3 x 3 matrix.
//!
//! nalgebra does all of this too; these plain loops over `[[f64; N]; N]` compile to a few
//! hundred instructions for `N = 9`, several times fewer than the generic versions, which
//! matters when thousands of small fits run in a batch.

/// The largest `N` the routines below take: [`unroll!`] spells out this many steps.
pub const MAX_N: usize = 10;

/// Runs `$body` once for each `$i` in `0..$n` (ascending; `rev` for descending), with `$i` a
/// literal constant in each copy, for `$n <= MAX_N` known at compile time.
///
/// Loops over a triangle have trip counts that depend on the outer index, which LLVM does not
/// unroll: as plain loops they cost about 7 instructions per flop (counters, bounds checks,
/// loads and stores of the whole factor). With the outer index a constant, every inner loop has
/// a constant trip count, all indices are fixed offsets and the copies past `$n` fold away:
/// about 2-3 instructions per flop. The arithmetic, and so the round-off, is that of the plain
/// loops.
macro_rules! unroll {
    ($i:ident in 0..$n:expr => $body:block) => {
        unroll!(@each $i, $n, $body, 0 1 2 3 4 5 6 7 8 9)
    };
    (rev $i:ident in 0..$n:expr => $body:block) => {
        unroll!(@each $i, $n, $body, 9 8 7 6 5 4 3 2 1 0)
    };
    (@each $i:ident, $n:expr, $body:block, $($k:literal)*) => {
        $(
            if $k < $n {
                let $i: usize = $k;
                $body
            }
        )*
    };
}

/// Factors the symmetric `a` in place: its lower triangle becomes the lower Cholesky factor
/// `L` (`A = L Lᵀ`); only the lower triangle is read, and the strict upper triangle is left as
/// it was (the solves below never read it). `false` (with `a` partly overwritten) unless `a` is
/// positive definite.
///
/// In place, so that a caller that builds the matrix only to solve with it pays for neither a
/// second zero-initialised `N x N` array nor its copy.
#[inline(always)]
pub fn cholesky_in_place<const N: usize>(a: &mut [[f64; N]; N]) -> bool {
    const { assert!(N <= MAX_N) };
    unroll!(j in 0..N => {
        let mut d = a[j][j];
        for k in 0..j {
            d -= a[j][k] * a[j][k];
        }
        // positive and finite (false for NaN); `d.is_finite()` compiles to a dozen integer
        // instructions here, the two comparisons to two
        if !(d > 0.0 && d < f64::INFINITY) {
            return false;
        }
        let djj = d.sqrt();
        a[j][j] = djj;
        let inv = 1.0 / djj;
        for i in j + 1..N {
            let mut s = a[i][j];
            for k in 0..j {
                s -= a[i][k] * a[j][k];
            }
            a[i][j] = s * inv;
        }
    });
    true
}

/// The lower Cholesky factor `L` (`A = L Lᵀ`) of the symmetric `a` in the lower triangle of the
/// result (only the lower triangle of `a` is read; the strict upper triangle of the result is
/// `a`'s); `None` unless `a` is positive definite.
#[inline]
pub fn cholesky<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let mut l = *a;
    cholesky_in_place(&mut l).then_some(l)
}

/// Solves `L Lᵀ x = b` in place (`b` becomes `x`) with the factor `l` from [`cholesky`] (its
/// lower triangle).
#[inline(always)]
pub fn cholesky_solve_in_place<const N: usize>(l: &[[f64; N]; N], y: &mut [f64; N]) {
    const { assert!(N <= MAX_N) };
    // the reciprocals of the diagonal first: N divisions that overlap, where a division in
    // each step made each step of both substitutions wait for one
    let inv: [f64; N] = std::array::from_fn(|i| 1.0 / l[i][i]);
    unroll!(i in 0..N => {
        let mut s = y[i];
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s * inv[i];
    });
    unroll!(rev i in 0..N => {
        let mut s = y[i];
        for k in i + 1..N {
            s -= l[k][i] * y[k];
        }
        y[i] = s * inv[i];
    });
}

/// Solves `A x = b` for the symmetric positive-definite `a` (its lower triangle), overwriting
/// `a` with its factor and `b` with `x`; `false` unless `a` is positive definite. For a factor
/// used once: the caller's matrix is the workspace.
#[inline(always)]
pub fn spd_solve_in_place<const N: usize>(a: &mut [[f64; N]; N], b: &mut [f64; N]) -> bool {
    if !cholesky_in_place(a) {
        return false;
    }
    cholesky_solve_in_place(a, b);
    true
}

/// `A⁻¹` from the factor of [`cholesky`] (`A⁻¹ = L⁻ᵀ L⁻¹`).
#[inline]
pub fn cholesky_inverse<const N: usize>(l: &[[f64; N]; N]) -> [[f64; N]; N] {
    const { assert!(N <= MAX_N) };
    // M = L⁻¹ (lower triangular; its strict upper triangle is never read)
    let mut m = [[0.0f64; N]; N];
    unroll!(j in 0..N => {
        m[j][j] = 1.0 / l[j][j];
        for i in j + 1..N {
            let mut s = 0.0;
            for k in j..i {
                s -= l[i][k] * m[k][j];
            }
            m[i][j] = s / l[i][i];
        }
    });
    // A⁻¹ = Mᵀ M
    let mut out = [[0.0f64; N]; N];
    unroll!(i in 0..N => {
        for j in i..N {
            let mut s = 0.0;
            for k in j..N {
                s += m[k][i] * m[k][j];
            }
            out[i][j] = s;
            out[j][i] = s;
        }
    });
    out
}

/// The symmetric positive-definite square root of the symmetric positive-definite `a`, by the
/// Newton iteration `X ← (X + A X⁻¹) / 2` from `√(tr A / 3) I` (every iterate is a polynomial
/// in `A`, hence symmetric; convergence is quadratic). `None` when it does not converge (`a`
/// not positive definite, or its eigenvalues spread by more than about 10⁴).
pub fn sqrtm3(a: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let tr = a[0][0] + a[1][1] + a[2][2];
    if !(tr > 0.0 && tr < f64::INFINITY) {
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
                // (comparisons rather than `f64::max`, whose NaN handling costs a few
                // instructions each: the same result, as neither side starts as NaN)
                let d = (next[i][j] - x[i][j]).abs();
                if d > change {
                    change = d;
                }
                let v = next[i][j].abs();
                if v > size {
                    size = v;
                }
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
    if !(det.abs() > 0.0 && det.abs() < f64::INFINITY) {
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
    use nalgebra::{Matrix3, SMatrix, SVector};

    #[test]
    fn cholesky_solve_and_inverse_match_nalgebra() {
        let b = SMatrix::<f64, 5, 5>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 1.5);
        let a = b * b.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.5;
        let arr: [[f64; 5]; 5] = std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
        let l = cholesky(&arr).unwrap();
        let rhs = [1.0, -2.0, 0.5, 3.0, -1.0];
        let mut x = rhs;
        cholesky_solve_in_place(&l, &mut x);
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
    fn unrolled_solve_matches_nalgebra_for_the_fit_sizes() {
        fn check<const N: usize>() {
            let b = SMatrix::<f64, N, N>::from_fn(|i, j| ((i * 7 + j * 3) % 5) as f64 - 1.5);
            let a = b * b.transpose() + SMatrix::<f64, N, N>::identity() * 0.5;
            let mut arr: [[f64; N]; N] =
                std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]));
            // the strict upper triangle is neither read nor written
            for i in 0..N {
                for j in i + 1..N {
                    arr[i][j] = f64::NAN;
                }
            }
            let rhs: [f64; N] = std::array::from_fn(|i| i as f64 - 2.0);
            let mut x = rhs;
            assert!(spd_solve_in_place(&mut arr, &mut x));
            let want = a.cholesky().unwrap().solve(&SVector::<f64, N>::from(rhs));
            for i in 0..N {
                assert!(
                    (x[i] - want[i]).abs() < 1e-10 * (1.0 + want[i].abs()),
                    "{N}"
                );
                assert!(arr[i][i + 1..].iter().all(|v| v.is_nan()));
            }
            let mut neg = [[0.0; N]; N];
            neg[0][0] = 1.0;
            assert!(!spd_solve_in_place(&mut neg, &mut [1.0; N]));
        }
        check::<3>();
        check::<4>();
        check::<6>();
        check::<7>();
        check::<9>();
        check::<10>();
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
