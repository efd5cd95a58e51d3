"""Studies: Algorithm 1 (detection), Monte Carlo, bootstrap detection, splits."""
