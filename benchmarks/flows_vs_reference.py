"""Our Glow flow against zuko's RealNVP on 2D toy densities: held-out negative log-likelihood.

Both models are affine-coupling flows with K couplings whose conditioners are 2-hidden-layer ReLU
MLPs. Ours adds Glow's ActNorm and LU-decomposed invertible linear layer in each step; zuko's
RealNVP alternates which coordinate is transformed. zuko's hidden width is the smallest that gives
it at least as many parameters as ours, so it never has the smaller budget.

Both see the same training set, the same mini-batches in the same order, the same optimiser
(Adam, constant learning rate) and the same number of steps; the negative log-likelihood is
measured on a held-out set drawn with another seed. Where the density is known in closed form
the script also prints its entropy, the best NLL any model can reach.

Usage:
    .venv/bin/python benchmarks/flows_vs_reference.py                 # about 10 minutes on 2 cores
    .venv/bin/python benchmarks/flows_vs_reference.py --steps 300 --seeds 1   # smoke run
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
import zuko

from gesturelib import toy_densities
from gesturelib.flows import glow

TRAIN_SIZE, TEST_SIZE = 20_000, 20_000
TRUE_LOG_PROB = {
    "eight_gaussians": toy_densities.eight_gaussians_log_prob,
    "checkerboard": toy_densities.checkerboard_log_prob,
}


def count_parameters(model: torch.nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def build_ours(steps: int, hidden: int, seed: int) -> tuple[torch.nn.Module, callable]:
    flow = glow(2, steps, hidden, seed=seed)
    return flow, flow.log_prob


def build_zuko(steps: int, budget: int, seed: int) -> tuple[torch.nn.Module, callable]:
    """RealNVP with the smallest hidden width whose parameter count is >= ``budget``."""
    hidden = 1
    while True:
        torch.manual_seed(seed)
        flow = zuko.flows.RealNVP(2, transforms=steps, hidden_features=(hidden, hidden))
        if count_parameters(flow) >= budget:
            return flow, lambda x, flow=flow: flow().log_prob(x)
        hidden += 1


def train(model, log_prob, train_x, batch, steps, lr, seed) -> float:
    """Adam on the mean NLL of mini-batches drawn (seeded) from ``train_x``; returns seconds."""
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    order = torch.Generator().manual_seed(seed)
    start = time.perf_counter()
    for _ in range(steps):
        index = torch.randint(0, train_x.shape[0], (batch,), generator=order)
        loss = -log_prob(train_x[index]).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return time.perf_counter() - start


@torch.no_grad()
def held_out_nll(log_prob, test_x) -> float:
    return -torch.cat([log_prob(chunk) for chunk in test_x.split(5000)]).mean().item()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--densities", nargs="+", default=list(toy_densities.TOY_DENSITIES))
    parser.add_argument("--steps", type=int, default=3000, help="training steps")
    parser.add_argument("--flow-steps", type=int, default=8, help="couplings K")
    parser.add_argument("--hidden", type=int, default=64, help="our conditioner width")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()

    print(
        f"K={args.flow_steps} couplings, {args.steps} Adam steps (lr {args.lr}), batch "
        f"{args.batch}, {TRAIN_SIZE} training / {TEST_SIZE} held-out points, "
        f"{args.seeds} seeds, torch threads {torch.get_num_threads()}\n"
    )
    header = (
        f"{'density':16} {'model':14} {'params':>7} {'held-out NLL (mean ± sd)':>26} {'train s':>8}"
    )
    print(header)
    print("-" * len(header))
    for name in args.densities:
        sampler = toy_densities.TOY_DENSITIES[name]
        train_x = sampler(TRAIN_SIZE, generator=1000)
        test_x = sampler(TEST_SIZE, generator=2000)
        results = {"gesturelib Glow": [], "zuko RealNVP": []}
        seconds = {key: 0.0 for key in results}
        params = {}
        for seed in range(args.seeds):
            ours, ours_log_prob = build_ours(args.flow_steps, args.hidden, seed)
            theirs, theirs_log_prob = build_zuko(args.flow_steps, count_parameters(ours), seed)
            for key, model, log_prob in [
                ("gesturelib Glow", ours, ours_log_prob),
                ("zuko RealNVP", theirs, theirs_log_prob),
            ]:
                params[key] = count_parameters(model)
                seconds[key] += train(
                    model, log_prob, train_x, args.batch, args.steps, args.lr, seed
                )
                results[key].append(held_out_nll(log_prob, test_x))
        for key, nlls in results.items():
            spread = statistics.stdev(nlls) if len(nlls) > 1 else 0.0
            figure = f"{statistics.mean(nlls):.3f} ± {spread:.3f}"
            print(
                f"{name:16} {key:14} {params[key]:7d} {figure:>26} {seconds[key] / args.seeds:8.1f}"
            )
        if name in TRUE_LOG_PROB:
            entropy = -TRUE_LOG_PROB[name](test_x.double()).mean().item()
            print(f"{name:16} {'true density':14} {'':7} {entropy:26.3f}")
        print()


if __name__ == "__main__":
    main()
