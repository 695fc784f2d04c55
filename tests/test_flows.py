"""Tests of gesturelib.flows (bijections, bases, flows) and gesturelib.toy_densities.

Every bijection is checked after its weights are randomised: a freshly built coupling is the
identity (zero-initialised last layer), which would hide a wrong log-determinant or inverse.
"""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
import scipy.stats
import torch
from torch.autograd.functional import jacobian

from gesturelib import toy_densities
from gesturelib.flows import (
    ActNorm,
    AdditiveCoupling,
    AffineCoupling,
    FlowStep,
    InvertibleLinear,
    MLPConditioner,
    RecurrentConditioner,
    RecurrentCoupling,
    RecurrentFlowStep,
    StandardNormal,
    StudentT,
    UninitialisedFlowError,
    ZeroLinear,
    glow,
    recurrent_glow,
)

DIM, COND, BATCH, FRAMES = 4, 3, 5, 3


def randomise(module: torch.nn.Module, seed: int = 0, scale: float = 0.3) -> torch.nn.Module:
    """Perturb every parameter and mark every data-initialised layer initialised."""
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for parameter in module.parameters():
            noise = torch.randn(parameter.shape, generator=generator, dtype=parameter.dtype)
            parameter.add_(scale * noise)
        for name, buffer in module.named_buffers():
            if name.endswith("initialized"):
                buffer.fill_(True)
    return module


def call(module, x, cond, inverse=False):
    """(output, logdet) of any block, whatever its signature."""
    fn = module.inverse if inverse else module.forward
    if isinstance(module, ActNorm | InvertibleLinear):
        return fn(x)
    out = fn(x, cond)
    return out[0], out[1]


# name -> (module factory, sequence input?, conditional?)
BIJECTIONS = {
    "actnorm": (lambda: ActNorm(DIM), False, False),
    "actnorm_sequence": (lambda: ActNorm(DIM), True, False),
    "linear_lu": (lambda: InvertibleLinear(DIM, lu=True), False, False),
    "linear_plain": (lambda: InvertibleLinear(DIM, lu=False), True, False),
    "linear_lu_reverse": (lambda: InvertibleLinear(DIM, init="reverse"), True, False),
    "affine": (lambda: AffineCoupling(DIM, COND, hidden=8), False, True),
    "affine_sequence": (lambda: AffineCoupling(DIM, COND, hidden=8), True, True),
    "additive": (lambda: AdditiveCoupling(DIM + 1, COND, hidden=8), False, True),
    "recurrent_lstm": (lambda: RecurrentCoupling(DIM, COND, 8), True, True),
    "recurrent_gru": (lambda: RecurrentCoupling(DIM + 1, 0, 8, cell="gru"), True, False),
    "recurrent_additive": (lambda: RecurrentCoupling(DIM, 0, 8, additive=True), True, False),
    "step": (lambda: FlowStep(DIM, COND, 8), False, True),
    "recurrent_step": (lambda: RecurrentFlowStep(DIM, COND, 8, num_layers=2), True, True),
    "flow": (lambda: glow(DIM, 3, 8, cond_dim=COND), False, True),
    "flow_additive_2d": (lambda: glow(2, 3, 8, coupling="additive"), False, False),
    "recurrent_flow_gru": (
        lambda: recurrent_glow(DIM, 2, 8, COND, cell="gru", coupling="additive"),
        True,
        True,
    ),
    "recurrent_flow_student": (lambda: recurrent_glow(DIM, 2, 8, COND, df=3), True, True),
}


def make_case(name, dtype=torch.float64, seed=0):
    factory, sequence, conditional = BIJECTIONS[name]
    module = randomise(factory().to(dtype), seed)
    dim = module.dim if hasattr(module, "dim") else module.coupling.dim
    generator = torch.Generator().manual_seed(seed + 1)
    lead = (BATCH, FRAMES) if sequence else (BATCH,)
    x = torch.randn(*lead, dim, generator=generator, dtype=dtype)
    cond = torch.randn(*lead, COND, generator=generator, dtype=dtype) if conditional else None
    return module, x, cond


@pytest.mark.parametrize("name", BIJECTIONS)
@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-10), (torch.float32, 1e-4)])
def test_inverse_undoes_forward(name, dtype, tol):
    module, x, cond = make_case(name, dtype)
    z, logdet = call(module, x, cond)
    x_back, logdet_inverse = call(module, z, cond, inverse=True)
    assert logdet.shape == (BATCH,)
    assert (z - x).abs().max() > 1e-2  # randomised: not the identity
    torch.testing.assert_close(x_back, x, atol=tol, rtol=tol)
    torch.testing.assert_close(logdet_inverse, -logdet, atol=tol, rtol=tol)


@pytest.mark.parametrize("name", BIJECTIONS)
@pytest.mark.parametrize("inverse", [False, True])
def test_logdet_matches_autograd_jacobian(name, inverse):
    """log|det J| of the whole sample (all its frames) equals the returned logdet."""
    module, x, cond = make_case(name)
    _, logdet = call(module, x, cond, inverse=inverse)
    for b in range(BATCH):
        cond_b = None if cond is None else cond[b : b + 1]

        def one_sample(sample, cond_b=cond_b):
            return call(module, sample[None], cond_b, inverse=inverse)[0][0]

        jac = jacobian(one_sample, x[b]).reshape(x[b].numel(), x[b].numel())
        torch.testing.assert_close(torch.linalg.slogdet(jac)[1], logdet[b], atol=1e-9, rtol=1e-9)


@pytest.mark.parametrize(
    "coupling",
    [
        AffineCoupling(DIM, COND, 8),
        AdditiveCoupling(DIM, COND, 8),
        RecurrentCoupling(DIM, COND, 8),
        RecurrentCoupling(DIM, COND, 8, cell="gru", additive=True),
    ],
    ids=["affine", "additive", "lstm", "gru_additive"],
)
def test_a_new_coupling_is_the_identity(coupling):
    x, cond = torch.randn(BATCH, FRAMES, DIM), torch.randn(BATCH, FRAMES, COND)
    y, logdet = coupling(x, cond)[:2]
    torch.testing.assert_close(y, x, atol=0, rtol=0)
    torch.testing.assert_close(logdet, torch.zeros(BATCH), atol=0, rtol=0)


# ---------------------------------------------------------------------------------- ActNorm


@pytest.mark.parametrize("shape", [(256, 3), (16, 20, 3)])
def test_actnorm_standardises_its_first_batch(shape):
    x = 5.0 + 3.0 * torch.randn(*shape, generator=torch.Generator().manual_seed(0))
    x[..., 1] *= 0.01
    y, _ = ActNorm(3)(x)
    frames = y.reshape(-1, 3)
    torch.testing.assert_close(frames.mean(0), torch.zeros(3), atol=1e-5, rtol=0)
    torch.testing.assert_close(frames.var(0, unbiased=False), torch.ones(3), atol=1e-3, rtol=0)


def test_actnorm_state_survives_save_and_load():
    generator = torch.Generator().manual_seed(0)
    trained = ActNorm(3)
    trained(2.0 + torch.randn(64, 3, generator=generator))
    buffer = io.BytesIO()
    torch.save(trained.state_dict(), buffer)
    buffer.seek(0)
    fresh = ActNorm(3)
    fresh.load_state_dict(torch.load(buffer, weights_only=True))
    assert bool(fresh.initialized)
    other_batch = -7.0 + 10.0 * torch.randn(64, 3, generator=generator)
    torch.testing.assert_close(fresh(other_batch)[0], trained(other_batch)[0])
    torch.testing.assert_close(fresh.loc, trained.loc)  # not re-initialised from other_batch


def test_actnorm_refuses_to_initialise_from_a_useless_batch():
    with pytest.raises(ValueError, match="at least 2 samples"):
        ActNorm(3)(torch.randn(1, 3))
    bad = torch.randn(8, 3)
    bad[2, 1] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        ActNorm(3)(bad)


# ------------------------------------------------------------------------------ conditioners


@pytest.mark.parametrize("scale", [0.01, 1.0, 100.0])
def test_mlp_conditioner_hidden_units_start_at_unit_scale_whatever_the_input_scale(scale):
    # With a zero-initialised last layer, the hidden features are what a coupling learns from
    # first: each must start at unit mean square before its ReLU.
    conditioner = MLPConditioner(3, 4, hidden=32, num_layers=2)
    inputs = scale * (1.0 + torch.randn(20, 6, 3, generator=torch.Generator().manual_seed(0)))
    pre_activations = []
    for layer in conditioner.hidden_layers:
        layer.register_forward_hook(lambda _, __, output: pre_activations.append(output))
    outputs = conditioner(inputs)
    assert outputs.shape == (20, 6, 4) and not outputs.any()  # zero last layer
    for hidden in pre_activations[-2:]:  # the forward pass after initialisation
        mean_square = hidden.reshape(-1, 32).square().mean(0)
        torch.testing.assert_close(mean_square, torch.ones(32), rtol=0, atol=1e-3)
    weights = conditioner.hidden_layers[0].weight.clone()
    conditioner(inputs + 5.0)  # a later batch does not rescale again
    assert torch.equal(conditioner.hidden_layers[0].weight, weights)


def test_mlp_conditioner_first_layer_units_switch_at_different_points_of_a_single_input():
    # A 2D flow's coupling conditions on one coordinate. Had the first batch centred every unit,
    # every first-layer ReLU would switch at its mean and the 64 units would span two features,
    # relu(x - m) and relu(m - x); scaled only, they switch where their random initialisation put
    # them and span many.
    torch.manual_seed(0)
    conditioner = MLPConditioner(1, 2, hidden=64, num_layers=2)
    conditioner(torch.randn(256, 1, generator=torch.Generator().manual_seed(1)))  # initialises
    line = torch.linspace(-3.0, 3.0, 601)[:, None]
    with torch.no_grad():
        first_layer_features = torch.relu(conditioner.hidden_layers[0](line))
    assert torch.linalg.matrix_rank(first_layer_features) >= 16


def test_zero_linear_starts_at_zero_and_scales_its_outputs_by_the_learned_gain():
    layer = ZeroLinear(5, 3)
    x = torch.randn(7, 5, generator=torch.Generator().manual_seed(0))
    assert not layer(x).any()  # the coupling starts as the identity
    assert not layer.log_gain.any()  # with a gain of exactly 1
    randomise(layer)
    plain = torch.nn.functional.linear(x, layer.weight, layer.bias)
    with torch.no_grad():
        layer.log_gain.copy_(torch.tensor([0.0, math.log(2.0), -math.log(4.0)]) / 3.0)
    torch.testing.assert_close(layer(x), plain * torch.tensor([1.0, 2.0, 0.25]))
    layer.reset_parameters()
    assert not any(parameter.any() for parameter in layer.parameters())


@pytest.mark.parametrize("cell", ["lstm", "gru"])
@pytest.mark.parametrize("num_layers", [1, 2])
def test_recurrent_conditioner_steps_frames_with_its_cells_as_the_sequence_pass(cell, num_layers):
    conditioner = randomise(RecurrentConditioner(5, 4, 8, cell, num_layers).double())
    inputs = torch.randn(3, 6, 5, dtype=torch.float64)
    outputs, final = conditioner(inputs)
    state, steps = None, []
    for t in range(6):
        output, state = conditioner(inputs[:, t : t + 1], state)
        steps.append(output)
    torch.testing.assert_close(torch.cat(steps, dim=1), outputs)
    torch.testing.assert_close(state, final)
    assert isinstance(conditioner.output, ZeroLinear)


def test_whole_flow_state_survives_save_and_load():
    x = toy_densities.two_moons(128, generator=0)
    trained = glow(2, 3, 16, seed=0)
    optimiser = torch.optim.Adam(trained.parameters(), lr=1e-2)
    for _ in range(3):
        optimiser.zero_grad()
        (-trained.log_prob(x).mean()).backward()
        optimiser.step()
    fresh = glow(2, 3, 16, seed=1)
    fresh.load_state_dict(trained.state_dict())
    new_batch = 3.0 * toy_densities.two_moons(64, generator=1)
    torch.testing.assert_close(fresh.log_prob(new_batch), trained.log_prob(new_batch))


# ------------------------------------------------------------------------ invertible linear


@pytest.mark.parametrize("lu", [True, False])
def test_linear_starts_as_a_seeded_rotation(lu):
    layer = InvertibleLinear(6, lu=lu, generator=torch.Generator().manual_seed(3))
    weight = layer.weight_matrix().detach()
    torch.testing.assert_close(weight @ weight.T, torch.eye(6), atol=1e-5, rtol=0)
    assert abs(torch.linalg.det(weight).item() - 1.0) < 1e-5
    again = InvertibleLinear(6, lu=lu, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(again.weight_matrix(), layer.weight_matrix())


@pytest.mark.parametrize("lu", [True, False])
def test_linear_reverse_init_reverses_the_features(lu):
    layer = InvertibleLinear(5, lu=lu, init="reverse")
    x = torch.randn(3, 5)
    y, logdet = layer(x)
    torch.testing.assert_close(y, x.flip(-1))
    torch.testing.assert_close(logdet, torch.zeros(3))


def test_glow_starts_with_swaps_in_two_dimensions_and_rotations_otherwise():
    swap = torch.tensor([[0.0, 1], [1, 0]])
    torch.testing.assert_close(glow(2, 2, 8).steps[1].linear.weight_matrix(), swap)
    rotation = glow(3, 2, 8).steps[0].linear.weight_matrix().detach()
    assert rotation.abs().lt(0.99).any()  # not a permutation
    assert glow(2, 2, 8, linear_init="rotation").steps[0].linear.init == "rotation"


@pytest.mark.parametrize("lu", [True, False])
def test_linear_inverse_follows_the_parameters_after_an_optimiser_step(lu):
    layer = InvertibleLinear(5, lu=lu).double()
    x = torch.randn(32, 5, dtype=torch.float64)
    optimiser = torch.optim.Adam(layer.parameters(), lr=0.1)
    weights = [layer.weight_matrix().detach().clone()]
    for _ in range(3):
        optimiser.zero_grad()
        y, logdet = layer(x)
        (((y - 1) ** 2).sum() - logdet.sum()).backward()
        optimiser.step()
        weights.append(layer.weight_matrix().detach().clone())
        torch.testing.assert_close(layer.inverse(layer(x)[0])[0], x)
    assert (weights[-1] - weights[0]).abs().max() > 0.1  # the steps did change W
    assert (layer.weight_matrix() @ layer.inverse_matrix() - torch.eye(5)).abs().max() < 1e-12


@pytest.mark.parametrize("shape", [(6,), (2, 3)])
def test_fixed_weights_computes_each_inverse_once_and_forgets_it_after(shape):
    flow = randomise(glow(DIM, 3, 8).double())
    z = torch.randn(*shape, DIM, dtype=torch.float64)
    expected, expected_logdet = flow.inverse(z)
    with flow.fixed_weights():
        assert all(step.fixed is not None for step in flow.steps)
        x, logdet = flow.inverse(z)
        torch.testing.assert_close(x, expected)
        torch.testing.assert_close(logdet, expected_logdet)
    assert all(step.fixed is None for step in flow.steps)


# ------------------------------------------------------------------------------- densities


@pytest.mark.parametrize("cond_dim", [0, 1])
def test_density_of_a_2d_flow_integrates_to_one(cond_dim):
    flow = randomise(glow(2, 3, 16, cond_dim=cond_dim, seed=2).double(), seed=5, scale=0.15)
    edge, n = 16.0, 641  # a box that holds all but ~1e-7 of this flow's mass; spacing 0.05
    axis = torch.linspace(-edge, edge, n, dtype=torch.float64)
    grid = torch.cartesian_prod(axis, axis)
    cond = torch.full((grid.shape[0], 1), 0.7, dtype=torch.float64) if cond_dim else None
    with torch.no_grad():
        density = flow.log_prob(grid, cond).exp()
    integral = density.sum() * (axis[1] - axis[0]) ** 2
    assert abs(integral.item() - 1.0) < 1e-3


@pytest.mark.parametrize("df", [0.7, 3.0, 30.0])
def test_student_t_log_prob_matches_scipy(df):
    z = torch.linspace(-30, 30, 61, dtype=torch.float64)[:, None]
    expected = scipy.stats.t(df).logpdf(z[:, 0].numpy())
    torch.testing.assert_close(StudentT(1, df).log_prob(z), torch.from_numpy(expected))
    z3 = torch.randn(20, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 4
    expected3 = scipy.stats.multivariate_t(loc=torch.zeros(3).numpy(), df=df).logpdf(z3.numpy())
    torch.testing.assert_close(StudentT(3, df).log_prob(z3), torch.from_numpy(expected3))


@pytest.mark.parametrize("df", [0.5, 4.0])
def test_student_t_samples_follow_the_distribution(df):
    generator = torch.Generator().manual_seed(0)
    z1 = StudentT(1, df).sample((20000,), generator=generator, dtype=torch.float64)
    assert scipy.stats.kstest(z1[:, 0].numpy(), scipy.stats.t(df).cdf).pvalue > 1e-3
    # multivariate: |z|^2 / D ~ F(D, df), which holds only if the D features share one chi-square
    z3 = StudentT(3, df).sample((20000,), generator=generator, dtype=torch.float64)
    statistic = (z3**2).sum(-1).numpy() / 3
    assert scipy.stats.kstest(statistic, scipy.stats.f(3, df).cdf).pvalue > 1e-3


def test_student_t_samples_come_from_the_generator_alone():
    torch.manual_seed(5)
    before = torch.get_rng_state()
    first = StudentT(3, 4.0).sample((50,), generator=torch.Generator().manual_seed(1))
    assert torch.equal(torch.get_rng_state(), before)  # the global stream is left alone
    torch.manual_seed(6)
    again = StudentT(3, 4.0).sample((50,), generator=torch.Generator().manual_seed(1))
    assert torch.equal(first, again)


def test_normal_base_log_prob():
    z = torch.randn(7, 4, dtype=torch.float64)
    expected = scipy.stats.norm.logpdf(z.numpy()).sum(-1)
    torch.testing.assert_close(StandardNormal(4).log_prob(z), torch.from_numpy(expected))


# ----------------------------------------------------------------------------- training use


@pytest.mark.parametrize("recurrent", [False, True])
def test_every_parameter_receives_a_gradient(recurrent):
    shape = (4, 6, DIM) if recurrent else (16, DIM)
    x, cond = torch.randn(*shape), torch.randn(*shape[:-1], COND)
    for randomised in (False, True):
        flow = recurrent_glow(DIM, 3, 8, COND) if recurrent else glow(DIM, 3, 8, COND)
        flow(x, cond)  # initialise ActNorm from data, as training does
        if randomised:
            randomise(flow)
        log_prob = flow.log_prob(x, cond)
        (-(log_prob[0] if recurrent else log_prob).mean()).backward()
        for name, parameter in flow.named_parameters():
            assert parameter.grad is not None, name
            assert torch.isfinite(parameter.grad).all(), name
            if randomised:  # a zero last layer blocks the gradient to earlier layers at first
                assert parameter.grad.abs().max() > 0, name


@pytest.mark.parametrize("cell", ["lstm", "gru"])
def test_sequence_mode_equals_frame_by_frame(cell):
    flow = randomise(recurrent_glow(DIM, 3, 8, COND, cell=cell, num_layers=2).double())
    x = torch.randn(2, 7, DIM, dtype=torch.float64)
    cond = torch.randn(2, 7, COND, dtype=torch.float64)
    z, logdet, final_state = flow(x, cond)

    state, frames, logdet_sum = None, [], torch.zeros(2, dtype=torch.float64)
    for t in range(7):
        z_t, logdet_t, state = flow(x[:, t : t + 1], cond[:, t : t + 1], state)
        frames.append(z_t)
        logdet_sum = logdet_sum + logdet_t
    torch.testing.assert_close(torch.cat(frames, dim=1), z)
    torch.testing.assert_close(logdet_sum, logdet)
    torch.testing.assert_close(state, final_state)

    # Sampling frame by frame (noise -> data) walks through the same states.
    state, frames = flow.initial_state(2, dtype=torch.float64), []
    with flow.fixed_weights():
        for t in range(7):
            x_t, _, state = flow.inverse(z[:, t : t + 1], cond[:, t : t + 1], state)
            frames.append(x_t)
    torch.testing.assert_close(torch.cat(frames, dim=1), x)
    torch.testing.assert_close(state, final_state)
    log_prob, _ = flow.log_prob(x, cond)
    torch.testing.assert_close(log_prob, flow.base.log_prob(z).sum(1) + logdet)


@pytest.mark.parametrize("recurrent, df", [(False, None), (True, 3.0)])
def test_temperature_zero_returns_the_mode_and_temperature_scales_the_noise(recurrent, df):
    build = recurrent_glow if recurrent else glow
    flow = randomise(build(DIM, 3, 8, COND, df=df))
    lead = (3, 4) if recurrent else (6,)
    cond = torch.randn(*lead, COND)

    def sample(**kwargs):
        out = flow.sample(cond=cond, **kwargs)
        return out[0] if recurrent else out

    mode = flow.inverse(torch.zeros(*lead, DIM), cond)[0]
    torch.testing.assert_close(sample(temperature=0.0), mode)
    torch.testing.assert_close(sample(temperature=0.0, generator=torch.Generator()), mode)
    z = flow.base.sample(lead, generator=torch.Generator().manual_seed(4))
    warm = sample(temperature=0.5, generator=torch.Generator().manual_seed(4))
    torch.testing.assert_close(warm, flow.inverse(0.5 * z, cond)[0])


@pytest.mark.parametrize("recurrent", [False, True])
def test_large_inputs_give_finite_outputs(recurrent):
    flow = recurrent_glow(DIM, 4, 16, COND, cell="gru") if recurrent else glow(DIM, 4, 16, COND)
    lead = (8, 5) if recurrent else (64,)
    flow(torch.randn(*lead, DIM), torch.randn(*lead, COND))  # initialise on ordinary data
    randomise(flow)
    x = 1e3 * torch.randn(*lead, DIM)
    cond = 1e3 * torch.randn(*lead, COND)
    z, logdet = flow(x, cond)[:2]
    x_back, _ = flow.inverse(z, cond)[:2]
    log_prob = flow.log_prob(x, cond)
    log_prob = log_prob[0] if recurrent else log_prob
    log_prob.sum().backward()
    for tensor in (z, logdet, x_back, log_prob, flow.inverse(x, cond)[0]):
        assert torch.isfinite(tensor).all()
    assert all(torch.isfinite(p.grad).all() for p in flow.parameters())


@pytest.mark.parametrize("build", [glow, recurrent_glow])
def test_flows_are_reproducible_and_leave_the_global_generator_alone(build):
    torch.manual_seed(123)
    before = torch.get_rng_state()
    first, second = build(6, 2, 8, seed=7), build(6, 2, 8, seed=7)
    assert torch.equal(torch.get_rng_state(), before)
    for (name, a), b in zip(first.state_dict().items(), second.state_dict().values(), strict=True):
        assert torch.equal(a, b), name
    other = build(6, 2, 8, seed=8)
    assert not torch.equal(other.steps[0].linear.lower, first.steps[0].linear.lower)


# ------------------------------------------------------------------------------- bad input


def test_bad_inputs_raise_clear_errors():
    flow = glow(DIM, 2, 8, cond_dim=COND)
    x, cond = torch.randn(8, DIM), torch.randn(8, COND)
    with pytest.raises(UninitialisedFlowError, match="not seen any data"):
        flow.sample(cond=cond)
    with pytest.raises(UninitialisedFlowError):
        flow.inverse(x, cond)
    with pytest.raises(ValueError, match=r"x must have shape \(B, D\) = \(B, 4\) or \(B, T, D\)"):
        flow.log_prob(torch.randn(8, DIM + 1), cond)
    with pytest.raises(ValueError, match=r"cond must have shape \(B, C\) = \(8, 3\)"):
        flow.log_prob(x, torch.randn(8, COND + 2))
    with pytest.raises(ValueError, match=r"cond must have shape \(B, T, C\) = \(8, 2, 3\)"):
        flow.log_prob(torch.randn(8, 2, DIM), cond)
    with pytest.raises(ValueError, match=r"conditional \(cond_dim=3\): pass cond"):
        flow.log_prob(x)
    with pytest.raises(ValueError, match="unconditional"):
        glow(DIM, 2, 8).log_prob(x, cond)
    bad = x.clone()
    bad[3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"non-finite.*first: \[3\]"):
        flow.log_prob(bad, cond)
    flow.log_prob(x, cond)  # initialises
    bad_cond = cond.clone()
    bad_cond[5, 0] = math.inf
    with pytest.raises(ValueError, match=r"cond contains 1 non-finite.*first: \[5\]"):
        flow.sample(cond=bad_cond)
    with pytest.raises(ValueError, match=r"z contains 1 non-finite"):
        flow.inverse(bad, cond)
    with pytest.raises(TypeError, match="x has dtype torch.float64"):
        flow.log_prob(x.double(), cond.double())
    with pytest.raises(TypeError, match="cond has dtype torch.float64"):
        flow.log_prob(x, cond.double())
    with pytest.raises(ValueError, match="temperature"):
        flow.sample(cond=cond, temperature=-1.0)
    with pytest.raises(TypeError, match="temperature"):
        flow.sample(cond=cond, temperature="warm")
    with pytest.raises(ValueError, match="sample shape"):
        flow.sample((4,), cond=cond)


def test_bad_sequence_inputs_raise_clear_errors():
    flow = recurrent_glow(DIM, 2, 8, COND)
    x, cond = torch.randn(2, 5, DIM), torch.randn(2, 5, COND)
    with pytest.raises(
        ValueError, match=r"x must have shape \(B, T, D\) = \(B, T, 4\), got \(2, 4\)"
    ):
        flow.log_prob(x[:, 0], cond[:, 0])
    with pytest.raises(ValueError, match="one entry per step"):
        flow(x, cond, state=flow.initial_state(2)[:1])
    with pytest.raises(ValueError, match=r"give cond \(B, T, C\)"):
        flow.sample()


def test_bad_construction_raises_clear_errors():
    with pytest.raises(ValueError, match="dim >= 2"):
        AffineCoupling(1)
    with pytest.raises(ValueError, match="unknown cell"):
        recurrent_glow(4, 2, 8, cell="transformer")
    with pytest.raises(ValueError, match="unknown init"):
        InvertibleLinear(4, init="identity")
    with pytest.raises(ValueError, match="unknown coupling"):
        glow(4, 2, 8, coupling="spline")
    with pytest.raises(ValueError, match="unknown coupling"):
        recurrent_glow(4, 2, 8, coupling="spline")
    with pytest.raises(ValueError, match="df"):
        glow(4, 2, 8, df=-1.0)
    with pytest.raises(ValueError, match="steps must be an integer >= 1"):
        glow(4, 0, 8)
    with pytest.raises(ValueError, match="cond_dim must be an integer >= 0"):
        glow(4, 2, 8, cond_dim=-1)
    with pytest.raises(ValueError, match="hidden must be an integer >= 1"):
        recurrent_glow(4, 2, 0)


def test_sample_counts_must_be_positive_integers_and_states_fit_their_batch():
    flow = glow(4, 2, 8)
    flow.log_prob(torch.randn(16, 4))  # ActNorm sees data
    assert flow.sample(np.int64(5)).shape == (5, 4)  # a NumPy integer is a count too
    for bad in (-1, 0, 5.0, (2, -3)):
        with pytest.raises(ValueError, match="positive count"):
            flow.sample(bad)
    recurrent = recurrent_glow(4, 2, 8, cond_dim=3)
    x, cond = torch.randn(2, 5, 4), torch.randn(2, 5, 3)
    _, _, state = recurrent(x, cond)
    with pytest.raises(ValueError, match="the state is of 2 sequences but x of 3"):
        recurrent(torch.randn(3, 5, 4), torch.randn(3, 5, 3), state)
    with pytest.raises(ValueError, match="the state is of 3 sequences but z of 2"):
        recurrent.inverse(x, cond, recurrent.initial_state(3))


# --------------------------------------------------------------------------- toy densities


@pytest.mark.parametrize("name", toy_densities.TOY_DENSITIES)
def test_toy_samplers_are_seeded(name):
    sampler = toy_densities.TOY_DENSITIES[name]
    first = sampler(100, generator=3)
    assert first.shape == (100, 2) and first.dtype == torch.float32
    torch.testing.assert_close(sampler(100, generator=torch.Generator().manual_seed(3)), first)
    assert not torch.equal(sampler(100, generator=4), first)


@pytest.mark.parametrize(
    "log_prob", [toy_densities.eight_gaussians_log_prob, toy_densities.checkerboard_log_prob]
)
def test_toy_log_densities_integrate_to_one(log_prob):
    axis = torch.linspace(-4, 4, 801, dtype=torch.float64)[:-1] + 0.005  # cell centres
    grid = torch.cartesian_prod(axis, axis)
    assert abs(log_prob(grid).exp().sum().item() * 0.01**2 - 1.0) < 1e-3


def test_toy_samples_lie_where_their_density_is():
    assert torch.isfinite(
        toy_densities.checkerboard_log_prob(toy_densities.checkerboard(5000))
    ).all()
    moons = toy_densities.two_moons(5000, noise=0.0, generator=0)
    upper = (moons - torch.tensor([-1.0, -0.5])).norm(dim=1)
    lower = (moons - torch.tensor([1.0, 0.5])).norm(dim=1)
    torch.testing.assert_close(
        torch.minimum((upper - 2).abs(), (lower - 2).abs()).max(), torch.tensor(0.0)
    )
    points, cond = toy_densities.rotated_crescent(2000, angle=1.0, generator=0)
    direction = points.mean(0) / points.mean(0).norm()
    torch.testing.assert_close(
        direction, torch.tensor([math.cos(1.0), math.sin(1.0)]), atol=0.02, rtol=0
    )
    torch.testing.assert_close(cond, torch.tensor([[math.cos(1.0), math.sin(1.0)]]).expand(2000, 2))
