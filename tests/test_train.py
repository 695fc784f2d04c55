import math
import os
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch
from torch import nn

from gesturelib import checkpoints
from gesturelib.checkpoints import (
    CheckpointError,
    CheckpointMismatchError,
    load_model,
    read_checkpoint,
    save_checkpoint,
)
from gesturelib.configs import config_from_dict
from gesturelib.data import Normaliser
from gesturelib.train import (
    _TRAINING_CODE,
    History,
    NonFiniteLossError,
    TrainConfig,
    evaluate,
    load_or_train,
    noam_learning_rate,
    train,
)

# ---------------------------------------------------------------------------------------------
# A toy problem: linear regression y = x . w + 0.5 + noise, items are dicts like WindowDataset's
# ---------------------------------------------------------------------------------------------

TRUE_WEIGHTS = torch.tensor([1.5, -2.0, 0.5])


def toy_data(n: int, seed: int) -> list[dict[str, torch.Tensor]]:
    generator = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 3, generator=generator)
    y = x @ TRUE_WEIGHTS + 0.5 + 0.1 * torch.randn(n, generator=generator)
    return [{"x": x[i], "y": y[i]} for i in range(n)]


TRAIN, VAL = toy_data(64, seed=1), toy_data(32, seed=2)


@dataclass(frozen=True)
class ToyConfig:
    dropout: float = 0.0
    hidden: int = 8


class ToyRegressor(nn.Module):
    """A small MLP with optional dropout; logs the MSE loss and the mean absolute error."""

    config_class = ToyConfig

    def __init__(self, config: ToyConfig):
        super().__init__()
        self.config = config
        self.net = nn.Sequential(
            nn.Linear(3, config.hidden), nn.Dropout(config.dropout), nn.Linear(config.hidden, 1)
        )

    def loss(self, batch):
        error = self.net(batch["x"]).squeeze(-1) - batch["y"]
        return {"loss": error.pow(2).mean(), "mae": error.abs().mean()}


class OtherModel(ToyRegressor):
    pass


def make_model(seed: int = 0, model_class=ToyRegressor, **config) -> nn.Module:
    torch.manual_seed(seed)
    return model_class(ToyConfig(**config))


def config(**changes) -> TrainConfig:
    """4 steps an epoch; the learning rate peaks after 8 steps."""
    base = dict(epochs=4, batch_size=16, warmup_steps=8, lr_max=0.05, lr_min=0.005, patience=None)
    return TrainConfig(**(base | changes))


def weights(model: nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def assert_same_weights(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


def assert_same_history(a: History, b: History) -> None:
    """Equal in everything but wall time."""
    assert (a.train, a.val, a.learning_rate) == (b.train, b.val, b.learning_rate)
    assert (a.best_epoch, a.stopped_early) == (b.best_epoch, b.stopped_early)


@pytest.fixture(scope="module")
def reference():
    """An uninterrupted 4-epoch run with dropout: (weights, history)."""
    model = make_model(dropout=0.3)
    history = train(model, TRAIN, VAL, config(), progress=False)
    return weights(model), history


# ---------------------------------------------------------------------------------------------
# Schedule and configuration
# ---------------------------------------------------------------------------------------------


def test_noam_schedule_rises_peaks_decays_and_floors():
    warmup, lr_max, lr_min = 100, 1e-3, 1e-4
    rates = np.array([noam_learning_rate(s, warmup, lr_max, lr_min) for s in range(20_000)])
    assert rates[0] == pytest.approx(lr_max / warmup)
    assert np.all(np.diff(rates[:warmup]) > 0)  # linear warm-up
    np.testing.assert_allclose(np.diff(rates[:warmup]), lr_max / warmup)
    assert np.argmax(rates) == warmup - 1 and rates.max() == pytest.approx(lr_max)
    assert np.all(np.diff(rates[warmup - 1 :]) <= 0)
    # inverse square root: lr * sqrt(step) is constant until the floor
    steps = np.arange(1, 20_001)
    decaying = (steps > warmup) & (rates > lr_min)
    np.testing.assert_allclose(rates[decaying] * np.sqrt(steps[decaying]), lr_max * np.sqrt(warmup))
    # the floor is reached at warmup * (lr_max / lr_min)**2 = 10 000 steps and kept
    assert rates[10_000:].min() == rates[10_000:].max() == lr_min
    assert rates[9_000] > lr_min


@pytest.mark.parametrize(
    "args", [(-1, 10, 1e-3, 1e-4), (0, 0, 1e-3, 1e-4), (0, 10, 1e-4, 1e-3), (0, 10, 1e-3, 0.0)]
)
def test_noam_rejects_bad_arguments(args):
    with pytest.raises(ValueError):
        noam_learning_rate(*args)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("epochs", 0),
        ("epochs", 2.5),
        ("batch_size", 0),
        ("batch_size", True),
        ("warmup_steps", 0),
        ("lr_max", -1e-3),
        ("lr_max", float("nan")),
        ("lr_min", 0.0),
        ("lr_min", 1.0),  # above lr_max
        ("grad_clip_norm", 0.0),
        ("patience", 0),
        ("seed", -1),
        ("num_workers", -1),
        ("drop_last", "yes"),
        ("device", "gpu-please"),
    ],
)
def test_train_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        TrainConfig(**{field: value})


def test_train_config_quick_and_round_trip():
    quick = TrainConfig.quick(seed=3)
    assert quick.epochs < TrainConfig().epochs and quick.seed == 3
    assert TrainConfig.from_dict(quick.to_dict()) == quick
    assert TrainConfig(grad_clip_norm=None, patience=None).grad_clip_norm is None
    with pytest.raises(ValueError, match="learning_rate"):
        TrainConfig.from_dict({**quick.to_dict(), "learning_rate": 1e-3})


def test_config_from_dict_rejects_unknown_keys_and_restores_tuples():
    @dataclass(frozen=True)
    class Sizes:
        widths: tuple = (4, 8)

    assert config_from_dict(Sizes, {"widths": [1, 2]}) == Sizes((1, 2))
    with pytest.raises(ValueError, match="'depth'"):
        config_from_dict(Sizes, {"widths": [1], "depth": 3})


# ---------------------------------------------------------------------------------------------
# The loop
# ---------------------------------------------------------------------------------------------


def test_loss_decreases_history_is_filled_and_best_weights_kept():
    model = make_model()
    before = evaluate(model, VAL)["loss"]
    history = train(model, TRAIN, VAL, config(epochs=6), progress=False)
    assert set(history.train) == set(history.val) == {"loss", "mae"}
    assert all(len(values) == 6 for values in [*history.train.values(), *history.val.values()])
    assert history.epochs == 6 and len(history.epoch_seconds) == 6
    assert all(seconds > 0 for seconds in history.epoch_seconds)
    assert history.learning_rate[0] == pytest.approx(0.05 * 4 / 8)  # 4 steps of 8 warm-up steps
    assert history.learning_rate[-1] == pytest.approx(0.05 * math.sqrt(8 / 24))
    assert history.val["loss"][-1] < 0.2 * before
    assert history.train["loss"][-1] < 0.2 * history.train["loss"][0]
    # the model ends with the weights of the best epoch
    best = history.best_epoch
    assert history.val["loss"][best - 1] == min(history.val["loss"])
    assert evaluate(model, VAL)["loss"] == pytest.approx(history.val["loss"][best - 1])
    assert model.training  # back in the mode it came in


def test_validation_runs_in_eval_mode_without_gradients():
    seen = []

    class Recorder(ToyRegressor):
        def loss(self, batch):
            seen.append((self.training, torch.is_grad_enabled()))
            return super().loss(batch)

    model = make_model(model_class=Recorder, dropout=0.5)
    train(model, TRAIN, VAL, config(epochs=2), progress=False)
    # per epoch: 4 training batches (64 / 16), then 2 validation batches (32 / 16)
    epoch = [(True, True)] * 4 + [(False, False)] * 2
    assert seen == epoch * 2
    # with dropout 0.5, the validation loss is still deterministic
    assert evaluate(model, VAL) == evaluate(model, VAL)
    assert model.training


def test_early_stopping_stops_and_keeps_the_best_epoch():
    scores = [3.0, 2.0, 2.5, 2.2, 2.1, 1.0, 0.5]
    snapshots = []

    class Scripted(ToyRegressor):
        """Validation loss follows `scores` (one validation batch per epoch)."""

        def loss(self, batch):
            terms = super().loss(batch)
            if not self.training:
                snapshots.append(weights(self))
                terms["loss"] = torch.tensor(scores[len(snapshots) - 1])
            return terms

    model = make_model(model_class=Scripted)
    history = train(model, TRAIN, VAL, config(epochs=7, batch_size=32, patience=3), progress=False)
    assert history.stopped_early and history.epochs == 5  # epochs 3, 4, 5 do not beat epoch 2
    assert history.best_epoch == 2 and history.val["loss"] == pytest.approx(scores[:5])
    assert_same_weights(weights(model), snapshots[1])


def test_training_without_validation_keeps_the_best_training_epoch():
    model = make_model()
    history = train(model, TRAIN, None, config(), progress=False)
    assert history.val == {} and history.best_epoch == int(np.argmin(history.train["loss"])) + 1


class ScriptedJudge:
    """Scores the epochs it judges with ``scores`` in turn, drawing random numbers as a judge that
    samples would, and records the model's mode, the gradient mode and the weights it saw."""

    def __init__(self, scores, name="scripted", interrupt_at=None):
        self.scores, self.identity = list(scores), {"judge": name}
        self.seen, self.interrupt_at = [], interrupt_at

    def __call__(self, model):
        if len(self.seen) == self.interrupt_at:
            self.interrupt_at = None
            raise KeyboardInterrupt("power cut while judging")
        torch.randn(100)  # must not change the training that follows
        self.seen.append((model.training, torch.is_grad_enabled(), weights(model)))
        return self.scores[len(self.seen) - 1]


def test_a_judged_run_keeps_the_best_judged_of_its_last_epochs(reference):
    judge = ScriptedJudge([5.0, 1.0, 3.0])
    model = make_model(dropout=0.3)
    history = train(model, TRAIN, VAL, config(judged_epochs=3), judge=judge, progress=False)
    # judging changes which epoch is kept, not the training: the losses are the reference's
    assert (history.train, history.val) == (reference[1].train, reference[1].val)
    assert history.judged == {2: 5.0, 3: 1.0, 4: 3.0} and history.best_epoch == 3
    assert [mode[:2] for mode in judge.seen] == [(False, False)] * 3  # eval, no gradients
    assert_same_weights(weights(model), judge.seen[1][2])
    assert model.training


def test_judged_epochs_compete_among_themselves_and_a_failed_judgement_is_the_worst(tmp_path):
    # epoch 1, unjudged, has a validation loss far below any judged score; it is not kept
    history = train(
        make_model(),
        TRAIN,
        VAL,
        config(judged_epochs=3),
        judge=ScriptedJudge([50.0, 40.0, 60.0]),
        progress=False,
    )
    assert history.best_epoch == 3
    # a judge that finds no finite score in any epoch: the loss decides, as in an unjudged run
    history = train(
        make_model(),
        TRAIN,
        VAL,
        config(judged_epochs=2),
        tmp_path,
        judge=ScriptedJudge([math.nan, math.inf]),
        progress=False,
    )
    assert history.judged == {3: math.inf, 4: math.inf}
    assert history.best_epoch == 1 + int(np.argmin(history.val["loss"]))
    best = read_checkpoint(tmp_path / "best.pt")
    assert best["epoch"] == history.best_epoch
    assert best["score"] == history.val["loss"][history.best_epoch - 1]  # the loss that chose it
    # the first finite judgement takes over from the loss; a later failed one never wins
    judge = ScriptedJudge([math.inf, 7.0, math.nan])
    history = train(make_model(), TRAIN, VAL, config(judged_epochs=3), judge=judge, progress=False)
    assert history.best_epoch == 3
    # judged from the first epoch, which the judge cannot score: the loss decides until it can
    judge = ScriptedJudge([math.nan, 9.0, 7.0, 8.0])
    history = train(
        make_model(), TRAIN, VAL, config(judged_epochs=4, patience=1), judge=judge, progress=False
    )
    assert history.best_epoch == 3 and history.epochs == 4


def test_a_judged_run_cannot_be_extended_and_an_unjudged_one_saves_no_judged_epochs(tmp_path):
    train(
        make_model(),
        TRAIN,
        VAL,
        config(judged_epochs=2),
        tmp_path / "judged",
        judge=ScriptedJudge([2.0, 1.0]),
        progress=False,
    )
    assert read_checkpoint(tmp_path / "judged" / "best.pt")["train_config"]["judged_epochs"] == 2
    with pytest.raises(ValueError, match=r"judged epochs \[3, 4\]; with epochs=6 it would judge"):
        train(
            make_model(),
            TRAIN,
            VAL,
            config(epochs=6, judged_epochs=2),
            tmp_path / "judged",
            judge=ScriptedJudge([2.0, 1.0]),
            progress=False,
        )
    # as in the run folders saved before judging existed, which still resume
    train(make_model(), TRAIN, VAL, config(), tmp_path / "plain", progress=False)
    assert "judged_epochs" not in read_checkpoint(tmp_path / "plain" / "last.pt")["train_config"]


def test_a_judged_run_resumes_with_its_scores_and_refuses_another_judge(tmp_path):
    scores = [4.0, 2.0, 3.0]

    def judged_run(model, folder, judge):
        return train(
            model,
            TRAIN,
            VAL,
            config(judged_epochs=3),
            tmp_path / folder,
            judge=judge,
            progress=False,
        )

    clean = make_model(dropout=0.3)
    history = judged_run(clean, "clean", ScriptedJudge(scores))
    with pytest.raises(KeyboardInterrupt):  # while judging epoch 3: last.pt holds epoch 2
        judged_run(make_model(dropout=0.3), "cut", ScriptedJudge(scores, interrupt_at=1))
    with pytest.raises(CheckpointMismatchError, match="judge"):
        judged_run(make_model(dropout=0.3), "cut", ScriptedJudge(scores, name="another"))
    resumed = make_model(seed=4, dropout=0.3)
    again = judged_run(resumed, "cut", ScriptedJudge(scores[1:]))
    assert again.judged == history.judged and again.best_epoch == history.best_epoch == 3
    assert_same_weights(weights(resumed), weights(clean))
    best = read_checkpoint(tmp_path / "cut" / "best.pt")
    assert best["score"] == 2.0 and History.from_dict(best["history"]).judged == history.judged


def test_a_judge_and_judged_epochs_come_together():
    with pytest.raises(ValueError, match="judged_epochs=2 needs a judge: pass judge="):
        train(make_model(), TRAIN, VAL, config(judged_epochs=2), progress=False)
    with pytest.raises(ValueError, match="a judge needs TrainConfig.judged_epochs > 0"):
        train(make_model(), TRAIN, VAL, config(), judge=ScriptedJudge([1.0]), progress=False)
    with pytest.raises(TypeError, match="with an identity dict; got function"):
        train(make_model(), TRAIN, VAL, config(judged_epochs=1), judge=lambda m: 1.0)
    with pytest.raises(ValueError, match="judged_epochs"):
        TrainConfig(judged_epochs=-1)


def test_load_or_train_keys_a_judged_run_by_its_judge(tmp_path):
    Counting.calls = 0
    for name in ("one", "one", "two"):
        load_or_train(
            Counting,
            ToyConfig(),
            TRAIN,
            VAL,
            config(judged_epochs=2),
            tmp_path,
            judge=ScriptedJudge([2.0, 1.0], name=name),
            progress=False,
        )
    assert Counting.calls == 2 * 4 * (4 + 2)  # the second run of judge "one" was loaded
    assert len(list(tmp_path.iterdir())) == 2


def test_same_seed_same_result_and_caller_random_state_untouched(reference):
    state = torch.get_rng_state()
    model = make_model(dropout=0.3)
    history = train(model, TRAIN, VAL, config(), progress=False)
    assert torch.equal(torch.get_rng_state(), state)
    assert_same_weights(weights(model), reference[0])
    assert_same_history(history, reference[1])
    other = make_model(dropout=0.3)
    train(other, TRAIN, VAL, config(seed=1), progress=False)
    assert not torch.equal(other.net[0].weight, model.net[0].weight)


@pytest.mark.parametrize(
    ("make_bad", "match"),
    [
        (lambda terms: terms["loss"], "dict"),
        (lambda terms: {"mae": terms["mae"]}, "'loss'"),
        (lambda terms: {**terms, "per_item": torch.zeros(3)}, "per_item"),
        (lambda terms: {"loss": terms["loss"].detach()}, "trainable"),
    ],
)
def test_model_protocol_violations_are_explained(make_bad, match):
    class Bad(ToyRegressor):
        def loss(self, batch):
            return make_bad(super().loss(batch))

    with pytest.raises((TypeError, ValueError), match=match):
        train(make_model(model_class=Bad), TRAIN, VAL, config(), progress=False)


def test_model_without_config_dataclass_is_rejected():
    model = make_model()
    model.config = {"hidden": 8}
    with pytest.raises(TypeError, match="config dataclass"):
        train(model, TRAIN, VAL, config(), progress=False)


def test_a_history_without_judged_epochs_loads_and_a_judged_one_plots_them(reference):
    saved = reference[1].to_dict()
    del saved["judged"]  # a history saved before judging existed
    assert History.from_dict(saved) == reference[1]
    judged = History.from_dict({**saved, "judged": {3: 2.0, 4: 1.0}, "best_epoch": 4})
    figure = judged.plot(["loss"])
    titles = [ax.get_title() for ax in figure.axes]
    assert titles == ["loss", "judged (lower is better)", "learning rate"]
    assert list(figure.axes[1].lines[-1].get_xdata()) == [3, 4]
    plt.close(figure)


def test_history_round_trip_and_plot(reference):
    history = reference[1]
    assert History.from_dict(history.to_dict()) == history
    figure = history.plot()
    assert [ax.get_title() for ax in figure.axes] == ["loss", "mae", "learning rate"]
    assert len(figure.axes[0].lines) == 3  # training, validation, best epoch
    plt.close(figure)


# ---------------------------------------------------------------------------------------------
# Checkpoints, resuming, faults
# ---------------------------------------------------------------------------------------------


def test_checkpoint_round_trip(tmp_path):
    normaliser = Normaliser(
        pose_mean=np.zeros(54, np.float32),
        pose_std=np.ones(54, np.float32),
        speech_mean=np.full(27, 2.0, np.float32),
        speech_std=np.ones(27, np.float32),
        style_mean=np.zeros(4, np.float32),
        style_std=np.ones(4, np.float32),
        style_percentiles=np.tile(np.arange(101.0)[:, None], (1, 4)),
    )
    model = make_model(hidden=6)
    history = train(model, TRAIN, VAL, config(), tmp_path, normaliser=normaliser, progress=False)
    loaded = load_model(tmp_path / "best.pt", ToyRegressor)
    assert loaded.config == ToyConfig(hidden=6) and not loaded.training
    assert_same_weights(weights(loaded), weights(model))
    best = torch.load(tmp_path / "best.pt", weights_only=True)
    assert best["epoch"] == history.best_epoch and best["epochs_done"] == 4
    assert History.from_dict(best["history"]) == history
    restored = Normaliser.from_dict(best["normaliser"])
    np.testing.assert_array_equal(restored.speech_mean, normaliser.speech_mean)
    last = torch.load(tmp_path / "last.pt", weights_only=True)
    assert last["epoch"] == 4 and last["step"] == 16 and last["optimizer"]["state"]


def test_resume_equals_uninterrupted_training(tmp_path, reference):
    train(make_model(dropout=0.3), TRAIN, VAL, config(epochs=2), tmp_path, progress=False)
    # other initial weights: they are replaced by the checkpoint's
    model = make_model(seed=99, dropout=0.3)
    history = train(model, TRAIN, VAL, config(epochs=4), tmp_path, progress=False)
    assert_same_weights(weights(model), reference[0])
    assert_same_history(history, reference[1])


@pytest.mark.parametrize("fault", [KeyboardInterrupt, RuntimeError])
def test_interruption_leaves_a_resumable_checkpoint(tmp_path, reference, fault):
    class Crashing(ToyRegressor):
        calls, fail_at = 0, 6 * 2 + 2  # in epoch 3 (6 calls an epoch: 4 training + 2 validation)

        def loss(self, batch):
            Crashing.calls += 1
            if Crashing.calls == Crashing.fail_at:
                raise fault("power cut")
            return super().loss(batch)

    with pytest.raises(fault) as raised:
        train(
            make_model(model_class=Crashing, dropout=0.3),
            TRAIN,
            VAL,
            config(),
            tmp_path,
            progress=False,
        )
    assert "last.pt (after epoch 2) is intact" in "".join(raised.value.__notes__)
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == 2
    Crashing.fail_at = None
    model = make_model(seed=5, model_class=Crashing, dropout=0.3)
    history = train(model, TRAIN, VAL, config(), tmp_path, progress=False)
    assert_same_weights(weights(model), reference[0])
    assert_same_history(history, reference[1])


@pytest.mark.parametrize("where", ["loss", "gradient"])
def test_non_finite_loss_stops_before_the_update(tmp_path, where):
    before_failure = {}

    class Exploding(ToyRegressor):
        calls = 0

        def loss(self, batch):
            terms = super().loss(batch)
            Exploding.calls += 1
            if Exploding.calls == 9:  # epoch 2, third training batch
                before_failure.update(weights(self))
                if where == "loss":
                    terms["loss"] = terms["loss"] * float("nan")
                else:  # a finite loss of 0 whose gradient is NaN: d sqrt(|w - w|)/dw
                    weight = self.net[0].weight
                    terms["loss"] = terms["loss"] + (weight - weight.detach()).abs().sum().sqrt()
            return terms

    model = make_model(model_class=Exploding)
    with pytest.raises(NonFiniteLossError, match=f"non-finite {where}.*epoch 2, batch 3"):
        train(model, TRAIN, VAL, config(), tmp_path, progress=False)
    assert_same_weights(weights(model), before_failure)  # no step was taken
    for name in ("last.pt", "best.pt"):
        saved = read_checkpoint(tmp_path / name)["model"]
        assert all(torch.isfinite(value).all() for value in saved.values())
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == 1


def test_checkpoint_write_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "best.pt"
    good = {"kind": "best", "model": {"w": torch.ones(3)}}
    save_checkpoint(good, path)

    def failing_save(contents, file):
        file.write(b"half a checkpoint")
        raise OSError("disk full")

    monkeypatch.setattr(checkpoints.torch, "save", failing_save)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint({"kind": "best", "model": {"w": torch.zeros(3)}}, path)
    monkeypatch.undo()
    assert os.listdir(tmp_path) == ["best.pt"]  # the temporary file is gone
    assert torch.equal(torch.load(path, weights_only=True)["model"]["w"], torch.ones(3))


def test_failed_save_during_training_keeps_the_previous_epoch(tmp_path, monkeypatch, reference):
    real_save, saves = torch.save, []

    def save_until_epoch_3(contents, file):
        saves.append(contents["kind"])
        if contents["kind"] == "last" and contents["epoch"] == 3:
            raise OSError("disk full")
        real_save(contents, file)

    monkeypatch.setattr(checkpoints.torch, "save", save_until_epoch_3)
    with pytest.raises(OSError):
        train(make_model(dropout=0.3), TRAIN, VAL, config(), tmp_path, progress=False)
    monkeypatch.undo()
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == 2
    model = make_model(dropout=0.3)
    train(model, TRAIN, VAL, config(), tmp_path, progress=False)
    assert_same_weights(weights(model), reference[0])


def test_corrupt_checkpoint_error_names_the_file(tmp_path):
    train(make_model(), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    best = tmp_path / "best.pt"
    best.write_bytes(best.read_bytes()[:200])  # truncated
    with pytest.raises(CheckpointError, match="best.pt.*corrupt"):
        load_model(best, ToyRegressor)
    with pytest.raises(CheckpointError, match="best.pt"):
        train(make_model(), TRAIN, VAL, config(epochs=2), tmp_path, progress=False)
    (tmp_path / "notes.pt").write_text("not a checkpoint")
    with pytest.raises(CheckpointError, match="notes.pt"):
        read_checkpoint(tmp_path / "notes.pt")
    with pytest.raises(CheckpointError, match="no checkpoint at .*missing.pt"):
        load_model(tmp_path / "missing.pt", ToyRegressor)


def test_mismatched_checkpoints_are_refused_with_the_difference(tmp_path):
    train(make_model(), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    best = tmp_path / "best.pt"
    with pytest.raises(CheckpointMismatchError, match="best.pt holds a 'ToyRegressor', not a 'Oth"):
        load_model(best, OtherModel)
    # another model config, another training config: refused, naming the field
    with pytest.raises(CheckpointMismatchError, match=r"last.pt.*\n.*model config.hidden"):
        train(make_model(hidden=4), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    with pytest.raises(CheckpointMismatchError, match="(?s)training config.lr_max.*overwrite=True"):
        train(make_model(), TRAIN, VAL, config(epochs=1, lr_max=0.1), tmp_path, progress=False)
    # ... unless asked to overwrite
    train(
        make_model(hidden=4), TRAIN, VAL, config(epochs=1), tmp_path, progress=False, overwrite=True
    )
    assert load_model(best, ToyRegressor).config.hidden == 4
    # a config its class rejects
    contents = read_checkpoint(best)
    save_checkpoint({**contents, "model_config": {"hidden": 4, "depth": 2}}, best)
    with pytest.raises(CheckpointMismatchError, match="best.pt.*ToyConfig.*'depth'"):
        load_model(best, ToyRegressor)
    # parameter shapes that do not fit the config
    contents["model"]["net.0.weight"] = torch.zeros(4, 5)
    save_checkpoint(contents, best)
    with pytest.raises(
        CheckpointMismatchError, match=r"best.pt.*\n.*net.0.weight.*\(4, 5\).*\(4, 3\)"
    ):
        load_model(best, ToyRegressor)


def test_a_finished_run_is_not_reused_for_other_data(tmp_path):
    train(make_model(), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    other = list(TRAIN)
    other[len(other) // 3] = {key: value + 1 for key, value in other[len(other) // 3].items()}
    for data in (toy_data(64, seed=9), other):  # other data, or one item changed anywhere
        with pytest.raises(
            CheckpointMismatchError, match=r"(?s)training data: the file has .*overwrite"
        ):
            train(make_model(), data, VAL, config(epochs=1), tmp_path, progress=False)


def test_a_checkpoint_folder_that_is_a_file_is_refused(tmp_path):
    path = tmp_path / "run"
    path.write_text("notes")
    with pytest.raises(CheckpointError, match="run is a file, not a folder"):
        train(make_model(), TRAIN, VAL, config(epochs=1), path, progress=False)
    assert path.read_text() == "notes"


def _os_full_disk(contents, file):
    raise OSError(28, "No space left on device")


def _torch_full_disk(contents, file):
    """What torch.save raises on a full disk: its own error, raised while handling the OSError."""
    try:
        raise OSError(28, "No space left on device")
    except OSError:
        raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos") from None


@pytest.mark.parametrize("full_disk", [_os_full_disk, _torch_full_disk], ids=["os", "torch"])
def test_a_full_disk_is_named_and_leaves_the_checkpoints_intact(tmp_path, monkeypatch, full_disk):
    train(make_model(), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    before = read_checkpoint(tmp_path / "last.pt")["epoch"]

    monkeypatch.setattr(checkpoints.torch, "save", full_disk)
    with pytest.raises(CheckpointError, match=r"no space left on the device to write .*\.pt"):
        train(make_model(), TRAIN, VAL, config(epochs=2), tmp_path, progress=False)
    monkeypatch.undo()
    assert read_checkpoint(tmp_path / "last.pt")["epoch"] == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best.pt", "last.pt"]


def test_a_checkpoint_of_another_format_version_says_to_retrain(tmp_path):
    train(make_model(), TRAIN, VAL, config(epochs=1), tmp_path, progress=False)
    contents = torch.load(tmp_path / "best.pt", weights_only=True)
    torch.save({**contents, "version": 1}, tmp_path / "best.pt")
    with pytest.raises(CheckpointError, match="version 1.*Retrain"):
        load_model(tmp_path / "best.pt", ToyRegressor)


# ---------------------------------------------------------------------------------------------
# Load or train
# ---------------------------------------------------------------------------------------------


class Counting(ToyRegressor):
    calls = 0

    def loss(self, batch):
        Counting.calls += 1
        return super().loss(batch)


def test_load_or_train_trains_once_then_loads(tmp_path):
    Counting.calls = 0
    model, history = load_or_train(
        Counting, ToyConfig(), TRAIN, VAL, config(), tmp_path, progress=False
    )
    assert Counting.calls == 4 * (4 + 2) and not model.training
    (folder,) = tmp_path.iterdir()
    assert folder.name.startswith("Counting-") and (folder / "best.pt").exists()

    Counting.calls = 0
    again, history_again = load_or_train(
        Counting, ToyConfig(), TRAIN, VAL, config(), tmp_path, progress=False
    )
    assert Counting.calls == 0
    assert_same_weights(weights(again), weights(model))
    assert history_again == history
    # execution settings do not make another run
    load_or_train(
        Counting,
        ToyConfig(),
        TRAIN,
        VAL,
        config(num_workers=0, device="cpu:0"),
        tmp_path,
        progress=False,
    )
    assert Counting.calls == 0 and len(list(tmp_path.iterdir())) == 1


def test_two_processes_asking_for_one_model_train_it_once(tmp_path, capsys):
    """The second waits for the first (here: threads, whose file locks conflict as processes'
    do) and then loads what it trained."""
    import threading

    # ast.parse is not thread-safe in CPython 3.11: the code's fingerprint is parsed here first
    # (processes, which the threads stand for, each parse their own).
    checkpoints.code_fingerprint(*_TRAINING_CODE, Counting.__module__)
    Counting.calls = 0
    results = []

    def ask():
        results.append(
            load_or_train(Counting, ToyConfig(), TRAIN, VAL, config(), tmp_path, progress=True)
        )

    askers = [threading.Thread(target=ask) for _ in range(2)]
    for asker in askers:
        asker.start()
    for asker in askers:
        asker.join(timeout=60)
    assert Counting.calls == 4 * (4 + 2)  # trained once
    (first, _), (second, _) = results
    assert_same_weights(weights(first), weights(second))
    assert "Loaded" in capsys.readouterr().out


def test_load_or_train_distinguishes_configs_and_data(tmp_path):
    Counting.calls = 0
    runs = [
        (ToyConfig(), config(), TRAIN),
        (ToyConfig(hidden=4), config(), TRAIN),
        (ToyConfig(), config(lr_max=0.02), TRAIN),
        (ToyConfig(), config(), toy_data(64, seed=7)),
    ]
    for model_config, train_config, data in runs:
        load_or_train(Counting, model_config, data, VAL, train_config, tmp_path, progress=False)
    assert Counting.calls == 4 * 4 * (4 + 2) and len(list(tmp_path.iterdir())) == 4


def test_load_or_train_resumes_a_partial_run(tmp_path):
    class Interrupted(ToyRegressor):
        calls, fail_at = 0, None

        def loss(self, batch):
            Interrupted.calls += 1
            if Interrupted.calls == Interrupted.fail_at:
                raise KeyboardInterrupt
            return super().loss(batch)

    clean, _ = load_or_train(
        Interrupted, ToyConfig(), TRAIN, VAL, config(), tmp_path / "clean", progress=False
    )
    Interrupted.calls, Interrupted.fail_at = 0, 6 * 2 + 1  # first batch of epoch 3
    with pytest.raises(KeyboardInterrupt):
        load_or_train(
            Interrupted, ToyConfig(), TRAIN, VAL, config(), tmp_path / "cut", progress=False
        )
    Interrupted.calls, Interrupted.fail_at = 0, None
    model, _ = load_or_train(
        Interrupted, ToyConfig(), TRAIN, VAL, config(), tmp_path / "cut", progress=False
    )
    assert Interrupted.calls == 2 * (4 + 2)  # only epochs 3 and 4
    assert_same_weights(weights(model), weights(clean))


def test_training_a_finished_run_again_only_loads_its_best_weights(tmp_path):
    model = make_model(model_class=Counting)
    history = train(model, TRAIN, VAL, config(), tmp_path, progress=False)
    Counting.calls = 0
    again = make_model(seed=3, model_class=Counting)
    assert train(again, TRAIN, VAL, config(), tmp_path, progress=False) == history
    assert Counting.calls == 0
    assert_same_weights(weights(again), weights(model))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_resume_on_a_gpu_equals_uninterrupted_training_and_loads_on_the_cpu(tmp_path):
    gpu = config(device="cuda")
    model = make_model(dropout=0.3)
    train(model, TRAIN, VAL, gpu, progress=False)
    assert model.net[0].weight.is_cuda
    train(
        make_model(dropout=0.3),
        TRAIN,
        VAL,
        config(epochs=2, device="cuda"),
        tmp_path,
        progress=False,
    )
    resumed = make_model(dropout=0.3)
    train(resumed, TRAIN, VAL, gpu, tmp_path, progress=False)
    assert_same_weights(weights(resumed), weights(model))
    on_cpu = load_model(tmp_path / "best.pt", ToyRegressor)
    assert_same_weights(weights(on_cpu), {k: v.cpu() for k, v in weights(model).items()})


class Stacked(ToyRegressor):
    """A regressor holding a frozen, separately trained one (as Aud2Repr2Pose holds its
    autoencoder); ``from_inner`` is how it must be built."""

    calls = 0

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.inner = ToyRegressor(ToyConfig()).requires_grad_(False)

    @classmethod
    def from_inner(cls, inner: ToyRegressor, config: ToyConfig) -> "Stacked":
        model = cls(config)
        model.inner.load_state_dict(inner.state_dict())
        return model

    def loss(self, batch):
        Stacked.calls += 1
        return super().loss(batch)


def test_load_or_train_with_build_keys_the_run_by_the_inner_model(tmp_path):
    inner = make_model(seed=1)
    other_inner = make_model(seed=2)

    def stacked_on(inner_model):
        build = lambda config: Stacked.from_inner(inner_model, config)  # noqa: E731
        model, _ = load_or_train(
            Stacked, ToyConfig(), TRAIN, VAL, config(), tmp_path, build=build, progress=False
        )
        return model

    Stacked.calls = 0
    model = stacked_on(inner)
    assert_same_weights(weights(model.inner), weights(inner))  # built by build, then trained
    first_calls = Stacked.calls
    assert_same_weights(weights(stacked_on(inner)), weights(model))
    assert Stacked.calls == first_calls  # loaded from the cache

    # Another inner model is another run, never the cached one.
    other = stacked_on(other_inner)
    assert Stacked.calls == 2 * first_calls and len(list(tmp_path.iterdir())) == 2
    assert_same_weights(weights(other.inner), weights(other_inner))


def test_load_or_train_refuses_a_build_of_another_class(tmp_path):
    with pytest.raises(TypeError, match="build must return a Stacked, got ToyRegressor"):
        load_or_train(
            Stacked,
            ToyConfig(),
            TRAIN,
            VAL,
            config(),
            tmp_path,
            build=lambda config: ToyRegressor(config),
            progress=False,
        )
    assert not any(tmp_path.iterdir())


def test_the_code_fingerprint_ignores_docstrings_and_sees_code(tmp_path, monkeypatch):
    import gesturelib.checkpoints as checkpoints

    package = tmp_path / "gesturelib"
    package.mkdir()
    fake = package / "checkpoints.py"
    fake.write_text("")
    monkeypatch.setattr(checkpoints, "__file__", str(fake))

    def fingerprint(root="gesturelib.model", **sources):
        for name, source in sources.items():
            (package / f"{name}.py").write_text(source)
        checkpoints.code_fingerprint.cache_clear()
        return checkpoints.code_fingerprint(root)

    helper = "from gesturelib.viz import draw\n\ndef scale():\n    return 2\n"
    base = fingerprint(
        model='"""A model."""\nfrom gesturelib.helper import scale\n\ndef f(x):\n'
        '    """Twice."""\n    return scale() * x\n',
        helper=helper,
        other="def g():\n    return 1\n",
        viz="def draw():\n    return 1\n",
    )
    reworded = fingerprint(
        model='"""Another word."""\nfrom gesturelib.helper import scale\n\n\n'
        "def f(x):  # a comment\n    return scale() * x\n"
    )
    assert reworded == base
    # Code the model does not import (another model, a presentation module) is not its code.
    assert fingerprint(other="def g():\n    return 2\n") == base
    assert fingerprint(viz="def draw():\n    return 2\n") == base
    # Code it imports, directly or not, is.
    assert fingerprint(helper=helper.replace("return 2", "return 3")) != base
    assert fingerprint(root="gesturelib.other") != base
    checkpoints.code_fingerprint.cache_clear()


# ---------------------------------------------------------------------------------------------
# Several processes (torchrun, gloo on CPUs)
# ---------------------------------------------------------------------------------------------

DISTRIBUTED_SCRIPT = """
import sys
from dataclasses import dataclass

import torch
from torch import nn

from gesturelib.distributed import all_sum, alone, finish, from_first, start_from_environment, world
from gesturelib.flows import ActNorm
from gesturelib.train import TrainConfig, train


@dataclass(frozen=True)
class Config:
    hidden: int = 8


class Regressor(nn.Module):
    config_class = Config

    def __init__(self, config):
        super().__init__()
        self.config = config
        self.norm = ActNorm(3)  # initialised from the first batch it sees
        self.net = nn.Sequential(nn.Linear(3, config.hidden), nn.Tanh(), nn.Linear(config.hidden, 1))

    def loss(self, batch):
        x, _ = self.norm(batch["x"])
        return {"loss": (self.net(x).squeeze(-1) - batch["y"]).pow(2).mean()}


def data(n, seed):
    generator = torch.Generator().manual_seed(seed)
    x = torch.randn(n, 3, generator=generator)
    y = x @ torch.tensor([1.5, -2.0, 0.5]) + 0.1 * torch.randn(n, generator=generator)
    return [{"x": x[i], "y": y[i]} for i in range(n)]


folder, epochs = sys.argv[1], int(sys.argv[2])
start_from_environment("cpu")
torch.manual_seed(0)
model = Regressor(Config())
config = TrainConfig(epochs=epochs, batch_size=16, warmup_steps=8, lr_max=0.05, lr_min=0.005)
history = train(model, data(64, 1), data(32, 2), config, folder, progress=False)
rank = world()[0]
shared = {"first": from_first({"rank": rank, "text": "ü" * 300}), "sum": all_sum({"a": (rank + 0.5, 1)})}
with alone():
    worlds = [world()]
    with alone():
        worlds.append(world())
    worlds.append(world())
worlds.append(world())
torch.save(
    {"weights": model.state_dict(), "train": history.train, "shared": shared, "worlds": worlds},
    f"{folder}/result{rank}.pt",
)
finish()  # leave the process group before exiting, as the command line does
"""


def run_two_processes(script, *arguments):
    import subprocess
    import sys

    command = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2"]
    done = subprocess.run(
        [*command, "--standalone", str(script), *map(str, arguments)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]


def test_two_processes_train_as_one_process_on_the_same_global_batch(tmp_path):
    """Each process takes half of every batch, the gradients are averaged, the ActNorm starts
    from the whole first batch: the weights and the losses are one process's, to float rounding,
    in both processes, also for a run resumed in two; process 0 alone writes the run folder;
    process 0's objects and the sums over processes reach both."""
    script = tmp_path / "train_two.py"
    script.write_text(DISTRIBUTED_SCRIPT)
    run_two_processes(script, tmp_path / "two", 2)
    run_two_processes(script, tmp_path / "two", 4)  # resumes from epoch 2
    together, other = (torch.load(tmp_path / "two" / f"result{rank}.pt") for rank in (0, 1))

    namespace = {}
    exec(DISTRIBUTED_SCRIPT.split("folder, epochs")[0], namespace)  # the model and data alone
    torch.manual_seed(0)
    alone = namespace["Regressor"](namespace["Config"]())
    settings = dict(epochs=4, batch_size=16, warmup_steps=8, lr_max=0.05, lr_min=0.005)
    history = train(
        alone,
        namespace["data"](64, 1),
        namespace["data"](32, 2),
        TrainConfig(**settings),
        progress=False,
    )
    for rank, result in enumerate((together, other)):
        # process 0's object, and the sum of both processes'
        assert result["shared"] == {"first": {"rank": 0, "text": "ü" * 300}, "sum": {"a": (2.0, 2)}}
        assert result["worlds"] == [(0, 1)] * 3 + [(rank, 2)]  # alone, nested, and after
    for key, value in alone.state_dict().items():
        torch.testing.assert_close(together["weights"][key], value, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(other["weights"][key], together["weights"][key])
    np.testing.assert_allclose(together["train"]["loss"], history.train["loss"], rtol=1e-5)
    written = {p.name for p in (tmp_path / "two").iterdir()}
    assert written == {"best.pt", "last.pt", "result0.pt", "result1.pt"}
