//! Tests of `allan.rs` (kept apart to keep that module short).

use super::*;

/// The textbook formula, straight from the phase (f64; fine for small inputs).
fn naive(y: &[f64], m: usize, stride: usize) -> (f64, usize) {
    let mut x = vec![0.0];
    for v in y {
        x.push(x.last().unwrap() + v);
    }
    let n = y.len();
    let mut s = 0.0;
    let mut terms = 0;
    let mut i = 0;
    while i + 2 * m <= n {
        let t = x[i + 2 * m] - 2.0 * x[i + m] + x[i];
        s += t * t;
        terms += 1;
        i += stride;
    }
    ((s / (2.0 * terms as f64)).sqrt() / m as f64, terms)
}

fn lcg(n: usize, seed: u64) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        })
        .collect()
}

#[test]
fn matches_the_formula_in_any_chunking() {
    let y = lcg(20_000, 7);
    let ms = [1u64, 2, 3, 7, 64, 1000, 4999];
    for chunk in [1usize, 3, 4096, 5000, 20_000] {
        let mut acc = Allan::new(10.0, 1, &ms, None).unwrap();
        for c in y.chunks(chunk) {
            acc.push(c).unwrap();
        }
        let r = acc.result();
        for (ci, c) in r.clusters.iter().enumerate() {
            let (want, terms) = naive(&y, c.m as usize, 1);
            assert_eq!(r.terms[ci], terms as u64);
            assert!(
                (r.adev[ci][0] - want).abs() <= 1e-12 * want,
                "chunk {chunk} m {}: {} vs {want}",
                c.m,
                r.adev[ci][0]
            );
            assert!((r.taus[ci] - c.m as f64 / 10.0).abs() < 1e-15);
        }
    }
}

#[test]
fn many_batches_of_three_axes_match_the_formula() {
    let n = 3 * BATCH + 123;
    let cols: Vec<Vec<f64>> = (0..3).map(|k| lcg(n, 10 + k)).collect();
    let rows: Vec<f64> = (0..n)
        .flat_map(|i| [cols[0][i], cols[1][i], cols[2][i]])
        .collect();
    let ms = [1u64, 2, 5, 1024, 20_000];
    for parallel in [false, true] {
        let mut acc = Allan::new(10.0, 3, &ms, None).unwrap();
        acc.set_parallel(parallel);
        acc.push(&rows).unwrap();
        let r = acc.result();
        let mut na = Allan::non_overlapping(10.0, 3, &ms).unwrap();
        na.set_parallel(parallel);
        na.push(&rows[..3 * 1000]).unwrap();
        na.push(&rows[3 * 1000..]).unwrap();
        let rn = na.result();
        for (ci, c) in r.clusters.iter().enumerate() {
            for k in 0..3 {
                let (want, terms) = naive(&cols[k], c.m as usize, 1);
                assert_eq!(r.terms[ci], terms as u64);
                assert!(
                    (r.adev[ci][k] - want).abs() <= 1e-12 * want,
                    "m {} axis {k}",
                    c.m
                );
                let (want, terms) = naive(&cols[k], c.m as usize, c.m as usize);
                assert_eq!(rn.terms[ci], terms as u64);
                assert!(
                    (rn.adev[ci][k] - want).abs() <= 1e-12 * want,
                    "adev m {}",
                    c.m
                );
            }
        }
    }
}

#[test]
fn strided_levels_match_the_strided_formula() {
    let y = lcg(300_000, 3);
    let ms = [5000u64, 9000, 70_000];
    let r = oadev(&y, 1, 1.0, &ms, Some(4096)).unwrap();
    for (ci, c) in r.clusters.iter().enumerate() {
        assert!(c.stride > 1 && c.m / c.stride >= DECIMATED_STARTS);
        let (want, terms) = naive(&y, c.m as usize, c.stride as usize);
        assert_eq!(r.terms[ci], terms as u64);
        assert!((r.adev[ci][0] - want).abs() <= 1e-11 * want);
    }
}

#[test]
fn axes_are_independent_and_offsets_do_not_matter() {
    let a = lcg(10_000, 1);
    let b = lcg(10_000, 2);
    let rows: Vec<f64> = a
        .iter()
        .zip(&b)
        .flat_map(|(x, y)| [*x + 1e6, *y * 3.0])
        .collect();
    let r = oadev(&rows, 2, 1.0, &[1, 10, 100], None).unwrap();
    for (ci, c) in r.clusters.iter().enumerate() {
        let wa = naive(&a, c.m as usize, 1).0;
        let wb = naive(&b, c.m as usize, 1).0 * 3.0;
        // a bias of 1e6 times the noise costs no digits (double-double phase)
        assert!(
            (r.adev[ci][0] - wa).abs() <= 1e-9 * wa,
            "{} {wa}",
            r.adev[ci][0]
        );
        assert!((r.adev[ci][1] - wb).abs() <= 1e-12 * wb);
    }
}

#[test]
fn bad_input_is_an_error_and_leaves_the_state_alone() {
    assert!(Allan::new(0.0, 1, &[1], None).is_err());
    assert!(Allan::new(1.0, 0, &[1], None).is_err());
    assert!(Allan::new(1.0, 1, &[0], None).is_err());
    assert!(Allan::new(1.0, 1, &[], None).is_err());
    assert!(Allan::new(1.0, 1, &[1 << 40], None).is_err());
    let mut acc = Allan::new(1.0, 2, &[1], None).unwrap();
    assert!(acc.push(&[1.0, 2.0, 3.0]).is_err());
    let e = acc.push(&[1.0, 2.0, f64::NAN, 0.0]).unwrap_err();
    assert!(e.to_string().contains("row 1"), "{e}");
    assert!(acc.is_empty());
}

#[test]
fn memory_is_fixed_by_the_clusters_not_the_samples() {
    let ms: Vec<u64> = (0..40).map(|k| 1u64 << k).collect();
    let acc = Allan::new(1000.0, 3, &ms, Some(65_536)).unwrap();
    assert!(acc.memory_bytes() < 40_000_000, "{}", acc.memory_bytes());
}

/// Integer readings on a large bias: every block sum and term is an integer, so the exact
/// non-overlapping deviation is known (sums of squares in u128).
fn exact_adev_of_integers(y: &[i64], m: usize) -> (f64, u64) {
    let blocks: Vec<i128> = y
        .chunks_exact(m)
        .map(|c| c.iter().map(|&v| v as i128).sum())
        .collect();
    let s: u128 = blocks
        .windows(2)
        .map(|w| ((w[1] - w[0]) * (w[1] - w[0])) as u128)
        .sum();
    let terms = blocks.len().saturating_sub(1) as u64;
    (((s as f64) / (2.0 * terms as f64)).sqrt() / m as f64, terms)
}

#[test]
fn the_pyramid_of_block_sums_is_exact_on_integers_in_any_chunking() {
    // readings of 2^40 plus small integer noise (a random walk and white noise): 2^40 times the
    // noise; the block sums of 2^17 samples reach 2^57, past a double's 53 bits
    let n = 2 * BATCH + 4099;
    let mut s = 12345u64;
    let mut walk = 0i64;
    let y: Vec<i64> = (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            walk += ((s >> 60) as i64) - 8;
            (1i64 << 40) + walk + ((s >> 33) & 0xff) as i64
        })
        .collect();
    let yf: Vec<f64> = y.iter().map(|&v| v as f64).collect();
    let ms: Vec<u64> = (0..16).map(|k| 1u64 << k).collect();
    for chunk in [1usize, 7, 4096, BATCH + 1, n] {
        for pyramid in [true, false] {
            let mut acc = Allan::non_overlapping_with(100.0, 1, &ms, pyramid).unwrap();
            assert_eq!(acc.octave.is_some(), pyramid);
            for c in yf.chunks(chunk) {
                acc.push(c).unwrap();
            }
            let r = acc.result();
            assert_eq!(r.n, n as u64);
            for (ci, c) in r.clusters.iter().enumerate() {
                assert_eq!(c.stride, c.m);
                let (want, terms) = exact_adev_of_integers(&y, c.m as usize);
                assert_eq!(r.terms[ci], terms, "m {}", c.m);
                if terms == 0 {
                    assert!(r.adev[ci][0].is_nan());
                    continue;
                }
                assert!(
                    (r.adev[ci][0] - want).abs() <= 1e-14 * want,
                    "pyramid {pyramid} chunk {chunk} m {}: {} vs exact {want}",
                    c.m,
                    r.adev[ci][0]
                );
            }
        }
    }
}

#[test]
fn the_pyramid_matches_the_general_path_on_three_axes_in_parallel() {
    let n = 5 * BATCH + 77;
    let rows: Vec<f64> = lcg(3 * n, 99)
        .iter()
        .enumerate()
        .map(|(i, v)| 250.0 * (i % 3) as f64 + v)
        .collect();
    let ms: Vec<u64> = vec![1, 2, 8, 64, 1 << 12, 1 << 15];
    let mut general = Allan::non_overlapping_with(50.0, 3, &ms, false).unwrap();
    general.push(&rows).unwrap();
    let want = general.result();
    for parallel in [false, true] {
        let mut acc = Allan::non_overlapping(50.0, 3, &ms).unwrap();
        assert!(acc.octave.is_some());
        acc.set_parallel(parallel);
        acc.push(&rows[..3 * 5000]).unwrap();
        acc.push(&rows[3 * 5000..]).unwrap();
        let r = acc.result();
        assert_eq!(r.terms, want.terms);
        assert_eq!(r.taus, want.taus);
        assert_eq!(r.clusters, want.clusters);
        for (ci, dev) in r.adev.iter().enumerate() {
            for k in 0..3 {
                let w = want.adev[ci][k];
                assert!((dev[k] - w).abs() <= 1e-13 * w, "m {} axis {k}", ms[ci]);
            }
        }
    }
    // a size that is not a power of two takes the general path
    assert!(Allan::non_overlapping(50.0, 3, &[1, 3])
        .unwrap()
        .octave
        .is_none());
    // an axis with nothing yet past the last level reports NaN, with 0 terms
    let mut few = Allan::non_overlapping(50.0, 1, &[1, 1 << 10]).unwrap();
    few.push(&[1.0, 2.0, 4.0]).unwrap();
    let r = few.result();
    assert_eq!(r.terms, vec![2, 0]);
    assert!((r.adev[0][0] - (2.5f64 / 2.0).sqrt()).abs() < 1e-15);
    assert!(r.adev[1][0].is_nan());
    // a non-finite value adds nothing, even one batch after the first
    assert!(few.push(&[1.0, f64::INFINITY]).is_err());
    assert_eq!(few.len(), 3);
    let mut late = vec![3.0; 2 * BATCH + 10];
    late[BATCH + 5] = f64::NAN;
    let e = few.push(&late).unwrap_err();
    assert!(
        e.to_string().contains(&format!("row {}", 3 + BATCH + 5)),
        "{e}"
    );
    assert_eq!(format!("{:?}", few.result()), format!("{r:?}"));
}

#[test]
fn the_pyramid_matches_the_general_path_for_any_number_of_axes() {
    // axes are taken four to a record: one to seven axes make full and partial groups; pushes
    // of odd lengths leave blocks waiting for their pairs, and end on rows whose four-wide
    // load would run past the slice
    let n = 2 * BATCH + 3001;
    let ms: Vec<u64> = (0..13).map(|k| 1u64 << k).collect();
    for nax in 1..=7 {
        let rows: Vec<f64> = lcg(nax * n, 11 + nax as u64)
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let (row, axis) = (i / nax, i % nax);
                1e3 * axis as f64 - 7.0 + v * (1 + axis) as f64 + row as f64 * 1e-5 * axis as f64
            })
            .collect();
        let mut general = Allan::non_overlapping_with(10.0, nax, &ms, false).unwrap();
        general.push(&rows).unwrap();
        let want = general.result();
        for cuts in [vec![n], vec![1, 2, 777, BATCH + 1, n], vec![4999, n - 1, n]] {
            let mut acc = Allan::non_overlapping(10.0, nax, &ms).unwrap();
            assert!(acc.octave.is_some());
            let mut from = 0;
            for &to in &cuts {
                acc.push(&rows[nax * from..nax * to]).unwrap();
                from = to;
            }
            let r = acc.result();
            assert_eq!(r.terms, want.terms);
            for (ci, dev) in r.adev.iter().enumerate() {
                assert_eq!(dev.len(), nax);
                for k in 0..nax {
                    let w = want.adev[ci][k];
                    assert!(
                        (dev[k] - w).abs() <= 1e-13 * w,
                        "{nax} axes, cuts {cuts:?}, m {}, axis {k}: {} vs {w}",
                        ms[ci],
                        dev[k]
                    );
                }
            }
        }
    }
}

#[test]
fn pieces_join_to_the_general_path_whatever_the_threads_and_the_chunks() {
    // 5 pieces of 2^16 rows and a short one; pushes that start and end off the boundaries
    let n = 5 * (1 << 16) + 9001;
    let rows: Vec<f64> = lcg(3 * n, 7)
        .iter()
        .enumerate()
        .map(|(i, v)| 1e6 * (1 + i % 3) as f64 + v + (i / 3) as f64 * 1e-3)
        .collect();
    let ms: Vec<u64> = (0..15).map(|k| 1u64 << k).collect();
    let mut general = Allan::non_overlapping_with(50.0, 3, &ms, false).unwrap();
    general.push(&rows).unwrap();
    let want = general.result();
    let mut seen: Option<AllanResult> = None;
    for cuts in [
        vec![n],
        vec![1, 70_000, n],
        vec![65_535, 65_537, 200_000, n],
    ] {
        for parallel in [false, true] {
            let mut acc = Allan::non_overlapping(50.0, 3, &ms).unwrap();
            acc.set_parallel(parallel);
            let mut from = 0;
            for &to in &cuts {
                acc.push(&rows[3 * from..3 * to]).unwrap();
                from = to;
            }
            let r = acc.result();
            assert_eq!(r.terms, want.terms);
            for (ci, dev) in r.adev.iter().enumerate() {
                for k in 0..3 {
                    let w = want.adev[ci][k];
                    assert!(
                        (dev[k] - w).abs() <= 1e-13 * w,
                        "cuts {cuts:?} m {} axis {k}: {} vs {w}",
                        ms[ci],
                        dev[k]
                    );
                }
            }
            if cuts.len() == 1 {
                // the same pieces joined in the same order, on one thread or two
                match &seen {
                    None => seen = Some(r),
                    Some(s) => assert_eq!(format!("{s:?}"), format!("{r:?}")),
                }
            }
        }
    }
    // a non-finite value in a later piece adds nothing, and is named by its row
    let mut acc = Allan::non_overlapping(50.0, 3, &ms).unwrap();
    acc.push(&rows[..3 * 1000]).unwrap();
    let before = format!("{:?}", acc.result());
    let mut bad = rows[3 * 1000..].to_vec();
    let row = 3 * (1 << 16) + 17;
    bad[3 * row + 2] = f64::NEG_INFINITY;
    bad[3 * (row + 5)] = f64::NAN;
    let e = acc.push(&bad).unwrap_err();
    assert_eq!(
        e,
        CalError::NonFiniteSample {
            row: 1000 + row as u64,
            axis: 2
        }
    );
    assert!(
        e.to_string()
            .contains(&format!("row {} of the stream", 1000 + row)),
        "{e}"
    );
    assert_eq!(format!("{:?}", acc.result()), before);
}

/// Three axes, one of them on a large bias and one drifting, `n` rows.
fn three_axes(n: usize) -> Vec<f64> {
    let cols: Vec<Vec<f64>> = (0..3).map(|k| lcg(n, 40 + k)).collect();
    (0..n)
        .flat_map(|i| {
            let drift = 1e-4 * i as f64;
            [
                cols[0][i] + 1e6,
                cols[1][i] * 3.0 + drift,
                cols[2][i] * 1e-3,
            ]
        })
        .collect()
}

#[test]
fn the_cascade_of_window_sums_matches_the_general_path_in_any_chunking() {
    // sixteen levels in two stages, and three in one
    for top in [15u32, 2] {
        cascade_matches_the_general_path(top);
    }
}

fn cascade_matches_the_general_path(top: u32) {
    let ms: Vec<u64> = (0..=top).map(|k| 1u64 << k).collect();
    for n in [5usize, 3 * BATCH + 123, 70_001] {
        let rows = three_axes(n);
        let mut general = Allan::new_with(100.0, 3, &ms, None, false).unwrap();
        general.push(&rows).unwrap();
        let want = general.result();
        for (chunk, parallel) in [
            (1, false),
            (7, true),
            (4096, true),
            (BATCH + 5, false),
            (n, true),
        ] {
            if chunk == 1 && n > 10_000 {
                continue;
            }
            let mut acc = Allan::new(100.0, 3, &ms, None).unwrap();
            assert!(acc.cascade.is_some());
            acc.set_parallel(parallel);
            for c in rows.chunks(3 * chunk) {
                acc.push(c).unwrap();
            }
            let r = acc.result();
            assert_eq!(r.terms, want.terms);
            assert_eq!(r.clusters, want.clusters);
            for (ci, c) in r.clusters.iter().enumerate() {
                for k in 0..3 {
                    let (got, w) = (r.adev[ci][k], want.adev[ci][k]);
                    if want.terms[ci] == 0 {
                        assert!(got.is_nan() && w.is_nan());
                    } else {
                        assert!(
                            (got - w).abs() <= 1e-12 * w,
                            "n {n} chunk {chunk} m {} axis {k}: {got} vs {w}",
                            c.m
                        );
                    }
                }
            }
        }
        // whole pushes: the same bits on one thread and on several
        let mut one = Allan::new(100.0, 3, &ms, None).unwrap();
        one.set_parallel(false);
        one.push(&rows).unwrap();
        let mut two = Allan::new(100.0, 3, &ms, None).unwrap();
        two.push(&rows).unwrap();
        let bits =
            |r: AllanResult| -> Vec<u64> { r.adev.iter().flatten().map(|v| v.to_bits()).collect() };
        let want = bits(one.result());
        assert_eq!(bits(two.result()), want);
        // and on pools of other sizes (more threads than the cores, too)
        for threads in [1, 3, 5] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let got = pool.install(|| {
                let mut acc = Allan::new(100.0, 3, &ms, None).unwrap();
                acc.push(&rows).unwrap();
                bits(acc.result())
            });
            assert_eq!(got, want, "{threads} threads");
        }
    }
}

#[test]
fn the_cascade_is_exact_on_integers_on_a_bias() {
    // integer readings: every term of the formula is an integer, summed exactly in i128
    let n = 50_000usize;
    let y: Vec<i64> = lcg(n, 9)
        .iter()
        .map(|v| 1_000_000 + (v * 2000.0).round() as i64)
        .collect();
    let ms: Vec<u64> = (0..15).map(|k| 1u64 << k).collect();
    let yf: Vec<f64> = y.iter().map(|&v| v as f64).collect();
    // in pushes shorter than the long clusters, whose rings then swap in place
    let mut acc = Allan::new(1.0, 1, &ms, None).unwrap();
    for c in yf.chunks(1000) {
        acc.push(c).unwrap();
    }
    let r = acc.result();
    let mut x = vec![0i128];
    for &v in &y {
        x.push(x.last().unwrap() + v as i128);
    }
    for (ci, &m) in ms.iter().enumerate() {
        let m = m as usize;
        let s: i128 = (0..=n - 2 * m)
            .map(|i| {
                let t = x[i + 2 * m] - 2 * x[i + m] + x[i];
                t * t
            })
            .sum();
        let terms = (n - 2 * m + 1) as f64;
        let want = (s as f64 / (2.0 * terms)).sqrt() / m as f64;
        assert!(
            (r.adev[ci][0] - want).abs() <= 1e-14 * want,
            "m {m}: {} vs {want}",
            r.adev[ci][0]
        );
    }
}

#[test]
fn a_large_push_with_a_nan_names_its_first_row_and_adds_nothing() {
    let ms: Vec<u64> = (0..10).map(|k| 1u64 << k).collect();
    for cascade in [true, false] {
        let mut acc = Allan::new_with(10.0, 3, &ms, None, cascade).unwrap();
        acc.push(&three_axes(1000)).unwrap();
        let before = format!("{:?}", acc.result());
        // a push of 600,000 values with a NaN and, earlier, an infinity
        let mut rows = three_axes(200_000);
        rows[3 * 150_000 + 1] = f64::NAN;
        rows[3 * 70_001 + 2] = f64::INFINITY;
        let e = acc.push(&rows).unwrap_err();
        assert_eq!(
            e,
            CalError::NonFiniteSample {
                row: 1000 + 70_001,
                axis: 2
            }
        );
        assert_eq!(format!("{:?}", acc.result()), before);
        assert_eq!(acc.len(), 1000);
    }
}
