"""Deprecated (issue 28): the normality gate's multiplicity correction is part of
:mod:`identification.studies.normality`; this path re-exports it until its last importer
(:mod:`identification.studies.montecarlo`) is switched, then goes."""
from identification.studies.normality import (GATE_CORRECTIONS, adjusted_pvalues, check_correction,  # noqa: F401
                                              correction_text, gate_fails)

__all__ = ["GATE_CORRECTIONS", "adjusted_pvalues", "gate_fails", "check_correction", "correction_text"]
