//! # triaxcal
//!
//! The numerical core of triaxcal: calibration of three-axis MEMS sensors (accelerometers,
//! gyroscopes, magnetometers) from raw readings. Plain slices and nalgebra types in, a
//! [`Result`](error::Result) out; nothing here names Python. The optional `python` feature adds
//! the thin binding layer in `rust/py/`.
//!
//! ```
//! use triaxcal::ellipsoid::{fit_ellipsoid, FitOptions, Model};
//! // six faces of a cube, seen by an accelerometer with offset (0.1, -0.2, 0.05) g
//! let pts = [[1.1, -0.2, 0.05], [-0.9, -0.2, 0.05], [0.1, 0.8, 0.05],
//!            [0.1, -1.2, 0.05], [0.1, -0.2, 1.05], [0.1, -0.2, -0.95]];
//! let fit = fit_ellipsoid(&pts, &FitOptions { model: Model::Sphere, radius: Some(1.0), ..Default::default() }).unwrap();
//! assert!((fit.offset[0] - 0.1).abs() < 1e-9);
//! ```

mod algebraic;
pub mod allan;
pub mod batch;
pub mod bounds;
pub mod ellipsoid;
pub mod error;
pub mod geometry;
mod kernel;
mod linalg;
pub mod logs;
mod pool;
mod simd;
pub mod sphere;

#[cfg(feature = "python")]
mod py;
