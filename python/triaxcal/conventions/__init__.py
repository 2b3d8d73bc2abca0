"""The conventions every layer shares, each kept in one place: units and conversions
(:mod:`~triaxcal.conventions.units`) and the 24 mounting rotations as the autopilots number
them (:mod:`~triaxcal.conventions.rotations`)."""
