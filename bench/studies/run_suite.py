#!/usr/bin/env python3
"""Run emu_vs_fem.py over mesh sizes and thread counts; print a markdown table.

    python bench/studies/run_suite.py --tets 5000 20000 80000 --threads 1 2 [--out bench/results]

Each run is a separate process (so thread settings and memory start clean) and
writes its JSON into --out; the table is printed at the end, ready to paste
into bench/README.md.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tets", type=int, nargs="+", default=[5000, 20000, 80000])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--out", default=os.path.join(HERE, "results"))
    ap.add_argument("--woodbury-max-iterations", type=int, default=500)
    ap.add_argument("--alpha", type=float, default=100.0)
    ap.add_argument("--schur", action="store_true", help="include Newton-Krylov with the Schur preconditioner")
    ap.add_argument("--skip-woodbury", action="store_true", help="do not run the paper's quasi-Newton step")
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    results = []
    for n in a.tets:
        for t in a.threads:
            path = os.path.join(a.out, f"fusiform_{n}_t{t}.json")
            cmd = [sys.executable, os.path.join(HERE, "emu_vs_fem.py"), "--tets", str(n), "--threads", str(t),
                   "--alpha", str(a.alpha), "--woodbury-max-iterations", str(a.woodbury_max_iterations),
                   "--json", path] + (["--schur"] if a.schur else []) + (["--skip-woodbury"] if a.skip_woodbury else [])
            print("+", " ".join(cmd), flush=True)
            subprocess.run(cmd, check=True)
            with open(path) as f:
                results.append(json.load(f))
    print()
    print("| tets | vertices | threads | method | setup s | solve s | iterations (CG) | converged | "
          "rel. energy change | error / diagonal | speed-up vs FEM |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        for key in ("fem", "emu_newton_krylov", "emu_newton_krylov_schur", "emu_woodbury"):
            if key not in r:
                continue
            m = r[key]
            its = f"{m['iterations']}" + (f" ({m['cg_iterations']})" if m["cg_iterations"] else "")
            print(f"| {r['tets']} | {r['vertices']} | {r['threads']} | {key} | {m['setup_s']:.2f} | "
                  f"{m['solve_s']:.2f} | {its} | {'yes' if m['converged'] else 'no'} | "
                  f"{m['rel_energy_change']:.1e} | {m['vertex_error_to_fem']:.2e} | {m['speedup_vs_fem']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
