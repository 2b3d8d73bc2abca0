"""The capture use case: a serial reader, still-pose detection and the session file written as
data arrive (:mod:`~triaxcal.capture.run`), one port or several (:mod:`~triaxcal.capture.multi`)."""
