"""The seed axis two ways: ``torch.func.vmap`` over stacked modules, or natively batched layers.

:class:`vslbook.srl.seed_axis.SeedStack` runs S seeds' networks with ``vmap`` over
``functional_call`` on stacked parameters. The alternative is to write every layer for a
leading seed axis: a linear layer as ``baddbmm`` on (S, in, out) weights, BatchRenorm with
(S, features) statistics. This benchmark times one forward and backward pass of the CrossQ
critic's body (Linear, BatchRenorm, ReLU twice, then the 101-atom head; the joint batch of
512 state-actions) for S seeds

    loop    S separate modules, one after the other (what S single-seed runs do)
    vmap    the stacked modules under vmap (SeedStack's path)
    bmm     the same layers written for a seed axis (baddbmm, batched statistics)

and checks first that all three compute the same outputs and gradients. It reports
milliseconds per pass and each path's time for S seeds against the loop's for one seed.

    python benchmarks/seed_axis_layers.py --seeds 3 --widths 64 256 --threads 2
"""

from __future__ import annotations

import argparse
import copy
import time

import torch
from torch import Tensor, nn
from torch.func import functional_call, stack_module_state, vmap

from vslbook.srl.batchrenorm import BatchRenorm1d

IN_DIM, ATOMS, BATCH = 88, 101, 512  # humanoid's 67 + 21 inputs; C51 atoms; joint batch


def critic_body(width: int) -> nn.Sequential:
    """The critic's layers as :func:`vslbook.srl.critic.critic_mlp` builds them."""
    return nn.Sequential(
        nn.Linear(IN_DIM, width), BatchRenorm1d(width, warmup_steps=0), nn.ReLU(),
        nn.Linear(width, width), BatchRenorm1d(width, warmup_steps=0), nn.ReLU(),
        nn.Linear(width, ATOMS),
    )  # fmt: skip


class BatchedBody(nn.Module):
    """S critic bodies as one module with a leading seed axis on every tensor."""

    def __init__(self, bodies: list[nn.Sequential]) -> None:
        super().__init__()
        linears = [[m for m in b if isinstance(m, nn.Linear)] for b in bodies]
        norms = [[m for m in b if isinstance(m, BatchRenorm1d)] for b in bodies]
        self.weights = nn.ParameterList(
            nn.Parameter(torch.stack([ls[k].weight.detach().t() for ls in linears]))
            for k in range(3)
        )  # (S, in, out)
        self.biases = nn.ParameterList(
            nn.Parameter(torch.stack([ls[k].bias.detach() for ls in linears])[:, None, :])
            for k in range(3)
        )  # (S, 1, out)
        self.gammas = nn.ParameterList(
            nn.Parameter(torch.stack([ns[k].weight.detach() for ns in norms])[:, None, :])
            for k in range(2)
        )
        self.betas = nn.ParameterList(
            nn.Parameter(torch.stack([ns[k].bias.detach() for ns in norms])[:, None, :])
            for k in range(2)
        )
        ref = norms[0][0]
        self.momentum, self.eps = ref.momentum, ref.eps
        self.r_max, self.d_max = ref.r_max, ref.d_max
        for k in range(2):
            self.register_buffer(f"mean{k}", torch.stack([ns[k].running_mean for ns in norms]))
            self.register_buffer(f"var{k}", torch.stack([ns[k].running_var for ns in norms]))

    def _renorm(self, x: Tensor, k: int) -> Tensor:
        """BatchRenorm1d's training pass (after warm-up) with per-seed statistics."""
        running_mean, running_var = getattr(self, f"mean{k}"), getattr(self, f"var{k}")
        var, mean = torch.var_mean(x, dim=1, unbiased=False)  # (S, F)
        inv_std = torch.rsqrt(var + self.eps)
        with torch.no_grad():
            inv_running = torch.rsqrt(running_var + self.eps)
            r = (inv_std.reciprocal() * inv_running).clamp(1.0 / self.r_max, self.r_max)
            d = ((mean - running_mean) * inv_running).clamp(-self.d_max, self.d_max)
            n, m = x.shape[1], self.momentum
            running_mean.mul_(m).add_(mean, alpha=1.0 - m)
            running_var.mul_(m).add_(var, alpha=(1.0 - m) * n / (n - 1))
        scale = self.gammas[k][:, 0] * r * inv_std
        shift = self.betas[k][:, 0] + self.gammas[k][:, 0] * (d - mean * r * inv_std)
        return torch.addcmul(shift[:, None, :], x, scale[:, None, :])

    def forward(self, x: Tensor) -> Tensor:  # x: (S, B, IN_DIM)
        for k in range(2):
            x = torch.baddbmm(self.biases[k], x, self.weights[k])
            x = torch.relu(self._renorm(x, k))
        return torch.baddbmm(self.biases[2], x, self.weights[2])


def _paths(width: int, seeds: int) -> dict:
    torch.manual_seed(0)
    bodies = [critic_body(width) for _ in range(seeds)]
    loop = [copy.deepcopy(b) for b in bodies]
    params, buffers = stack_module_state([copy.deepcopy(b) for b in bodies])
    template = copy.deepcopy(bodies[0]).to("meta")
    batched = BatchedBody([copy.deepcopy(b) for b in bodies])

    def run_loop(x: Tensor) -> list[Tensor]:
        outs = [body(x[s]) for s, body in enumerate(loop)]
        sum(o.square().mean() for o in outs).backward()
        return [torch.stack(o) for o in zip(*[list(b.parameters()) for b in loop], strict=True)]

    def run_vmap(x: Tensor) -> list[Tensor]:
        def one(p, b, xs):
            return functional_call(template, (p, b), (xs,))

        out = vmap(one)(params, buffers, x)
        out.square().mean(dim=(1, 2)).sum().backward()
        return list(params.values())

    def run_bmm(x: Tensor) -> list[Tensor]:
        batched(x).square().mean(dim=(1, 2)).sum().backward()
        return list(batched.parameters())

    return {"loop": run_loop, "vmap": run_vmap, "bmm": run_bmm, "_bodies": loop,
            "_params": params, "_batched": batched}  # fmt: skip


def check_same(width: int, seeds: int) -> float:
    """Largest difference of the linear weights' gradients between loop and vmap, loop and bmm."""
    paths = _paths(width, seeds)
    x = torch.randn(seeds, BATCH, IN_DIM)
    for name in ("loop", "vmap", "bmm"):
        paths[name](x)
    stacked = [n for n, p in paths["_params"].items() if n.endswith("weight") and p.dim() == 3]
    worst = 0.0
    for s, body in enumerate(paths["_bodies"]):
        linears = [m for m in body if isinstance(m, nn.Linear)]
        for k, (lin, name) in enumerate(zip(linears, stacked, strict=True)):
            g = lin.weight.grad
            worst = max(worst, float((g - paths["_params"][name].grad[s]).abs().max()))
            worst = max(worst, float((g - paths["_batched"].weights[k].grad[s].t()).abs().max()))
    return worst


def time_path(fn, x: Tensor, seconds: float) -> float:
    for _ in range(3):
        fn(x)
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        fn(x)
        n += 1
    return 1e3 * (time.perf_counter() - start) / n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--widths", type=int, nargs="+", default=[64, 256])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=5.0, help="timing per row")
    args = parser.parse_args()
    if args.seeds < 1 or args.threads < 1 or args.seconds <= 0:
        parser.error(f"need --seeds, --threads >= 1 and --seconds > 0, got {vars(args)}")
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, batch {BATCH}, "
          f"critic body {IN_DIM} -> W -> W -> {ATOMS}, forward + backward")  # fmt: skip
    head = f"{'width':>5s} {'path':5s} {'seeds':>5s} {'ms/pass':>8s} {'x loop, 1 seed':>15s}"
    print(head)
    print("-" * len(head))
    for width in args.widths:
        diff = check_same(width, args.seeds)
        if diff > 1e-5:
            raise SystemExit(f"width {width}: the paths disagree (gradient difference {diff:.2e})")
        one = None
        for path in ("loop", "vmap", "bmm"):
            for s in sorted({1, args.seeds}):
                fn = _paths(width, s)[path]
                ms = time_path(fn, torch.randn(s, BATCH, IN_DIM), args.seconds)
                one = one or ms
                print(f"{width:5d} {path:5s} {s:5d} {ms:8.2f} {ms / one:15.2f}", flush=True)
        print(f"{'':5s} (gradients of the three paths agree to {diff:.1e})")


if __name__ == "__main__":
    main()
