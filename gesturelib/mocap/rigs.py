"""Which joint of a motion-capture rig is which of the course's keypoints.

A rig names its joints its own way. Each map below gives, for our root (``spine_base``) and
keypoints (:data:`gesturelib.skeleton.KEYPOINTS`), the rig's joint that sits there:

* ``sternum``: the base of the neck, where the spine ends and the neck starts;
* ``left_shoulder`` .. ``right_wrist``: the shoulder, elbow and wrist joints (the upper arm's,
  the forearm's and the hand's joints: not the clavicles, whose joints start at the sternum);
* ``head``: the head's joint, at the top of the neck;
* ``nose``: few rigs have one; without it the nose is placed in front of the head, turned with
  the head's joint (:mod:`gesturelib.mocap.retarget`), which is what carries a nod.

Names are compared without case and without a namespace (``mixamorig:LeftArm`` is ``LeftArm``).
BEAT, ZeroEGGS, Trinity (GENEA 2020), CMU (the BVH conversion) and Mixamo share one naming;
Talking With Hands (GENEA 2022 and 2023) has its own; ``gesturelib`` reads our own BVH export.
"""

from __future__ import annotations

from gesturelib.skeleton import KEYPOINTS, ROOT

_SIDES = {"left": "Left", "right": "Right"}

#: Rig name -> {our joint: the rig's joint name}; ``nose`` only where the rig has one.
RIGS: dict[str, dict[str, str]] = {
    "gesturelib": {name: name for name in (ROOT, *KEYPOINTS)},
    "genea": {
        "spine_base": "b_root",
        "sternum": "b_neck0",
        "head": "b_head",
        **{f"{side}_shoulder": f"b_{side[0]}_arm" for side in _SIDES},
        **{f"{side}_elbow": f"b_{side[0]}_forearm" for side in _SIDES},
        **{f"{side}_wrist": f"b_{side[0]}_wrist" for side in _SIDES},
    },
    "mixamo": {
        "spine_base": "Hips",
        "sternum": "Neck",
        "head": "Head",
        **{f"{side}_shoulder": f"{name}Arm" for side, name in _SIDES.items()},
        **{f"{side}_elbow": f"{name}ForeArm" for side, name in _SIDES.items()},
        **{f"{side}_wrist": f"{name}Hand" for side, name in _SIDES.items()},
    },
}
#: Other names a user may give ``--rig``: the datasets that use each naming.
ALIASES = {
    "talking_with_hands": "genea",
    "beat": "mixamo",
    "zeggs": "mixamo",
    "trinity": "mixamo",
    "cmu": "mixamo",
}
RIG_NAMES = (*RIGS, *ALIASES)


class RigError(ValueError):
    """A BVH skeleton that none of the known rigs (or not the one asked for) describes."""


def _plain(name: str) -> str:
    return name.rsplit(":", 1)[-1].lower()


def joint_map(joint_names, rig: str | None = None) -> tuple[str, dict[str, str]]:
    """The rig of a BVH skeleton and, for each of our joints it has, its joint's name there.

    Args:
        joint_names: the BVH file's joint names.
        rig: one of :data:`RIG_NAMES`, or None to find the first rig whose joints are all there.
    Returns:
        ``(rig, {our joint: the file's joint name})``, ``rig`` as in :data:`RIGS`.
    Raises:
        RigError: for an unknown ``rig``, a file without a joint the rig needs (naming each
            missing one), or, when detecting, a file that no rig fits (naming what each lacks).
    """
    if rig is not None and rig not in RIG_NAMES:
        raise RigError(f"unknown rig {rig!r}; choose one of {', '.join(RIG_NAMES)}")
    present = {_plain(name): name for name in joint_names}
    candidates = [ALIASES.get(rig, rig)] if rig is not None else list(RIGS)
    missing = {}
    for candidate in candidates:
        wanted = RIGS[candidate]
        found = {ours: present.get(theirs.lower()) for ours, theirs in wanted.items()}
        missing[candidate] = [wanted[ours] for ours, name in found.items() if name is None]
        if not missing[candidate]:
            return candidate, found
    lacks = "; ".join(f"{name} lacks {', '.join(joints)}" for name, joints in missing.items())
    advice = (
        "rename the joints, or export with one of these namings"
        if rig is None
        else "is it another rig? leave --rig out to detect it"
    )
    raise RigError(f"the skeleton fits no rig we know ({lacks}): {advice}")
