import numpy as np
import pytest
import torch

from gesturelib.rotations import (
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
