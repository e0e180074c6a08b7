"""The source tree's shape: no import cycle among the project's modules (imports inside functions counted), no
module over 450 lines, recording constructed only through the library (never in the CLI), and a demo that
does not go through the CLI. Read from the source with ``ast``, so nothing is imported."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
# rigctl's packages and the folders installed under the rigctl namespace (pyproject's package-dir)
ROOTS = {"rigctl": REPO / "rigctl", "rigctl.drivers": REPO / "drivers", "rigctl.simulators": REPO / "simulators"}
MAX_LINES = 450


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for prefix, root in ROOTS.items():
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root).with_suffix("").parts
            if rel[-1] == "__init__":
                rel = rel[:-1]
            out[".".join([prefix, *rel])] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Project modules ``name`` imports anywhere in its source (top level, functions, TYPE_CHECKING blocks
    excluded: those never run)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for b in node.body for n in ast.walk(b))
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join([*parts, base]) if base else ".".join(parts)
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)
    return {_owner(m) for m in found if _owner(m) is not None} - {name}  # type: ignore[misc]


def _owner(dotted: str) -> str | None:
    """The project module an imported name belongs to (``rigctl.a.b.func`` -> ``rigctl.a.b``)."""
    while dotted:
        if dotted in MODULES:
            return dotted
        dotted = dotted.rpartition(".")[0]
    return None


def _graph() -> dict[str, set[str]]:
    return {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each a cycle to report."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle_through_a_function_local_import(tmp_path: Path) -> None:
    """The check itself can fail: a function-local import that closes a loop is a cycle."""
    (tmp_path / "a.py").write_text("import rigctl.errors\n")
    (tmp_path / "b.py").write_text("def f():\n    from rigctl.errors import RigctlError\n")
    graph = {"rigctl.errors": {"rigctl.rig"}, "rigctl.rig": _imports("rigctl.rig", tmp_path / "b.py")}
    assert _cycles(graph) == [["rigctl.errors", "rigctl.rig"]]
    graph["rigctl.rig"] = _imports("rigctl.rig", tmp_path / "a.py")
    assert _cycles(graph) == [["rigctl.errors", "rigctl.rig"]]
    assert _cycles({"rigctl.errors": {"rigctl.rig"}, "rigctl.rig": set()}) == []


def test_no_import_cycle_among_project_modules() -> None:
    graph = _graph()
    assert len(graph) > 50 and graph["rigctl.cli.main"], "the module walk found the tree"
    assert _cycles(graph) == []


# split on other branches of the same change; the lead removes an entry when its split is merged
@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_module_over_450_lines(name: str) -> None:
    lines = len(MODULES[name].read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_LINES, f"{MODULES[name].relative_to(REPO)} has {lines} lines; split it by responsibility"


def test_the_cli_never_constructs_a_recorder() -> None:
    """Recording is one library call (``record_take``); the CLI does not assemble a Recorder itself."""
    for name, path in MODULES.items():
        if not name.startswith("rigctl.cli"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call):
                callee = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
                assert callee != "Recorder", f"{path.relative_to(REPO)}:{node.lineno} constructs a Recorder"


def test_the_demo_imports_nothing_from_the_cli() -> None:
    graph = _graph()
    assert "rigctl.demo" in graph
    assert not {m for m in graph["rigctl.demo"] if m.startswith("rigctl.cli")}


def test_no_two_public_classes_share_a_name() -> None:
    """A name says what a thing is: two public classes of one name (a rig file's camera and a device, a
    captured frame and a bridge frame) make a newcomer read the import to know which is meant."""
    where: dict[str, list[str]] = {}
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in tree.body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                where.setdefault(node.name, []).append(name)
    clashes = {cls: mods for cls, mods in where.items() if len(mods) > 1}
    assert not clashes, f"classes defined more than once: {clashes}"


def test_the_registry_hands_out_interfaces_never_any() -> None:
    """What the registry returns (and what a DeviceSet holds) is typed with the interfaces, not ``Any``."""
    path = REPO / "rigctl" / "registry.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    annotations = [
        (node.lineno, node.returns) for node in ast.walk(tree) if isinstance(node, ast.FunctionDef) and node.returns
    ]
    annotations += [(node.lineno, node.annotation) for node in ast.walk(tree) if isinstance(node, ast.AnnAssign)]
    assert len(annotations) > 10
    for line, annotation in annotations:
        assert "Any" not in ast.unparse(annotation), f"rigctl/registry.py:{line}: {ast.unparse(annotation)}"
