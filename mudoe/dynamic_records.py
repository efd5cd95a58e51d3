"""Deprecated: ``Trajectories`` and ``MeshSummary`` live in :mod:`identification.studies.records` (the report reads
them as typed records of the study's :class:`oed.study_record.StudyRecord`)."""
from __future__ import annotations

import identification.studies.records as _records
from reports.moved import moved

__all__ = ["Trajectories", "MeshSummary"]

__getattr__ = moved(__name__, _records, __all__)
