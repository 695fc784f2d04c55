"""gesturelib.locks, and the shared caches that wait for each other instead of failing."""

import os
import threading
import time

import pytest

from gesturelib.locks import LockedError, _try_lock, exclusive


def test_a_held_lock_is_refused_naming_its_holder_or_waited_for(tmp_path, capsys):
    path = tmp_path / "lock"
    order = []

    def second():
        with exclusive(path, wait_for="filling the cache"):
            order.append("second")

    with exclusive(path):
        with pytest.raises(LockedError, match=f"process {os.getpid()} holds") as refused:
            with exclusive(path):
                pass
        assert refused.value.holder == f"process {os.getpid()}"
        waiter = threading.Thread(target=second)
        waiter.start()
        time.sleep(0.3)
        order.append("first")  # the waiter has not got in meanwhile
    waiter.join(timeout=10)
    assert order == ["first", "second"]
    assert (
        f"Waiting for process {os.getpid()}, which is filling the cache" in capsys.readouterr().out
    )
    assert path.exists()  # kept: a waiter may be about to lock it


def test_a_holder_that_has_not_yet_written_its_number_is_another_process(tmp_path):
    path = tmp_path / "lock"
    with open(path, "a+") as stream:
        assert _try_lock(stream)  # locked, but no number written yet: the moment after locking
        with pytest.raises(LockedError, match="another process holds") as refused:
            with exclusive(path):
                pass
    assert refused.value.holder == "another process"


def test_a_removable_lock_is_gone_after_release_also_after_an_error(tmp_path):
    path = tmp_path / "lock"
    with pytest.raises(KeyError):
        with exclusive(path, remove=True):
            raise KeyError("the work failed")
    assert not path.exists()
    with exclusive(path):  # free again
        pass


def test_two_processes_asking_for_one_dataset_write_it_once(tmp_path, capsys):
    """The second waits for the first (threads here, whose file locks conflict as processes'
    do), then finds the dataset written and reuses it."""
    from data_synth.dataset import ensure_dataset

    folder = tmp_path / "data" / "quick"
    manifests, errors = [], []

    def ask():
        try:
            manifests.append(
                ensure_dataset(folder, minutes=0.3, seed=0, conversation_s=6.0, progress=False)
            )
        except Exception as error:  # noqa: BLE001 - reported below
            errors.append(error)

    askers = [threading.Thread(target=ask) for _ in range(2)]
    for asker in askers:
        asker.start()
    for asker in askers:
        asker.join(timeout=120)
    assert not errors and len(manifests) == 2 and manifests[0] == manifests[1]
    assert "Waiting for " in capsys.readouterr().out  # "process N" or, racing, "another process"
