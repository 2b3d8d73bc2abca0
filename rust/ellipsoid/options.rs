//! What a fit is asked for ([`Model`], [`Method`], [`FitOptions`]) and what it gives
//! ([`EllipsoidFit`]).

use crate::error::{CalError, Result};

/// Which parameters are fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// Offset and one scale: `W = k I`.
    Sphere,
    /// Offset and three gains: `W = diag(g)`.
    Axis,
    /// Offset and a symmetric `W`: scale, cross-axis, hard and soft iron.
    Full,
}

impl Model {
    /// Parses `"sphere"`, `"axis"` or `"full"`.
    pub fn parse(name: &str) -> Result<Model> {
        match name {
            "sphere" => Ok(Model::Sphere),
            "axis" => Ok(Model::Axis),
            "full" => Ok(Model::Full),
            other => Err(CalError::InvalidArgument(format!(
                "unknown model {other:?}: use \"sphere\" (offset only), \"axis\" (offset + 3 gains) \
                 or \"full\" (offset + symmetric 3x3 matrix)"
            ))),
        }
    }
    /// The name accepted by [`Model::parse`].
    pub fn name(self) -> &'static str {
        match self {
            Model::Sphere => "sphere",
            Model::Axis => "axis",
            Model::Full => "full",
        }
    }
    /// The model's name in quotes followed by "model", for messages.
    pub(super) fn label(self) -> &'static str {
        match self {
            Model::Sphere => "\"sphere\" model",
            Model::Axis => "\"axis\" model",
            Model::Full => "\"full\" model",
        }
    }
    /// Number of unknowns.
    pub fn nparams(self) -> usize {
        match self {
            Model::Sphere => 4,
            Model::Axis => 6,
            Model::Full => 9,
        }
    }
    /// Names of the parameters whose standard errors [`EllipsoidFit::stderr`] reports.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            Model::Sphere => &["offset_x", "offset_y", "offset_z", "data_radius"],
            Model::Axis => &[
                "offset_x", "offset_y", "offset_z", "diag_x", "diag_y", "diag_z",
            ],
            Model::Full => &FIXABLE,
        }
    }
}

/// Names of the entries of [`FitOptions::fixed`], in order. For the sphere model entry 3 is its
/// one gain (`W = gain I`); entries past the model's parameters must be `None`.
pub const FIXABLE: [&str; 9] = [
    "offset_x",
    "offset_y",
    "offset_z",
    "diag_x",
    "diag_y",
    "diag_z",
    "offdiag_xy",
    "offdiag_xz",
    "offdiag_yz",
];

/// How the parameters are refined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Levenberg-Marquardt (the default).
    LevenbergMarquardt,
    /// Gauss-Newton with step halving.
    GaussNewton,
    /// No refinement: the algebraic (least-squares quadric) fit on all points.
    Algebraic,
}

impl Method {
    /// Parses `"lm"`, `"gn"` or `"algebraic"`.
    pub fn parse(name: &str) -> Result<Method> {
        match name {
            "lm" => Ok(Method::LevenbergMarquardt),
            "gn" => Ok(Method::GaussNewton),
            "algebraic" => Ok(Method::Algebraic),
            other => Err(CalError::InvalidArgument(format!(
                "unknown method {other:?}: use \"lm\" (Levenberg-Marquardt), \"gn\" (Gauss-Newton) \
                 or \"algebraic\" (no refinement)"
            ))),
        }
    }
}

/// Options of [`fit_ellipsoid`](super::fit_ellipsoid).
#[derive(Debug, Clone, Copy)]
pub struct FitOptions {
    /// The model.
    pub model: Model,
    /// Magnitude calibrated readings must have (1.0 for g, 9.80665 for m/s², the local field in
    /// µT); `None` keeps the data's own scale (`det W = 1`).
    pub radius: Option<f64>,
    /// Most iterations (trial steps and polishing passes) of the refinement.
    pub max_iter: usize,
    /// Converged when an accepted step lowers the cost by less than this fraction.
    pub tol: f64,
    /// How to refine.
    pub method: Method,
    /// Use rayon inside the fit (off in batches, which parallelise over data sets).
    pub parallel: bool,
    /// Correct the geometric residual for the bias that noise adds to vector lengths (see
    /// the module documentation). Off: the plain geometric least-squares fit.
    pub debias: bool,
    /// Compute the coverage of the sphere and the plain-language warnings. Batches, which
    /// report no warnings, turn it off.
    pub diagnostics: bool,
    /// Parameters held at these values instead of fitted, named by [`FIXABLE`]: offsets in raw
    /// units, gains (`diag`, `offdiag`, the sphere's gain) in calibrated units per raw unit,
    /// which needs `radius`.
    pub fixed: [Option<f64>; 9],
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            model: Model::Full,
            radius: None,
            max_iter: 100,
            tol: 1e-10,
            method: Method::LevenbergMarquardt,
            parallel: true,
            debias: true,
            diagnostics: true,
            fixed: [None; 9],
        }
    }
}

/// The result of [`fit_ellipsoid`](super::fit_ellipsoid).
#[derive(Debug, Clone, PartialEq)]
pub struct EllipsoidFit {
    /// The model fitted.
    pub model: Model,
    /// Offset (bias, hard iron), in raw units.
    pub offset: [f64; 3],
    /// `W`, row-major: `calibrated = W (raw - offset)`.
    pub matrix: [[f64; 3]; 3],
    /// Magnitude of calibrated readings: the requested radius, or the data's own.
    pub radius: f64,
    /// RMS of `‖calibrated‖ - radius`, in calibrated units.
    pub rms: f64,
    /// Standard errors of the parameters named by [`Model::param_names`] (offset in raw units,
    /// matrix terms in calibrated units per raw unit, `data_radius` in raw units); 0 for a
    /// fixed parameter, NaN for all when the solve is exactly determined.
    pub stderr: Vec<f64>,
    /// Trial steps and polishing passes taken by the refinement (0 for the algebraic method).
    pub iterations: usize,
    /// Whether the refinement met its tolerance.
    pub converged: bool,
    /// Condition number (Frobenius norm) of the column-scaled normal matrix at the solution.
    pub condition: f64,
    /// Number of points.
    pub n: usize,
    /// Plain-language warnings and notes (poor coverage, no convergence, exactly determined).
    pub warnings: Vec<String>,
}
