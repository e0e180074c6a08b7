"""Benchmark data that comes from the simulator (kept out of ``rigctl.depth``, which never reaches devices
or simulators itself: it receives the simulated array through the registry)."""

from __future__ import annotations

from rigctl.depth.bench import Dataset, dataset_from_array


def presenter(ideal: bool, rig_name: str = "sim-3x3", seed: int = 0) -> Dataset:
    """One frame of the simulated presenter, rectified with the true calibration (ideal takes need none)."""
    from rigctl.registry import simulated_array
    from rigctl.rig import load_rig

    rig = load_rig(rig_name)
    array = simulated_array(rig, [f"ideal={str(ideal).lower()}", "motion=false", f"seed={seed}"])
    return dataset_from_array(array, "presenter, " + ("ideal" if ideal else "realistic"))
