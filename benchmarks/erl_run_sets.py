"""Wall time of the training behind the Chapter 3 and 4 notebooks, run set by run set.

Trains the run sets of :mod:`vslbook.experiments.erl_run_sets` (exactly the runs the
notebook's cells start) at a budget from scratch in ``--root`` (default: a new temporary
folder) and prints the wall time of each set and of all of them, i.e. what the chapter's
training costs at that budget; the notebook itself then finds every run finished. Sets
already finished in ``--root`` are reused, not timed. Two processes with disjoint
``--sets`` and one thread each use two cores.

    python benchmarks/erl_run_sets.py --chapter 3 --budget reduced
    python benchmarks/erl_run_sets.py --chapter 4 --sets 4.3c 4.4a --root runs-ch4
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path


def time_run_sets(chapter: int, budget: str, root: str | None, only: list[str] | None) -> float:
    """Train the sets and print one line per set; returns the total wall time in seconds."""
    import torch

    from vslbook.budget import get_budget
    from vslbook.experiments.erl_run_sets import RUN_SETS, run_sets

    if chapter not in RUN_SETS:
        raise SystemExit(f"--chapter must be one of {sorted(RUN_SETS)}, got {chapter}")
    unknown = sorted(set(only or ()) - set(RUN_SETS[chapter]))
    if unknown:
        raise SystemExit(f"unknown run set(s) {unknown}; the sets are {list(RUN_SETS[chapter])}")
    b = get_budget(budget)
    base = Path(root) if root else Path(tempfile.mkdtemp(prefix=f"ch{chapter}-run-sets-"))
    if base.exists() and any(base.iterdir()):
        print(f"note: {base} already holds runs; finished ones are reused, not timed")
    print(f"Chapter {chapter} run sets at budget {b.name!r} ({b.seeds} seeds) in {base}")
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    total = 0.0

    def report(name: str, runs: int, seconds: float) -> None:
        nonlocal total
        total += seconds
        print(f"{name:14s} {runs:3d} runs {seconds / 60:8.1f} min", flush=True)

    run_sets(chapter, b, base, only=only, report=report)
    print(f"{'all':14s} {'':8s} {total / 60:8.1f} min")
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--chapter", type=int, required=True, help="3 or 4")
    parser.add_argument("--budget", default="reduced", help="smoke | reduced | full")
    parser.add_argument("--sets", nargs="+", default=None, help="only these run sets")
    parser.add_argument("--root", default=None, help="run folder (default: a temp dir)")
    parser.add_argument("--threads", type=int, default=None, help="torch threads")
    args = parser.parse_args()
    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    time_run_sets(args.chapter, args.budget, args.root, args.sets)


if __name__ == "__main__":
    main()
