"""The command line loads only the verb it runs: `rigctl record` does not import depth, rendering or the
farm, and `rigctl --help` still lists every verb."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from rigctl.cli.main import VERBS, _verb, build_parser


def test_the_verb_is_the_first_word_that_is_not_an_option() -> None:
    assert _verb(["--debug", "record", "--take", "t"]) == "record"
    assert _verb(["plan", "rigs/x.yaml"]) == "plan"
    assert _verb(["--version"]) is None
    assert _verb(["nosuch", "plan"]) is None  # not a verb: the whole parser, which names the choices


def test_help_lists_every_verb() -> None:
    text = build_parser().format_help()
    assert all(v in text for v in VERBS)


def test_running_one_verb_imports_only_what_it_needs(tmp_path: Path) -> None:
    code = (
        "import json, sys; from rigctl.cli.main import build_parser; build_parser('record'); "
        "print(json.dumps(sorted("
        "m for m in sys.modules if m.startswith(('rigctl.cli.', 'rigctl.depth', 'rigctl.render', "
        "'rigctl.farm', 'rigctl.calib', 'textual', 'distributed', 'numba')))))"
    )
    # outside the repository: from its root, ``-c`` would import the source folder, not the installed package
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    loaded = json.loads(out)
    assert "rigctl.cli.record" in loaded
    assert not [m for m in loaded if m.startswith(("rigctl.depth", "rigctl.render", "rigctl.farm", "rigctl.calib"))]
    assert not [m for m in loaded if m.split(".")[0] in ("textual", "distributed", "numba")]
    assert not {f"rigctl.cli.{v}" for v in VERBS if v != "record"} & set(loaded)


def test_a_take_summary_with_lost_frames_reads_as_words_not_a_python_dict() -> None:
    """take info (and record's last lines) once printed ``r0c1: 6 frames, {'source_drops': 2}``."""
    from rigctl.cli.record import format_summary

    counts = dict.fromkeys(("source_drops", "error_frames", "writer_drops", "not_written", "torn_excluded"), 0)
    summary = {
        "take": "t", "status": "complete", "frame_sets": 8, "complete_sets": 6, "format": "96x54 UYVY 25 fps",
        "skew": {"p50_us": 1, "p99_us": 2, "max_us": 3},
        "cameras": {
            "r0c0": {"frames": 8, **counts}, "r0c1": {"frames": 6, **counts, "source_drops": 2, "not_written": 1}
        },
    }  # fmt: skip
    lines = format_summary(summary).splitlines()
    assert "  r0c0: 8 frames" in lines and "  r0c1: 6 frames, source drops 2, not written 1" in lines, lines
    assert not any(c in "".join(lines) for c in "{}'"), lines
