//! The core's physical bounds and warning thresholds (`crate::bounds`), handed to Python as
//! `_core.BOUNDS`, so that `triaxcal.quality.bounds` reads them instead of writing them again.

use crate::bounds;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Adds `BOUNDS`, a dict of the bound's name (as in `rust/bounds.rs`) to its value.
pub fn add(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let d = PyDict::new(m.py());
    d.set_item("MAX_AXIS_RATIO", bounds::MAX_AXIS_RATIO)?;
    d.set_item(
        "MAX_UNCONVERGED_OFFSET_SE",
        bounds::MAX_UNCONVERGED_OFFSET_SE,
    )?;
    d.set_item("WARN_OFFSET_SE", bounds::WARN_OFFSET_SE)?;
    d.set_item("WARN_RMS_FRACTION", bounds::WARN_RMS_FRACTION)?;
    d.set_item("WARN_MIN_SPREAD", bounds::WARN_MIN_SPREAD)?;
    d.set_item("EMPTY_FACE", bounds::EMPTY_FACE)?;
    m.add("BOUNDS", d)
}
