"""The help teaches what works: the cheap examples of every ``--help`` run as written, in a scratch folder,
through the installed console script (in the order a reader would run them: a take is recorded before it is
inspected); ``rigctl completion bash`` is a script bash accepts and completes with; help is coloured on a
terminal."""

from __future__ import annotations

import os
import pty
import shlex
import shutil
import subprocess
import time
from pathlib import Path

import pytest
from cli_help_support import ALL, example_lines
from conftest import rigctl_command

HELP_EXAMPLES = {c for _, p in ALL for c in example_lines(p.format_help())}

# examples that need no demo output, no hardware, no server and less than a few seconds each on the simulated rig
CHEAP = [
    "rigctl plan bmd-micro-studio-4k-3x3 --subject-depth 1",
    "rigctl plan sim-3x3 --near 2.5 --far inf",
    "rigctl plan sim-3x3 --subject-depth 1 --json",
    "rigctl devices sim-3x3 --json",
    "rigctl tally sim-3x3 --program r1c1 --preview r1c0 r1c2",
    "rigctl tally sim-3x3",
    "rigctl control sim-3x3 --exposure-us 10000 --gain 2",
    "rigctl control sim-3x3 --white-balance-k 5600 --camera r1c1 --json",
    "rigctl board --out board",
    "rigctl board --out small-board --squares 10x7 --square-mm 30 --marker-mm 22 --dpi 300",
    "rigctl record sim-3x3 --take T001 --frames 10 --sim deterministic=true",
    "rigctl take info takes/T001",
    "rigctl take check takes/T001",
    "rigctl take export takes/T001 --out T001-png --frames 0-2",
    "rigctl take export takes/T001 --out T001-exr --format exr --colour acescg --layout sequence",
    "rigctl rectify takes/T001 --calibration takes/T001/truth/calibration.yaml --out takes/T001-rectified",
    "rigctl record sim-3x3 --take ideal --frames 3 --sim ideal=true --sim deterministic=true",
    "rigctl render takes/ideal --disparity takes/ideal/truth/disparity --at 1.5,1 --out views",
    "rigctl usd takes/ideal --out ideal.usda --rig sim-3x3 --window",
    "rigctl miv export takes/ideal takes/ideal/truth/disparity --out miv",
    "rigctl miv import miv/cameras.json --out miv-grid",
    "rigctl miv ivpsnr miv/r1c1_texture_960x540_yuv420p10le.yuv miv/r1c1_texture_960x540_yuv420p10le.yuv "
    "--size 960x540 --pix-fmt yuv420p10le",
    "rigctl completion bash > ~/.local/share/bash-completion/completions/rigctl",
]


@pytest.mark.slow
def test_the_cheap_examples_run_as_written(tmp_path: Path) -> None:
    assert not [c for c in CHEAP if c not in HELP_EXAMPLES], "an example here is no longer in any --help"
    exe = Path(rigctl_command()[0]).parent
    env = {**os.environ, "PATH": f"{exe}:{os.environ['PATH']}", "HOME": str(tmp_path / "home")}
    (tmp_path / "home" / ".local/share/bash-completion/completions").mkdir(parents=True)
    work = tmp_path / "work"
    work.mkdir()
    for command in CHEAP:
        res = subprocess.run(
            ["bash", "-c", command], cwd=work, env=env, capture_output=True, text=True, timeout=300,
            stdin=subprocess.DEVNULL,
        )  # fmt: skip
        assert res.returncode == 0, (command, res.stdout[-1500:], res.stderr[-1500:])
    # what they wrote is what their comments say
    assert (work / "takes" / "T001" / "take.yaml").exists() and (work / "takes" / "T001-rectified").is_dir()
    assert len(list((work / "T001-png").glob("*/*.png"))) == 27 and (work / "views" / "000000").is_dir()
    assert (tmp_path / "home" / ".local/share/bash-completion/completions/rigctl").stat().st_size > 1000


def _take_yaml(cameras: list[str], folder: str = "cameras/") -> str:
    """take.yaml's cameras as the recorder writes them (two-space keys; a rectified take's files at its top)."""
    listed = "".join(f"  {c}:\n    essence: {folder}{c}.essence\n    index: {folder}{c}.index\n" for c in cameras)
    return f"spec: 1\ntake: T\ncameras:\n{listed}status: complete\n"


def _complete(script: Path, words: list[str], cwd: Path) -> list[str]:
    """What bash's completion function offers for the last of ``words`` (the script sourced in a real bash)."""
    line = " ".join(shlex.quote(w) for w in words)
    code = (
        f"source {shlex.quote(str(script))}; COMP_WORDS=({line}); COMP_CWORD={len(words) - 1}; "
        'COMP_LINE="${COMP_WORDS[*]}"; _shtab_rigctl; printf "%s\\n" "${COMPREPLY[@]}"'
    )
    res = subprocess.run(["bash", "-c", code], capture_output=True, text=True, cwd=cwd, timeout=60, check=True)
    return sorted(w for w in res.stdout.splitlines() if w)


def test_bash_completion_script_is_accepted_and_completes_commands_rigs_and_cameras(tmp_path: Path) -> None:
    res = subprocess.run([*rigctl_command(), "completion", "bash"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    script = tmp_path / "rigctl.bash"
    script.write_text(res.stdout)
    subprocess.run(["bash", "-n", str(script)], check=True, timeout=60)
    assert _complete(script, ["rigctl", "de"], tmp_path) == ["demo", "depth", "devices"]
    assert _complete(script, ["rigctl", "take", "e"], tmp_path) == ["export"]
    assert _complete(script, ["rigctl", "plan", "bmd"], tmp_path) == ["bmd-micro-studio-4k-3x3"]
    assert "--subject-depth" in _complete(script, ["rigctl", "plan", "--sub"], tmp_path)
    # the cameras of the take named earlier on the line (a take's camera files, as the recorder names them)
    take = tmp_path / "T9"
    take.mkdir()
    (take / "take.yaml").write_text(_take_yaml(["r0c0", "r0c1", "r1c0"]))
    assert _complete(script, ["rigctl", "depth", "T9", "--cameras", "r0"], tmp_path) == ["r0c0", "r0c1"]
    # a rig's cameras for tally, and file names where the argument is a path
    assert _complete(script, ["rigctl", "tally", "sim-3x3", "--program", "r2"], tmp_path) == ["r2c0", "r2c1", "r2c2"]
    assert _complete(script, ["rigctl", "take", "info", "T"], tmp_path) == ["T9"]
    # miv import's positional ``cameras`` is the content's JSON file, not camera names
    assert _complete(script, ["rigctl", "miv", "import", "T"], tmp_path) == ["T9"]


def test_bash_completes_inside_a_folder_whose_name_has_a_space(tmp_path: Path) -> None:
    """``rigctl take info "cdir/a b/"`` offers the folder's contents: the file and folder completions passed the
    word unquoted to compgen, which completed "cdir/a" and "b/" and offered "cdir/a b" itself."""
    res = subprocess.run([*rigctl_command(), "completion", "bash"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    script = tmp_path / "rigctl.bash"
    script.write_text(res.stdout)
    (tmp_path / "cdir" / "a b" / "T 1").mkdir(parents=True)
    (tmp_path / "cdir" / "a b" / "c.yaml").write_text("")
    inside = ["cdir/a b/T 1", "cdir/a b/c.yaml"]
    assert _complete(script, ["rigctl", "take", "info", "cdir/a b/"], tmp_path) == inside  # a file argument
    assert _complete(script, ["rigctl", "rectify", "T", "--calibration", "cdir/a b/c"], tmp_path) == inside[1:]
    assert _complete(script, ["rigctl", "depth", "T", "--out", "cdir/a b/"], tmp_path) == inside[:1]  # a folder
    assert _complete(script, ["rigctl", "plan", "cdir/a b/"], tmp_path) == inside  # a rig or a rig file


def _tmux(*argv: str) -> str:
    return subprocess.run(["tmux", *argv], capture_output=True, text=True, check=True, timeout=30).stdout


def _completed(session: str, line: str) -> str:
    """The prompt's line in tmux ``session`` after typing ``line`` and Tab, once it stops changing."""
    _tmux("send-keys", "-t", session, "C-u")
    _tmux("send-keys", "-t", session, "-l", line)
    _tmux("send-keys", "-t", session, "Tab")
    t0, last, seen = time.monotonic(), None, ""
    while time.monotonic() - t0 < 20:
        time.sleep(0.3)
        rows = [r for r in _tmux("capture-pane", "-p", "-t", session).splitlines() if r.startswith("$ rigctl")]
        seen = rows[-1][2:].rstrip() if rows else ""
        if seen.startswith(line) and seen == last and seen != line:
            return seen
        last = seen
    return seen


@pytest.mark.parametrize("shell", ["bash", "zsh"])
def test_a_real_shell_completes_the_cameras_of_a_take_whose_path_is_quoted(tmp_path: Path, shell: str) -> None:
    """Typed in a real bash and zsh in a terminal (tmux), with the script installed as the help says: the
    cameras after ``--cameras`` are the take's when its path has a space (escaped or quoted) or starts with
    ``~/``. Before, both shells looked for the word as typed (its quotes and backslashes kept), found no take
    and offered the simulated rig's nine; a word on the line is never run (no eval)."""
    for tool in ("tmux", shell):
        assert shutil.which(tool), f"{tool} is needed (.ci/run installs it)"
    home = tmp_path / "home"
    take = home / "my take"  # a rectified take: its camera files at its top, all listed in take.yaml
    take.mkdir(parents=True)
    (take / "take.yaml").write_text(_take_yaml(["r0c0", "r1c0"], ""))  # r1c0 alone begins with r1 (sim: three)
    grid = home / "g [1]"  # a grid folder from someone else: file names that are commands
    grid.mkdir()
    (grid / "grid.yaml").write_text("spec: 1\n")
    for name in ("r1c5", "r$(touch ran)c", "r`touch ran`c", "r1c$(touch ran)"):
        (grid / f"{name}.png").write_bytes(b"")
    (home / "five by five.yaml").write_text("".join(f"  - name: r4c{c}\n" for c in (3, 4)))
    res = subprocess.run([*rigctl_command(), "completion", shell], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    if shell == "bash":
        (home / "rigctl.bash").write_text(res.stdout)
        start, setup = "bash --norc --noprofile", "source ~/rigctl.bash"
    else:
        (home / "fn").mkdir()
        (home / "fn" / "_rigctl").write_text(res.stdout)
        start, setup = "zsh -f", "fpath=(~/fn $fpath); autoload -U compinit; compinit -u"
    name = f"rigctl-complete-{shell}-{tmp_path.name}"
    env = f"env -i HOME={shlex.quote(str(home))} TERM=xterm PATH=/usr/bin:/bin"
    _tmux("new-session", "-d", "-s", name, "-x", "250", "-y", "20", "-c", str(home), f"{env} {start}")
    try:
        _tmux("send-keys", "-t", name, f"{setup}; PS1='$ '", "Enter")

        def completed(line: str) -> str:
            return _completed(name, line)

        for typed in ("my\\ take", "'my take'", '"my take"', "~/my\\ take"):
            line = f"rigctl depth {typed} --cameras r1"
            assert completed(line) == f"{line}c0", (shell, typed)
        # quoted, the tilde is a folder named ~: no take there, so the simulated rig's cameras (r1c0..r1c2)
        assert completed("rigctl depth '~/my take' --cameras r1") == "rigctl depth '~/my take' --cameras r1c"
        assert completed("rigctl depth $(touch ran) --cameras r1") == "rigctl depth $(touch ran) --cameras r1c"
        assert completed("rigctl depth 'g [1]' --cameras r1") == "rigctl depth 'g [1]' --cameras r1c5"
        # a rig file's cameras (r4c3, r4c4: their common part), not the simulated rig's (no r4 there)
        rig = "rigctl tally 'five by five.yaml' --program r4"
        assert completed(rig) == f"{rig}c"
        assert not (home / "ran").exists()
    finally:
        subprocess.run(["tmux", "kill-session", "-t", name], capture_output=True)


def test_a_real_bash_completes_words_it_splits_at_colons_and_equals(tmp_path: Path) -> None:
    """Session 28's review: bash splits a word at : and = (COMP_WORDBREAKS), so a take in "take 12:30" or
    "x=y" completed nothing, nor did a --name=value option's value. Typed in a real bash in a terminal (tmux),
    with the script sourced: each completes, a folder with its slash, and the cameras of a take whose path has
    a colon are the take's (not the simulated rig's)."""
    for tool in ("tmux", "bash"):
        assert shutil.which(tool), f"{tool} is needed (.ci/run installs it)"
    home = tmp_path / "home"
    (home / "shoot 12:30" / "T1").mkdir(parents=True)
    (home / "shoot 12:30" / "T1" / "take.yaml").write_text(_take_yaml(["r0c0", "r1c0"], ""))
    (home / "x=y" / "T2").mkdir(parents=True)
    res = subprocess.run([*rigctl_command(), "completion", "bash"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    (home / "rigctl.bash").write_text(res.stdout)
    name = f"rigctl-breaks-{tmp_path.name}"
    env = f"env -i HOME={shlex.quote(str(home))} TERM=xterm PATH=/usr/bin:/bin"
    _tmux("new-session", "-d", "-s", name, "-x", "250", "-y", "20", "-c", str(home), f"{env} bash --norc --noprofile")
    try:
        _tmux("send-keys", "-t", name, "source ~/rigctl.bash; PS1='$ '", "Enter")

        def completed(line: str) -> str:
            return _completed(name, line)

        assert completed("rigctl take info shoot\\ 12:30/T") == "rigctl take info shoot\\ 12:30/T1/"
        # inside quotes bash does not split: the folder, its quote closed by bash itself
        assert completed("rigctl take info 'shoot 12:") == "rigctl take info 'shoot 12:30'/"
        assert completed("rigctl take info x=y/T") == "rigctl take info x=y/T2/"
        assert completed("rigctl depth x --out=x=") == "rigctl depth x --out=x=y/"
        line = "rigctl depth 'shoot 12:30/T1' --cameras r1"
        assert completed(line) == f"{line}c0"  # the take's r1c0, not the simulated rig's r1c0..r1c2
        assert completed("rigctl take e") == "rigctl take export"  # words without : or = as before
    finally:
        subprocess.run(["tmux", "kill-session", "-t", name], capture_output=True)


def test_zsh_and_tcsh_scripts_are_generated() -> None:
    for shell, marker in (("zsh", "#compdef rigctl"), ("tcsh", "complete rigctl")):
        res = subprocess.run([*rigctl_command(), "completion", shell], capture_output=True, text=True, timeout=120)
        assert res.returncode == 0 and marker in res.stdout, (shell, res.stderr)


def test_help_is_coloured_on_a_terminal(tmp_path: Path) -> None:
    pid, fd = pty.fork()
    if pid == 0:  # the child: rigctl's help on a real terminal
        os.execvpe(rigctl_command()[0], [*rigctl_command(), "board", "--help"], {**os.environ, "COLUMNS": "100"})
    out = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    os.waitpid(pid, 0)
    text = out.decode()
    assert "\x1b[" in text and "examples:" in text and "%%" not in text
