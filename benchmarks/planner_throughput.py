"""Planner throughput: 10^6 configurations, vectorised against a plain Python loop, in one run.

Prints configurations per second for both and their ratio. Both paths compute the same thing (minimum
near distance and the parallax at it, equations (1) and (2)); the loop uses math, the vectorised path
the planner's numpy functions, and the results are compared so the ratio is of equal work.

    python benchmarks/planner_throughput.py [--n 1000000]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from rigctl.planning import planner


def loop(f: list[float], sp: list[float], b: list[float], d: list[float], bpx: float) -> list[float]:
    out = []
    for i in range(len(f)):
        c0 = f[i] / sp[i]
        a = c0 * b[i] / bpx
        root = math.sqrt(d[i])
        near = 2.0 * a * root / (root + math.sqrt(d[i] + 4.0 * a))
        out.append(c0 * b[i] * d[i] / near / (near + d[i]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1_000_000)
    n = parser.parse_args().n
    rng = np.random.default_rng(0)
    f = rng.uniform(1e-3, 1.0, n)
    sp = rng.uniform(0.5e-6, 50e-6, n)
    b = rng.uniform(1e-6, 10.0, n)
    d = rng.uniform(0.01, 1e4, n)
    bpx = 153.6

    t0 = time.perf_counter()
    c0 = planner.c0_px(f, sp)
    near = planner.min_near_m(c0, b, d, bpx)
    vec = planner.subject_parallax_px(c0, b, near, d)
    t_vec = time.perf_counter() - t0

    lists = f.tolist(), sp.tolist(), b.tolist(), d.tolist()
    t0 = time.perf_counter()
    ref = loop(*lists, bpx)
    t_loop = time.perf_counter() - t0

    worst = float(np.max(np.abs(np.asarray(ref) - vec) / bpx))
    print(f"configurations        {n}")
    print(f"vectorised            {t_vec * 1e3:9.1f} ms  {n / t_vec / 1e6:8.2f} M configs/s")
    print(f"python loop           {t_loop * 1e3:9.1f} ms  {n / t_loop / 1e6:8.2f} M configs/s")
    print(f"speed-up (loop / vec) {t_loop / t_vec:9.1f} x")
    print(f"max relative diff     {worst:.2e} (both return the budget, {bpx} px)")


if __name__ == "__main__":
    main()
