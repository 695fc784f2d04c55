"""Our Glow flow against zuko's RealNVP on 2D toy densities: held-out negative log-likelihood.

Both models are affine-coupling flows with K couplings whose conditioners are 2-hidden-layer ReLU
MLPs. Ours adds Glow's ActNorm and LU-decomposed invertible linear layer in each step; zuko's
RealNVP alternates which coordinate is transformed. Ours runs twice: with the linear layers
starting as random rotations (Glow's choice, the library default) and as the reversing
permutation (``linear_init="reverse"``, which starts as RealNVP's alternation). zuko's hidden width
is the smallest that gives it at least as many parameters as ours, so it never has the smaller
budget.

Both see the same training set, the same mini-batches in the same order, the same optimiser
(Adam, its learning rate annealed from ``--lr`` to zero along a cosine over the run) and the same
number of steps; the negative log-likelihood is measured on a held-out set drawn with another seed
at several points of training, to show both how fast and how far each model learns. The annealing
is there for a fair final figure: at a constant rate the held-out NLL of either model still jumps
by a few hundredths of a nat from one step to the next, more than the gaps being measured. Where
the density is known in closed form the script also prints its entropy, the best NLL any model can
reach.

Usage:
    .venv/bin/python benchmarks/flows_vs_reference.py   # every density and model: 1.5-2 h, one core
    .venv/bin/python benchmarks/flows_vs_reference.py --densities two_moons --threads 1 &  # one
    # density per process uses more cores
    .venv/bin/python benchmarks/flows_vs_reference.py --densities two_moons --first-seed 4 &  # seeds
    # 4..7 in another process; each model's final NLL is also printed per seed, to pool the runs
    # (the README's table pools 16 seeds: 4 seeds can miss a model's bad seeds, see its text)
    .venv/bin/python benchmarks/flows_vs_reference.py --grad-clip 5  # clip every model's gradient
    .venv/bin/python benchmarks/flows_vs_reference.py --checkpoints 100 300 --seeds 1  # smoke run
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
#: The models compared, by name: None for zuko, else our linear layers' initial matrix.
MODELS = {
    "zuko RealNVP": None,
    "gesturelib Glow rotation": "rotation",
    "gesturelib Glow reverse": "reverse",
}
TRUE_LOG_PROB = {
    "eight_gaussians": toy_densities.eight_gaussians_log_prob,
    "checkerboard": toy_densities.checkerboard_log_prob,
}


def count_parameters(model: torch.nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def build_ours(steps: int, hidden: int, seed: int, linear_init: str):
    flow = glow(2, steps, hidden, seed=seed, linear_init=linear_init)
    return flow, flow.log_prob


def build_zuko(steps: int, budget: int, seed: int):
    """RealNVP with the smallest hidden width whose parameter count is >= ``budget``."""
    hidden = 1
    while True:
        torch.manual_seed(seed)
        flow = zuko.flows.RealNVP(2, transforms=steps, hidden_features=(hidden, hidden))
        if count_parameters(flow) >= budget:
            return flow, lambda x, flow=flow: flow().log_prob(x)
        hidden += 1


@torch.no_grad()
def held_out_nll(log_prob, test_x) -> float:
    return -torch.cat([log_prob(chunk) for chunk in test_x.split(5000)]).mean().item()


def train(model, log_prob, train_x, test_x, batch, checkpoints, lr, seed, grad_clip=None):
    """Adam on the mean NLL of mini-batches drawn (seeded) from ``train_x``, the learning rate
    annealed from ``lr`` to zero along a cosine over ``max(checkpoints)`` steps, the gradient's
    total norm clipped to ``grad_clip`` if given.

    Returns the held-out NLL at each checkpoint (a number of steps) and the training seconds.
    """
    steps = max(checkpoints)
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=steps)
    order = torch.Generator().manual_seed(seed)
    nlls, seconds = [], 0.0
    for step in range(1, steps + 1):
        start = time.perf_counter()
        index = torch.randint(0, train_x.shape[0], (batch,), generator=order)
        loss = -log_prob(train_x[index]).mean()
        optimiser.zero_grad()
        loss.backward()
        if grad_clip is not None:
            torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
        optimiser.step()
        schedule.step()
        seconds += time.perf_counter() - start
        if step in checkpoints:
            nlls.append(held_out_nll(log_prob, test_x))
    return nlls, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--densities", nargs="+", default=list(toy_densities.TOY_DENSITIES))
    parser.add_argument(
        "--checkpoints",
        nargs="+",
        type=int,
        default=[2500, 5000, 10000],
        help="training steps after which the held-out NLL is measured (the last ends training)",
    )
    parser.add_argument("--flow-steps", type=int, default=8, help="couplings K")
    parser.add_argument("--hidden", type=int, default=64, help="our conditioner width")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3, help="initial learning rate")
    parser.add_argument(
        "--grad-clip",
        type=float,
        default=None,
        help="clip every model's total gradient norm to this (default: no clipping)",
    )
    parser.add_argument("--seeds", type=int, default=4, help="how many seeds")
    parser.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="seeds run from this one (to split seeds across processes)",
    )
    parser.add_argument(
        "--models",
        nargs="+",
        choices=["RealNVP", "rotation", "reverse"],
        default=["RealNVP", "rotation", "reverse"],
        help="zuko's RealNVP, and ours with each initial linear layer",
    )
    parser.add_argument(
        "--threads", type=int, default=None, help="torch threads (default: torch's)"
    )
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    if args.grad_clip is not None and not args.grad_clip > 0:
        parser.error(f"--grad-clip must be positive, got {args.grad_clip}")
    if args.first_seed < 0:
        parser.error(f"--first-seed must be non-negative, got {args.first_seed}")
    checkpoints = sorted(set(args.checkpoints))
    seeds = range(args.first_seed, args.first_seed + args.seeds)

    clipping = (
        "no gradient clipping"
        if args.grad_clip is None
        else f"gradient norm clipped to {args.grad_clip}"
    )
    print(
        f"K={args.flow_steps} couplings, Adam (lr {args.lr} cosine-annealed to 0), {clipping}, "
        f"batch {args.batch}, {TRAIN_SIZE} training / {TEST_SIZE} held-out points, seeds {seeds[0]}..{seeds[-1]}, "
        f"torch threads {torch.get_num_threads()}; held-out NLL in nats, mean ± sd over seeds\n"
    )
    columns = "".join(f"{f'after {c} steps':>18}" for c in checkpoints)
    header = f"{'density':16} {'model':24} {'params':>7}{columns} {'train s':>8}"
    print(header)
    print("-" * len(header))
    models = {key: value for key, value in MODELS.items() if key.split()[-1] in args.models}
    for name in args.densities:
        sampler = toy_densities.TOY_DENSITIES[name]
        train_x = sampler(TRAIN_SIZE, generator=1000)
        test_x = sampler(TEST_SIZE, generator=2000)
        results = {key: [] for key in models}
        seconds = dict.fromkeys(models, 0.0)
        params = {}
        for seed in seeds:
            for key, linear_init in models.items():
                ours = build_ours(args.flow_steps, args.hidden, seed, linear_init or "rotation")
                model, log_prob = (
                    build_zuko(args.flow_steps, count_parameters(ours[0]), seed)
                    if linear_init is None
                    else ours
                )
                params[key] = count_parameters(model)
                nlls, spent = train(
                    model,
                    log_prob,
                    train_x,
                    test_x,
                    args.batch,
                    checkpoints,
                    args.lr,
                    seed,
                    args.grad_clip,
                )
                results[key].append(nlls)
                seconds[key] += spent
        for key, runs in results.items():
            figures = ""
            for column in zip(*runs, strict=True):
                spread = statistics.stdev(column) if len(column) > 1 else 0.0
                figures += f"{f'{statistics.mean(column):.3f} ± {spread:.3f}':>18}"
            print(f"{name:16} {key:24} {params[key]:7d}{figures} {seconds[key] / args.seeds:8.1f}")
            finals = ", ".join(
                f"{seed}: {run[-1]:.4f}" for seed, run in zip(seeds, runs, strict=True)
            )
            print(f"{'':16} {'  final NLL per seed':24} {finals}")
        if name in TRUE_LOG_PROB:
            entropy = -TRUE_LOG_PROB[name](test_x.double()).mean().item()
            print(f"{name:16} {'true density (entropy)':24} {'':7}{f'{entropy:.3f}':>18}")
        print(flush=True)


if __name__ == "__main__":
    main()
