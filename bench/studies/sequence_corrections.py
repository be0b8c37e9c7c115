"""What a warm frame's FEM steps cost in a sequence, with and without the
lagged factor's refresh (SolverOptions::lagged_refresh).

For each scene, bench/shipped.py's frames (activation ramps), warm-started:
1. EMU (accuracy 0.01): per frame its seconds, the estimate's seconds, and each
   of the estimator's FEM steps as PCG iterations / factorisations / seconds
   (first: x1 from EMU's answer; corr: a certificate step or correction;
   settle: a FEM solve from the certificate's last point);
2. FEM with a lagged factor (accuracy 0.01): warm seconds, Newton / PCG /
   factorisations summed over the warm frames.

    python bench/studies/sequence_corrections.py [--scenes fusiform_20k] [--frames 25]
        [--no-refresh] [--threads 1] [--per-frame]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import emu
from emu.core.geometry import vertex_error
from emu.solve import estimate as estimate_module

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # bench/: shared scenes
from bench_scenes import SCENES, start_run  # noqa: E402
from shipped import frame_activations  # noqa: E402


LOG: list = []   # the estimator's FEM steps of the current frame


def traced_estimator(log: list):
    """ErrorEstimator's FEM steps appended to log as (kind, PCG, factorisations, seconds)."""
    cls = estimate_module.ErrorEstimator
    for name, kind in (("first_correction", "first"), ("correction", "corr"), ("settle", "settle")):
        method = getattr(cls, name)

        def traced(self, *args, _method=method, _kind=kind, **kw):
            fem = self.fem
            p0, f0 = (fem.pcg_iterations, fem.factorizations) if fem else (0, 0)
            t0 = time.perf_counter()
            out = _method(self, *args, **kw)
            seconds = time.perf_counter() - t0
            fem = self.fem
            if fem is not None:
                log.append((_kind, fem.pcg_iterations - p0, fem.factorizations - f0, seconds))
            return out
        setattr(cls, name, traced)


def emu_sequence(name: str, frames: list, normalized: bool, refresh: bool, per_frame: bool) -> None:
    estimate_module.ESTIMATE_REFRESH = refresh
    scene = SCENES[name]()[0]
    solver = emu.Solver(scene, method="emu", accuracy=0.01)
    prev, warm, estimate = None, 0.0, 0.0
    for k, act in enumerate(frames):
        LOG.clear()
        t0 = time.perf_counter()
        prev = solver.solve(act, normalized=normalized, initial=prev)
        seconds = time.perf_counter() - t0
        if k:
            warm, estimate = warm + seconds, estimate + prev.error_estimate_time_s
        if per_frame:
            steps = " ".join(f"{kind}:{pcg}/{fz}/{t:.3f}" for kind, pcg, fz, t in LOG)
            chain = [prev.emu_positions] + list(prev.fem_steps or [])
            lengths = " ".join(f"{vertex_error(a, b):.1e}" for a, b in zip(chain, chain[1:])
                               if a is not None and b is not None)
            print(f"  {k:2d} {seconds:.3f} s, estimate {prev.error_estimate_time_s:.3f} s, Newton / CG "
                  f"{prev.iterations} / {prev.cg_iterations}, corrected {int(prev.corrected)}, "
                  f"estimate {prev.error_estimate:.1e} | {steps} | steps {lengths}")
    fem = solver._estimator.fem
    print(f"{name}: EMU warm frames {warm:.2f} s (estimate {estimate:.2f} s); the estimator's PCG "
          f"{fem.pcg_iterations}, factorisations {fem.factorizations}")


def fem_sequence(name: str, frames: list, normalized: bool, refresh: bool) -> None:
    scene = SCENES[name]()[0]
    solver = emu.Solver(scene, method="fem", lagged_factor=True, lagged_refresh=refresh, accuracy=0.01)
    prev, warm, newton, pcg = None, 0.0, 0, 0
    for k, act in enumerate(frames):
        t0 = time.perf_counter()
        prev = solver.solve(act, normalized=normalized, initial=prev)
        if k:
            warm += time.perf_counter() - t0
            newton, pcg = newton + prev.iterations, pcg + prev.cg_iterations
    print(f"{name}: lagged FEM warm frames {warm:.2f} s, Newton {newton}, PCG {pcg}, factorisations "
          f"{solver._core.factorizations} (all frames)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=["fusiform_20k"])
    ap.add_argument("--frames", type=int, default=25)
    ap.add_argument("--no-refresh", action="store_true", help="lagged_refresh off (EMU's estimator and FEM)")
    ap.add_argument("--per-frame", action="store_true", help="EMU's frames one by one")
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    start_run(a.threads)
    traced_estimator(LOG)
    refresh = not a.no_refresh
    print(f"lagged_refresh {refresh}")
    for name in a.scenes:
        _, act, normalized = SCENES[name]()
        frames = frame_activations(act, a.frames)
        emu_sequence(name, frames, normalized, refresh, a.per_frame)
        fem_sequence(name, frames, normalized, refresh)


if __name__ == "__main__":
    main()
