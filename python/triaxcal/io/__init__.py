"""Bytes and files in, nothing above: the wire protocols (:mod:`~triaxcal.io.protocol`, pure:
bytes in, records out), framing, the serial reader, tables of numbers
(:mod:`~triaxcal.io.tables`), logs of autopilots and ROS (:mod:`~triaxcal.io.logs`), wearable
files, bounded reads and atomic writes (:mod:`~triaxcal.io.files`)."""

from .logs import read_log
from .recording import LogRecording, Stream
from .tables import Table, read_table

#: The public names (``triaxcal.__all__`` gathers them).
__all__ = ["LogRecording", "Stream", "Table", "read_log", "read_table"]
