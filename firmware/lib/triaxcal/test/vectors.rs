//! Test vectors for the C library in `firmware/lib/triaxcal`: point sets, and what the Rust
//! core (`sphere::descend_center`, `ellipsoid::fit_ellipsoid` with the "axis" and "full"
//! models) makes of them, written as a C header.
//!
//! ```text
//! cargo run --release --no-default-features --example firmware_vectors \
//!     > firmware/lib/triaxcal/test/vectors.h
//! ```
//!
//! Every coordinate is rounded to the nearest float32 first, so that the C library's float
//! build reads exactly the points the core fitted. The fits are the plain geometric fit
//! (`debias: false`; the C library has no noise correction, see `triaxcal.h`), converged to
//! round-off (`tol` 1e-14). Errors become
//! the C library's codes (`enum tc_code`), warnings its `TC_WARN_*` bits, by their wording.

use triaxcal::ellipsoid::{fit_ellipsoid, FitOptions, Model};
use triaxcal::error::CalError;
use triaxcal::sphere::{descend_center, DescentOptions};

/// The fits' tolerance: converged to round-off (the default, 1e-10, stops up to a few 1e-6 of
/// the radius short of the minimum on the noisiest sets, where the C library goes on).
const REFERENCE_TOL: f64 = 1e-14;

/// xorshift64*: deterministic uniform numbers in (0, 1).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.next(), self.next());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
    fn unit(&mut self) -> [f64; 3] {
        let u = [self.normal(), self.normal(), self.normal()];
        let r = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        u.map(|v| v / r)
    }
}

/// `offset + minv u + noise`, rounded to float32.
fn reading(
    u: [f64; 3],
    offset: [f64; 3],
    minv: [[f64; 3]; 3],
    noise: f64,
    rng: &mut Rng,
) -> [f64; 3] {
    let mut p = [0.0; 3];
    for i in 0..3 {
        let v = offset[i] + minv[i][0] * u[0] + minv[i][1] * u[1] + minv[i][2] * u[2];
        p[i] = (v + noise * rng.normal()) as f32 as f64;
    }
    p
}

fn diag(d: [f64; 3]) -> [[f64; 3]; 3] {
    [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
}

fn sph(lat: f64, lon: f64) -> [f64; 3] {
    let (la, lo) = (lat.to_radians(), lon.to_radians());
    [la.cos() * lo.cos(), la.cos() * lo.sin(), la.sin()]
}

struct Case {
    name: &'static str,
    points: Vec<[f64; 3]>,
    radius: f64,
    descent: DescentOptions,
}

fn seed_opts() -> DescentOptions {
    DescentOptions::default()
}

fn scaled_opts(step: f64, min_step: f64) -> DescentOptions {
    DescentOptions {
        step,
        min_step,
        ..DescentOptions::default()
    }
}

fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let mut rng = Rng(0x5eed_1234_abcd_ef01);
    // The sphere-centre method's globe: 7 latitudes x 12 turns, pose means of an MPU-6050 at +-2 g (noise of
    // a mean of 100 samples), small cross-axis terms.
    let minv = [
        [16630.0, 40.0, -25.0],
        [40.0, 16120.0, 31.0],
        [-25.0, 31.0, 16450.0],
    ];
    let mut pts = Vec::new();
    for lat in 0..7 {
        for turn in 0..12 {
            let u = sph(-90.0 + 30.0 * lat as f64, 30.0 * turn as f64);
            pts.push(reading(u, [180.0, -240.0, 350.0], minv, 0.3, &mut rng));
        }
    }
    out.push(Case {
        name: "globe84",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // 26 directions (the cube's faces, edges and corners), single noisy samples
    let mut pts = Vec::new();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) == (0, 0, 0) {
                    continue;
                }
                let n = ((x * x + y * y + z * z) as f64).sqrt();
                let u = [x as f64 / n, y as f64 / n, z as f64 / n];
                pts.push(reading(
                    u,
                    [-512.0, 300.0, 45.0],
                    diag([16400.0, 16300.0, 16500.0]),
                    3.0,
                    &mut rng,
                ));
            }
        }
    }
    out.push(Case {
        name: "cube26",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // a magnetometer in uT: hard and soft iron, random directions
    let field = 48.0;
    let si = [[1.05, 0.04, -0.02], [0.04, 0.97, 0.03], [-0.02, 0.03, 1.01]];
    let minv = si.map(|r| r.map(|v| v * field));
    let pts = (0..60)
        .map(|_| {
            let u = rng.unit();
            reading(u, [12.5, -30.25, 45.0], minv, 0.4, &mut rng)
        })
        .collect();
    out.push(Case {
        name: "mag60",
        points: pts,
        radius: field,
        descent: scaled_opts(10.0, 1e-4),
    });
    // an accelerometer in g
    let pts = (0..40)
        .map(|_| {
            let u = rng.unit();
            reading(
                u,
                [0.02, -0.015, 0.03],
                diag([1.02, 0.98, 1.01]),
                0.002,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "accel_g40",
        points: pts,
        radius: 1.0,
        descent: scaled_opts(0.1, 1e-6),
    });
    // the fixed-step descent of the sphere-centre method's first listing (step 1 count)
    let pts = (0..30)
        .map(|_| {
            let u = rng.unit();
            reading(u, [31.0, -17.0, 8.0], diag([16384.0; 3]), 2.0, &mut rng)
        })
        .collect();
    out.push(Case {
        name: "fixed_step",
        points: pts,
        radius: 16384.0,
        descent: scaled_opts(1.0, 1.0),
    });
    // a cap: directions within 60 degrees of +Z only
    let pts = (0..30)
        .map(|_| {
            let mut u = rng.unit();
            u[2] = u[2].abs() * 0.5 + 0.5;
            let r = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            let u = u.map(|v| v / r);
            reading(
                u,
                [100.0, 50.0, -80.0],
                diag([16500.0, 16250.0, 16400.0]),
                2.0,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "cap",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // a band: within 8 degrees of the equator
    let pts = (0..36)
        .map(|i| {
            let u = sph(8.0 * (2.0 * rng.next() - 1.0), 10.0 * i as f64);
            reading(
                u,
                [100.0, 50.0, -80.0],
                diag([16500.0, 16250.0, 16400.0]),
                2.0,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "band",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // a band of 1 degree: the full model's gains along z are not determined
    let pts = (0..36)
        .map(|i| {
            let u = sph(1.0 * (2.0 * rng.next() - 1.0), 10.0 * i as f64);
            reading(
                u,
                [100.0, 50.0, -80.0],
                diag([16500.0, 16250.0, 16400.0]),
                2.0,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "band1",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // a cap of 20 degrees
    let pts = (0..30)
        .map(|_| {
            let mut u = rng.unit();
            u[2] = u[2].abs() * 0.06 + 0.94;
            let r = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            let u = u.map(|v| v / r);
            reading(
                u,
                [100.0, 50.0, -80.0],
                diag([16500.0, 16250.0, 16400.0]),
                2.0,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "cap20",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // a sensor turned about its z axis only: the points lie on a plane
    let pts = (0..24)
        .map(|i| {
            let u = sph(20.0, 15.0 * i as f64);
            reading(u, [0.0, 0.0, 0.0], diag([16384.0; 3]), 0.0, &mut rng)
        })
        .collect();
    out.push(Case {
        name: "plane",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    let pts = (0..12)
        .map(|i| [1000.0 * i as f64, 500.0 * i as f64 - 3000.0, 250.0])
        .collect();
    out.push(Case {
        name: "line",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    let pts = vec![[120.0, -44.0, 16000.0]; 10];
    out.push(Case {
        name: "same",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // the six faces of a cube less one, then the six faces plus two corners
    let faces = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let d = diag([16420.0, 16350.0, 16300.0]);
    let pts = faces[..5]
        .iter()
        .map(|&u| reading(u, [60.0, -90.0, 30.0], d, 1.0, &mut rng))
        .collect();
    out.push(Case {
        name: "five",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    let mut pts: Vec<[f64; 3]> = faces
        .iter()
        .map(|&u| reading(u, [60.0, -90.0, 30.0], d, 1.0, &mut rng))
        .collect();
    let s = 1.0 / 3f64.sqrt();
    pts.push(reading([s, s, s], [60.0, -90.0, 30.0], d, 1.0, &mut rng));
    pts.push(reading([-s, s, -s], [60.0, -90.0, 30.0], d, 1.0, &mut rng));
    out.push(Case {
        name: "eight",
        points: pts.clone(),
        radius: 16384.0,
        descent: seed_opts(),
    });
    out.push(Case {
        name: "six_faces",
        points: pts[..6].to_vec(),
        radius: 16384.0,
        descent: seed_opts(),
    });
    // gains of 1 : 4 between axes (a badly scaled axis): refused by the bound on their ratio
    let pts = (0..40)
        .map(|_| {
            let u = rng.unit();
            reading(
                u,
                [10.0, 20.0, 30.0],
                diag([16384.0, 16384.0, 4096.0]),
                1.0,
                &mut rng,
            )
        })
        .collect();
    out.push(Case {
        name: "ratio4",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    // noise of a third of the radius: residuals far above the warning
    let pts = (0..50)
        .map(|_| {
            let u = rng.unit();
            reading(u, [0.0, 0.0, 0.0], diag([16384.0; 3]), 5000.0, &mut rng)
        })
        .collect();
    out.push(Case {
        name: "noisy",
        points: pts,
        radius: 16384.0,
        descent: seed_opts(),
    });
    out
}

/// The C library's code for a core error (`enum tc_code` in triaxcal.h).
fn code(e: &CalError) -> i32 {
    match e {
        CalError::InvalidArgument(_) => 1,
        CalError::NonFinite { .. } | CalError::NonFiniteSample { .. } => 2,
        CalError::TooFewPoints { .. } => 3,
        CalError::Degenerate { why, .. } => {
            if why.contains("identical") {
                4
            } else if why.contains("straight line") {
                5
            } else if why.contains("on a plane") {
                6
            } else if why.contains("gains differ by a factor") {
                8
            } else if why.contains("no convergence") {
                9
            } else {
                7
            }
        }
    }
}

/// The `TC_WARN_*` bits of the core's warnings.
fn warning_bits(w: &[String]) -> u32 {
    let table = [
        ("exactly determined", 0x01),
        ("did not converge", 0x02),
        ("poorly determined", 0x04),
        ("ill-conditioned", 0x08),
        ("residuals are", 0x10),
        ("part of the sphere is empty", 0x20),
        ("cover only a band", 0x40),
    ];
    let mut bits = 0;
    for s in w {
        let hit: Vec<u32> = table
            .iter()
            .filter(|(k, _)| s.contains(k))
            .map(|&(_, b)| b)
            .collect();
        assert_eq!(hit.len(), 1, "a warning the C library does not know: {s}");
        bits |= hit[0];
    }
    bits
}

fn num(v: f64) -> String {
    if v == 0.0 {
        "0.0".into()
    } else {
        format!("{v:.17e}")
    }
}

fn nums(v: &[f64]) -> String {
    v.iter().map(|&x| num(x)).collect::<Vec<_>>().join(", ")
}

fn main() {
    let cases = cases();
    let mut points = String::new();
    let mut table = String::new();
    let mut first = 0;
    let mut maxn = 0;
    for c in &cases {
        for p in &c.points {
            assert_eq!(p.map(|v| v as f32 as f64), *p);
            points.push_str(&format!("    {{{}}},\n", nums(p)));
        }
        maxn = maxn.max(c.points.len());
        let o = c.descent;
        let (dcode, dc, de, di, dconv) = match descend_center(&c.points, c.radius, o) {
            Ok(d) => (0, d.center, d.error, d.iterations, d.converged),
            Err(e) => (code(&e), [0.0; 3], 0.0, 0, false),
        };
        let mut fits = String::new();
        for model in [Model::Axis, Model::Full] {
            let opts = FitOptions {
                model,
                radius: Some(c.radius),
                debias: false,
                parallel: false,
                tol: REFERENCE_TOL,
                ..FitOptions::default()
            };
            let (fc, off, m, rms, warn, se) = match fit_ellipsoid(&c.points, &opts) {
                Ok(f) => {
                    // the largest standard errors of the offsets and of the matrix terms
                    // (-1: none, an exactly determined solve)
                    let big = |v: &[f64]| {
                        let m = v.iter().fold(0.0f64, |a, &b| a.max(b));
                        if v.iter().all(|x| x.is_finite()) {
                            m
                        } else {
                            -1.0
                        }
                    };
                    let se = [big(&f.stderr[..3]), big(&f.stderr[3..])];
                    (
                        0,
                        f.offset,
                        f.matrix.concat(),
                        f.rms,
                        warning_bits(&f.warnings),
                        se,
                    )
                }
                Err(e) => (code(&e), [0.0; 3], vec![0.0; 9], 0.0, 0, [0.0; 2]),
            };
            fits.push_str(&format!(
                "     {{{fc}, {{{}}},\n      {{{}}},\n      {}, 0x{warn:02x}, {{{}}}}}",
                nums(&off),
                nums(&m),
                num(rms),
                nums(&se)
            ));
            fits.push_str(if model == Model::Axis { ",\n" } else { "" });
        }
        table.push_str(&format!(
            "    {{\"{}\", {}, {first}, {},\n     {{{}}}, {}, {}, {},\n     {dcode}, {{{}}}, {}, {di}, {},\n{fits}}},\n",
            c.name, c.points.len(), num(c.radius), nums(&o.start), num(o.step), num(o.min_step),
            num(o.shrink), nums(&dc), num(de), u8::from(dconv)));
        first += c.points.len();
    }
    print!(
        "/* Test vectors for the triaxcal C library: what the Rust core computes. Generated by\n \
         * firmware/lib/triaxcal/test/vectors.rs (cargo run --release --no-default-features\n \
         * --example firmware_vectors > firmware/lib/triaxcal/test/vectors.h); do not edit.\n \
         * The types are in tcv.h; include after it, with TCV_STORE defined. */\n\
         #define TCV_NCASES {}\n#define TCV_NPOINTS {first}\n#if TCV_MAXN < {maxn}\n\
         #error \"TCV_MAXN (tcv.h) is below the largest case ({maxn} points)\"\n#endif\n\n\
         static const TCV_NUM TCV_POINTS[TCV_NPOINTS][3] TCV_STORE = {{\n{points}}};\n\n\
         static const struct tcv_case TCV_CASES[TCV_NCASES] TCV_STORE = {{\n{table}}};\n",
        cases.len()
    );
}
