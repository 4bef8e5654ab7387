"""`record_checkpoints`: a recorded set keeps the final checkpoint of each method's first
seed only, whichever order its seeds were recorded in."""

from __future__ import annotations

import gzip
import json
from types import SimpleNamespace

import pandas as pd

from vslbook.data import register_file, verify_file
from vslbook.experiments.recorded_runs import CHECKPOINTS, record_checkpoints
from vslbook.results import RunDir


def _run(root, method, seed):
    """A run directory with a checkpoint whose bytes name it, and its plan entry."""
    name = f"{method}-vslbook_Task-v0-s{seed}-0000000{seed}"
    rd = RunDir(root / name)
    rd.checkpoint_path.parent.mkdir(parents=True)
    rd.checkpoint_path.write_bytes(name.encode())
    return name, (rd, SimpleNamespace(method=method, env="vslbook/Task-v0", seed=seed))


def _frame(fresh):
    return pd.DataFrame([{"run": n, "method": r.method, "env": r.env, "seed": r.seed}
                         for n, (_, r) in fresh.items()])  # fmt: skip


def _kept(out):
    folder = out / CHECKPOINTS
    names = sorted(p.name for p in folder.glob("*.pt.gz"))
    registry = json.loads((folder / "registry.json").read_text()) if names else {}
    assert sorted(registry) == names  # every file registered, no entry without a file
    for name in names:
        verify_file(folder / name)
    return names


def test_the_first_seed_of_each_method_is_kept(tmp_path):
    fresh = dict(_run(tmp_path / "runs", m, s) for m in ("a", "b") for s in (1, 0, 2))
    written = record_checkpoints(tmp_path / "set", fresh, _frame(fresh))
    assert written == ["a-vslbook_Task-v0-s0-00000000", "b-vslbook_Task-v0-s0-00000000"]
    assert _kept(tmp_path / "set") == [f"{n}.pt.gz" for n in written]
    saved = gzip.decompress((tmp_path / "set" / CHECKPOINTS / f"{written[0]}.pt.gz").read_bytes())
    assert saved == written[0].encode()


def test_a_later_seed_adds_no_checkpoint_and_a_stale_one_goes(tmp_path):
    out = tmp_path / "set"
    early = dict(_run(tmp_path / "early", "a", s) for s in (0, 1))
    # a set recorded before the rule: seed 1's checkpoint too
    folder = out / CHECKPOINTS
    folder.mkdir(parents=True)
    for name in early:
        (folder / f"{name}.pt.gz").write_bytes(gzip.compress(name.encode()))
        register_file(folder / f"{name}.pt.gz", "a checkpoint")
    # seed 2 recorded from a folder without seeds 0 and 1
    late = dict([_run(tmp_path / "late", "a", 2)])
    written = record_checkpoints(out, late, _frame(early | late))
    assert written == []
    assert _kept(out) == ["a-vslbook_Task-v0-s0-00000000.pt.gz"]
    # without the set's table, the fresh runs alone decide (the old behaviour)
    assert record_checkpoints(tmp_path / "alone", late) == ["a-vslbook_Task-v0-s2-00000002"]
