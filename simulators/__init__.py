"""Simulated cameras, scenes with ground truth and simulated serial devices (installed as rigctl.simulators)."""
