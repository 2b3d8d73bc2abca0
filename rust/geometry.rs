//! Shared geometry of a point cloud: centroid, scale and principal spreads.
//!
//! The fits work on normalised coordinates `(p - mean) / scale` so that raw counts with
//! offsets of thousands condition as well as data in g. The principal spreads tell a cloud on a
//! line or a plane from one that can determine a sphere or an ellipsoid.

use crate::error::{CalError, Result};
use nalgebra::{Matrix3, Vector3};

/// Centroid, RMS distance from it and principal variances of a point cloud.
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    /// Mean of the points.
    pub mean: Vector3<f64>,
    /// RMS distance of the points from the mean (0 when all points coincide).
    pub scale: f64,
    /// Variances along the principal axes, largest first.
    pub variances: [f64; 3],
}

/// Relative variance below which a principal direction counts as empty (a spread of one
/// millionth of the largest one).
pub const FLAT_RATIO: f64 = 1e-12;

/// Computes the [`Spread`] of `points` in one streaming pass (sums of the points shifted by the
/// first one, so that large offsets do not cancel).
pub fn spread(points: &[[f64; 3]]) -> Spread {
    let n = points.len().max(1) as f64;
    let p0 = points.first().copied().unwrap_or([0.0; 3]);
    let mut s1 = [0.0f64; 3];
    let mut s2 = [0.0f64; 6]; // xx yy zz xy xz yz
    for p in points {
        let d = [p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]];
        for k in 0..3 {
            s1[k] += d[k];
        }
        s2[0] += d[0] * d[0];
        s2[1] += d[1] * d[1];
        s2[2] += d[2] * d[2];
        s2[3] += d[0] * d[1];
        s2[4] += d[0] * d[2];
        s2[5] += d[1] * d[2];
    }
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
    let mean = Vector3::new(p0[0] + m[0], p0[1] + m[1], p0[2] + m[2]);
    let scale = cov.trace().max(0.0).sqrt();
    let v = sym3_eigenvalues(&cov);
    Spread {
        mean,
        scale,
        variances: [v[0].max(0.0), v[1].max(0.0), v[2].max(0.0)],
    }
}

/// Eigenvalues of a symmetric 3x3 matrix, largest first, in closed form (the trigonometric
/// solution of the characteristic cubic). Absolute accuracy: a few ulps of the largest
/// eigenvalue, except that two nearly equal eigenvalues are only good to about 1e-8 of it
/// (acos is ill-conditioned there); the callers compare ratios with thresholds far from both.
pub fn sym3_eigenvalues(a: &Matrix3<f64>) -> [f64; 3] {
    let p1 = a[(0, 1)].powi(2) + a[(0, 2)].powi(2) + a[(1, 2)].powi(2);
    let q = a.trace() / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if !(p > 0.0) {
        let mut d = [a[(0, 0)], a[(1, 1)], a[(2, 2)]];
        d.sort_by(|x, y| y.total_cmp(x));
        return d;
    }
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
    [e1, 3.0 * q - e1 - e3, e3]
}

/// Fails unless the points span all three dimensions.
///
/// `what` names the model for the message. Points that are all equal, on a line or on a plane
/// cannot determine a centre in three dimensions whatever the model.
pub fn check_three_dimensional(points: &[[f64; 3]], what: &str) -> Result<Spread> {
    let s = spread(points);
    let [l1, l2, l3] = s.variances;
    if !(l1 > 0.0) || s.scale == 0.0 {
        return Err(CalError::Degenerate {
            why: format!(
                "all {} points are identical, so the {what} is undetermined",
                points.len()
            ),
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
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SymmetricEigen;

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
    fn spread_of_cube_corners() {
        let mut pts = Vec::new();
        for i in 0..8 {
            pts.push([(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]);
        }
        let s = spread(&pts);
        assert!((s.mean - Vector3::new(0.5, 0.5, 0.5)).norm() < 1e-12);
        for v in s.variances {
            assert!((v - 0.25).abs() < 1e-12);
        }
    }
}
