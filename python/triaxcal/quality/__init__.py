"""How good the data and a fit are: the one coverage measure of the sphere
(:mod:`~triaxcal.quality.coverage`) and its largest empty caps (:mod:`~triaxcal.quality.caps`)."""
