"""Hardware tests: run against real V4L2 devices named in RIGCTL_V4L2_DEVICES (comma-separated paths).

CI runs them inside a throw-away VM on the kernel's vivid devices (.ci/v4l2-vm); on a workstation with
capture cards, name the devices and run ``pytest tests/hardware``. Without the variable they skip: the
main test run ignores this folder (see pyproject.toml).
"""

from __future__ import annotations

import os

import pytest


@pytest.fixture(scope="session")
def v4l2_devices() -> list[str]:
    value = os.environ.get("RIGCTL_V4L2_DEVICES", "")
    if not value:
        pytest.skip("no V4L2 devices given (set RIGCTL_V4L2_DEVICES=/dev/video0,...)")
    devices = [d for d in value.split(",") if d]
    missing = [d for d in devices if not os.path.exists(d)]
    assert not missing, f"RIGCTL_V4L2_DEVICES names devices that do not exist: {missing}"
    return devices
