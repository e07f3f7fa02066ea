"""Reports people look at: publication figures (matplotlib) and a standalone HTML report.

Public API:

* :func:`write_html_report` / :func:`build_html_report`: one offline HTML file per run.
* :mod:`grfguard.report.figures`: pure plot functions returning ``(fig, axes)`` and
  :func:`write_png_figures`.
* :func:`sensor_summary`: the per-sensor table both use.
"""

from __future__ import annotations

from grfguard.report.html import build_html_report, write_html_report
from grfguard.report.summary import sensor_summary

__all__ = ["write_html_report", "build_html_report", "sensor_summary", "write_png_figures"]


def __getattr__(name: str):  # figures import matplotlib: load it only when asked
    if name == "write_png_figures":
        from grfguard.report.figures import write_png_figures

        return write_png_figures
    raise AttributeError(f"module 'grfguard.report' has no attribute {name!r}")
