"""Depth across a rectified camera grid: the keyed subject (rigctl.keying), multi-baseline matching, outputs, and
the benchmark."""
