"""Deprecated: the plan records live in :mod:`oed.plan_records` (the report reads them as typed records)."""
from __future__ import annotations

import oed.plan_records as _moved
from reports.moved import moved

__all__ = ["PlannedDesign", "RobustPlan", "RobustExactPlan", "DiscriminationPlan", "DynamicDesign", "design_rows_text"]

__getattr__ = moved(__name__, _moved, __all__)
