"""The ``vslbook`` command line.

    vslbook budgets                         the presets and what they scale
    vslbook algorithms                      registered algorithms and their envs
    vslbook figures                         registered figures
    vslbook run ALGO --env ENV --seed S --budget B [--set key=value ...] [--root runs]
                [--dry-run] [--wait] [--restart]
    vslbook run ALGO --env ENV --seeds 0 1 2 ...   several seeds in one process
    vslbook sweep ALGO --env ENV [--env ENV2] --seeds 0 1 2 [--grid key=v1,v2] \
                  [--executor debug|local|slurm] [--slurm slurm.yaml] [--no-wait]
    vslbook figure ID [--budget B] [--out DIR]
    vslbook plan FIGURE [--budget B] [--root DIR] [--seeds ..]  a figure's runs, core-hours left
    vslbook train FIGURE [--budget B] [--seeds ..] [--jobs N]  a figure's runs, N at once
    vslbook record FIGURE [--budget B] [--root DIR] a figure's finished runs into data/results/
    vslbook results [--json] [--verify]      recorded run sets: final IQM, 95 % CI, stale
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from vslbook.budget import BUDGETS, get_budget
from vslbook.registry import ALGORITHMS, FIGURES, check_seed, get_figure, load_plugins


def _pairs(items: Sequence[str] | None, *, lists: bool) -> dict:
    out: dict = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"expected key=value, got {item!r}")
        key, value = item.split("=", 1)
        out[key] = value.split(",") if lists else value
    return out


def _seed(text: str) -> int:
    """argparse type of a seed: an integer in ``[0, 2**32)``, with a clear message otherwise."""
    try:
        return check_seed(int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer with 0 <= seed < 2**32, got {text!r}"
        ) from None


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
    r.add_argument(
        "--dry-run", action="store_true",
        help="print the name of the run directory it would train; create nothing",
    )  # fmt: skip
    r.add_argument(
        "--wait", action="store_true",
        help="if another process trains the run, wait for it instead of stopping",
    )  # fmt: skip
    r.add_argument(
        "--restart", action="store_true",
        help="move the existing run directory to ROOT/_restarted/ and train afresh "
        "(a corrupt checkpoint, a DONE its metrics do not back)",
    )  # fmt: skip

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
    s.add_argument(
        "--no-wait", action="store_true",
        help="submit and return, printing the job ids (local and slurm executors); the same "
        "sweep run again later waits for them",
    )  # fmt: skip

    pl = sub.add_parser(
        "plan", help="the state of every run a figure needs and the core-hours left",
        description="One line per run the figure draws: '<state> <run directory name>', "
        "state done, partial (with progress), missing, failed or recorded, noting a run "
        "made by other code (stale only if its first rows replay differently, checked when "
        "it is resumed or recorded); then the core-hours still to train, from the "
        "per-iteration times the runs in ROOT measured. --seeds, --methods and --envs "
        "keep only those runs (as vslbook train takes them).",
    )  # fmt: skip
    pl.add_argument("figure", help="a figure id (vslbook figures), e.g. fig4-3c")
    pl.add_argument("--budget", default=None)
    pl.add_argument("--root", default="runs", help="folder of run directories")
    pl.add_argument("--seeds", type=_seed, nargs="+", default=None)
    pl.add_argument("--methods", nargs="+", default=None, help="legend names, e.g. SVSL")
    pl.add_argument("--envs", nargs="+", default=None, help="environment ids")
    pl.add_argument("--until", type=int, default=None, metavar="N",
                    help="plan probes, as `vslbook train --until N` trains them: each run "
                    "counted in iterations to iteration N (at most its length)")  # fmt: skip

    tr = sub.add_parser(
        "train", help="train a figure's runs, one per process (finished ones are reused)",
        description="Train the runs FIGURE draws at BUDGET (those `vslbook plan` lists), "
        "optionally only some seeds, methods or envs, with JOBS processes of one thread "
        "each. Finished runs are reused, partial ones resume, runs another process holds "
        "are skipped.",
    )  # fmt: skip
    tr.add_argument("figure", help="a figure id (vslbook figures), e.g. fig4-3c")
    tr.add_argument("--budget", default=None)
    tr.add_argument("--root", default="runs", help="folder for run directories")
    tr.add_argument("--seeds", type=_seed, nargs="+", default=None)
    tr.add_argument("--methods", nargs="+", default=None, help="legend names, e.g. SVSL")
    tr.add_argument("--envs", nargs="+", default=None, help="environment ids")
    tr.add_argument("--jobs", type=int, default=1, help="processes (one run each)")
    tr.add_argument("--dry-run", action="store_true",
                    help="print the runs it would train, in order; train nothing")  # fmt: skip
    tr.add_argument("--until", type=int, default=None, metavar="N",
                    help="stop each run at iteration N (a probe; training again without "
                    "--until continues it)")  # fmt: skip

    rec = sub.add_parser(
        "record", help="export a figure's finished runs into data/results/FIGURE/BUDGET/",
        description="Write runs.csv, evals.csv.gz, provenance.json and registry.json for the "
        "runs of FIGURE at BUDGET that are DONE, intact and made by the current code; runs "
        "recorded earlier are kept (ROOT's copy wins). Lists the runs not recorded.",
    )  # fmt: skip
    rec.add_argument("figure", help="a figure id (vslbook figures), e.g. fig4-3c")
    rec.add_argument("--budget", default=None)
    rec.add_argument("--root", default="runs", help="folder of run directories")
    rec.add_argument("--partial", action="store_true",
                     help="also record runs still training (probes), up to their checkpoint")

    res = sub.add_parser(
        "results", help="the recorded run sets: final IQM with a 95 %% CI per method",
        description="One line per recorded (figure, method, budget): seeds, the figure's "
        "metric, the IQM of each run's final evaluation with a 95 % stratified-bootstrap CI, "
        "and whether the code the runs can reach has changed since (stale).",
    )  # fmt: skip
    res.add_argument("--json", action="store_true", help="one JSON object per line")
    res.add_argument("--verify", action="store_true",
                     help="replay the first rows of every recorded run whose code has changed "
                     "and compare them with the record: equal rows keep it current")  # fmt: skip

    f = sub.add_parser("figure", help="reproduce a registered figure")
    f.add_argument("id")
    f.add_argument("--budget", default=None)
    f.add_argument(
        "--out", default=None, help="output folder (default: $VSLBOOK_FIGURES or build/figures)"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; bad input, a locked run, a damaged run directory and file
    system errors end in one line ``vslbook: error: ...`` and exit status 2."""
    from vslbook.run_lock import RunLockedError

    args = _parser().parse_args(argv)
    try:
        return _dispatch(args)
    except (ValueError, RunLockedError) as err:
        print(f"vslbook: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except OSError as err:
        where = f" ({err.filename})" if getattr(err, "filename", None) else ""
        what = err.strerror or str(err)
        print(f"vslbook: error: {what}{where}", file=sys.stderr)
        return 2


def _one_line(err: BaseException) -> str:
    """The message of ``err``; a multi-line one (a config diff) keeps its lines joined."""
    return "; ".join(line.strip() for line in str(err).splitlines() if line.strip())


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
    if args.command == "run" and args.dry_run:
        from vslbook.training import run_name

        for seed in args.seeds if args.seeds is not None else [args.seed or 0]:
            print(run_name(args.algo, args.env, seed, args.budget,
                           overrides=_pairs(args.set, lists=False)))  # fmt: skip
        return 0
    if args.command == "run" and args.seeds is not None:
        from vslbook.training import run_seeds

        rds = run_seeds(
            args.algo, args.env, args.seeds, args.budget, root=args.root,
            overrides=_pairs(args.set, lists=False), progress=not args.no_progress,
            reuse_stale=True if args.reuse_stale else None, wait=args.wait,
            restart=args.restart,
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
            wait=args.wait,
            restart=args.restart,
        )
        print(rd.path)
        if rd.failed:
            print(f"FAILED: {rd.failure.get('message')}", file=sys.stderr)
            return 1
        if rd.done:
            print(json.dumps(json.loads((rd.path / "DONE").read_text() or "{}"), indent=1))
        return 0
    if args.command == "sweep":
        from vslbook.sweep import SweepError, sweep

        try:
            paths = sweep(
                args.algo,
                args.env,
                args.seeds,
                grid=_pairs(args.grid, lists=True),
                budget=args.budget,
                root=args.root,
                executor=args.executor,
                slurm=args.slurm,
                wait=not args.no_wait,
            )
        except SweepError as err:  # jobs ended without a result: the finished runs, then why
            for p in err.paths:
                print(p)
            for line in err.problems:
                print(f"vslbook: error: {line}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:  # the sweep said what stays queued and how to cancel it
            return 130
        for p in paths:
            print(p.job_id if args.no_wait else p)
        return 0
    if args.command == "plan":
        from vslbook.experiments.record import recorded_names
        from vslbook.experiments.run_plan import plan, plan_text
        from vslbook.experiments.train_figure import select_runs

        names = recorded_names(args.figure, args.budget)
        rows = plan(args.figure, args.budget, args.root, recorded=lambda r: r.name in names,
                    until=args.until)  # fmt: skip
        if (args.seeds, args.methods, args.envs) != (None, None, None):
            keep = {r.name for r in select_runs(args.figure, args.budget, seeds=args.seeds,
                                                methods=args.methods, envs=args.envs)}
            rows = [r for r in rows if r.run.name in keep]  # timed on all the figure's runs
        print(plan_text(rows))
        return 0
    if args.command == "train":
        from vslbook.experiments.train_figure import select_runs, train_figure

        runs = select_runs(args.figure, args.budget, seeds=args.seeds, methods=args.methods,
                           envs=args.envs)  # fmt: skip
        if args.dry_run:
            for run in runs:
                print(run.name)
            return 0
        results = train_figure(runs, args.root, args.jobs, until=args.until,
                               report=lambda line: print(line, flush=True))  # fmt: skip
        return 0 if all(r.state in ("done", "probed") for r in results) else 1
    if args.command == "record":
        from vslbook.experiments.record import record, record_text

        print(record_text(record(args.figure, args.budget, args.root, partial=args.partial)))
        return 0
    if args.command == "results":
        from vslbook.experiments.record import result_rows, results_text

        if args.verify:
            from vslbook.experiments.record_verify import verify_recorded, verify_text

            print(verify_text(verify_recorded(progress=not args.json)))
        rows = result_rows()
        if args.json:
            for row in rows:
                print(json.dumps(row))
        else:
            print(results_text(rows))
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
