"""Fitting: the one estimation problem (:class:`Problem`), the reduced problem, the NLP, the Newton core, checks and
the plain fit record."""
from identification.fit.problem import Problem

__all__ = ["Problem"]
