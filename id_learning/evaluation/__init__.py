"""Metrics, summaries and reports."""

from __future__ import annotations

from id_learning.evaluation.data_summary import (
    DataSummary,
    nominal_components,
    summarise,
    write_summary,
)

__all__ = ['DataSummary', 'nominal_components', 'summarise', 'write_summary']
