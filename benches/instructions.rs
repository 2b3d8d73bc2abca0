//! Fixed workloads for counting instructions with valgrind's callgrind (`make
//! bench-instructions`, and the regression guard in `tests/test_instructions.py`).
//!
//! ```text
//! instructions fit N          fit_ellipsoid("full", radius 1) on N synthetic points
//! instructions batch B        fit_batch of B sets x 200 points (the batch options)
//! instructions pass N         one accumulation pass with JᵀJ over N points (the unit of work)
//! instructions polish N       one polishing pass (Jᵀr and the noise sums, no JᵀJ)
//! instructions last N         the last polishing pass (JᵀJ, noise sums and coverage)
//! instructions descend N      descend_center (radius 16384, the seed's steps) of N points
//! instructions allan N        overlapping Allan deviation of N rows x 3 axes, octave taus
//! instructions adev N         non-overlapping Allan deviation of the same rows
//! instructions ulog PATH      read a ULog, every topic decoded
//! instructions dataflash PATH read a DataFlash log's MAG, ATT, BAT, IMU and PARM messages
//! instructions none N         only generate the N points (subtract from the others)
//! ```
//!
//! The data are deterministic (a fixed xorshift generator), so the same binary on the same
//! CPU features executes the same instructions; run single-threaded (`parallel: false`, one
//! rayon thread) so that no spinning thread adds a variable count. `TRIAXCAL_PORTABLE=1` runs
//! the portable kernels instead of the AVX2 ones.

use triaxcal::batch::fit_batch;
use triaxcal::ellipsoid::{fit_ellipsoid, FitOptions, Model};

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
}

/// Readings of a distorted sphere in counts (offset, MEMS-like matrix, `noise` counts of noise
/// per axis): the data of `benches/bench_fit.py` (1 % noise = 164 counts for the fits, 0.3 % =
/// 49 counts for the batch).
fn points(n: usize, seed: u64, noise: f64) -> Vec<[f64; 3]> {
    let minv = [
        [15756.0, -165.0, 163.0],
        [-165.0, 16894.0, -251.0],
        [163.0, -251.0, 16388.0],
    ];
    points_of(n, seed, noise, minv)
}

/// Readings `offset + minv u + noise` of unit vectors `u`.
fn points_of(n: usize, seed: u64, noise: f64, minv: [[f64; 3]; 3]) -> Vec<[f64; 3]> {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ seed.wrapping_mul(0xd1b5_4a32_d192_ed03));
    let off = [412.0, -230.5, 97.25];
    (0..n)
        .map(|_| {
            let mut u = [rng.normal(), rng.normal(), rng.normal()];
            let r = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
            u.iter_mut().for_each(|v| *v /= r);
            let mut p = [0.0; 3];
            for i in 0..3 {
                p[i] = off[i]
                    + minv[i][0] * u[0]
                    + minv[i][1] * u[1]
                    + minv[i][2] * u[2]
                    + noise * rng.normal();
            }
            p
        })
        .collect()
}

/// Rate readings at rest, 3 axes: a bias, white noise and a random walk (the data of
/// `benches/bench_noise.py`).
fn allan_rows(n: usize) -> Vec<f64> {
    let mut rng = Rng(0x5eed);
    let mut walk = [0.0; 3];
    let mut rows = Vec::with_capacity(3 * n);
    for _ in 0..n {
        for w in walk.iter_mut() {
            *w += 2e-4 * rng.normal();
            rows.push(250.0 + 0.05 * rng.normal() + *w);
        }
    }
    rows
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: instructions {fit|batch|pass|polish|last|descend|allan|adev|none} N, \
                 or instructions {ulog|dataflash} PATH";
    let what = args.get(1).expect(usage).as_str();
    let arg = args.get(2).expect(usage);
    match what {
        "ulog" => {
            let log = triaxcal::logs::ulog::read(std::path::Path::new(arg), None).unwrap();
            let rows: usize = log
                .datasets
                .iter()
                .map(|d| d.fields.first().map_or(0, |(_, c)| c.len()))
                .sum();
            println!("ulog: {} topics, {rows} messages", log.datasets.len());
            return;
        }
        "dataflash" => {
            let types = ["MAG", "ATT", "BAT", "IMU", "PARM"];
            let out = triaxcal::logs::dataflash::read(std::path::Path::new(arg), &types).unwrap();
            match out {
                triaxcal::logs::dataflash::Outcome::Read { messages, .. } => {
                    println!("dataflash: {} message types", messages.len())
                }
                _ => panic!("the DataFlash reader fell back on {arg}"),
            }
            return;
        }
        _ => {}
    }
    let n: usize = arg.parse().expect(usage);
    let opts = FitOptions {
        model: Model::Full,
        radius: Some(1.0),
        parallel: false,
        ..Default::default()
    };
    match what {
        "fit" => {
            let pts = points(n, 1, 164.0);
            // the one-time CPU feature detection (which reads the environment, so its count
            // depends on the environment's size) happens here, outside the counted fit
            let _ = triaxcal::geometry::spread(&pts);
            let f = fit_ellipsoid(&pts, &opts).unwrap();
            println!("fit {n}: iterations {} offset {:?}", f.iterations, f.offset);
        }
        "batch" => {
            let sets: Vec<Vec<[f64; 3]>> =
                (0..n).map(|i| points(200, 100 + i as u64, 49.0)).collect();
            let refs: Vec<&[[f64; 3]]> = sets.iter().map(|s| s.as_slice()).collect();
            let t0 = std::time::Instant::now();
            let out = fit_batch(&refs, &opts);
            let dt = t0.elapsed();
            let ok = out.iter().filter(|r| r.is_ok()).count();
            println!(
                "batch {n} x 200: {ok} fitted in {:.1} ms",
                dt.as_secs_f64() * 1e3
            );
        }
        "pass" | "polish" | "last" => {
            let pts = points(n, 1, 164.0);
            let kind = ["pass", "polish", "last"]
                .iter()
                .position(|k| *k == what)
                .unwrap();
            let sp = triaxcal::geometry::spread(&pts);
            let mean = [sp.mean.x, sp.mean.y, sp.mean.z];
            let s = triaxcal::ellipsoid::bench_one_pass(&pts, mean, sp.scale, kind as u8);
            println!("{what} {n}: {s:e}");
        }
        "descend" => {
            // the data of benches/bench_fit.py's descent row: a sphere of 16384 counts, 0.2 %
            // noise = 33 counts
            let sphere = [
                [16384.0, 0.0, 0.0],
                [0.0, 16384.0, 0.0],
                [0.0, 0.0, 16384.0],
            ];
            let pts = points_of(n, 3, 33.0, sphere);
            let opts = triaxcal::sphere::DescentOptions::default();
            let d = triaxcal::sphere::descend_center(&pts, 16384.0, opts).unwrap();
            println!(
                "descend {n}: centre {:?} after {} neighbourhoods",
                d.center, d.iterations
            );
        }
        "allan" | "adev" => {
            let rows = allan_rows(n);
            let ms: Vec<u64> = (0..64)
                .map(|k| 1u64 << k)
                .take_while(|&m| m <= (n as u64 - 1) / 2)
                .collect();
            // one thread, so that no spinning worker adds a variable count
            let mut acc = if what == "allan" {
                triaxcal::allan::Allan::new(100.0, 3, &ms, None).unwrap()
            } else {
                triaxcal::allan::Allan::non_overlapping(100.0, 3, &ms).unwrap()
            };
            acc.set_parallel(false);
            acc.push(&rows).unwrap();
            let r = acc.result();
            println!("{what} {n}: {} taus, adev[0] {:?}", r.taus.len(), r.adev[0]);
        }
        "none" => {
            let pts = points(n, 1, 164.0);
            let sets: Vec<Vec<[f64; 3]>> = (0..n / 200)
                .map(|i| points(200, 100 + i as u64, 49.0))
                .collect();
            println!("none {n}: {} {}", pts.len(), sets.len());
        }
        _ => panic!("{usage}"),
    }
}
