"""The simulated presenter as benchmark input: one frame as a depth dataset (``rigctl bench depth``, the demo)
and as render input with the simulator's own novel view (``rigctl bench render``). It lives outside
``rigctl.depth`` and ``rigctl.render``, which never reach the simulators: it gets the array from the registry."""

from __future__ import annotations

from typing import Any

from rigctl.depth.bench import Dataset, dataset_from_array


def presenter(ideal: bool, rig_name: str = "sim-3x3", seed: int = 0) -> Dataset:
    """One frame of the simulated presenter, rectified with the true calibration (ideal takes need none)."""
    from rigctl.registry import simulated_array
    from rigctl.rig import load_rig

    rig = load_rig(rig_name)
    array = simulated_array(rig, [f"ideal={str(ideal).lower()}", "motion=false", f"seed={seed}"])
    return dataset_from_array(array, "presenter, " + ("ideal" if ideal else "realistic"))


def presenter_render(rig_name: str = "sim-3x3", seed: int = 0) -> Any:
    """The ideal simulated presenter as render input (colour, key, true disparity) with the simulator's own
    view at 1.5,1 (``rigctl.render.bench.RenderBenchData``)."""
    import numpy as np

    from rigctl.depth.key import Keyer
    from rigctl.pixfmt import to_rgb
    from rigctl.registry import simulated_array, simulated_array_view
    from rigctl.render.bench import RenderBenchData, frame_from_arrays
    from rigctl.rig import load_rig

    rig = load_rig(rig_name)
    array = simulated_array(rig, ["ideal=true", "motion=false", f"seed={seed}"])
    fmt = array.format
    raw = array.frames(0)
    disp, _ = array.truth(0)
    g = array.rectified
    origin = np.mean([g.position_m(n) for n in array.names], axis=0)
    keyer = Keyer()
    views = {}
    for i, n in enumerate(array.names):
        rgb = to_rgb(raw[i], fmt.pixel_format, fmt.width, fmt.height)
        off = (g.position_m(n) - origin)[:2] / g.spacing_x_m
        views[n] = ((float(off[0]), float(off[1])), rgb, keyer.matte(rgb), disp[i])
    truth_rgb, _ = simulated_array_view(array, 1.5, 1.0)
    return RenderBenchData(frame_from_arrays(views, g.focal_px, g.spacing_x_m), (1.5, 1.0), truth_rgb)
