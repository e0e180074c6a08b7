"""A stereo pair from the four nearest cameras at 1920x1080 against the budget (33 ms: a 30 fps preview on
two CPU cores) and against the paper's GPU renderer (11.1 ms per eye pair at 90 fps), measured in one run,
with the renderer's quality on the ideal simulated presenter (true disparity).

    python benchmarks/render_stereo.py [--size 1920x1080] [--repeats N]
"""

from __future__ import annotations

import argparse

from rigctl.cli.render import size
from rigctl.render.bench import bench_render, format_bench
from rigctl.simulated_presenter import presenter_render


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=size, default=(1920, 1080))
    parser.add_argument("--repeats", type=int, default=10)
    ns = parser.parse_args()
    r = bench_render(presenter_render(), ns.size, ns.repeats)
    print(format_bench(r))
    print(f"ratio to the 33 ms budget: {r['stereo_pair_ms'] / r['budget_ms']:.2f}")


if __name__ == "__main__":
    main()
