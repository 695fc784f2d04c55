"""Our Glow flow against zuko's RealNVP on 2D toy densities: held-out NLL and time per step.

Both models are affine-coupling flows with K couplings whose conditioners are 2-hidden-layer ReLU
MLPs. Ours is the library's default, ``glow(2, K, hidden)``: Glow's ActNorm and LU-decomposed
invertible linear layer in each step, the linear layers starting as swaps of the two coordinates.
zuko's RealNVP alternates which coordinate is transformed; its hidden width is the smallest that
gives it at least as many parameters as ours, so it never has the smaller budget.

Both see the same training set, the same mini-batches in the same order, the same optimiser (Adam
at a constant learning rate by default, the short budget that notebooks and quick experiments
use; ``--anneal`` anneals it to zero along a cosine, for a fair final figure of a long run) and the
same number of steps. The held-out NLL is measured once at the end on points drawn with another
seed. Seeds are paired (both models see seed s's batches), so the script reports the mean
difference ours - zuko with its standard error over seeds, which is what tells a real gap from
noise. Time per step is the process's CPU time (one torch thread), which other programs running on
the machine disturb far less than wall time. Where the density is known in closed form the script
prints its entropy, the best NLL any model can reach. ``docs/benchmarks.md`` has the results.

Usage:
    .venv/bin/python benchmarks/flows_vs_reference.py      # 1.5k steps, 8 seeds: ~15 min, 1 core
    .venv/bin/python benchmarks/flows_vs_reference.py --densities two_moons --seeds 4 \\
        --first-seed 4      # seeds 4..7 in another process; each seed's NLLs are printed to pool
    .venv/bin/python benchmarks/flows_vs_reference.py --steps 10000 --anneal   # the long run
"""

from __future__ import annotations

import argparse
import math
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


def build_ours(steps: int, hidden: int, seed: int):
    flow = glow(2, steps, hidden, seed=seed)
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


def train(model, log_prob, train_x, batch: int, steps: int, lr: float, anneal: bool, seed: int):
    """Adam on the mean NLL of mini-batches drawn (seeded) from ``train_x``; returns the CPU
    seconds per step."""
    optimiser = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = (
        torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=steps) if anneal else None
    )
    order = torch.Generator().manual_seed(seed)
    started = time.process_time()
    for _ in range(steps):
        index = torch.randint(0, train_x.shape[0], (batch,), generator=order)
        loss = -log_prob(train_x[index]).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        if schedule is not None:
            schedule.step()
    return (time.process_time() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--densities", nargs="+", default=list(toy_densities.TOY_DENSITIES))
    parser.add_argument("--steps", type=int, default=1500, help="training steps")
    parser.add_argument("--flow-steps", type=int, default=8, help="couplings K")
    parser.add_argument("--hidden", type=int, default=64, help="our conditioner width")
    parser.add_argument("--batch", type=int, default=256)
    parser.add_argument("--lr", type=float, default=1e-3, help="(initial) learning rate")
    parser.add_argument("--anneal", action="store_true", help="anneal the rate along a cosine")
    parser.add_argument("--seeds", type=int, default=8, help="how many seeds")
    parser.add_argument("--first-seed", type=int, default=0, help="seeds run from this one")
    args = parser.parse_args()
    for name in ("steps", "seeds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    if args.first_seed < 0:
        parser.error(f"--first-seed must be non-negative, got {args.first_seed}")
    torch.set_num_threads(1)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    schedule = "cosine-annealed to 0" if args.anneal else "constant"
    print(
        f"K={args.flow_steps} couplings, {args.steps} steps of Adam (lr {args.lr}, {schedule}), "
        f"batch {args.batch}, seeds {seeds[0]}..{seeds[-1]}, one torch thread; held-out NLL "
        "in nats, mean ± sd over seeds\n"
    )
    for name in args.densities:
        sampler = toy_densities.TOY_DENSITIES[name]
        train_x, test_x = sampler(TRAIN_SIZE, generator=1000), sampler(TEST_SIZE, generator=2000)
        nll = {"zuko RealNVP": [], "gesturelib Glow": []}
        seconds = {key: [] for key in nll}
        params = {}
        for seed in seeds:
            ours = build_ours(args.flow_steps, args.hidden, seed)
            models = {
                "zuko RealNVP": build_zuko(args.flow_steps, count_parameters(ours[0]), seed),
                "gesturelib Glow": ours,
            }
            for key, (model, log_prob) in models.items():
                params[key] = count_parameters(model)
                options = (args.batch, args.steps, args.lr, args.anneal, seed)
                seconds[key].append(train(model, log_prob, train_x, *options))
                nll[key].append(held_out_nll(log_prob, test_x))
        for key, values in nll.items():
            spread = statistics.stdev(values) if len(values) > 1 else 0.0
            milliseconds = 1000 * statistics.mean(seconds[key])
            print(
                f"{name:16} {key:16} {params[key]:7d} parameters  NLL "
                f"{statistics.mean(values):.3f} ± {spread:.3f}  {milliseconds:6.2f} ms/step"
            )
            print(
                f"{'':16}   per seed: "
                + ", ".join(f"{s}: {v:.4f}" for s, v in zip(seeds, values, strict=True))
            )
        gaps = [o - z for o, z in zip(nll["gesturelib Glow"], nll["zuko RealNVP"], strict=True)]
        error = statistics.stdev(gaps) / math.sqrt(len(gaps)) if len(gaps) > 1 else math.nan
        ratio = statistics.mean(seconds["gesturelib Glow"]) / statistics.mean(
            seconds["zuko RealNVP"]
        )
        print(
            f"{name:16} ours - zuko: {statistics.mean(gaps):+.3f} nats (standard error "
            f"{error:.3f}); time per step {ratio:.2f} x zuko's"
        )
        if name in TRUE_LOG_PROB:
            entropy = -TRUE_LOG_PROB[name](test_x.double()).mean().item()
            print(f"{name:16} true density (entropy): {entropy:.3f}")
        print(flush=True)


if __name__ == "__main__":
    main()
