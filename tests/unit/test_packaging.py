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
    import rigctl.drivers
    import rigctl.rigs
    import rigctl.simulators

    assert Path(rigctl.drivers.__file__).parent.name in ("drivers",)
    assert rigctl.simulators.__name__ == "rigctl.simulators"
    assert rigctl.rigs.__name__ == "rigctl.rigs"
