"""What the C++ core runs on (BLAS, threads) and the package version: every
timing should say what it ran on.

Threads: by default the core runs on every core this process may use, and
each solve steps down to as many as other processes leave free (at least
one). OpenMP's team meets at thousands of barriers per second in EMU's
solve; where another process holds a core, a team thread waits a scheduler
time slice at each, and two threads ran 6.5x slower than one (neck_roll
with a busy process per core; docs/DESIGN.md, "Threads on a busy machine").
What other processes use is measured from /proc/stat (Linux) between solves:
the busy time of this process's cores less its own CPU time. A count chosen
by the user (set_threads, Solver(threads=), emu ... --threads,
OMP_NUM_THREADS) is kept as it is.
"""
from __future__ import annotations

import os
import time

from .. import _core

__all__ = ["__version__", "info", "set_threads", "adapt_threads", "free_cores", "THREADS_WINDOW_S"]

__version__ = "0.1.0"

# The shortest stretch of time over which other processes' CPU use is
# measured (shorter: the count is left as it is).
THREADS_WINDOW_S = 0.05

_default_threads = max(1, int(_core.blas_info()["omp_threads"]))
_chosen = int(os.environ["OMP_NUM_THREADS"]) if os.environ.get("OMP_NUM_THREADS", "").isdigit() else None
_running = _default_threads if _chosen is None else _chosen


def info() -> dict:
    """Which BLAS and how many threads the C++ core runs on: ``kernel``
    (OpenBLAS's kernel, and who chose it: emu.core.blas_kernel), ``threads``
    ("auto (up to N)" or the count chosen)."""
    from . import blas_kernel

    d = dict(_core.blas_info())
    d["version"] = __version__
    why = blas_kernel.decision.get("why", "OpenBLAS's own choice")
    d["kernel"] = f"{d.get('kernel') or 'unknown'} ({why})"
    d["threads"] = f"auto (up to {_default_threads})" if _chosen is None else str(_chosen)
    return d


def set_threads(threads) -> None:
    """Set the OpenMP and OpenBLAS threads of the C++ core (threads >= 1), or
    None: automatic again (every core this process may use, fewer where other
    processes hold them)."""
    global _chosen, _running, _last, _measured
    if threads is None:
        _chosen = None
        _running = _default_threads
        _core.set_threads(_default_threads)
        _last = _sample(_cpus) if _cpus else None   # measured afresh from here
        _measured = False
        return
    if isinstance(threads, bool) or int(threads) != threads or int(threads) < 1:
        raise ValueError(f"threads must be an integer >= 1 (or None: automatic), got {threads!r}")
    _chosen = _running = int(threads)
    _core.set_threads(_chosen)


def _cpu_lines(cpus) -> list:
    """The /proc/stat jiffy counters of the given cores (None where unreadable)."""
    try:
        with open("/proc/stat") as f:
            rows = {p[0]: [int(v) for v in p[1:]] for p in (line.split() for line in f) if p and p[0].startswith("cpu")}
    except (OSError, ValueError):
        return None
    out = [rows.get(f"cpu{c}") for c in cpus]
    return None if any(r is None for r in out) else out


def _busy_jiffies(rows) -> int:
    # user nice system idle iowait irq softirq steal ...: all but idle and iowait
    # (steal: time a virtual machine's core ran someone else)
    return sum(sum(r[:8]) - r[3] - r[4] for r in rows)


class _Sample:
    __slots__ = ("busy_s", "own_s", "wall_s")

    def __init__(self, busy_s, own_s, wall_s):
        self.busy_s, self.own_s, self.wall_s = busy_s, own_s, wall_s


def _sample(cpus):
    rows = _cpu_lines(cpus)
    if rows is None:
        return None
    t = os.times()
    return _Sample(_busy_jiffies(rows) / os.sysconf("SC_CLK_TCK"), t.user + t.system, time.monotonic())


def free_cores(before, after, cores: int) -> float | None:
    """Cores other processes left free between two samples: ``cores`` less
    their busy time per second (the cores' busy time less this process's own
    CPU time); None for a stretch under THREADS_WINDOW_S."""
    if before is None or after is None:
        return None
    wall = after.wall_s - before.wall_s
    if wall < THREADS_WINDOW_S:
        return None
    others = (after.busy_s - before.busy_s) - (after.own_s - before.own_s)
    return cores - max(0.0, others) / wall


try:
    _cpus = sorted(os.sched_getaffinity(0))
except (AttributeError, OSError):
    _cpus = None
_last = _sample(_cpus) if _cpus else None
_measured = False


def adapt_threads() -> int:
    """Before a solve: the thread count to run it on, set in the core. The
    count chosen by the user where there is one; else every core this
    process may use, less those other processes kept busy since the last
    call (rounded, at least one)."""
    global _last, _running, _measured
    if _chosen is not None or not _cpus:
        return _running
    now = _sample(_cpus)
    if (not _measured and now is not None and _last is not None
            and now.wall_s - _last.wall_s < THREADS_WINDOW_S):
        # no measurement yet (a first solve right after import or set_threads(None)):
        # the rest of the stretch, once
        time.sleep(THREADS_WINDOW_S - (now.wall_s - _last.wall_s))
        now = _sample(_cpus)
    free = free_cores(_last, now, len(_cpus))   # None for a short stretch: it grows to the next solve
    if now is not None and free is not None:
        _last, _measured = now, True
        want = max(1, min(_default_threads, int(round(free))))
        if want != _running:
            _running = want
            _core.set_threads(want)
    return _running
