//! Physical bounds on a fit, checked in one place, and the coverage of the sphere.
//!
//! A fit can be numerically converged and still be physically absurd when the readings cover
//! only a band or a cap of the sphere: the ellipsoid then stretches along the direction the
//! data do not constrain. These checks turn such results into errors that say which bound
//! failed, and poor (but usable) coverage into warnings that say which way to turn the sensor.

use crate::error::CalError;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

/// Largest ratio between the largest and smallest gain (eigenvalues of `W`) accepted. MEMS
/// scale errors are a few percent and soft iron rarely distorts a field by more than tens of
/// percent; a factor of 3 means the fit has run along a direction the data do not determine.
pub const MAX_AXIS_RATIO: f64 = 3.0;

/// A fit that did not converge is rejected when its offset's standard error exceeds this
/// fraction of the radius (the parameters are then not determined by the data).
pub const MAX_UNCONVERGED_OFFSET_SE: f64 = 0.1;

/// Offset standard errors above this fraction of the radius give a warning.
pub const WARN_OFFSET_SE: f64 = 0.01;

/// A residual RMS above this fraction of the radius gives a warning: the readings do not lie
/// on the fitted surface at all (a sensor that hardly turned, so that the fit has wrapped a
/// small sphere round the noise; mixed sensors; wrong columns). MEMS noise and unmodelled
/// distortion stay at a few percent; a sphere fitted to strong soft iron (gains 1 : 1.5) at
/// about 15 %.
pub const WARN_RMS_FRACTION: f64 = 0.2;

/// Coverage warnings start when the smallest eigenvalue of the direction scatter matrix
/// `mean(d dᵀ)` falls below this (1/3 for readings spread evenly over the sphere, 0 for a ring).
pub const WARN_MIN_SPREAD: f64 = 0.1;

/// Checks the gains of a fit from the eigenvalues of its `W` (any order; the fit has them
/// already, or knows from cheaper bounds that the check passes); `model` names it in the
/// message.
pub fn check_gains(eigenvalues: [f64; 3], model: &str) -> Result<(), CalError> {
    let e = eigenvalues.map(f64::abs);
    let ratio =
        e.iter().cloned().fold(0.0, f64::max) / e.iter().cloned().fold(f64::INFINITY, f64::min);
    if !(ratio <= MAX_AXIS_RATIO) {
        return Err(CalError::Degenerate {
            why: format!(
                "the \"{model}\" fit is physically implausible: its gains differ by a factor of \
                 {ratio:.1} between axes (bound: {MAX_AXIS_RATIO}), which happens when the points \
                 cover only a band or a cap of the sphere"
            ),
            fix: "turn the sensor through more orientations (upside down and on each side), or \
                  use a simpler model (the sphere model)"
                .into(),
        });
    }
    Ok(())
}

/// Names the sensor direction closest to `v` ("+X", "-Z", ...), up to sign when `signed` is false.
pub fn axis_name(v: &Vector3<f64>, signed: bool) -> String {
    let i = v.iamax();
    let axis = ["X", "Y", "Z"][i];
    if signed {
        format!("{}{axis}", if v[i] >= 0.0 { "+" } else { "-" })
    } else {
        format!("±{axis}")
    }
}

/// Coverage of the sphere by calibrated directions: `(smallest eigenvalue of mean(d dᵀ), its
/// eigenvector, |mean(d)|)`.
pub fn direction_spread(dirs: impl Iterator<Item = Vector3<f64>>) -> (f64, Vector3<f64>, f64) {
    let mut t = Matrix3::zeros();
    let mut m = Vector3::zeros();
    let mut n = 0usize;
    for d in dirs {
        let nrm = d.norm();
        if nrm > 0.0 {
            let u = d / nrm;
            t += u * u.transpose();
            m += u;
            n += 1;
        }
    }
    if n == 0 {
        return (0.0, Vector3::z(), 0.0);
    }
    t /= n as f64;
    m /= n as f64;
    let e = SymmetricEigen::new(t);
    let i = e.eigenvalues.imin();
    (
        e.eigenvalues[i],
        e.eigenvectors.column(i).into_owned(),
        m.norm(),
    )
}

/// Counts of directions by the sensor axis they are closest to, in the order +X, -X, +Y, -Y,
/// +Z, -Z (the six faces of a cube).
pub fn face_counts(dirs: impl Iterator<Item = Vector3<f64>>) -> [usize; 6] {
    let mut c = [0usize; 6];
    for d in dirs {
        let i = d.iamax();
        if d[i] != 0.0 {
            c[2 * i + usize::from(d[i] < 0.0)] += 1;
        }
    }
    c
}

/// Names of the six faces in the order of [`face_counts`].
pub const FACES: [&str; 6] = ["+X", "-X", "+Y", "-Y", "+Z", "-Z"];

/// A face with fewer than this fraction of the readings counts as empty.
pub const EMPTY_FACE: f64 = 0.01;

/// Plain-language coverage warnings from [`face_counts`] and [`direction_spread`].
pub fn coverage_warnings(faces: &[usize; 6], min_spread: f64, weak: &Vector3<f64>) -> Vec<String> {
    let n: usize = faces.iter().sum();
    let empty: Vec<&str> = (0..6)
        .filter(|&i| (faces[i] as f64) < EMPTY_FACE * n as f64)
        .map(|i| FACES[i])
        .collect();
    let mut out = Vec::new();
    if !empty.is_empty() {
        out.push(format!(
            "part of the sphere is empty: no readings point along {} (of {n}): turn the sensor \
             so that each of those axes points up (accelerometer) or along the field \
             (magnetometer) for a while",
            empty.join(", ")
        ));
    } else if min_spread < WARN_MIN_SPREAD {
        out.push(format!(
            "the readings cover only a band of the sphere: few point along {} (spread {:.2}, \
             0.33 when even): turn the sensor so that its {} side points up and then down",
            axis_name(weak, false),
            min_spread,
            axis_name(weak, false)
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_is_a_band_and_cube_faces_are_even() {
        let ring = (0..36).map(|i| {
            let a = i as f64 * 10f64.to_radians();
            Vector3::new(a.cos(), a.sin(), 0.05)
        });
        let (s, weak, m) = direction_spread(ring);
        assert!(s < 0.01 && weak.z.abs() > 0.99 && m < 0.1);
        let w = coverage_warnings(&[9, 9, 9, 9, 0, 0], s, &weak);
        assert!(w[0].contains("+Z, -Z"), "{w:?}");
        let w = coverage_warnings(&[9, 9, 9, 9, 1, 1], s, &weak);
        assert!(w[0].contains("band") && w[0].contains("±Z"), "{w:?}");
        let faces = [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
            -Vector3::z(),
        ];
        let (s, _, m) = direction_spread(faces.into_iter());
        assert!((s - 1.0 / 3.0).abs() < 1e-12 && m < 1e-12);
    }

    #[test]
    fn axis_ratio_bound() {
        let gains = |d: [f64; 3]| {
            crate::geometry::sym3_eigenvalues(&Matrix3::from_diagonal(&Vector3::from(d)))
        };
        assert!(check_gains(gains([1.0, 1.2, 0.9]), "full").is_ok());
        let e = check_gains(gains([2.2, 2.3, 0.2]), "full").unwrap_err();
        assert!(e.to_string().contains("factor of 11.5"), "{e}");
    }
}
