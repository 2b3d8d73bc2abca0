"""Input checks every layer uses: array data (:mod:`~triaxcal._checks.arrays`), keyword options
(:mod:`~triaxcal._checks.options`). A bad value raises :class:`~triaxcal.CalibrationError`
naming the argument, the value and the valid range; nothing is clipped or coerced."""
