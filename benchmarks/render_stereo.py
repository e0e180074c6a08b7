"""A stereo pair from the four nearest cameras at 1920x1080 against the budget (33 ms: a 30 fps preview on
two CPU cores) and against the paper's GPU renderer (11.1 ms per eye pair at 90 fps), measured in one run,
first alone and then beside two CPU-bound processes (``yes > /dev/null``, as CI runs), with the renderer's
quality on the ideal simulated presenter (true disparity).

    python benchmarks/render_stereo.py [--size 1920x1080] [--repeats N] [--busy 0 2]
"""

from __future__ import annotations

import argparse
import subprocess

from rigctl.cli.render import size
from rigctl.render.bench import BUDGET_MS, PAPER_PAIR_MS, RenderBenchResult, bench_render, format_bench
from rigctl.simulated_presenter import presenter_render


def beside(busy: int, data: object, wh: tuple[int, int], repeats: int) -> RenderBenchResult:
    """The benchmark with ``busy`` copies of ``yes`` writing to /dev/null beside it (stopped after)."""
    hogs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(busy)]
    try:
        return bench_render(data, wh, repeats)  # type: ignore[arg-type]
    finally:
        for p in hogs:
            p.kill()
            p.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=size, default=(1920, 1080))
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--busy", type=int, nargs="+", default=[0, 2], help="CPU-bound processes beside it")
    ns = parser.parse_args()
    data = presenter_render()
    results = {}
    for busy in ns.busy:
        r = beside(busy, data, ns.size, ns.repeats)
        results[busy] = r
        print(f"--- beside {busy} CPU-bound process(es)")
        print(format_bench(r))
    print("--- summary (median warm pair)")
    for busy, r in results.items():
        ms = r["stereo_pair_ms"]
        print(
            f"beside {busy}: {ms:.1f} ms = {ms / BUDGET_MS:.2f}x the {BUDGET_MS:.0f} ms budget, "
            f"{ms / PAPER_PAIR_MS:.2f}x the paper's GPU pair ({PAPER_PAIR_MS:.1f} ms)"
        )


if __name__ == "__main__":
    main()
