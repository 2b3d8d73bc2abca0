//! Shared geometry of a point cloud: centroid, scale and principal spreads.
//!
//! The fits work on normalised coordinates `(p - mean) / scale` so that raw counts with
//! offsets of thousands condition as well as data in g. The principal spreads tell a cloud on a
//! line or a plane from one that can determine a sphere or an ellipsoid.

use crate::error::{check_finite, CalError, Result};
use crate::simd::{arr3, dispatch, Simd};
use nalgebra::{Matrix3, Vector3};

/// Centroid, RMS distance from it and covariance of a point cloud.
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    /// Mean of the points.
    pub mean: Vector3<f64>,
    /// RMS distance of the points from the mean (0 when all points coincide).
    pub scale: f64,
    /// Covariance matrix of the points.
    pub cov: Matrix3<f64>,
}

impl Spread {
    /// Variances along the principal axes, largest first.
    pub fn variances(&self) -> [f64; 3] {
        sym3_eigenvalues(&self.cov).map(|v| v.max(0.0))
    }
}

/// Relative variance below which a principal direction counts as empty (a spread of one
/// millionth of the largest one).
pub const FLAT_RATIO: f64 = 1e-12;

/// Readings whose largest magnitude is outside `[2^-RESCALE_EXP, 2^RESCALE_EXP]` are rescaled
/// by a power of two before fitting, so that no square or sum of squares overflows or
/// underflows (the rescaling is exact).
pub const RESCALE_EXP: i32 = 400;

/// The sums of one pass over a point cloud: moments about the first point (so that large
/// offsets do not cancel), the largest magnitude of any coordinate.
#[derive(Debug, Clone, Copy)]
pub struct Scan {
    /// The first point (the moments are about it).
    pub p0: [f64; 3],
    /// Number of points.
    pub n: usize,
    /// Σ (p - p0).
    pub s1: [f64; 3],
    /// Σ of the products of (p - p0): xx yy zz xy xz yz.
    pub s2: [f64; 6],
    /// Largest |coordinate|.
    pub max_abs: f64,
}

/// Points per rayon task of [`scan`]; smaller inputs are scanned on the calling thread.
const SCAN_CHUNK: usize = 16_384;

/// One pass over `points`: fails with [`CalError::NonFinite`] at the first NaN or infinite
/// coordinate, and otherwise returns the moments and the largest magnitude.
pub fn scan(points: &[[f64; 3]], parallel: bool) -> Result<Scan> {
    let p0 = points.first().copied().unwrap_or([0.0; 3]);
    let part = |c: &[[f64; 3]]| scan_part(c, p0);
    let (s1, s2, max_abs, probe) = if parallel && points.len() > 4 * SCAN_CHUNK {
        let parts = crate::pool::map_chunks(points, SCAN_CHUNK, part);
        crate::kernel::in_order(
            parts,
            || ([0.0; 3], [0.0; 6], 0.0, 0.0),
            |a, b| {
                let mut s1 = a.0;
                let mut s2 = a.1;
                for k in 0..3 {
                    s1[k] += b.0[k];
                }
                for k in 0..6 {
                    s2[k] += b.1[k];
                }
                (s1, s2, a.2.max(b.2), a.3 + b.3)
            },
        )
    } else {
        part(points)
    };
    if !probe.is_finite() {
        check_finite(points)?; // a NaN or an infinity; otherwise an overflow (rescaled later)
    }
    Ok(Scan {
        p0,
        n: points.len(),
        s1,
        s2,
        max_abs,
    })
}

/// [`scan`] and, in the same pass (chunk by chunk, while each chunk is in cache), the points
/// sorted into `K` lists by `sort`, which appends the points of a chunk it picks to the lists
/// (in their order): one read of the points where separate passes would read them again.
pub fn scan_picking<const K: usize, F: Fn(&[[f64; 3]], &mut [Vec<[f64; 3]>; K]) + Sync>(
    points: &[[f64; 3]],
    parallel: bool,
    sort: F,
) -> Result<(Scan, [Vec<[f64; 3]>; K])> {
    let p0 = points.first().copied().unwrap_or([0.0; 3]);
    type Sums = ([f64; 3], [f64; 6], f64, f64);
    let add = |a: Sums, b: Sums| -> Sums {
        let mut s1 = a.0;
        let mut s2 = a.1;
        for k in 0..3 {
            s1[k] += b.0[k];
        }
        for k in 0..6 {
            s2[k] += b.1[k];
        }
        (s1, s2, a.2.max(b.2), a.3 + b.3)
    };
    let mut lists: [Vec<[f64; 3]>; K] = std::array::from_fn(|_| Vec::new());
    let (s1, s2, max_abs, probe) = if parallel && points.len() > 4 * SCAN_CHUNK {
        let parts: Vec<(Sums, [Vec<[f64; 3]>; K])> =
            crate::pool::map_chunks(points, SCAN_CHUNK, |c| {
                let mut l: [Vec<[f64; 3]>; K] = std::array::from_fn(|_| Vec::new());
                sort(c, &mut l);
                (scan_part(c, p0), l)
            });
        // the lists at their final size at once (growing them by doubling would hold up to
        // three times the points while copying)
        for (k, list) in lists.iter_mut().enumerate() {
            list.reserve_exact(parts.iter().map(|(_, l)| l[k].len()).sum());
        }
        let mut total = ([0.0; 3], [0.0; 6], 0.0, 0.0);
        for (sums, l) in parts {
            total = add(total, sums);
            for (x, y) in lists.iter_mut().zip(l) {
                x.extend_from_slice(&y);
            }
        }
        total
    } else {
        let mut total = ([0.0; 3], [0.0; 6], 0.0, 0.0);
        for c in points.chunks(SCAN_CHUNK) {
            total = add(total, scan_part(c, p0));
            sort(c, &mut lists);
        }
        total
    };
    if !probe.is_finite() {
        check_finite(points)?;
    }
    Ok((
        Scan {
            p0,
            n: points.len(),
            s1,
            s2,
            max_abs,
        },
        lists,
    ))
}

/// Moments about `p0`, the largest magnitude, and a probe that is finite exactly when every
/// coordinate is (a NaN or an infinity makes the sums non-finite; so can an overflow, which
/// the caller tells apart with [`check_finite`]).
fn scan_part(points: &[[f64; 3]], p0: [f64; 3]) -> ([f64; 3], [f64; 6], f64, f64) {
    dispatch!(|simd| scan_lanes(simd, points, p0))
}

#[inline(always)]
fn scan_lanes<S: Simd>(s: S, points: &[[f64; 3]], p0: [f64; 3]) -> ([f64; 3], [f64; 6], f64, f64) {
    let c = arr3!(|k| s.splat(p0[k]));
    let mut s1 = [s.zero(); 3];
    let mut s2 = [s.zero(); 6];
    let mut m = s.zero();
    let (groups, rest) = points.as_chunks::<4>();
    for g in groups {
        let x = s.load_xyz(g);
        let d = arr3!(|k| s.sub(x[k], c[k]));
        for k in 0..3 {
            s1[k] = s.add(s1[k], d[k]);
        }
        s2[0] = s.fma(d[0], d[0], s2[0]);
        s2[1] = s.fma(d[1], d[1], s2[1]);
        s2[2] = s.fma(d[2], d[2], s2[2]);
        s2[3] = s.fma(d[0], d[1], s2[3]);
        s2[4] = s.fma(d[0], d[2], s2[4]);
        s2[5] = s.fma(d[1], d[2], s2[5]);
        m = s.max(m, s.max(s.abs(x[0]), s.max(s.abs(x[1]), s.abs(x[2]))));
    }
    let mut t1 = arr3!(|k| s.sum(s1[k]));
    let mut t2 = [0.0; 6];
    for k in 0..6 {
        t2[k] = s.sum(s2[k]);
    }
    let ma = s.to_array(m);
    let mut mx = ma[0].max(ma[1]).max(ma[2].max(ma[3]));
    for p in rest {
        let d = [p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]];
        for k in 0..3 {
            t1[k] += d[k];
            mx = mx.max(p[k].abs());
        }
        t2[0] += d[0] * d[0];
        t2[1] += d[1] * d[1];
        t2[2] += d[2] * d[2];
        t2[3] += d[0] * d[1];
        t2[4] += d[0] * d[2];
        t2[5] += d[1] * d[2];
    }
    let probe = t1.iter().sum::<f64>() + t2.iter().sum::<f64>();
    (t1, t2, mx, probe)
}

/// Whether readings of largest magnitude `max_abs` must be rescaled (see [`RESCALE_EXP`]).
pub fn needs_rescale(max_abs: f64) -> bool {
    let lim = 2f64.powi(RESCALE_EXP);
    max_abs > lim || (max_abs > 0.0 && max_abs < 1.0 / lim)
}

/// The power of two `e` with `x = m 2^e`, `0.5 <= m < 1` (`x` finite and non-zero).
pub fn exponent(x: f64) -> i32 {
    let bits = x.abs().to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    if biased == 0 {
        // subnormal: the position of the leading bit of the mantissa
        let mant = bits & ((1u64 << 52) - 1);
        -1074 + 64 - mant.leading_zeros() as i32
    } else {
        biased - 1022
    }
}

/// `x 2^e`, exact unless the result overflows or underflows (in two steps, so that any `e`
/// between -2098 and 2098 is fine).
pub fn times_pow2(x: f64, e: i32) -> f64 {
    let a = e / 2;
    let b = e - a;
    x * pow2(a) * pow2(b)
}

fn pow2(e: i32) -> f64 {
    if e >= -1022 {
        f64::from_bits(((e + 1023) as u64) << 52)
    } else {
        f64::from_bits(1u64 << (e + 1074))
    }
}

/// The [`Spread`] of a [`Scan`].
pub fn spread_of(s: &Scan) -> Spread {
    let n = s.n.max(1) as f64;
    let (s1, s2) = (s.s1, s.s2);
    let m = [s1[0] / n, s1[1] / n, s1[2] / n];
    let c = |i: usize, a: usize, b: usize| s2[i] / n - m[a] * m[b];
    let cov = Matrix3::new(
        c(0, 0, 0),
        c(3, 0, 1),
        c(4, 0, 2),
        c(3, 0, 1),
        c(1, 1, 1),
        c(5, 1, 2),
        c(4, 0, 2),
        c(5, 1, 2),
        c(2, 2, 2),
    );
    let mean = Vector3::new(s.p0[0] + m[0], s.p0[1] + m[1], s.p0[2] + m[2]);
    let scale = cov.trace().max(0.0).sqrt();
    Spread { mean, scale, cov }
}

/// Computes the [`Spread`] of `points` in one streaming pass (non-finite points give NaN).
pub fn spread(points: &[[f64; 3]]) -> Spread {
    let p0 = points.first().copied().unwrap_or([0.0; 3]);
    let (s1, s2, max_abs, _) = scan_part(points, p0);
    spread_of(&Scan {
        p0,
        n: points.len(),
        s1,
        s2,
        max_abs,
    })
}

/// Bounds `(lo, hi)` on the eigenvalues of the symmetric `a` (its upper triangle is read):
/// their mean `q = tr a / 3` minus and plus the Frobenius norm of `a - q I`, which bounds every
/// `|λ - q|`. About 20 instructions against several hundred for [`sym3_eigenvalues`] (`acos`,
/// `cos`): for tests that only compare eigenvalues with a bound, which these settle whenever the
/// matrix is not far from a multiple of the identity (calibrated gains, well spread directions).
/// NaN or infinite when `a` is not finite.
pub fn sym3_eigenvalue_bounds(a: &Matrix3<f64>) -> (f64, f64) {
    let q = (a[(0, 0)] + a[(1, 1)] + a[(2, 2)]) / 3.0;
    let off = a[(0, 1)] * a[(0, 1)] + a[(0, 2)] * a[(0, 2)] + a[(1, 2)] * a[(1, 2)];
    let d = [a[(0, 0)] - q, a[(1, 1)] - q, a[(2, 2)] - q];
    let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 2.0 * off).sqrt();
    (q - r, q + r)
}

/// Eigenvalues of a symmetric 3x3 matrix, largest first.
///
/// The trigonometric solution of the characteristic cubic gives the most isolated eigenvalue
/// to a few ulps of the largest; the other two come from the invariants (their sum is the
/// trace minus it, their product the sum of principal 2x2 minors minus it times their sum),
/// which stays accurate when two eigenvalues nearly coincide (points on a line or a plane),
/// where `acos` is ill-conditioned. The matrix is scaled to a largest entry of 1 first, so that
/// no square overflows or underflows.
pub fn sym3_eigenvalues(a: &Matrix3<f64>) -> [f64; 3] {
    let m = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(m > 0.0 && m.is_finite()) {
        let mut d = [a[(0, 0)], a[(1, 1)], a[(2, 2)]];
        d.sort_by(|x, y| y.total_cmp(x));
        return d;
    }
    let a = a / m;
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let tr = a.trace();
    let q = tr / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if !(p > 0.0) {
        let mut d = [a[(0, 0)] * m, a[(1, 1)] * m, a[(2, 2)] * m];
        d.sort_by(|x, y| y.total_cmp(x));
        return d;
    }
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    // sum of the principal 2x2 minors: l1 l2 + l1 l3 + l2 l3
    let minors = a[(0, 0)] * a[(1, 1)] - a[(0, 1)].powi(2) + a[(0, 0)] * a[(2, 2)]
        - a[(0, 2)].powi(2)
        + a[(1, 1)] * a[(2, 2)]
        - a[(1, 2)].powi(2);
    // the other two as the roots of x² - s x + prod, the larger first
    let pair = |isolated: f64| {
        let s = tr - isolated;
        let prod = minors - isolated * s;
        let big = 0.5 * (s + (s * s - 4.0 * prod).max(0.0).sqrt());
        let small = if big > 0.0 && prod > 0.0 {
            (prod / big).min(big)
        } else {
            s - big
        };
        (big, small)
    };
    let out = if r >= 0.0 {
        // the largest is the isolated one
        let e1 = q + 2.0 * p * phi.cos();
        let (e2, e3) = pair(e1);
        [e1, e2, e3]
    } else {
        let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
        let (e1, e2) = pair(e3);
        [e1, e2, e3]
    };
    out.map(|v| v * m)
}

/// Fails unless the points span all three dimensions.
///
/// `what` names the model for the message. Points that are all equal, on a line or on a plane
/// cannot determine a centre in three dimensions whatever the model. The points must be finite
/// and within [`RESCALE_EXP`] binary orders of magnitude of 1 (see [`needs_rescale`]).
pub fn check_three_dimensional(points: &[[f64; 3]], what: &str) -> Result<Spread> {
    let s = scan(points, false)?;
    classify(&s, points.len(), what)
}

/// [`check_three_dimensional`] from a [`Scan`] of `n` points.
pub fn classify(s: &Scan, n: usize, what: &str) -> Result<Spread> {
    let sp = spread_of(s);
    // points spread in every direction (the usual case) need no eigenvalues: the lower bound
    // on the smallest one is then far above FLAT_RATIO times the upper bound on the largest
    // (a million times: far beyond the eigenvalues' round-off)
    let (lo, hi) = sym3_eigenvalue_bounds(&sp.cov);
    if lo > 1e6 * FLAT_RATIO * hi && hi < f64::INFINITY && sp.scale > 0.0 {
        return Ok(sp);
    }
    let [l1, l2, l3] = sp.variances();
    if !(l1 > 0.0) || sp.scale == 0.0 {
        return Err(CalError::Degenerate {
            why: format!("all {n} points are identical, so the {what} is undetermined"),
            fix: "the sensor did not move or the readings are stuck: check the wiring, then turn \
                  the sensor through many orientations"
                .into(),
        });
    }
    if l2 / l1 < FLAT_RATIO {
        return Err(CalError::Degenerate {
            why: format!("the points lie on a straight line, so the {what} is undetermined"),
            fix: "turn the sensor through orientations about more than one axis (for example the \
                  six faces of a cube)"
                .into(),
        });
    }
    if l3 / l1 < FLAT_RATIO {
        return Err(CalError::Degenerate {
            why: format!("the points lie on a plane, so the {what} is undetermined"),
            fix: "the sensor was turned about one axis only: add orientations that tilt that \
                  axis (turn the board on its side and upside down)"
                .into(),
        });
    }
    Ok(sp)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SymmetricEigen;

    #[test]
    fn eigenvalue_bounds_bracket_the_eigenvalues() {
        let ms = [
            Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5),
            Matrix3::new(1.02, 0.01, -0.03, 0.01, 0.97, 0.02, -0.03, 0.02, 1.0),
            Matrix3::new(4.0, 1.0, 0.0, 1.0, -4.0, 0.0, 0.0, 0.0, 0.0),
            Matrix3::identity() * 3.0,
        ];
        for m in ms {
            let (lo, hi) = sym3_eigenvalue_bounds(&m);
            let ev = sym3_eigenvalues(&m);
            assert!(
                lo <= ev[2] + 1e-15 && ev[0] <= hi + 1e-15,
                "{lo} {ev:?} {hi}"
            );
        }
        let (lo, hi) = sym3_eigenvalue_bounds(&(Matrix3::identity() * f64::NAN));
        assert!(lo.is_nan() && hi.is_nan());
    }

    #[test]
    fn closed_form_eigenvalues_match_nalgebra() {
        let ms = [
            Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.0, 0.2, -0.1, 0.2, 0.5),
            Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1e-20),
            Matrix3::new(4.0, 1.0, 0.0, 1.0, 4.0, 0.0, 0.0, 0.0, 0.0),
            Matrix3::identity() * 3.0,
        ];
        for m in ms {
            let mut want: Vec<f64> = SymmetricEigen::new(m).eigenvalues.iter().copied().collect();
            want.sort_by(|a, b| b.total_cmp(a));
            let got = sym3_eigenvalues(&m);
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() < 1e-8 * want[0].abs().max(1.0),
                    "{got:?} {want:?}"
                );
            }
            // the smallest one is what the flatness checks use: good to ulps of the largest
            assert!(
                (got[2] - want[2]).abs() < 1e-14 * want[0].abs(),
                "{got:?} {want:?}"
            );
        }
    }

    #[test]
    fn detects_line_and_plane() {
        let line: Vec<[f64; 3]> = (0..10).map(|i| [i as f64, 2.0 * i as f64, 0.5]).collect();
        assert!(matches!(
            check_three_dimensional(&line, "sphere"),
            Err(CalError::Degenerate { .. })
        ));
        let plane: Vec<[f64; 3]> = (0..50)
            .map(|i| [(i as f64).cos(), (i as f64).sin(), 3.0])
            .collect();
        let e = check_three_dimensional(&plane, "sphere").unwrap_err();
        assert!(e.to_string().contains("plane"), "{e}");
        let same = vec![[1.0, 2.0, 3.0]; 7];
        assert!(check_three_dimensional(&same, "sphere")
            .unwrap_err()
            .to_string()
            .contains("identical"));
    }

    #[test]
    fn thin_slabs_are_judged_by_their_eigenvalues() {
        // a slab of thickness t about a tilted plane: variance ratio about t²; the eigenvalue
        // bound settles only clearly three-dimensional clouds, the rest go to the eigenvalues
        let slab = |t: f64| -> Vec<[f64; 3]> {
            (0..60)
                .map(|i| {
                    // in the plane spanned by (1, 0, 1) and (0, 1, 0), off it along (1, 0, -1)
                    let a = (i as f64) * 0.7;
                    let (x, y) = (a.cos(), (1.3 * a).sin());
                    let e = if i % 2 == 0 { t } else { -t };
                    [x + e, y, x - e]
                })
                .collect()
        };
        for (t, flat) in [(1e-9, true), (1e-5, false), (1e-2, false), (0.5, false)] {
            let got = check_three_dimensional(&slab(t), "sphere");
            let want = {
                let s = scan(&slab(t), false).unwrap();
                let v = spread_of(&s).variances();
                v[2] / v[0] < FLAT_RATIO
            };
            assert_eq!(got.is_err(), flat, "thickness {t}");
            assert_eq!(want, flat, "thickness {t}");
        }
    }

    #[test]
    fn spread_of_cube_corners() {
        let mut pts = Vec::new();
        for i in 0..8 {
            pts.push([(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]);
        }
        let s = spread(&pts);
        assert!((s.mean - Vector3::new(0.5, 0.5, 0.5)).norm() < 1e-12);
        for v in s.variances() {
            assert!((v - 0.25).abs() < 1e-12);
        }
    }
}
