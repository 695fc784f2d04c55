"""Training in several processes, started by ``torchrun``: who this process is, which part of
each batch it computes, and the sums they share.

``torchrun --nproc_per_node=N -m gesturelib train MODEL ...`` starts N copies of the command;
:func:`start_from_environment` joins them into one process group (gloo on CPUs, NCCL on GPUs).
The training loop (:mod:`gesturelib.train`) then runs as one run on N processes: every process
draws the same shuffled order and takes its share of each batch (:class:`ShardedBatches`), the
gradients are averaged over processes (PyTorch's ``DistributedDataParallel``), so each optimiser
step sees the same global batch as one process would; process 0 alone writes checkpoints and
shows progress. Without ``torchrun`` nothing here does anything.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import time

import torch
import torch.distributed as dist
from torch import nn
from torch.utils.data import Sampler


def world() -> tuple[int, int]:
    """``(rank, size)``: this process's number and how many train together; ``(0, 1)`` alone
    (also inside :func:`alone`)."""
    if dist.is_available() and dist.is_initialized() and not _alone:
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


_alone = False


@contextlib.contextmanager
def alone():
    """Within the block this process works as if it were alone (``world() == (0, 1)``): what it
    trains there, it trains by itself, waiting for no other process. For what every process needs
    alike and the cache of trained runs holds (the judge's feature network): the first to take
    the cache's lock trains it, the others wait for the lock and load it."""
    global _alone
    before, _alone = _alone, True
    try:
        yield
    finally:
        _alone = before


def start_from_environment(device: str) -> str:
    """Join the process group that ``torchrun`` describes in the environment (``WORLD_SIZE``,
    ``RANK``, ``LOCAL_RANK``), if any; return the device this process trains on: ``device``,
    or for ``cuda`` the GPU of this process's local rank."""
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1 or world()[1] > 1:
        return device
    cuda = device.startswith("cuda")
    dist.init_process_group(backend="nccl" if cuda else "gloo")
    if cuda:
        local = int(os.environ.get("LOCAL_RANK", "0"))
        torch.cuda.set_device(local)
        return f"cuda:{local}"
    return device


def barrier() -> None:
    """Wait for every process (nothing alone)."""
    if world()[1] > 1:
        dist.barrier()


def all_sum(sums: dict[str, tuple[float, int]]) -> dict[str, tuple[float, int]]:
    """``{key: (total, count)}`` summed over processes (the same keys in each)."""
    if world()[1] == 1:
        return sums
    keys = sorted(sums)
    values = torch.tensor([v for key in keys for v in sums[key]], dtype=torch.float64)
    values = _share(dist.all_reduce, values)
    return {key: (float(values[2 * i]), int(values[2 * i + 1])) for i, key in enumerate(keys)}


def from_first(value):
    """Process 0's ``value`` (any picklable object) in every process: one decision for all."""
    rank, size = world()
    if size == 1:
        return value
    data = pickle.dumps(value) if rank == 0 else b""
    length = _share(dist.broadcast, torch.tensor([len(data)]), src=0)
    if rank == 0:
        # A copy torch owns: freeing a view of Python's bytes would need Python's lock too.
        buffer = torch.frombuffer(bytearray(data), dtype=torch.uint8).clone()
    else:
        buffer = torch.empty(int(length), dtype=torch.uint8)
    return pickle.loads(_share(dist.broadcast, buffer, src=0).numpy().tobytes())


def _share(collective, tensor: torch.Tensor, **options) -> torch.Tensor:
    """``collective(tensor, **options)`` (in place) on the backend's device; the result on the
    CPU, and under gloo once gloo has let go of the tensor.

    Gloo's worker threads release a collective's tensors a moment after it completes. If the
    last reference to a tensor made in Python is one of theirs, releasing it needs Python's
    lock; should that happen while the interpreter shuts down, the process aborts ("terminate
    called without an active exception"), and ``destroy_process_group`` does not stop those
    threads. So Python keeps the tensor until gloo has dropped it (a few microseconds)."""
    if dist.get_backend() == "nccl":  # NCCL works on GPU tensors only
        tensor = tensor.to(torch.cuda.current_device())
        collective(tensor, **options)
        return tensor.cpu()
    collective(tensor, **options)
    deadline = time.monotonic() + 10.0
    while tensor._use_count() > 1 and time.monotonic() < deadline:
        time.sleep(0.0005)  # lets the worker thread take Python's lock
    return tensor


def finish() -> None:
    """Leave the process group, if this process joined one."""
    if world()[1] > 1:
        dist.destroy_process_group()


class ShardedBatches(Sampler):
    """The batches of one epoch, each cut into this process's share: the order is
    ``torch.randperm(n, generator)`` (as a shuffling ``DataLoader`` draws it), cut into batches of
    ``batch_size`` (a multiple of ``size``), and process ``rank`` of ``size`` takes every
    ``size``-th item of each, so the processes together see the batches one process would. The
    last, smaller batch is shared as evenly as it divides, and dropped if it cannot give every
    process an item (a process without items would wait for the others' gradients)."""

    def __init__(self, n: int, batch_size: int, drop_last: bool, generator, rank: int, size: int):
        if batch_size % size:
            raise ValueError(
                f"a batch of {batch_size} does not divide among {size} processes; choose a "
                "batch size that is a multiple of the number of processes"
            )
        self.n, self.batch_size, self.generator = n, batch_size, generator
        self.rank, self.size = rank, size
        last = n % batch_size
        self.batches = n // batch_size + (1 if last >= size and not drop_last else 0)

    def __iter__(self):
        order = torch.randperm(self.n, generator=self.generator).tolist()
        for start in range(0, self.batches * self.batch_size, self.batch_size):
            yield order[start : start + self.batch_size][self.rank :: self.size]

    def __len__(self) -> int:
        return self.batches


class LossOf(nn.Module):
    """``model.loss`` as a module's ``forward``: ``DistributedDataParallel`` averages the
    gradients of what its wrapped module's forward computes."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, batch: dict) -> dict:
        return self.model.loss(batch)
