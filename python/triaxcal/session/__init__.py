"""A recorded session, fitted as the command line fits it.

:mod:`~triaxcal.session.source` reads a session table or a log (one way in for every command),
:mod:`~triaxcal.session.pose_options` and :mod:`~triaxcal.session.field_options` turn options
into pose-detection settings and the Earth's expected field, and :mod:`~triaxcal.session.fit`
fits one sensor from them. The command line, ``triaxcal batch`` (:mod:`triaxcal.fleet`) and
the live page (:mod:`triaxcal.live`) all build on this package; it imports nothing of theirs.
"""
