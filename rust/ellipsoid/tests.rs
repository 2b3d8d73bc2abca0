use super::*;
use proptest::prelude::*;

/// Fibonacci sphere mapped through `W⁻¹` and shifted by `offset`.
pub(crate) fn ellipsoid_points(
    offset: [f64; 3],
    w: Matrix3<f64>,
    r: f64,
    n: usize,
) -> Vec<[f64; 3]> {
    let winv = w.try_inverse().unwrap();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rr = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            let f = Vector3::new(rr * t.cos(), rr * t.sin(), z) * r;
            let p = winv * f + Vector3::from(offset);
            [p.x, p.y, p.z]
        })
        .collect()
}

#[test]
fn recovers_exact_full_model() {
    let w = Matrix3::new(1.1, 0.05, -0.02, 0.05, 0.9, 0.03, -0.02, 0.03, 1.05) / 16384.0;
    let pts = ellipsoid_points([300.0, -200.0, 150.0], w, 1.0, 400);
    let f = fit_ellipsoid(
        &pts,
        &FitOptions {
            radius: Some(1.0),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(f.converged);
    for k in 0..3 {
        assert!(
            (f.offset[k] - [300.0, -200.0, 150.0][k]).abs() < 1e-6,
            "{:?}",
            f.offset
        );
        for j in 0..3 {
            assert!((f.matrix[k][j] - w[(k, j)]).abs() < 1e-12, "{:?}", f.matrix);
        }
    }
    assert!(f.rms < 1e-10);
}

#[test]
fn large_input_takes_the_subsample_path() {
    let w = Matrix3::new(1.02, 0.01, 0.0, 0.01, 0.98, 0.0, 0.0, 0.0, 1.0);
    let pts = ellipsoid_points([0.1, 0.2, -0.3], w, 9.80665, 100_000);
    let f = fit_ellipsoid(
        &pts,
        &FitOptions {
            radius: Some(9.80665),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(f.converged && f.rms < 1e-9, "{f:?}");
    // readings spread evenly over the sphere: no coverage warning, whatever the size of the
    // subsample the coverage is measured on (it once read as "only a band of the sphere")
    assert!(f.warnings.is_empty(), "{:?}", f.warnings);
    for n in [60_001, 250_000] {
        let pts = ellipsoid_points([0.1, 0.2, -0.3], w, 9.80665, n);
        let f = fit_ellipsoid(&pts, &FitOptions::default()).unwrap();
        assert!(f.warnings.is_empty(), "{n}: {:?}", f.warnings);
    }
}

#[test]
fn own_scale_has_unit_determinant() {
    let w = Matrix3::from_diagonal(&Vector3::new(1.5, 1.0, 0.7));
    let pts = ellipsoid_points([1.0, 2.0, 3.0], w, 5.0, 200);
    let f = fit_ellipsoid(
        &pts,
        &FitOptions {
            model: Model::Axis,
            ..Default::default()
        },
    )
    .unwrap();
    let m = Matrix3::from_fn(|i, j| f.matrix[i][j]);
    assert!((m.determinant() - 1.0).abs() < 1e-9);
    let want = 5.0 / w.determinant().cbrt(); // W_unit = w / 5, radius = det(W_unit)^(-1/3)
    assert!((f.radius - want).abs() < 1e-9, "{} vs {want}", f.radius);
}

#[test]
fn too_few_points_and_cap_errors() {
    let pts = ellipsoid_points([0.0; 3], Matrix3::identity(), 1.0, 8);
    assert!(matches!(
        fit_ellipsoid(&pts, &FitOptions::default()),
        Err(CalError::TooFewPoints { need: 9, .. })
    ));
    // a thin cap: all points within ~3 degrees of the north pole
    let cap: Vec<[f64; 3]> = (0..200)
        .map(|i| {
            let t = i as f64 * 0.7;
            let a = 0.05 * ((i % 7) as f64 / 7.0 + 0.1);
            [a * t.cos(), a * t.sin(), (1.0 - a * a).sqrt()]
        })
        .collect();
    let e = fit_ellipsoid(&cap, &FitOptions::default()).unwrap_err();
    assert!(matches!(e, CalError::Degenerate { .. }), "{e}");
}

#[test]
fn six_points_solve_the_axis_model_exactly() {
    let w = Matrix3::from_diagonal(&Vector3::new(1.02, 0.97, 1.01)) / 16384.0;
    let winv = w.try_inverse().unwrap();
    let faces = [
        Vector3::x(),
        -Vector3::x(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::z(),
        -Vector3::z(),
    ];
    let pts: Vec<[f64; 3]> = faces
        .iter()
        .map(|f| {
            let p = winv * (f + Vector3::new(0.01, -0.02, 0.015)).normalize()
                + Vector3::new(300.0, -200.0, 50.0);
            [p.x, p.y, p.z]
        })
        .collect();
    let opts = FitOptions {
        model: Model::Axis,
        radius: Some(1.0),
        ..Default::default()
    };
    let f = fit_ellipsoid(&pts, &opts).unwrap();
    assert!(
        f.rms < 1e-12 && f.stderr.iter().all(|v| v.is_nan()),
        "{f:?}"
    );
    assert!(f.warnings.iter().any(|w| w.contains("exactly determined")));
    assert!(matches!(
        fit_ellipsoid(&pts[..5], &opts),
        Err(CalError::TooFewPoints { need: 6, .. })
    ));
}

#[test]
fn fixed_gain_sphere_fits_the_centre_only() {
    let pts = ellipsoid_points([10.0, -20.0, 30.0], Matrix3::identity() / 100.0, 1.0, 200);
    // a 60 degree cap around +z
    let cap: Vec<[f64; 3]> = pts.iter().filter(|p| p[2] - 30.0 > 50.0).copied().collect();
    let mut fixed = [None; 9];
    fixed[3] = Some(1.0);
    let opts = FitOptions {
        model: Model::Sphere,
        radius: Some(100.0),
        fixed,
        ..Default::default()
    };
    let f = fit_ellipsoid(&cap, &opts).unwrap();
    for k in 0..3 {
        assert!(
            (f.offset[k] - [10.0, -20.0, 30.0][k]).abs() < 1e-8,
            "{:?}",
            f.offset
        );
    }
    assert_eq!(
        f.matrix,
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    assert_eq!(f.stderr[3], 0.0);
}

#[test]
fn large_inputs_do_not_depend_on_point_order() {
    let w = Matrix3::new(1.02, 0.01, 0.0, 0.01, 0.98, 0.0, 0.0, 0.0, 1.0);
    let mut pts = ellipsoid_points([0.1, 0.2, -0.3], w, 1.0, 70_001);
    // a little deterministic "noise" so that the minimum is not exact
    for (i, p) in pts.iter_mut().enumerate() {
        p[0] += 1e-3 * ((i * 7919 % 1000) as f64 / 500.0 - 1.0);
    }
    let a = fit_ellipsoid(&pts, &FitOptions::default()).unwrap();
    pts.reverse();
    pts.rotate_left(12_345);
    let b = fit_ellipsoid(&pts, &FitOptions::default()).unwrap();
    for k in 0..3 {
        assert!((a.offset[k] - b.offset[k]).abs() < 1e-12, "{a:?} {b:?}");
        for j in 0..3 {
            assert!((a.matrix[k][j] - b.matrix[k][j]).abs() < 1e-12);
        }
    }
}

#[test]
fn huge_and_tiny_magnitudes_are_rescaled_exactly() {
    let w = Matrix3::from_diagonal(&Vector3::new(1.1, 0.9, 1.0));
    let pts = ellipsoid_points([0.1, 0.2, -0.3], w, 1.0, 300);
    let base = fit_ellipsoid(
        &pts,
        &FitOptions {
            radius: Some(1.0),
            ..Default::default()
        },
    )
    .unwrap();
    for k in [1e200, 1e-200, 1e300] {
        let big: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|v| v * k)).collect();
        let f = fit_ellipsoid(
            &big,
            &FitOptions {
                radius: Some(1.0),
                ..Default::default()
            },
        )
        .unwrap();
        for i in 0..3 {
            assert!((f.offset[i] / k - base.offset[i]).abs() < 1e-9);
            assert!((f.matrix[i][i] * k - base.matrix[i][i]).abs() < 1e-9);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn recovers_random_offset_and_matrix(
        ox in -500.0..500.0f64, oy in -500.0..500.0f64, oz in -500.0..500.0f64,
        d in proptest::array::uniform3(0.8..1.25f64), e in proptest::array::uniform3(-0.08..0.08f64),
    ) {
        let w = Matrix3::new(d[0], e[0], e[1], e[0], d[1], e[2], e[1], e[2], d[2]) / 1000.0;
        let pts = ellipsoid_points([ox, oy, oz], w, 1.0, 300);
        let f = fit_ellipsoid(&pts, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
        for k in 0..3 {
            prop_assert!((f.offset[k] - [ox, oy, oz][k]).abs() < 1e-6);
            for j in 0..3 {
                prop_assert!((f.matrix[k][j] - w[(k, j)]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn invariant_under_translation_and_rotation(tx in -1e4..1e4f64, angle in 0.0..std::f64::consts::TAU) {
        let w = Matrix3::new(1.1, 0.0, 0.0, 0.0, 0.95, 0.0, 0.0, 0.0, 1.0);
        let pts = ellipsoid_points([0.0; 3], w, 1.0, 200);
        let f0 = fit_ellipsoid(&pts, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
        let rot = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), angle);
        let moved: Vec<[f64; 3]> = pts.iter().map(|p| {
            let v = rot * Vector3::new(p[0], p[1], p[2]) + Vector3::new(tx, -tx, 0.5 * tx);
            [v.x, v.y, v.z]
        }).collect();
        let f1 = fit_ellipsoid(&moved, &FitOptions { radius: Some(1.0), ..Default::default() }).unwrap();
        let want = rot * Vector3::from(f0.offset) + Vector3::new(tx, -tx, 0.5 * tx);
        for k in 0..3 { prop_assert!((f1.offset[k] - want[k]).abs() < 1e-6 * (1.0 + tx.abs())); }
        let w0 = Matrix3::from_fn(|i, j| f0.matrix[i][j]);
        let w1 = Matrix3::from_fn(|i, j| f1.matrix[i][j]);
        let w0r = rot.matrix() * w0 * rot.matrix().transpose();
        prop_assert!((w1 - w0r).norm() < 1e-8);
        prop_assert!((f1.rms - f0.rms).abs() < 1e-9);
    }
}
