"""Fitting: the reduced problem, the NLP, the Newton core, checks and the plain fit record."""
