//! Shared geometry of a point cloud: centroid, scale and principal spreads.
//!
//! The fits work on normalised coordinates `(p - mean) / scale` so that raw counts with
//! offsets of thousands condition as well as data in g. The principal spreads tell a cloud on a
//! line or a plane from one that can determine a sphere or an ellipsoid.

use crate::error::{CalError, Result};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

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
    let mut variances: Vec<f64> = SymmetricEigen::new(cov)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    variances.sort_by(|a, b| b.total_cmp(a));
    Spread {
        mean,
        scale,
        variances: [
            variances[0].max(0.0),
            variances[1].max(0.0),
            variances[2].max(0.0),
        ],
    }
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
