"""Speed of pose-sized flows: training throughput and sampling speed on this machine.

Two flows over poses of 54 numbers (9 limbs x 6D rotation), K = 8 Glow steps:

* MLP conditioner, unconditional, over single poses ``(B, 54)`` (as in notebook 04);
* LSTM conditioner (MoGlow), over sequences ``(B, T, 54)`` with a ``(B, T, C)`` condition that
  stands in for the control signal (past poses, speech, activity).

Training throughput counts samples (poses, i.e. frames) per second through one full step:
forward, backward and an Adam update. Sampling speed counts poses per second drawn without
gradients: for the MLP flow in one batch; for the LSTM flow both over whole sequences at once
(possible when the condition is known in advance) and frame by frame with the recurrent state
passed along (what autoregressive generation has to do).

Usage:
    .venv/bin/python benchmarks/bench_flows.py [--repeats 20] [--threads N]
"""

from __future__ import annotations

import argparse
import time

import torch

from gesturelib.flows import RecurrentFlow, glow, recurrent_glow

POSE_DIM, STEPS = 54, 8


def seconds_per_call(fn, repeats: int, warmup: int = 3) -> float:
    """Median wall time of ``fn()`` over ``repeats`` calls, after ``warmup`` calls."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2]


def training_step(flow, x, cond, optimiser):
    def step():
        log_prob = flow.log_prob(x, cond)
        loss = -(log_prob[0] if isinstance(flow, RecurrentFlow) else log_prob).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()

    return step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument(
        "--threads", type=int, default=None, help="torch threads (default: torch's)"
    )
    parser.add_argument("--hidden", type=int, default=256)
    parser.add_argument("--batch", type=int, default=256, help="poses per MLP training batch")
    parser.add_argument("--sequences", type=int, default=16, help="sequences per LSTM batch")
    parser.add_argument("--frames", type=int, default=40, help="frames per LSTM sequence")
    parser.add_argument("--cond-dim", type=int, default=64, help="LSTM flow condition size")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    generator = torch.Generator().manual_seed(0)

    rows = []
    mlp = glow(POSE_DIM, STEPS, args.hidden)
    x = torch.randn(args.batch, POSE_DIM, generator=generator)
    train = training_step(mlp, x, None, torch.optim.Adam(mlp.parameters(), lr=1e-4))
    mlp.log_prob(x)  # initialises ActNorm, as training would
    train_rate = args.batch / seconds_per_call(train, args.repeats)
    n_samples = 4096
    with torch.no_grad():
        sample_rate = n_samples / seconds_per_call(
            lambda: mlp.sample(n_samples, generator=generator), args.repeats
        )
    rows.append(
        ("MLP", f"(B={args.batch}, 54)", mlp, train_rate, f"{sample_rate:,.0f} (batch {n_samples})")
    )

    lstm = recurrent_glow(POSE_DIM, STEPS, args.hidden, cond_dim=args.cond_dim)
    shape = (args.sequences, args.frames)
    x = torch.randn(*shape, POSE_DIM, generator=generator)
    cond = torch.randn(*shape, args.cond_dim, generator=generator)
    train = training_step(lstm, x, cond, torch.optim.Adam(lstm.parameters(), lr=1e-4))
    frames = args.sequences * args.frames
    train_rate = frames / seconds_per_call(train, args.repeats)

    def frame_by_frame():
        state = None
        with lstm.fixed_weights():  # each linear layer's inverse computed once
            for t in range(args.frames):
                _, state = lstm.sample(cond[:, t : t + 1], generator=generator, state=state)

    lstm.log_prob(x, cond)  # initialises ActNorm, as training would
    with torch.no_grad():
        parallel = frames / seconds_per_call(
            lambda: lstm.sample(cond, generator=generator), args.repeats
        )
        stepwise = frames / seconds_per_call(frame_by_frame, max(3, args.repeats // 4))
    rows.append(
        (
            "LSTM",
            f"(B={args.sequences}, T={args.frames}, 54)",
            lstm,
            train_rate,
            f"{parallel:,.0f} whole sequences / {stepwise:,.0f} frame by frame",
        )
    )

    print(
        f"54-dim pose flows, K={STEPS} steps, hidden {args.hidden} (2 MLP layers, 1 LSTM layer), "
        f"float32, CPU, {torch.get_num_threads()} torch threads; LSTM condition C={args.cond_dim}"
    )
    header = (
        f"{'conditioner':11} {'batch':22} {'params':>10} {'train poses/s':>14}  sampling poses/s"
    )
    print(header)
    print("-" * (len(header) + 30))
    for name, batch, flow, train_rate, sampling in rows:
        params = sum(p.numel() for p in flow.parameters())
        print(f"{name:11} {batch:22} {params:10,d} {train_rate:14,.0f}  {sampling}")


if __name__ == "__main__":
    main()
