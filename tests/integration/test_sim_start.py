"""The simulator's real renders give the same bytes whoever renders a state and when: in the background
in order, on demand out of order, or loaded from the disk cache of an earlier run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rigctl.simulators.array import SimArray
from rigctl.simulators.settings import SimSettings

from rigctl.rig import load_rig, rig_from_dict


def small_rig():  # type: ignore[no-untyped-def]
    data = load_rig("sim-3x3").to_dict()
    data["format"].update(width_px=320, height_px=180)
    return rig_from_dict(data)


def test_same_bytes_in_the_background_on_demand_and_from_the_cache(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rig = small_rig()
    settings = SimSettings(seed=3, motion_states=3)
    monkeypatch.setenv("RIGCTL_SIM_CACHE", "off")
    background = SimArray(rig, settings)
    background.render_in_background()
    background.states.join()
    assert background.states.rendered == [0, 1, 2] and background.states.error is None
    on_demand = SimArray(rig, settings)
    for state in (2, 0, 1):
        on_demand.frames(state)
    assert on_demand.states.rendered == [2, 0, 1]
    monkeypatch.setenv("RIGCTL_SIM_CACHE", str(tmp_path))
    SimArray(rig, settings).frames(1)  # an earlier run leaves state 1 on disk
    cached = SimArray(rig, settings)
    for state in range(3):
        a, b, c = background.frames(state), on_demand.frames(state), cached.frames(state)
        assert all(np.array_equal(x, y) and np.array_equal(x, z) for x, y, z in zip(a, b, c, strict=True)), state
    assert cached.states.rendered == [0, 2]  # state 1 came from the disk
    # and the states differ: the presenter moves
    assert not np.array_equal(background.frames(0)[4], background.frames(1)[4])
