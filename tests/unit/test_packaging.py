"""The package list in pyproject.toml covers every package in the tree, under its rigctl name."""

from __future__ import annotations

import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_every_package_is_listed() -> None:
    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    mapping = conf["package-dir"]
    found = set()
    for name, folder in mapping.items():
        root = REPO / folder
        for init in root.rglob("__init__.py"):
            rel = init.parent.relative_to(root)
            found.add(".".join([name, *rel.parts]) if rel.parts else name)
    # subfolders of rigctl/ that are mapped elsewhere are not packages of rigctl/ itself
    assert found == listed, f"add to or remove from pyproject.toml: {sorted(found ^ listed)}"


def test_installed_under_the_rigctl_namespace() -> None:
    """drivers/, simulators/ and rigs/ are importable only under rigctl, with the repository's own contents."""
    import importlib.resources
    import importlib.util

    import rigctl.drivers.v4l2.camera
    import rigctl.simulators.camera

    for generic in ("drivers", "simulators", "rigs"):
        assert importlib.util.find_spec(generic) is None, f"a top-level package {generic!r} is importable"
    assert Path(rigctl.drivers.v4l2.camera.__file__).read_bytes() == (REPO / "drivers/v4l2/camera.py").read_bytes()
    assert Path(rigctl.simulators.camera.__file__).read_bytes() == (REPO / "simulators/camera.py").read_bytes()
    shipped = {p.name for p in importlib.resources.files("rigctl.rigs").iterdir() if p.name.endswith(".yaml")}
    assert shipped == {p.name for p in (REPO / "rigs").glob("*.yaml")}, "rig files missing from the package data"
