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


def presenter_video(motion: bool, frames: int, ideal: bool = False, seed: int = 5, rig_name: str = "sim-3x3") -> Any:
    """A simulated presenter take of ``frames`` frame sets held in memory (``rigctl.depth.array_take.ArrayTake``):
    still (``motion=false``) or moving (the presenter's motion cycle in 40 poses, so every frame set at 25 fps
    shows a new one, from the first frame on), realistic unless ``ideal``, with camera noise per frame,
    rectified with the true calibration."""
    from rigctl.depth.array_take import ArrayTake
    from rigctl.registry import simulated_array
    from rigctl.rig import load_rig

    rig = load_rig(rig_name)
    sim = [f"ideal={str(ideal).lower()}", f"motion={str(motion).lower()}", f"seed={seed}"]
    if motion:
        sim += ["motion_states=40", "motion_ramp_s=0"]
    name = f"presenter, {'ideal' if ideal else 'realistic'}, {'moving' if motion else 'still'}"
    return ArrayTake(simulated_array(rig, sim), frames, name)


def presenter_render(rig_name: str = "sim-3x3", seed: int = 0) -> Any:
    """The ideal simulated presenter as render input (colour, key, true disparity) with the simulator's own
    view at 1.5,1 (``rigctl.render.bench.RenderBenchData``)."""
    from rigctl.depth.grid import camera_offsets
    from rigctl.keying import Keyer
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
    offsets = camera_offsets({n: g.position_m(n) for n in array.names}, list(array.names), g.spacing_x_m, rig_name)
    keyer = Keyer()
    views = {}
    for i, n in enumerate(array.names):
        rgb = to_rgb(raw[i], fmt.pixel_format, fmt.width, fmt.height)
        views[n] = (offsets[n], rgb, keyer.matte(rgb), disp[i])
    truth_rgb, _ = simulated_array_view(array, 1.5, 1.0)
    return RenderBenchData(frame_from_arrays(views, g.focal_px, g.spacing_x_m), (1.5, 1.0), truth_rgb)
