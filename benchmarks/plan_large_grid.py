"""``rigctl plan --json`` on square grids up to the largest a rig file allows (64x64, 8.4 million pairs).

Each size runs in its own process, so its peak resident memory is its own: the process loads the rig file,
plans, and writes the JSON, timing each phase. Printed per size: pairs, pairs listed (one per offset
beyond 10,000), the seconds of load + plan + JSON, the plan alone, the whole CLI run as a user sees it
(interpreter start and imports included), peak RSS, and time and memory as a share of the budget the
issue sets for 64x64 (2 s, 200 MB) -- ratios measured in this one run.

    python benchmarks/plan_large_grid.py [--sizes 3,16,32,64] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

BUDGET_S = 2.0
BUDGET_MB = 200.0


def rig_text(n: int) -> str:
    rig = {
        "spec": 1,
        "name": f"grid-{n}x{n}",
        "sensor": {"width_mm": 13.056, "height_mm": 7.344},
        "format": {"width_px": 960, "height_px": 540, "fps": 25},
        "lens": {"focal_length_mm": 25.0},
        "grid": {"rows": n, "columns": n, "spacing_x_m": 0.12, "spacing_y_m": 0.078},
        "cameras": [{"name": f"r{r}c{c}", "device": f"sim://{r}/{c}"} for r in range(n) for c in range(n)],
    }
    return yaml.safe_dump(rig, sort_keys=False)


CHILD = """
import json, resource, sys, time
from rigctl.planning.report import plan_rig
from rigctl.rig import load_rig
t0 = time.perf_counter()
rig = load_rig(sys.argv[1])
t1 = time.perf_counter()
plan = plan_rig(rig, subject_depth_m=1.0)
t2 = time.perf_counter()
text = json.dumps(plan.as_json(), indent=2, allow_nan=False)
t3 = time.perf_counter()
print(json.dumps({"pairs": plan.pair_count, "listed": len(plan.pairs), "load_s": t1 - t0, "plan_s": t2 - t1,
                  "json_s": t3 - t2, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run(n: int, folder: Path) -> dict[str, float]:
    path = folder / f"grid-{n}.yaml"
    path.write_text(rig_text(n))
    out = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=True)
    row = {"grid": n, **json.loads(out.stdout)}
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "rigctl", "plan", str(path), "--subject-depth", "1", "--json"],
        capture_output=True,
        check=True,
    )
    row["cli_s"] = time.perf_counter() - t0
    row["seconds"] = row["load_s"] + row["plan_s"] + row["json_s"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="3,16,32,64")
    parser.add_argument("--json", action="store_true")
    ns = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (int(v) for v in ns.sizes.split(",")):
            rows.append(run(n, Path(tmp)))
    if ns.json:
        print(json.dumps(rows))
        return
    print(
        f"{'grid':>7}{'pairs':>11}{'listed':>8}{'load+plan+json s':>18}{'plan s':>8}{'of 2 s':>8}{'CLI s':>7}"
        f"{'peak MB':>9}{'of 200 MB':>11}"
    )
    for r in rows:
        print(
            f"{r['grid']:>4}x{r['grid']:<2}{r['pairs']:>11,}{r['listed']:>8,}{r['seconds']:>18.2f}{r['plan_s']:>8.3f}"
            f"{r['seconds'] / BUDGET_S:>8.0%}{r['cli_s']:>7.2f}{r['peak_mb']:>9.0f}{r['peak_mb'] / BUDGET_MB:>11.0%}"
        )


if __name__ == "__main__":
    main()
