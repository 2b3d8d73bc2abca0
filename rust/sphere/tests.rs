use super::*;

fn sphere_points(c: [f64; 3], r: f64, n: usize) -> Vec<[f64; 3]> {
    // a Fibonacci sphere: deterministic and even coverage
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rr = (1.0 - z * z).sqrt();
            let t = golden * i as f64;
            [
                c[0] + r * rr * t.cos(),
                c[1] + r * rr * t.sin(),
                c[2] + r * z,
            ]
        })
        .collect()
}

fn brute_neighbours(points: &[[f64; 3]], c: [f64; 3], r2: f64, h: f64) -> [f64; 26] {
    let mut out = [0.0; 26];
    for (t, d) in NEIGHBOURS.iter().enumerate() {
        let cc = [
            c[0] + h * d[0] as f64,
            c[1] + h * d[1] as f64,
            c[2] + h * d[2] as f64,
        ];
        out[t] = error_sum(points, cc, r2);
    }
    out
}

#[test]
fn neighbour_sums_match_direct_evaluation() {
    // several blocks and rayon chunks; one block and a point after the groups of four;
    // fewer points than a group
    for n in [70_000, 1001, 7] {
        let pts = sphere_points([100.0, -50.0, 20.0], 1000.0, n);
        for (c, h) in [
            ([0.0, 0.0, 0.0], 1000.0),
            ([90.0, -45.0, 25.0], 10.0),
            ([100.0, -50.0, 20.0], 0.01),
            ([100.0, -50.0, 20.0], 3.0),
        ] {
            let fast = neighbour_sums(&pts, c, 1e6, h);
            let slow = brute_neighbours(&pts, c, 1e6, h);
            for t in 0..26 {
                assert!(
                    (fast[t] - slow[t]).abs() <= 1e-9 * slow[t].max(1.0),
                    "{n} points, {t}: {} vs {}",
                    fast[t],
                    slow[t]
                );
            }
        }
    }
}

#[test]
fn descent_finds_centre_of_exact_sphere() {
    let pts = sphere_points([123.4, -56.7, 8.9], 16384.0, 500);
    let d = descend_center(&pts, 16384.0, DescentOptions::default()).unwrap();
    for k in 0..3 {
        assert!(
            (d.center[k] - [123.4, -56.7, 8.9][k]).abs() < 0.02,
            "{:?}",
            d.center
        );
    }
    assert!(d.converged && d.step < 0.01);
}

#[test]
fn grid_matches_descent_at_the_grid_step() {
    let pts = sphere_points([3.0, -2.0, 1.0], 10.0, 300);
    let g = grid_center(&pts, 10.0, [-5.0; 3], [5.0; 3], 1.0).unwrap();
    assert_eq!(g.center, [3.0, -2.0, 1.0]);
    assert_eq!(g.iterations, 11 * 11 * 11);
}

#[test]
fn grid_refuses_huge_work() {
    let pts = sphere_points([0.0; 3], 1.0, 1000);
    assert!(matches!(
        grid_center(&pts, 1.0, [-1e4; 3], [1e4; 3], 0.01),
        Err(CalError::InvalidArgument(_))
    ));
}

#[test]
fn linear_fit_exact() {
    let pts = sphere_points([1e4, -2e4, 500.0], 16384.0, 100);
    let f = fit_sphere_linear(&pts).unwrap();
    assert!((f.center[0] - 1e4).abs() < 1e-6 && (f.radius - 16384.0).abs() < 1e-6);
    assert!(f.rms < 1e-6);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let mut pts = sphere_points([0.0; 3], 1.0, 10);
    pts[3][1] = f64::NAN;
    assert_eq!(
        fit_sphere_linear(&pts),
        Err(CalError::NonFinite { index: 3 })
    );
    assert!(matches!(
        fit_sphere_linear(&pts[..2]),
        Err(CalError::NonFinite { .. }) | Err(CalError::TooFewPoints { .. })
    ));
    let ok = sphere_points([0.0; 3], 1.0, 10);
    assert!(matches!(
        descend_center(&ok, -1.0, DescentOptions::default()),
        Err(CalError::InvalidArgument(_))
    ));
    let o = DescentOptions {
        shrink: 1.0,
        ..Default::default()
    };
    assert!(matches!(
        descend_center(&ok, 1.0, o),
        Err(CalError::InvalidArgument(_))
    ));
}
