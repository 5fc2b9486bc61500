"""Time thesis_lib.dtw against fastdtw (the authors' choice) and dtaidistance (C).

Cases:
  (a) DEFENDER's per-step work: one 20-step query against 50 demonstrations of 20 steps,
      11 features (hopper observations), one batch of costs.
  (b) one 1000 x 1000 pair of 1-D sequences.

Numba compile time is measured separately (a fresh NUMBA_CACHE_DIR forces a real compile,
unless --use-cache) and excluded from the timings. Times are per call: the best and the
median of --repeats runs, each run looping until it lasts at least --min-time seconds;
the methods of a case take turns run by run, so background load affects them alike.
fastdtw (pure Python, 0.1-0.3 s a call) gets at most 3 runs.

    python benchmarks/bench_dtw.py --repeats 25
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from collections.abc import Callable
from typing import NamedTuple


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--repeats", type=int, default=25, help="timed runs per method (best and median reported)"
    )
    p.add_argument(
        "--min-time", type=float, default=0.002, help="seconds each timed run lasts at least"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--use-cache",
        action="store_true",
        help="keep numba's disk cache (compile time = load time)",
    )
    return p.parse_args()


ARGS = parse_args()
if not ARGS.use_cache:  # must happen before numba is imported
    os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="bench_dtw_numba_")

import numpy as np  # noqa: E402

_t0 = time.perf_counter()
import thesis_lib.dtw as tdtw  # noqa: E402

IMPORT_S = time.perf_counter() - _t0

try:
    from fastdtw import fastdtw
except ImportError:  # pragma: no cover
    fastdtw = None
try:
    from dtaidistance import dtw as dtai_dtw
    from dtaidistance import dtw_ndim as dtai_ndim
except ImportError:  # pragma: no cover
    dtai_dtw = dtai_ndim = None

FASTDTW_RUNS = 3


class Method(NamedTuple):
    name: str
    fn: Callable[[], object]
    n_runs: int


class Row(NamedTuple):
    case: str
    name: str
    best: float
    median: float
    base: float  # best time of the case's first method


def calibrate(fn: Callable[[], object], min_time: float) -> int:
    """Loops of fn (after a warm-up call) that last at least min_time seconds."""
    fn()
    loops = 1
    while True:
        t = time.perf_counter()
        for _ in range(loops):
            fn()
        elapsed = time.perf_counter() - t
        if elapsed >= min_time:
            return loops
        loops = max(loops * 2, int(loops * min_time / max(elapsed, 1e-9) * 1.2))


def time_case(case: str, methods: list[Method]) -> list[Row]:
    """Best and median seconds per call of each method, runs interleaved round-robin."""
    loops = [calibrate(m.fn, ARGS.min_time) for m in methods]
    runs: list[list[float]] = [[] for _ in methods]
    for r in range(ARGS.repeats):
        for k, m in enumerate(methods):
            if r < m.n_runs:
                t = time.perf_counter()
                for _ in range(loops[k]):
                    m.fn()
                runs[k].append((time.perf_counter() - t) / loops[k])
    base = min(runs[0])
    return [Row(case, m.name, min(v), float(np.median(v)), base) for m, v in zip(methods, runs)]


def measure_compile() -> float:
    """Seconds for the first call of every kernel the benchmark uses (compile or cache load)."""
    rng = np.random.default_rng(0)
    x, refs = rng.normal(size=(3, 2)), [rng.normal(size=(4, 2)), rng.normal(size=(5, 2))]
    t = time.perf_counter()
    for metric in ("l1", "sqeuclidean"):
        tdtw.dtw(x, refs[0], metric=metric)
        tdtw.dtw(x[:, 0], refs[0][:, 0], metric=metric)
        tdtw.dtw_batch(x, refs, metric=metric)
    return time.perf_counter() - t


def case_a(rng: np.random.Generator) -> tuple[list[Row], list[str]]:
    query = rng.normal(size=(20, 11))
    demos = [rng.normal(size=(20, 11)) for _ in range(50)]
    packed = tdtw.pack_references(demos)
    n = ARGS.repeats
    methods = [
        Method(
            "thesis_lib dtw_batch l1 (list in)",
            lambda: tdtw.dtw_batch(query, demos, metric="l1"),
            n,
        ),
        Method(
            "thesis_lib dtw_batch l1 (packed)",
            lambda: tdtw.dtw_batch(query, packed, metric="l1"),
            n,
        ),
        Method(
            "thesis_lib dtw_batch sqeucl (packed)",
            lambda: tdtw.dtw_batch(query, packed, metric="sqeuclidean"),
            n,
        ),
    ]
    checks = []
    exact_l1 = tdtw.dtw_batch(query, packed, metric="l1")
    if fastdtw is not None:
        methods.append(
            Method(
                "fastdtw r=1 L1, loop (paper)",
                lambda: [fastdtw(query, d, radius=1, dist=1) for d in demos],
                min(n, FASTDTW_RUNS),
            )
        )
        over = np.array([fastdtw(query, d, radius=1, dist=1)[0] for d in demos]) / exact_l1 - 1
        checks.append(
            f"(a) fastdtw r=1 vs exact L1: never below: {bool((over > -1e-12).all())}; above on "
            f"{int((over > 1e-12).sum())}/{len(demos)} demos, by up to {max(over.max(), 0.0):.1%}"
        )
    if dtai_ndim is not None:
        series = [query, *demos]
        block = ((0, 1), (1, len(series)))
        methods += [
            Method(
                "dtaidistance ndim.distance_fast loop",
                lambda: [dtai_ndim.distance_fast(query, d) for d in demos],
                n,
            ),
            Method(
                "dtaidistance ndim.distance_matrix_fast",
                lambda: dtai_ndim.distance_matrix_fast(series, block=block, parallel=False),
                n,
            ),
        ]
        ours = np.sqrt(tdtw.dtw_batch(query, packed, metric="sqeuclidean"))
        theirs = np.array([dtai_ndim.distance_fast(query, d) for d in demos])
        checks.append(
            f"(a) max |sqrt(our sqeuclidean) - dtaidistance| = {np.max(np.abs(ours - theirs)):.1e}"
        )
    return time_case("(a) 1 x 50 demos, 20x20 steps, F=11", methods), checks


def case_b(rng: np.random.Generator) -> tuple[list[Row], list[str]]:
    x, y = rng.normal(size=1000), rng.normal(size=1000)
    n = ARGS.repeats
    methods = [
        Method("thesis_lib dtw l1", lambda: tdtw.dtw(x, y, metric="l1"), n),
        Method("thesis_lib dtw sqeucl", lambda: tdtw.dtw(x, y, metric="sqeuclidean"), n),
    ]
    checks = []
    if fastdtw is not None:
        methods.append(
            Method(
                "fastdtw r=1 L1 (paper)",
                lambda: fastdtw(x, y, radius=1, dist=1),
                min(n, FASTDTW_RUNS),
            )
        )
        over = fastdtw(x, y, radius=1, dist=1)[0] / tdtw.dtw(x, y, metric="l1") - 1
        checks.append(f"(b) fastdtw r=1 cost is {over:.1%} above exact L1")
    if dtai_dtw is not None:
        methods.append(
            Method("dtaidistance dtw.distance_fast", lambda: dtai_dtw.distance_fast(x, y), n)
        )
        diff = abs(np.sqrt(tdtw.dtw(x, y, metric="sqeuclidean")) - dtai_dtw.distance_fast(x, y))
        checks.append(f"(b) |sqrt(our sqeuclidean) - dtaidistance| = {diff:.1e}")
    return time_case("(b) 1 pair, 1000x1000, 1-D", methods), checks


def fmt(seconds: float) -> str:
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6)):
        if seconds >= scale:
            return f"{seconds / scale:8.2f} {unit}"
    return f"{seconds / 1e-9:8.2f} ns"


def speedups(rows: list[Row]) -> list[str]:
    """How many times faster thesis_lib is than each library's fastest route (best times)."""
    ours_by_case = {
        "(a)": ("thesis_lib dtw_batch l1 (list in)", "thesis_lib dtw_batch sqeucl (packed)"),
        "(b)": ("thesis_lib dtw l1", "thesis_lib dtw sqeucl"),
    }
    best = {(r.case[:3], r.name): r.best for r in rows}
    lines = []
    for case, ours in ours_by_case.items():
        for library in ("fastdtw", "dtaidistance"):
            group = {n: b for (c, n), b in best.items() if c == case and n.startswith(library)}
            if not group:
                continue
            name, other = min(group.items(), key=lambda kv: kv[1])
            parts = [
                f"{other / best[(case, o)]:.1f}x ({o.removeprefix('thesis_lib ')})" for o in ours
            ]
            lines.append(f"{case} speed-up over {name}: " + ", ".join(parts))
    return lines


def main() -> None:
    import numba

    rng = np.random.default_rng(ARGS.seed)
    compile_s = measure_compile()
    rows_a, checks_a = case_a(rng)
    rows_b, checks_b = case_b(rng)
    rows = rows_a + rows_b

    print(
        f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
        f"{platform.machine()}, {os.cpu_count()} CPUs; thesis_lib kernels are single-threaded"
    )
    what = "cache load" if ARGS.use_cache else "numba compile"
    print(
        f"import thesis_lib.dtw: {IMPORT_S:.2f} s; first calls ({what}, excluded below): {compile_s:.2f} s"
    )
    print(
        f"repeats={ARGS.repeats}, min-time={ARGS.min_time}s per run; ratio = time / first row of the case\n"
    )
    width = max(len(r.name) for r in rows)
    current = None
    for r in rows:
        if r.case != current:
            current = r.case
            print(current)
            print(f"  {'method':<{width}}  {'best':>11}  {'median':>11}  {'ratio':>8}")
        print(f"  {r.name:<{width}}  {fmt(r.best)}  {fmt(r.median)}  {r.best / r.base:8.2f}x")
    print()
    for line in speedups(rows) + checks_a + checks_b:
        print(line)


if __name__ == "__main__":
    main()
