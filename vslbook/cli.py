"""The ``vslbook`` command line.

    vslbook budgets                         the presets and what they scale
    vslbook algorithms                      registered algorithms and their envs
    vslbook figures                         registered figures
    vslbook run ALGO --env ENV --seed S --budget B [--set key=value ...] [--root runs]
    vslbook run ALGO --env ENV --seeds 0 1 2 ...   several seeds in one process
    vslbook sweep ALGO --env ENV [--env ENV2] --seeds 0 1 2 [--grid key=v1,v2] \
                  [--executor debug|local|slurm] [--slurm slurm.yaml]
    vslbook figure ID [--budget B] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from vslbook.budget import BUDGETS, get_budget
from vslbook.registry import ALGORITHMS, FIGURES, get_figure, load_plugins


def _pairs(items: Sequence[str] | None, *, lists: bool) -> dict:
    out: dict = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"expected key=value, got {item!r}")
        key, value = item.split("=", 1)
        out[key] = value.split(",") if lists else value
    return out


def _seed(text: str) -> int:
    """argparse type of a seed: an integer >= 0, with a clear message otherwise."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return seed


def _algorithm_list() -> str:
    """The registered algorithms, one a line, for the help of ``run`` and ``sweep``."""
    load_plugins()
    lines = ["registered algorithms (vslbook algorithms):"]
    for name, algo in sorted(ALGORITHMS.items()):
        lines.append(f"  {name:16s} {algo.doc}")
        if algo.envs:
            lines.append(f"  {'':16s} envs: {', '.join(algo.envs)}")
    return "\n".join(lines)


class _SubParser(argparse.ArgumentParser):
    """A sub-command parser; with ``list_algorithms`` its help ends with the algorithms.

    The list is built only when help is shown, so other commands do not import the
    algorithm modules (and torch) just to parse their arguments.
    """

    def __init__(self, *args, list_algorithms: bool = False, **kwargs) -> None:
        if list_algorithms:
            kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)
        self.list_algorithms = list_algorithms

    def format_help(self) -> str:
        if self.list_algorithms and self.epilog is None:
            self.epilog = _algorithm_list()
        return super().format_help()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vslbook", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_SubParser)
    algo_help = {"list_algorithms": True}
    sub.add_parser("budgets", help="list the budget presets")
    sub.add_parser("algorithms", help="list registered algorithms")
    sub.add_parser("figures", help="list registered figures")

    r = sub.add_parser("run", help="train one algorithm on one env with one seed", **algo_help)
    r.add_argument("algo", help="a registered algorithm (listed below)")
    r.add_argument("--env", required=True, help="environment id, e.g. vslbook/PointReach-v0")
    one = r.add_mutually_exclusive_group()
    # default None, not 0: argparse cannot tell an explicit "--seed 0" from a default 0
    one.add_argument("--seed", type=_seed, default=None, help="integer >= 0 (default 0)")
    one.add_argument(
        "--seeds", type=_seed, nargs="+", default=None,
        help="several seeds in one process (DIME and its variants: a seed axis on every "
        "tensor); one run directory per seed",
    )  # fmt: skip
    r.add_argument(
        "--budget",
        default=None,
        help="smoke | reduced | full (default: $VSLBOOK_BUDGET or reduced)",
    )
    r.add_argument("--root", default="runs", help="folder for run directories")
    r.add_argument(
        "--set", nargs="*", action="extend", metavar="KEY=VALUE",
        help="override config fields (repeatable: the pairs of every --set count)",
    )
    r.add_argument("--no-progress", action="store_true")
    r.add_argument(
        "--reuse-stale",
        action="store_true",
        help="reuse or resume a run directory made by other code (prints a warning)",
    )

    s = sub.add_parser(
        "sweep", help="train a grid of configs and seeds via submitit", **algo_help
    )
    s.add_argument("algo", help="a registered algorithm (listed below)")
    s.add_argument("--env", action="append", required=True, help="environment id (repeatable)")
    s.add_argument("--seeds", type=_seed, nargs="*", default=None)
    s.add_argument("--budget", default=None)
    s.add_argument("--root", default="runs")
    s.add_argument(
        "--grid", nargs="*", action="extend", metavar="KEY=V1,V2",
        help="grid over config fields (repeatable)",
    )
    s.add_argument("--executor", default="local", choices=["debug", "local", "slurm"])
    s.add_argument("--slurm", default=None, help="YAML file of submitit SLURM parameters")

    f = sub.add_parser("figure", help="reproduce a registered figure")
    f.add_argument("id")
    f.add_argument("--budget", default=None)
    f.add_argument(
        "--out", default=None, help="output folder (default: $VSLBOOK_FIGURES or build/figures)"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return _dispatch(args)
    except ValueError as err:
        print(f"vslbook: error: {err}", file=sys.stderr)
        return 2


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "budgets":
        for b in BUDGETS.values():
            print(
                f"{b.name:8s} fraction={b.fraction:<6g} seeds={b.seeds:<3d} "
                f"eval_episodes={b.eval_episodes:<3d} bootstrap_reps={b.bootstrap_reps}"
            )
        return 0
    if args.command in ("algorithms", "figures"):
        load_plugins()
        table = ALGORITHMS if args.command == "algorithms" else FIGURES
        for name, item in sorted(table.items()):
            extra = f"  [{', '.join(item.envs)}]" if getattr(item, "envs", ()) else ""
            print(f"{name:24s} {item.doc}{extra}")
        return 0
    if args.command == "run" and args.seeds is not None:
        from vslbook.training import run_seeds

        rds = run_seeds(
            args.algo, args.env, args.seeds, args.budget, root=args.root,
            overrides=_pairs(args.set, lists=False), progress=not args.no_progress,
            reuse_stale=True if args.reuse_stale else None,
        )  # fmt: skip
        for rd in rds:
            print(rd.path, rd.status)
        return 1 if any(rd.failed for rd in rds) else 0
    if args.command == "run":
        from vslbook.training import run

        rd = run(
            args.algo,
            args.env,
            0 if args.seed is None else args.seed,
            args.budget,
            root=args.root,
            overrides=_pairs(args.set, lists=False),
            progress=not args.no_progress,
            reuse_stale=True if args.reuse_stale else None,
        )
        print(rd.path)
        if rd.failed:
            print(f"FAILED: {rd.failure.get('message')}", file=sys.stderr)
            return 1
        if rd.done:
            print(json.dumps(json.loads((rd.path / "DONE").read_text() or "{}"), indent=1))
        return 0
    if args.command == "sweep":
        from vslbook.sweep import sweep

        paths = sweep(
            args.algo,
            args.env,
            args.seeds,
            grid=_pairs(args.grid, lists=True),
            budget=args.budget,
            root=args.root,
            executor=args.executor,
            slurm=args.slurm,
        )
        for p in paths:
            print(p)
        return 0
    if args.command == "figure":
        fig = get_figure(args.id)
        out = Path(args.out) if args.out else None
        for path in fig.make(budget=get_budget(args.budget), out_dir=out):
            print(path)
        return 0
    raise AssertionError(args.command)  # argparse guarantees a known command


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
