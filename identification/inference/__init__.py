"""Inference: intervals, profiles, bootstrap and the Estimate users get."""
