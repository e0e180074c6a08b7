"""Depth across a rectified camera grid: keying, multi-baseline matching, outputs, and the benchmark."""
