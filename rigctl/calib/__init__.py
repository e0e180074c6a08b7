"""Calibration of the whole array: inputs, corner detection, joint solve, checks, report and exports."""
