import numpy as np
import pytest
import torch

from gesturelib.rotations import (
    RotationError,
    axis_angle_to_matrix,
    geodesic_angle,
    matrix_to_rot6d,
    normalize_rot6d,
    rot6d_to_matrix,
    shortest_arc,
)


def random_rotations(n, seed=0):
    """Uniformly random rotations ``(n, 3, 3)`` from QR of Gaussian matrices."""
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=-2, axis2=-1))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1  # make them proper (det +1)
    return q


def assert_valid_rotation(matrix, atol):
    eye = np.broadcast_to(np.eye(3), matrix.shape)
    np.testing.assert_allclose(matrix @ np.swapaxes(matrix, -1, -2), eye, atol=atol)
    np.testing.assert_allclose(np.linalg.det(matrix), 1.0, atol=atol)


def test_matrix_to_6d_and_back_is_exact_for_rotations():
    matrices = random_rotations(1000)
    np.testing.assert_allclose(rot6d_to_matrix(matrix_to_rot6d(matrices)), matrices, atol=1e-12)


def test_arbitrary_6d_gives_a_valid_rotation():
    rot6d = np.random.default_rng(1).normal(scale=3.0, size=(500, 6))
    assert_valid_rotation(rot6d_to_matrix(rot6d), atol=1e-12)


def test_gram_schmidt_keeps_the_first_row_direction():
    rot6d = np.random.default_rng(2).normal(size=(100, 6))
    first_row = rot6d_to_matrix(rot6d)[:, 0]
    expected = rot6d[:, :3] / np.linalg.norm(rot6d[:, :3], axis=-1, keepdims=True)
    np.testing.assert_allclose(first_row, expected, atol=1e-12)


def test_normalize_is_idempotent():
    once = normalize_rot6d(np.random.default_rng(3).normal(size=(50, 6)))
    np.testing.assert_allclose(normalize_rot6d(once), once, atol=1e-12)


def test_batch_shapes_are_kept_and_numpy_torch_agree():
    rot6d = np.random.default_rng(4).normal(size=(2, 5, 9, 6)).astype(np.float32)
    from_numpy = rot6d_to_matrix(rot6d)
    from_torch = rot6d_to_matrix(torch.from_numpy(rot6d))
    assert isinstance(from_numpy, np.ndarray) and from_numpy.shape == (2, 5, 9, 3, 3)
    assert from_numpy.dtype == np.float32
    assert isinstance(from_torch, torch.Tensor) and from_torch.dtype == torch.float32
    np.testing.assert_allclose(from_torch.numpy(), from_numpy, atol=1e-6)


def test_torch_version_is_differentiable():
    rot6d = torch.randn(10, 6, dtype=torch.float64, requires_grad=True)
    rot6d_to_matrix(rot6d).sum().backward()
    assert torch.isfinite(rot6d.grad).all() and rot6d.grad.abs().sum() > 0


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.3, np.pi / 2, 3.0, np.pi - 1e-9, np.pi])
def test_shortest_arc_maps_source_to_target(angle):
    rng = np.random.default_rng(5)
    source = rng.normal(size=(20, 3))
    # Build targets at a known angle from each source, in a random plane through it.
    rotation = axis_angle_to_matrix(np.cross(source, rng.normal(size=(20, 3))), np.full(20, angle))
    target = 2.5 * (rotation @ source[..., None])[..., 0]
    arc = shortest_arc(source, target)
    assert_valid_rotation(arc, atol=1e-9)
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
    np.testing.assert_allclose((arc @ unit(source)[..., None])[..., 0], unit(target), atol=1e-7)
    # Shortest: the rotation angle equals the angle between the two directions.
    np.testing.assert_allclose(geodesic_angle(np.eye(3), arc), angle, atol=1e-6)


def test_shortest_arc_has_no_twist_about_the_limb():
    # The axis of the shortest arc is perpendicular to both directions.
    rng = np.random.default_rng(6)
    source, target = rng.normal(size=(2, 50, 3))
    arc = shortest_arc(source, target)
    axis = np.stack(
        [arc[:, 2, 1] - arc[:, 1, 2], arc[:, 0, 2] - arc[:, 2, 0], arc[:, 1, 0] - arc[:, 0, 1]], -1
    )
    np.testing.assert_allclose(np.einsum("nd,nd->n", axis, source), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("nd,nd->n", axis, target), 0.0, atol=1e-9)


def test_axis_angle_quarter_turn_about_y():
    rotation = axis_angle_to_matrix(np.array([0.0, 1.0, 0.0]), np.pi / 2)
    np.testing.assert_allclose(rotation @ np.array([0.0, 0.0, 1.0]), [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    ("function", "bad_shape", "expected"),
    [
        (rot6d_to_matrix, (4, 5), r"\(\.\.\., 6\), got \(4, 5\)"),
        (matrix_to_rot6d, (4, 3, 2), r"\(\.\.\., 3, 3\), got \(4, 3, 2\)"),
        (normalize_rot6d, (7,), r"\(\.\.\., 6\), got \(7,\)"),
    ],
)
def test_wrong_shapes_are_rejected_with_the_expected_shape(function, bad_shape, expected):
    with pytest.raises(ValueError, match=expected):
        function(np.zeros(bad_shape))


# --------------------------------------------------------------------------- input kinds


def test_integers_and_lists_give_floats_of_the_kind_given():
    identity6d = [1, 0, 0, 0, 1, 0]
    for given in (np.array(identity6d), identity6d):
        matrix = rot6d_to_matrix(given)
        assert isinstance(matrix, np.ndarray) and matrix.dtype == np.float64
        np.testing.assert_array_equal(matrix, np.eye(3))
    from_tensor = rot6d_to_matrix(torch.tensor(identity6d))
    assert isinstance(from_tensor, torch.Tensor) and from_tensor.dtype == torch.get_default_dtype()
    assert matrix_to_rot6d(np.eye(3, dtype=int)).dtype == np.float64
    np.testing.assert_allclose(
        axis_angle_to_matrix([0, 1, 0], 1), axis_angle_to_matrix(np.array([0.0, 1.0, 0.0]), 1.0)
    )


def test_mixed_inputs_are_promoted_and_a_tensor_among_them_gives_a_tensor():
    arc = shortest_arc(np.ones(3, np.float32), np.array([1.0, 0.0, 0.0]))
    assert isinstance(arc, np.ndarray) and arc.dtype == np.float64
    target = torch.tensor([1.0, 0.0, 0.0], requires_grad=True)
    arc = shortest_arc(np.ones(3), target)  # numpy float64 and a float32 tensor
    assert isinstance(arc, torch.Tensor) and arc.dtype == torch.float64
    arc.sum().backward()
    assert target.grad is not None
    assert geodesic_angle(np.eye(3, dtype=np.float32), np.eye(3)).dtype == np.float64


@pytest.mark.parametrize(
    "bad", [np.array(list("abcdef")), np.zeros(6, dtype=complex), [[1.0, 2.0], [3.0]]]
)
def test_non_real_inputs_raise_a_type_error_naming_the_argument(bad):
    with pytest.raises(TypeError, match="rot6d must"):
        rot6d_to_matrix(bad)


# --------------------------------------------------------------------------- what is no rotation


@pytest.mark.parametrize(
    ("matrix", "message"),
    [
        (2 * np.eye(3), "differs from the identity by 3 and its determinant is 8"),
        (np.diag([-1.0, 1.0, 1.0]), "determinant is -1"),
        (np.arange(9.0).reshape(3, 3), "not a rotation"),
        (np.full((3, 3), np.nan), "holds NaN"),
    ],
)
def test_matrix_to_rot6d_refuses_matrices_that_are_not_rotations(matrix, message):
    batch = np.stack([np.eye(3), np.eye(3), matrix])  # the third is named
    with pytest.raises(RotationError, match=rf"matrix\[2\] .*{message}") as caught:
        matrix_to_rot6d(batch)
    assert caught.value.index == (2,)
    with pytest.raises(RotationError, match="not a rotation|NaN"):
        geodesic_angle(np.eye(3), matrix)


def test_matrix_to_rot6d_accepts_float32_round_off():
    rotations = random_rotations(50).astype(np.float32)
    noisy = rotations + np.float32(1e-5) * np.random.default_rng(7).standard_normal((50, 3, 3))
    np.testing.assert_allclose(matrix_to_rot6d(noisy), noisy[:, :2].reshape(50, 6))


@pytest.mark.parametrize(
    ("rot6d", "dtype"),
    [
        ([0.0, 0, 0, 0, 0, 0], np.float64),
        ([1.0, 2, 3, 2, 4, 6], np.float64),
        ([1.0, 2, 3, 2, 4, 6], np.float32),
        ([0.3, -0.2, 0.7, 0.09, -0.06, 0.21], np.float32),  # parallel up to float32 round-off
        ([0.0, 0, 0, 1, 0, 0], np.float64),
        ([1.0, 0, 0, 0, 0, 0], np.float64),
    ],
)
def test_zero_or_parallel_6d_vectors_are_refused(rot6d, dtype):
    batch = np.array([[1.0, 0, 0, 0, 1, 0], rot6d], dtype=dtype)
    for function in (rot6d_to_matrix, normalize_rot6d):
        with pytest.raises(RotationError, match=r"rot6d\[1\] = .* zero or parallel"):
            function(batch)


def test_nan_6d_vectors_are_refused_and_tiny_ones_are_exact():
    with pytest.raises(RotationError, match="rot6d holds NaN"):
        rot6d_to_matrix(np.full(6, np.nan))
    # Not parallel, only small: Gram-Schmidt still has two directions (it used to return
    # rows of length 1e-12 here).
    np.testing.assert_allclose(rot6d_to_matrix(1e-20 * np.array([1.0, 0, 0, 0, 1, 0])), np.eye(3))


def test_zero_directions_are_refused():
    with pytest.raises(RotationError, match=r"target\[1\] is a zero vector"):
        shortest_arc(np.ones(3), np.array([[1.0, 0, 0], [0, 0, 0]]))
    with pytest.raises(RotationError, match="axis is a zero vector"):
        axis_angle_to_matrix(np.zeros(3), 0.5)


def test_axis_angle_refuses_angles_that_are_no_angle_and_shapes_that_do_not_fit():
    with pytest.raises(RotationError, match="NaN or infinite"):
        axis_angle_to_matrix([0.0, 0.0, 1.0], float("nan"))
    with pytest.raises(
        ValueError, match=r"angle \(3,\) must broadcast against axis\[..., 0\] \(4,\)"
    ):
        axis_angle_to_matrix(np.ones((4, 3)), np.ones(3))
