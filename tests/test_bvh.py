"""gesturelib.bvh: BVH files that a BVH library (bvhio) reads back to our keypoints."""

from pathlib import Path

import numpy as np
import pytest

from gesturelib.bvh import JOINTS, write_bvh
from gesturelib.skeleton import KEYPOINTS, forward_kinematics


def read_positions(path, frames) -> np.ndarray:
    """World positions ``(len(frames), 9, 3)`` of the keypoint joints, as bvhio computes them."""
    import bvhio

    root = bvhio.readAsHierarchy(str(path))
    positions = []
    for frame in frames:
        root.loadPose(frame)
        joints = {joint.Name: joint for joint, _, _ in root.layout()}
        positions.append([np.array(joints[k].PositionWorld) for k in KEYPOINTS])
    return np.array(positions)


def test_a_bvh_library_reads_back_the_keypoints_of_generated_motion(tmp_path):
    from data_synth import generate_conversation

    rotations = generate_conversation(3.0, seed=3).rotations
    path = write_bvh(tmp_path / "agent.bvh", rotations)
    frames = range(0, len(rotations), 5)
    np.testing.assert_allclose(
        read_positions(path, frames), forward_kinematics(rotations)[list(frames)], atol=1e-3
    )
    text = path.read_text()
    assert f"Frames: {len(rotations)}" in text and "Frame Time: 0.040000" in text


def test_each_limb_from_the_sternum_turns_alone(tmp_path):
    """Raising one arm moves neither the other arm nor the head (their own zero-offset joints)."""
    rest = np.tile(np.array([1.0, 0, 0, 0, 1, 0]), (2, 9, 1))
    raised = rest.copy()
    quarter_turn = np.array([0.0, 1, 0, -1, 0, 0])  # the left shoulder limb turned about z
    raised[1, KEYPOINTS.index("left_shoulder")] = quarter_turn
    positions = read_positions(write_bvh(tmp_path / "raised.bvh", raised), [0, 1])
    moved = np.linalg.norm(positions[1] - positions[0], axis=-1) > 1e-3
    assert {KEYPOINTS[j] for j in np.flatnonzero(moved)} == {
        "left_shoulder",
        "left_elbow",
        "left_wrist",
    }
    np.testing.assert_allclose(positions, forward_kinematics(raised), atol=1e-3)
    assert {name for name, _, _ in JOINTS} >= set(KEYPOINTS)  # every keypoint is a joint


def test_bad_motion_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"shape \(T, 9, 6\)"):
        write_bvh(tmp_path / "x.bvh", np.zeros((5, 9, 3)))
    with pytest.raises(ValueError, match="fps"):
        write_bvh(tmp_path / "x.bvh", np.tile(np.array([1.0, 0, 0, 0, 1, 0]), (2, 9, 1)), fps=0)


def test_generate_turns_a_real_recording_into_a_bvh_that_a_bvh_library_reads(tmp_path):
    """End to end: a committed telephone-band recording (8 kHz FLAC), the shipped MoGlow, the
    command line, and bvhio reading the file back to the positions saved beside it."""
    from gesturelib.cli import main
    from gesturelib.features import load_audio, num_frames
    from gesturelib.pretrained import pretrained_folder

    recording = Path(__file__).parent / "data" / "voices" / "scottish_phone.flac"
    out = tmp_path / "out"
    command = ["generate", str(pretrained_folder("moglow")), "--audio", str(recording)]
    assert main([*command, "--out", str(out), "--no-video"]) == 0
    positions = np.load(out / "motion.npz")["positions"]
    audio, rate = load_audio(recording)
    assert len(positions) == num_frames(len(audio), rate)
    frames = range(0, len(positions), 25)
    np.testing.assert_allclose(
        read_positions(out / "agent.bvh", frames), positions[list(frames)], atol=1e-3
    )
