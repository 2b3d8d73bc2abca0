"""What a calibration is worth, for a person to read: the quality report's numbers and
plain-language warnings (:mod:`~triaxcal.report.quality`), the coefficients as a table and a
fit's summary (:mod:`~triaxcal.report.text`), and the report figure
(:mod:`~triaxcal.report.figure`)."""

from .figure import plot_report, report_figure
from .quality import (
    QualityReport,
    cap_words,
    direction_words,
    empty_regions,
    have_matplotlib,
    quality_report,
)
from .text import coefficient_table, context_lines

#: The public names (``triaxcal.__all__`` gathers them).
__all__ = ["QualityReport", "coefficient_table", "plot_report", "quality_report"]
