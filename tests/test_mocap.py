"""gesturelib.mocap: BVH takes of rigs unlike ours, made here, imported onto our skeleton."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from gesturelib.cli import main
from gesturelib.features import save_audio
from gesturelib.mocap.bvh_reader import BvhError, read_bvh
from gesturelib.mocap.dataset import MocapError, import_bvh, load_recordings
from gesturelib.mocap.retarget import retarget
from gesturelib.mocap.rigs import RigError, joint_map
from gesturelib.rotations import rot6d_to_matrix
from gesturelib.skeleton import JOINT_INDEX

# A Mixamo-like rig in metres: other names, a longer spine, clavicles, fingers and legs, and
# each joint's own Euler order. (name, parent, rest offset in our axes, channel order, the limb
# whose rotation the joint carries: the limb that starts at it).
RIG = [
    ("Hips", None, (0, 0, 0), "ZXY", "sternum"),
    ("Spine", "Hips", (0, 0.22, 0), "XYZ", "sternum"),
    ("Spine1", "Spine", (0, 0.30, 0), "ZXY", "sternum"),
    ("Neck", "Spine1", (0, 0, 0), "XYZ", "head"),
    ("Head", "Neck", (0, 0.13, 0), "ZXY", "nose"),
    ("HeadTop_End", "Head", (0, 0.16, 0), "YXZ", "nose"),
    *(
        joint
        for side, sign in (("Left", 1), ("Right", -1))
        for joint in (
            (f"{side}Shoulder", "Spine1", (0, 0, 0), "ZXY", f"{side.lower()}_shoulder"),
            (f"{side}Arm", f"{side}Shoulder", (sign * 0.19, 0, 0), "XYZ", f"{side.lower()}_elbow"),
            (f"{side}ForeArm", f"{side}Arm", (sign * 0.31, 0, 0), "ZXY", f"{side.lower()}_wrist"),
            (f"{side}Hand", f"{side}ForeArm", (sign * 0.26, 0, 0), "XYZ", f"{side.lower()}_wrist"),
            (
                f"{side}HandIndex1",
                f"{side}Hand",
                (sign * 0.09, 0, 0),
                "ZYX",
                f"{side.lower()}_wrist",
            ),
            (f"{side}UpLeg", "Hips", (sign * 0.1, -0.06, 0), "ZXY", "sternum"),
            (f"{side}Leg", f"{side}UpLeg", (0, -0.45, 0), "XYZ", "sternum"),
        )
    ),
]
#: The rig's rest pose faces another way in its file: our axes turned by this.
REST_TURN = Rotation.from_euler("YX", [-120, 10], degrees=True).as_matrix()


def write_rig_bvh(
    path,
    rotations,
    fps,
    prefix="",
    yaw_deg=(70.0, 90.0),
    shift=(0.3, -0.1),
    positions=False,
    names=None,
):
    """Our limb rotations ``(T, 9, 6)`` at 25 fps as a take of :data:`RIG` at ``fps``: in metres,
    the rest pose turned by :data:`REST_TURN`, the body walking ``shift`` metres and turning from
    ``yaw_deg[0]`` to ``yaw_deg[1]`` degrees over the take; with ``positions``, every joint has
    position channels (holding its offset), as some exporters write; ``names`` renames joints."""
    limbs = rot6d_to_matrix(np.asarray(rotations, dtype=np.float64))  # (T, 9, 3, 3)
    n = int(round(len(limbs) * fps / 25))
    # Frames stand for the middle of their intervals: the file's (i + 0.5) / fps, ours (k + 0.5) / 25.
    times = np.clip((np.arange(n) + 0.5) / fps - 0.5 / 25, 0, (len(limbs) - 1) / 25)
    keys = np.arange(len(limbs)) / 25
    limb_at = {
        name: Slerp(keys, Rotation.from_matrix(limbs[:, index]))(times).as_matrix()
        for name, index in JOINT_INDEX.items()
    }
    share = np.arange(n) / max(n - 1, 1)
    up = REST_TURN @ np.array([0.0, 1.0, 0.0])
    yaw = Rotation.from_rotvec(np.radians(np.interp(share, [0, 1], yaw_deg))[:, None] * up)
    turn = yaw.as_matrix() @ REST_TURN  # (n, 3, 3): our axes into the file's, turned
    world = {name: turn @ limb_at[limb] @ REST_TURN.T for name, _, _, _, limb in RIG}
    root = np.outer(share, [shift[0], 0.0, shift[1]]) + [0.0, 0.95, 0.0]
    lines, written = ["HIERARCHY"], []

    def describe(index, depth):
        name, parent, offset, order, _ = RIG[index]
        written.append(name)
        pad = "\t" * depth
        channels = " ".join(f"{axis}rotation" for axis in order)
        if parent is None or positions:
            channels = f"6 Xposition Yposition Zposition {channels}"
        else:
            channels = f"3 {channels}"
        offset = " ".join(f"{v:.6f}" for v in REST_TURN @ np.array(offset, dtype=float))
        lines.extend(
            [
                f"{pad}{'ROOT' if parent is None else 'JOINT'} {prefix}{(names or {}).get(name, name)}",
                f"{pad}{{",
                f"{pad}\tOFFSET {offset}",
                f"{pad}\tCHANNELS {channels}",
            ]
        )
        children = [i for i, joint in enumerate(RIG) if joint[1] == name]
        for child in children:
            describe(child, depth + 1)
        if not children:
            lines.extend(
                [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET 0 0.02 0", f"{pad}\t}}"]
            )
        lines.append(f"{pad}}}")

    describe(0, 0)
    columns = [root]  # in the file's order: the hierarchy's, depth first
    for name in written:
        _, parent, offset, order, _ = RIG[[joint[0] for joint in RIG].index(name)]
        local = world[name] if parent is None else np.swapaxes(world[parent], 1, 2) @ world[name]
        if parent is not None and positions:
            columns.append(np.tile(REST_TURN @ np.array(offset, dtype=float), (n, 1)))
        columns.append(Rotation.from_matrix(local).as_euler(order, degrees=True))
    motion = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {n}", f"Frame Time: {1 / fps:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in frame) for frame in motion]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def conversation():
    from data_synth import generate_conversation

    return generate_conversation(8.0, seed=5)


def test_our_reader_agrees_with_a_bvh_library_on_a_foreign_rig(tmp_path, conversation):
    import bvhio

    path = write_rig_bvh(tmp_path / "take.bvh", conversation.rotations, fps=60, prefix="mixamorig:")
    take = read_bvh(path)
    names = ["mixamorig:LeftHandIndex1", "mixamorig:Head", "mixamorig:RightLeg", "mixamorig:Hips"]
    positions, _ = take.world(names)
    root = bvhio.readAsHierarchy(str(path))
    for frame in (0, 77, take.num_frames - 1):
        root.loadPose(frame)
        joints = {joint.Name: joint for joint, _, _ in root.layout()}
        expected = [np.array(joints[name].PositionWorld) for name in names]
        np.testing.assert_allclose(positions[frame], expected, atol=1e-4)
    assert take.fps == pytest.approx(60) and take.channels[0][:3] == (
        "Xposition",
        "Yposition",
        "Zposition",
    )


#: The rig above as Talking With Hands (GENEA 2022, 2023) names its joints.
GENEA_NAMES = {
    "Hips": "b_root",
    "Spine": "b_spine0",
    "Spine1": "b_spine3",
    "Neck": "b_neck0",
    "Head": "b_head",
    "HeadTop_End": "b_head_null",
    **{
        f"{side}{part}": f"b_{side[0].lower()}_{theirs}"
        for side in ("Left", "Right")
        for part, theirs in (
            ("Shoulder", "shoulder"),
            ("Arm", "arm"),
            ("ForeArm", "forearm"),
            ("Hand", "wrist"),
            ("HandIndex1", "index1"),
            ("UpLeg", "upleg"),
            ("Leg", "leg"),
        )
    },
}


@pytest.mark.parametrize(
    "fps, prefix, names, rig",
    [
        (60, "mixamorig:", None, "mixamo"),
        (120, "", None, "mixamo"),
        (120, "", GENEA_NAMES, "genea"),
    ],
)
def test_a_foreign_rig_in_metres_turning_and_walking_lands_on_our_skeleton(
    tmp_path, conversation, fps, prefix, names, rig
):
    """Names, units, channel orders, frame rate, facing and the walk all differ from ours; the
    import gives back the generator's motion: every keypoint, the nod's nose included."""
    path = write_rig_bvh(
        tmp_path / "take.bvh", conversation.rotations, fps=fps, prefix=prefix, names=names
    )
    moved = retarget(read_bvh(path), conversation.num_frames)
    assert (moved.rig, moved.units, moved.source_fps) == (rig, "m", pytest.approx(fps))
    error = np.linalg.norm(moved.positions - conversation.positions, axis=-1)  # cm
    inner = error[25:-25]  # a second from each end: the facing's average reaches past them
    assert np.median(inner) < 0.3 and inner.max() < 2.0, (np.median(inner), inner.max())
    assert error.max() < 5.0
    nose = JOINT_INDEX["nose"]

    def pitch(p):
        return np.degrees(
            np.arctan2(p[:, nose, 1] - p[:, nose - 1, 1], p[:, nose, 2] - p[:, nose - 1, 2])
        )

    assert np.abs(pitch(moved.positions) - pitch(conversation.positions))[25:-25].max() < 2.0


def test_position_channels_on_every_joint_and_a_byte_order_mark_are_read(tmp_path, conversation):
    path = write_rig_bvh(tmp_path / "take.bvh", conversation.rotations, fps=60, positions=True)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())  # a UTF-8 byte order mark
    moved = retarget(read_bvh(path), conversation.num_frames)
    error = np.linalg.norm(moved.positions - conversation.positions, axis=-1)[25:-25]
    assert moved.units == "m" and np.median(error) < 0.3


def test_our_own_export_reads_back_exactly(tmp_path, conversation):
    from gesturelib.bvh import write_bvh

    path = write_bvh(tmp_path / "agent.bvh", conversation.rotations)
    moved = retarget(read_bvh(path), conversation.num_frames)
    assert (moved.rig, moved.units) == ("gesturelib", "cm")
    np.testing.assert_allclose(moved.positions, conversation.positions, atol=0.01)


def test_rigs_are_told_apart_and_missing_joints_named(conversation, tmp_path):
    names = [f"mixamorig:{name}" for name, *_ in RIG]
    rig, found = joint_map(names)
    assert rig == "mixamo" and found["left_wrist"] == "mixamorig:LeftHand"
    assert joint_map(names, rig="beat")[0] == "mixamo"
    genea = [
        "b_root",
        "b_spine3",
        "b_neck0",
        "b_head",
        *(f"b_{s}_{j}" for s in "lr" for j in ("shoulder", "arm", "forearm", "wrist")),
    ]
    assert joint_map(genea)[0] == "genea"
    with pytest.raises(RigError, match="mixamo lacks LeftForeArm"):
        joint_map([n for n in names if not n.endswith("LeftForeArm")])
    with pytest.raises(RigError, match="unknown rig 'kinect'"):
        joint_map(names, rig="kinect")


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda t: t.replace("HIERARCHY", "HIERARCHIE"), "starts with HIERARCHY"),
        (lambda t: t[: len(t) // 2], "a frame holds .* values, the joints have 63 channels"),
        (
            lambda t: "\n".join(t.splitlines()[:-5]),
            "the header promises 60 frames, the file holds 55",
        ),
        (lambda t: t.replace("Frame Time: ", "Frame Time: -"), "positive time"),
        (lambda t: t.replace("CHANNELS 3 Xrotation", "CHANNELS 3 Wrotation", 1), "channels"),
        (lambda t: t.rsplit("\n", 3)[0] + "\n1 2 nan\n", "not a number|NaN|values"),
        (lambda t: t.replace("MOTION", "MOTON"), "keyword|MOTION"),
    ],
)
def test_a_broken_bvh_file_is_named_with_its_line(tmp_path, conversation, damage, message):
    path = write_rig_bvh(tmp_path / "take.bvh", conversation.rotations[:50], fps=30)
    path.write_text(damage(path.read_text()))
    with pytest.raises(BvhError, match=message) as refused:
        read_bvh(path)
    assert str(path) in str(refused.value)


def make_takes(folder, count=3, seconds=8.0, partner=False):
    """``count`` takes of generated conversations: NAME.bvh (the rig above, 60 fps) and NAME.wav."""
    from data_synth import generate_conversation

    folder.mkdir(exist_ok=True)
    conversations = []
    for index in range(count):
        conversation = generate_conversation(seconds, seed=20 + index)
        name = f"take{index}"
        write_rig_bvh(folder / f"{name}.bvh", conversation.rotations, fps=60)
        save_audio(folder / f"{name}.wav", conversation.audio, conversation.sample_rate)
        if partner:
            other = generate_conversation(seconds, seed=40 + index).audio
            save_audio(folder / f"{name}_partner.wav", other, conversation.sample_rate)
        conversations.append(conversation)
    return conversations


def test_a_folder_of_takes_imports_trains_moglow_and_evaluates(tmp_path):
    """The course's loop on data the generator did not make: import, train, info, evaluate."""
    source, data = tmp_path / "takes", tmp_path / "data"
    conversations = make_takes(source, partner=True)
    assert main(["import-bvh", str(source), "--out", str(data)]) == 0
    manifest = json.loads((data / "manifest.json").read_text())
    assert manifest["rig"] == ["mixamo"] and manifest["units"] == ["m"]
    splits = load_recordings(data)
    assert sorted(len(v) for v in splits.values()) == [1, 1, 1]
    by_name = {r.name: r for takes in splits.values() for r in takes}
    for index, conversation in enumerate(conversations):
        take = by_name[f"take{index}"]
        assert take.num_frames == conversation.num_frames and take.events is None
        assert np.median(np.linalg.norm(take.positions - conversation.positions, axis=-1)) < 1.0

    run = tmp_path / "run"
    assert main(["train", "moglow", "--out", str(run), "--quick", "--data", str(data)]) == 0
    assert main(["info", str(run)]) == 0
    out = tmp_path / "evaluation"
    command = ["evaluate", str(run), "--out", str(out), "--quick", "--samples", "1"]
    assert main([*command, "--cache", str(tmp_path / "cache")]) == 0
    rows = (out / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    table = {row.split(",")[0]: dict(zip(header, row.split(","), strict=True)) for row in rows[1:]}
    assert "floor" not in table and {"ground_truth", "mismatched", "run"} <= set(table)
    assert table["run"]["hellinger"] and table["run"]["lead_error"] == ""


def test_an_import_refuses_what_it_cannot_use_and_overwrites_only_when_asked(tmp_path, capsys):
    source, data = tmp_path / "takes", tmp_path / "data"
    make_takes(source, count=3, seconds=6.0)
    (source / "take2.wav").rename(tmp_path / "aside.wav")
    assert main(["import-bvh", str(source), "--out", str(data)]) == 2
    assert "take2.bvh has no recording beside it" in capsys.readouterr().err
    assert not data.exists()  # nothing written

    long = np.zeros(int(16000 * 7.5), dtype=np.float32)
    long[:96000] = save_and_load(tmp_path / "aside.wav")
    save_audio(source / "take2.wav", long, 16000)
    with pytest.raises(MocapError, match=r"take2.bvh lasts 6.00 s and .*take2.wav 7.50 s"):
        import_bvh(source, data, progress=False)

    (tmp_path / "aside.wav").replace(source / "take2.wav")
    import_bvh(source, data, progress=False)
    mine = data / "notes.txt"
    mine.write_text("my notes")
    with pytest.raises(FileExistsError, match="--overwrite"):
        import_bvh(source, data, progress=False)
    import_bvh(source, data, overwrite=True, progress=False)
    assert mine.read_text() == "my notes"
    assert sorted(p.name for p in data.iterdir()) == [
        "manifest.json",
        "notes.txt",
        "test",
        "train",
        "val",
    ]
    (data / "train" / "take9.npz").write_bytes(b"mine")  # a file of the user's beside the takes
    generated = tmp_path / "generated"
    from data_synth import write_dataset

    write_dataset(generated, minutes=0.3, seed=0, conversation_s=6.0, progress=False)
    with pytest.raises(FileExistsError, match="another dataset"):
        import_bvh(source, generated, overwrite=True, progress=False)
    assert (generated / "manifest.json").exists()
    (source / "take1.bvh").unlink()
    with pytest.raises(MocapError, match="at least 3"):
        import_bvh(source, tmp_path / "two", progress=False)


def save_and_load(path):
    from gesturelib.features import load_audio

    return load_audio(path)[0]
