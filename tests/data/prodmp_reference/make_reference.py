"""Make the ProDMP reference trajectories that tests/test_prodmp_reference.py compares against.

Run OUTSIDE the project, in a throw-away environment that has MP_PyTorch; neither the package
nor the tests import this file. Two flavours:

* ``di-skill``: the MP_PyTorch copy vendored in the authors' Di-SkilL code (github
  ALRhub/di-skill, folder MP_PyTorch/), put first on PYTHONPATH; it is the one whose
  ``relative_goal`` the Di-SkilL task registrations rely on.
* ``0.1.3``: the PyPI release mp_pytorch 0.1.3 (the version fancy-gym 0.3.0 pins). It has no
  ``relative_goal`` (the keyword is ignored), so only the tasks with an absolute goal are made.

    python3.11 -m venv venv && venv/bin/pip install mp_pytorch==0.1.3 'numpy<2' torch==2.13.0
    PYTHONPATH=/path/to/di-skill/MP_PyTorch venv/bin/python make_reference.py di-skill OUTDIR
    venv/bin/python make_reference.py 0.1.3 OUTDIR

The ProDMP of every task is built the way the fancy-gym black-box wrapper builds it (task
settings from the Di-SkilL registrations), in float64: the parameters are clipped to the
phase generator's bounds, the initial condition is set at time 0, and the trajectory is read at
the control times ``dt, 2 dt, ..., T dt`` (``set_duration`` drops t = 0), so row k is what
control step k tracks.
"""

from __future__ import annotations

import datetime
import json
import platform
import sys
from pathlib import Path

import numpy as np
import torch

N_THETA = 20
SEED = 20261126

# Per task: ProDMP settings of the Di-SkilL registration (fancy-gym black-box wrapper).
TASKS = {
    "reacher5": dict(
        n_dof=5, n_basis=5, alpha=10.0, alpha_phase=3.0, tau=1.5, dt=0.02, steps=200,
        weights_scale=0.3, goal_scale=0.3, relative_goal=True, disable_goal=False,
        q0=[0.0] * 5,
    ),
    "hopper_jump": dict(
        n_dof=3, n_basis=3, alpha=10.0, alpha_phase=3.0, tau=0.8, dt=0.008, steps=250,
        weights_scale=1.0, goal_scale=1.0, relative_goal=False, disable_goal=False,
        q0=[-0.25, -0.1, 0.4],
    ),
    "table_tennis_4d": dict(
        n_dof=7, n_basis=3, alpha=25.0, alpha_phase=3.0, tau=1.5, dt=0.008, steps=350,
        weights_scale=0.7, goal_scale=1.0, relative_goal=True, disable_goal=True,
        tau_bound=[0.56, 1.5], delay_bound=[0.05, 0.6], q0=[0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 1.5],
    ),
    "table_tennis_hard": dict(
        n_dof=7, n_basis=3, alpha=25.0, alpha_phase=3.0, tau=1.5, dt=0.008, steps=350,
        weights_scale=0.7, goal_scale=1.0, relative_goal=True, disable_goal=True,
        tau_bound=[0.56, 1.5], delay_bound=[0.05, 0.6], q0=[0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 1.5],
    ),
    "box_pushing": dict(
        n_dof=7, n_basis=4, alpha=10.0, alpha_phase=3.0, tau=1.5, dt=0.02, steps=100,
        weights_scale=0.3, goal_scale=0.3, relative_goal=False, disable_goal=False,
        q0=[0.387, 0.176, 0.250, -2.399, -0.080, 2.569, 1.480],
    ),
    "mini_golf": dict(
        n_dof=7, n_basis=4, alpha=25.0, alpha_phase=3.0, tau=1.5, dt=0.02, steps=100,
        weights_scale=0.3, goal_scale=1.0, relative_goal=True, disable_goal=True,
        tau_bound=[0.45, 1.7], q0=[0.9014, 0.9491, 0.1518, -1.0553, -0.1357, 1.9953, 1.8262],
    ),
}


def build(cfg: dict):
    """The trajectory generator as fancy-gym's ``make_bb`` builds it (float64)."""
    from mp_pytorch.basis_gn import ProDMPBasisGenerator
    from mp_pytorch.mp import ProDMP
    from mp_pytorch.phase_gn import ExpDecayPhaseGenerator

    phase_kw = dict(tau=cfg["tau"], alpha_phase=cfg["alpha_phase"], dtype=torch.float64)
    if "tau_bound" in cfg:
        phase_kw.update(learn_tau=True, tau_bound=cfg["tau_bound"])
    if "delay_bound" in cfg:
        phase_kw.update(learn_delay=True, delay_bound=cfg["delay_bound"])
    phase = ExpDecayPhaseGenerator(**phase_kw)
    basis = ProDMPBasisGenerator(
        phase, num_basis=cfg["n_basis"], basis_bandwidth_factor=3, alpha=cfg["alpha"],
        dtype=torch.float64,
    )
    return ProDMP(
        basis, cfg["n_dof"], weights_scale=cfg["weights_scale"], goal_scale=cfg["goal_scale"],
        auto_scale_basis=True, relative_goal=cfg["relative_goal"],
        disable_goal=cfg["disable_goal"], dtype=torch.float64,
    )


def sample_thetas(cfg: dict, rng: np.random.Generator, n_params: int) -> np.ndarray:
    """Random θ in mp_pytorch's layout; τ and the delay drawn a little beyond their bounds so
    that the clipping is exercised too."""
    theta = rng.normal(size=(N_THETA, n_params))
    i = 0
    for key in ("tau_bound", "delay_bound"):
        if key in cfg:
            lo, hi = cfg[key]
            theta[:, i] = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), N_THETA)
            i += 1
    return theta


def main(flavour: str, out: Path) -> None:
    import mp_pytorch

    out.mkdir(parents=True, exist_ok=True)
    names = [k for k, c in TASKS.items() if flavour == "di-skill" or not c["relative_goal"]]
    for k, name in enumerate(names):
        cfg = TASKS[name]
        mp = build(cfg)
        rng = np.random.default_rng(SEED + k)
        lo, hi = (b.numpy() for b in mp.get_params_bounds())
        thetas = sample_thetas(cfg, rng, len(lo))
        q0 = np.asarray(cfg["q0"]) + 0.1 * rng.normal(size=(N_THETA, cfg["n_dof"]))
        dq0 = np.zeros((N_THETA, cfg["n_dof"]))
        if "delay_bound" not in cfg:  # mp_pytorch refuses a start velocity with a delay
            dq0[N_THETA // 2 :] = 0.5 * rng.normal(size=(N_THETA - N_THETA // 2, cfg["n_dof"]))
        pos, vel = [], []
        for theta, p0, v0 in zip(thetas, q0, dq0, strict=True):
            mp.reset()
            mp.set_params(torch.as_tensor(np.clip(theta, lo, hi)))
            mp.set_initial_conditions(torch.tensor(0.0, dtype=torch.float64),
                                      torch.as_tensor(p0), torch.as_tensor(v0))
            mp.set_duration(cfg["steps"] * cfg["dt"], cfg["dt"])
            pos.append(mp.get_traj_pos().numpy())
            vel.append(mp.get_traj_vel().numpy())
        tag = "" if flavour == "di-skill" else "_mp_pytorch_0_1_3"
        np.savez_compressed(
            out / f"{name}{tag}.npz", theta=thetas, q0=q0, dq0=dq0, pos=np.stack(pos),
            vel=np.stack(vel),
        )
    prov_path = out / "provenance.json"
    prov = json.loads(prov_path.read_text()) if prov_path.exists() else {}
    prov[flavour] = dict(
        mp_pytorch=getattr(mp_pytorch, "__version__", None) or _dist_version(flavour),
        mp_pytorch_path=str(Path(mp_pytorch.__file__).parent),
        torch=torch.__version__, numpy=np.__version__, python=platform.python_version(),
        date=datetime.date.today().isoformat(), n_theta=N_THETA, seed=SEED, dtype="float64",
        tasks={n: TASKS[n] for n in names},
        times="control times dt, 2 dt, ..., steps * dt (row k = control step k)",
        theta_layout="[tau if learned, delay if learned, per dof [w_1..w_B, g if not disabled]]",
        clipping="theta clipped to the phase generator's bounds before set_params",
    )
    prov_path.write_text(json.dumps(prov, indent=1) + "\n")


def _dist_version(flavour: str) -> str:
    if flavour == "di-skill":
        return "MP_PyTorch vendored in ALRhub/di-skill (HEAD 3e5a9e2), after mp_pytorch 0.1.4"
    from importlib.metadata import version

    return version("mp_pytorch")


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]))
