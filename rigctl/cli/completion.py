"""``rigctl completion bash|zsh|tcsh``: a shell completion script generated from the parser (shtab).

Commands and options come from the parser itself; an argument that is a rig completes the shipped rigs' names
and rig files, one that names cameras completes the camera names of the take (or grid folder, or rig) given
earlier on the line, and every other path argument completes file names."""

from __future__ import annotations

import argparse
from importlib import resources
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.helptext import examples

SHELLS = ("bash", "zsh", "tcsh")
RIG_DESTS = ("rig",)  # positional rig of plan, devices, record, tally, control, tui; --rig of usd
CAMERA_DESTS = ("cameras", "camera", "program", "preview")  # options only

# $1 is the word being completed; COMP_WORDS the line. Names containing "_file" make shtab's script ask bash
# for file-name treatment (a slash after a folder).
_BASH = r"""
_rigctl_compgen_files() {  # shtab's own pass $1 unquoted: "a b/" became the words "a" and "b/"
  compgen -f -- "$(_rigctl_plain "$1")"
}
_rigctl_compgen_dirs() {
  compgen -d -- "$(_rigctl_plain "$1")"
}
_rigctl_plain() {  # the word as typed, its quotes and backslashes taken off (compgen takes it as it is); a ~ is
  # left to compgen, which keeps it in what it offers
  case "$1" in "~"*) printf '%s' "$1" ;; *) _rigctl_word "$1" ;; esac
}
_rigctl_rig_or_file() {
  compgen -W "__RIGS__" -- "$1"
  compgen -f -- "$1"
}
_rigctl_rig_cameras() {  # a shipped rig's camera names or a rig file's (name: rXcY lines), one a line
  case "$1" in
__RIG_CASES__
    *) [ -f "$1" ] && sed -n 's/.*name: *\(r[0-9]*c[0-9]*\).*/\1/p' "$1" 2>/dev/null ;;
  esac
}
_rigctl_folder_cameras() {  # a take's cameras (take.yaml lists them all, rectified and --dest takes too) or a
  # grid folder's (rXcY.png), one a line; no cd (a user's cd function), failglob off in this subshell only
  if [ -f "$1/take.yaml" ]; then
    sed -n '/^cameras:/,/^[^ ]/s/^  \(r[0-9]*c[0-9]*\):.*/\1/p' "$1/take.yaml" 2>/dev/null
  elif [ -f "$1/grid.yaml" ]; then
    (shopt -s nullglob; shopt -u failglob; for f in "$1"/r*c*.png; do f=${f##*/}; printf '%s\n' "${f%.png}"; done)
  fi
}
_rigctl_word() {  # a word of COMP_WORDS (kept as typed: quotes, backslashes, ~/) as the command gets it; no eval
  local w=$1 out="" c q="" i
  [ ${#w} -gt 4096 ] && return  # longer than any path: not one (and each character costs more, UTF-8)
  for ((i = 0; i < ${#w}; i++)); do
    c=${w:i:1}
    if [ "$q" = "'" ]; then
      if [ "$c" = "'" ]; then q=""; else out+=$c; fi
    elif [ "$q" = '"' ]; then
      if [ "$c" = '"' ]; then q=""
      elif [ "$c" = '\' ] && [[ "${w:i+1:1}" == [\"\\\$\`] ]]; then i=$((i + 1)); out+=${w:i:1}
      else out+=$c; fi
    elif [ "$c" = "'" ] || [ "$c" = '"' ]; then q=$c
    elif [ "$c" = '\' ]; then i=$((i + 1)); out+=${w:i:1}
    else out+=$c; fi
  done
  case "$w" in "~/"*) out=$HOME/${out:2} ;; "~") out=$HOME ;; esac
  printf '%s' "$out"
}
_rigctl_complete() {  # what bash calls: it splits a word at : and = (COMP_WORDBREAKS), so a path such as
  # "take 12:30/" reached shtab's function as three words. The parts are joined again (a --name=value option as
  # the two words it stands for), shtab's function completes the whole word, and each completion loses what
  # bash keeps of the word before its last : or =; a folder gets its slash here (bash no longer sees the folder)
  local line=${COMP_LINE:0:COMP_POINT} pos=0 i tok lead w r
  local -a joined=() split=() out=()
  for ((i = 0; i < ${#COMP_WORDS[@]} && i <= COMP_CWORD; i++)); do
    tok=${COMP_WORDS[i]}
    lead=${line:pos}
    lead=${lead%%[![:blank:]]*}  # the blanks before this part: none where bash split a word
    pos=$((pos + ${#lead} + ${#tok}))
    if ((i > 1 && ${#lead} == 0)) && [[ $tok =~ ^[:=]+$ || ${COMP_WORDS[i-1]} =~ ^[:=]+$ ]]; then
      joined[${#joined[@]}-1]+=$tok
    else
      joined+=("$tok")
    fi
  done
  for w in "${joined[@]}"; do
    if [[ $w =~ ^(--[A-Za-z0-9][-A-Za-z0-9]*)=(.*)$ ]]; then split+=("${BASH_REMATCH[1]}" "${BASH_REMATCH[2]}")
    else split+=("$w"); fi
  done
  local typed=${COMP_WORDS[COMP_CWORD]}
  [[ $typed =~ ^[:=]+$ ]] && typed=""
  local whole=${split[${#split[@]}-1]}
  local kept=${whole%"$typed"}
  local COMP_WORDS=("${split[@]}") COMP_CWORD=$((${#split[@]} - 1))
  _shtab_rigctl
  [ -z "$kept" ] && return 0
  kept=$(_rigctl_plain "$kept")  # what the completions, unquoted, begin with
  for r in "${COMPREPLY[@]}"; do
    [[ $r == "$kept"* ]] || continue
    if [ -d "$r" ]; then out+=("${r#"$kept"}/"); compopt -o nospace 2>/dev/null
    else out+=("${r#"$kept"}"); fi
  done
  COMPREPLY=("${out[@]}")
}
_rigctl_cameras() {  # camera names of the take, grid folder or rig named earlier on the line
  local w typed names="" rig="" n
  for typed in "${COMP_WORDS[@]:1:COMP_CWORD-1}"; do
    w=$(_rigctl_word "$typed")
    names=$(_rigctl_folder_cameras "$w")
    [ -n "$names" ] && break
    if [ -z "$rig" ] && [[ " __RIGS__ " == *" $w "* || "$w" == *.yaml ]]; then rig=$w; fi
  done
  [ -z "$names" ] && names=$(_rigctl_rig_cameras "${rig:-sim-3x3}")
  # printed as they are, camera names only: compgen -W would expand a $(...) or `...` in a file's name
  while IFS= read -r n; do
    [[ $n =~ ^r[0-9]+c[0-9]+$ && $n == "$1"* ]] && printf '%s\n' "$n"
  done <<< "$names"
}
"""

_ZSH = r"""
_rigctl_rig_or_file() {
  compadd -- __RIGS__
  _files
}
_rigctl_rig_cameras() {  # a shipped rig's camera names or a rig file's (name: rXcY lines), one a line
  case $1 in
__RIG_CASES__
    *) [[ -f $1 ]] && sed -n 's/.*name: *\(r[0-9]*c[0-9]*\).*/\1/p' $1 2>/dev/null ;;
  esac
}
_rigctl_cameras() {  # camera names of the take, grid folder or rig named earlier on the line
  local w typed rig=""
  local -a names
  for typed in ${words[2,CURRENT-1]}; do
    w=${(Q)typed}  # the word as the command gets it ($words keeps its quotes); ~/ as the shell expands it
    [[ $typed == '~/'* ]] && w=$HOME/${w#'~/'}
    if [[ -f $w/take.yaml ]]; then  # take.yaml lists every camera (rectified and --dest takes too)
      names=(${(f)"$(sed -n '/^cameras:/,/^[^ ]/s/^  \(r[0-9]*c[0-9]*\):.*/\1/p' $w/take.yaml 2>/dev/null)"})
    elif [[ -f $w/grid.yaml ]]; then
      names=($w/r*c*.png(N:t:r))
    elif [[ -z $rig && ( " __RIGS__ " == *" $w "* || $w == *.yaml ) ]]; then
      rig=$w
    fi
    (( ${#names} )) && break
  done
  (( ${#names} )) || names=(${(f)"$(_rigctl_rig_cameras ${rig:-sim-3x3})"})
  compadd -- ${(M)names:#r<->c<->}
}
"""


def shipped_rigs() -> dict[str, str]:
    """Each shipped rig's name and its camera names (space-separated)."""
    import yaml

    rigs = {}
    for entry in sorted(resources.files("rigctl.rigs").iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".yaml"):
            data = yaml.safe_load(entry.read_text(encoding="utf-8"))
            rigs[entry.name[: -len(".yaml")]] = " ".join(str(c["name"]) for c in data.get("cameras", []))
    return rigs


def _mark(parser: argparse.ArgumentParser) -> None:
    """Tell shtab what each argument completes, walking every subcommand."""
    import shtab

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in {id(p): p for p in action.choices.values()}.values():
                _mark(sub)
            continue
        if action.nargs == 0 or action.choices:
            continue
        if action.dest in RIG_DESTS:
            action.complete = {"bash": "_rigctl_rig_or_file", "zsh": "_rigctl_rig_or_file", "tcsh": "f"}  # type: ignore[attr-defined]
        elif action.dest in CAMERA_DESTS and action.option_strings:  # ``miv import CAMERAS`` is a JSON file
            action.complete = {"bash": "_rigctl_cameras", "zsh": "_rigctl_cameras"}  # type: ignore[attr-defined]
        elif action.metavar in ("DIR", "OUT", "RECTIFIED_TAKE"):
            action.complete = {**shtab.DIRECTORY, "bash": "_rigctl_compgen_dirs"}  # type: ignore[attr-defined]
        elif action.type is Path or isinstance(action.type, args.InputPath):
            action.complete = {**shtab.FILE, "bash": "_rigctl_compgen_files"}  # type: ignore[attr-defined]


def script(shell: str) -> str:
    """The completion script for ``shell``, from the whole command line's parser."""
    import shtab

    from rigctl.cli.main import build_parser

    parser = build_parser()
    _mark(parser)
    rigs = shipped_rigs()
    names = " ".join(rigs)
    cases = "\n".join(f"    {name}) printf '%s\\n' {cams} ;;" for name, cams in rigs.items())
    preamble = {
        "bash": _BASH.replace("__RIGS__", names).replace("__RIG_CASES__", cases),
        "zsh": _ZSH.replace("__RIGS__", names).replace("__RIG_CASES__", cases),
        "tcsh": "",
    }[shell]
    text = shtab.complete(parser, shell=shell, preamble=preamble)
    if shell == "bash":  # bash calls the function that joins the words it split at : and = (see _BASH)
        hook = "complete -o bashdefault -F _shtab_rigctl rigctl"
        if hook not in text:
            raise RuntimeError(f"shtab's bash script no longer ends in {hook!r}: update rigctl.cli.completion")
        text = text.replace(hook, "complete -o bashdefault -F _rigctl_complete rigctl")
    return text


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "completion",
        help="print a shell completion script (bash, zsh, tcsh): commands, options, rigs, cameras, files",
        description="Prints a completion script generated from rigctl's own parser: commands and options, the "
        "shipped rigs' names, the camera names of the take named earlier on the line (--cameras), and file "
        "names where an argument is a path. Install it once per shell, as the examples show.",
        epilog=examples(
            ("bash, for this shell only", "source <(rigctl completion bash)"),
            (
                "bash, for every new shell (bash-completion loads it on first use)",
                "rigctl completion bash > ~/.local/share/bash-completion/completions/rigctl",
            ),
            (
                "zsh: a file named _rigctl in a folder of $fpath (then: autoload -U compinit && compinit)",
                "rigctl completion zsh > ~/.zfunc/_rigctl",
            ),
            ("tcsh: source it from ~/.tcshrc", "rigctl completion tcsh > ~/.rigctl.completion.csh"),
        ),
    )
    p.add_argument("shell", choices=SHELLS, help="the shell the script is for")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    print(script(ns.shell), end="")
    return 0
