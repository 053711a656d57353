"""Reliability benchmarks: leaks over many calls, peak memory at large N."""
