"""The evaluation's pictures, for any set of systems: each takes ``motions``, a dict from a system's
name to its keypoints ``(T, 9, 3)``, one per held-out conversation (one draw of each system).

* :func:`plot_speed_histograms`: wrist-speed distributions against the ground truth's (what
  the Hellinger distance summarises);
* :func:`plot_mean_pose_distance`: each keypoint's distance from the mean pose, box plots per
  joint (Taylor et al. 2021, Figure 6);
* :func:`plot_speaking_listening`: the rate of change of that distance while the agent speaks
  and while it listens (their Figure 8);
* :func:`plot_pause_profile`: the wrists' speed through the agent's short pauses, from its
  phrase's end and up to its next phrase's start, against the ground truth's;
* :func:`plot_hands`: each wrist's speed over time, per system: whether one hand rests while
  the other gestures;
* :func:`plot_overlays`: each system's skeleton drawn once a second, overlaid.

and, for one model with style inputs, :func:`plot_style_response`: the style realised against
the style asked.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from gesturelib.conventions import FPS
from gesturelib.evaluation.headline import (
    WRIST_SPEED_BINS,
    pause_speed_profile,
    wrist_speed_histogram,
    wrist_speeds,
)
from gesturelib.evaluation.style_control import LEVELS
from gesturelib.metrics import distance_from_mean_pose, speaking_listening_statistics
from gesturelib.skeleton import JOINT_INDEX, KEYPOINTS


def plot_speed_histograms(motions: dict, truth) -> plt.Figure:
    """Wrist-speed histograms of each system (lines) over the ground truth's (grey)."""
    fig, ax = plt.subplots(figsize=(7, 3.4))
    centres = (WRIST_SPEED_BINS[:-1] + WRIST_SPEED_BINS[1:]) / 2
    ax.fill_between(
        centres, wrist_speed_histogram(truth), color="0.8", label="ground truth", step="mid"
    )
    for name, motion in motions.items():
        ax.step(centres, wrist_speed_histogram(motion), where="mid", label=name, linewidth=1.2)
    ax.set(xlabel="wrist speed (cm/s)", ylabel="share of frames", yscale="log", xlim=(0, 300))
    ax.set_ylim(bottom=1e-4)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig


#: The keypoints whose distance from the mean pose :func:`plot_mean_pose_distance` shows.
MOVING_KEYPOINTS = ("left_elbow", "left_wrist", "right_elbow", "right_wrist", "nose")


def plot_mean_pose_distance(motions: dict, mean_pose: np.ndarray) -> plt.Figure:
    """Box plots of each moving keypoint's distance from ``mean_pose`` ``(9, 3)``: one panel per
    keypoint, one box per system (Taylor et al. 2021, Figure 6)."""
    names = list(motions)
    distances = {
        name: np.concatenate([distance_from_mean_pose(m, mean_pose) for m in motion])
        for name, motion in motions.items()
    }
    fig, axes = plt.subplots(
        1, len(MOVING_KEYPOINTS), figsize=(2.3 * len(MOVING_KEYPOINTS), 3.6), sharey=True
    )
    for ax, keypoint in zip(axes, MOVING_KEYPOINTS, strict=True):
        joint = KEYPOINTS.index(keypoint)
        box = ax.boxplot(
            [distances[name][:, joint] for name in names], showfliers=False, patch_artist=True
        )
        for s, patch in enumerate(box["boxes"]):
            patch.set_facecolor(f"C{s % 10}")
        ax.set_xticks(range(1, len(names) + 1), names, rotation=60, ha="right", fontsize=7)
        ax.set_title(keypoint.replace("_", " "), fontsize=9)
    axes[0].set_ylabel("distance from the mean pose (cm)")
    fig.tight_layout()
    return fig


def plot_mean_pose_distance_series(
    motions: dict, mean_pose: np.ndarray, activity: np.ndarray, seconds: float = 20.0
) -> plt.Figure:
    """Each moving keypoint's distance from ``mean_pose`` over the first ``seconds`` of the first
    conversation, one panel per system, the agent's speech shaded (``activity`` ``(T,)`` of that
    conversation) (Taylor et al. 2021, Figure 6, left)."""
    from gesturelib import viz

    frames = int(seconds * FPS)
    times = np.arange(frames) / FPS
    fig, axes = plt.subplots(
        len(motions), 1, figsize=(9, 1.3 * len(motions) + 0.6), sharex=True, sharey=True
    )
    for ax, (name, motion) in zip(np.atleast_1d(axes), motions.items(), strict=True):
        distance = distance_from_mean_pose(motion[0][:frames], mean_pose)
        for k, keypoint in enumerate(MOVING_KEYPOINTS):
            ax.plot(
                times,
                distance[:, KEYPOINTS.index(keypoint)],
                lw=0.9,
                color=f"C{k}",
                label=keypoint.replace("_", " "),
            )
        shading = viz.shade_activity(ax, activity[:frames])
        ax.set_ylabel(name, fontsize=8, rotation=0, ha="right", va="center")
    axes = np.atleast_1d(axes)
    keypoints = axes[0].get_legend_handles_labels()
    fig.legend(*keypoints, fontsize=7, ncol=len(MOVING_KEYPOINTS), loc="upper left")
    fig.legend(handles=shading, fontsize=7, loc="upper right", title="who is talking")
    axes[-1].set_xlabel("time (s)")
    fig.supylabel("distance from the mean pose (cm)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    return fig


def plot_hands(motions: dict, activity: np.ndarray, seconds: float = 12.0) -> plt.Figure:
    """Each wrist's speed over the first ``seconds`` of one conversation, one panel per system
    (``motions``: a system's name to its keypoints ``(T, 9, 3)`` of that conversation), the
    agent's speech shaded (``activity`` ``(T,)``): whether one hand rests while the other
    gestures."""
    from gesturelib import viz

    frames = int(seconds * FPS)
    times = np.arange(1, frames) / FPS
    fig, axes = plt.subplots(
        len(motions), 1, figsize=(9, 1.4 * len(motions) + 0.6), sharex=True, sharey=True
    )
    axes = np.atleast_1d(axes)
    wrists = ("left_wrist", "right_wrist")  # the columns of wrist_speeds
    for ax, (name, motion) in zip(axes, motions.items(), strict=True):
        speeds = wrist_speeds(motion[:frames])
        for column, wrist in enumerate(wrists):
            colour = viz.bone_colour(JOINT_INDEX[wrist])
            ax.plot(times, speeds[:, column], lw=1.0, color=colour, label=wrist.replace("_", " "))
        shading = viz.shade_activity(ax, activity[:frames])
        ax.set_ylabel(name, fontsize=8, rotation=0, ha="right", va="center")
    lines, _ = axes[0].get_legend_handles_labels()
    fig.legend(handles=[*lines, *shading], fontsize=7, loc="upper left", ncol=len(lines) + 3)
    axes[-1].set_xlabel("time (s)")
    fig.supylabel("wrist speed (cm/s)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    return fig


def plot_head_drops(drops: dict) -> plt.Figure:
    """The head's mean downward speed after the partner's phrase ends, one line per system
    (``drops``: a system's name to its curve ``(F,)`` in deg/s, one value a frame from the end
    on, e.g. the mean over the rows of
    :func:`~gesturelib.evaluation.rules.head_drops_after_phrase_ends`): when a listening nod
    begins, and how fast it goes."""
    fig, ax = plt.subplots(figsize=(8, 3))
    for name, curve in drops.items():
        ax.plot(np.arange(len(curve)) * 1000 / FPS, curve, marker=".", label=name)
    ax.set(xlabel="time after the partner's phrase end (ms)", ylabel="downward speed (°/s)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    return fig


def plot_style_response(responses: dict, recorded: np.ndarray) -> plt.Figure:
    """One panel per style feature: the mean style realised at each level asked, against the
    level (``responses``: :func:`~gesturelib.evaluation.style_control.style_response`), with the
    line of full obedience and a band where the middle 70 % of recorded clips lie (``recorded``:
    ``(N, 4)`` their styles, :func:`~gesturelib.evaluation.transfer.clip_style`)."""
    fig, axes = plt.subplots(1, len(responses), figsize=(3.3 * len(responses), 3.2), squeeze=False)
    low, high = np.percentile(recorded, [LEVELS[0], LEVELS[-1]], axis=0)
    for k, (ax, (name, response)) in enumerate(zip(axes[0], responses.items(), strict=True)):
        ax.axhspan(low[k], high[k], color="0.85", label="recorded clips, 15th-85th percentile")
        ax.plot(response.asked, response.asked, "k--", lw=1, label="realised = asked")
        ax.plot(response.asked, response.realised, "o-", label="realised (mean)")
        ax.set(title=f"{name}: share {response.share:.2f}", xlabel="asked")
    axes[0, 0].set_ylabel("realised (clip average)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncols=3)
    fig.tight_layout(rect=(0, 0, 1, 0.86))
    return fig


def plot_speaking_listening(motions: dict, conversations, mean_pose: np.ndarray) -> plt.Figure:
    """Box plots of how fast the keypoints move towards or away from ``mean_pose`` (the size of
    the change of their distance from it, cm/s, mean over keypoints), while the agent speaks and
    while it listens, per system (Taylor et al., Figure 8)."""
    fig, ax = plt.subplots(figsize=(max(6.0, 0.7 * len(motions)), 3.6))
    for s, motion in enumerate(motions.values()):
        for m, mode in enumerate(("speaking", "listening")):
            rates = np.concatenate(
                [
                    np.abs(
                        speaking_listening_statistics(p, c.activity, FPS, mean_pose)[mode][
                            "distance_rate"
                        ]
                    ).mean(axis=1)
                    for p, c in zip(motion, conversations, strict=True)
                ]
            )
            box = ax.boxplot(
                [rates], positions=[3 * s + m], widths=0.8, showfliers=False, patch_artist=True
            )
            box["boxes"][0].set(facecolor=f"C{s % 10}", alpha=1.0 if m == 0 else 0.45)
    ax.set_xticks(
        [3 * s + 0.5 for s in range(len(motions))],
        list(motions),
        fontsize=7,
        rotation=35,
        ha="right",
    )
    ax.set(ylabel="|change of distance\nfrom the mean pose| (cm/s)")
    ax.set_title("each system: speaking (dark), listening (light)", fontsize=9)
    fig.tight_layout()
    return fig


def plot_pause_profile(motions: dict, truth, conversations, seconds: float = 1.5) -> plt.Figure:
    """The wrists' mean speed through the agent's short pauses between its phrases
    (:func:`~gesturelib.evaluation.headline.pause_speed_profile`), per system (lines) over the
    ground truth's (grey): after a phrase ends (left) and before the next starts (right)."""
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.2), sharey=True)
    shown = {"ground truth": truth, **motions}
    for index, (name, motion) in enumerate(shown.items()):
        after_end, before_start = pause_speed_profile(motion, conversations, seconds)
        times = np.arange(len(after_end)) / FPS
        style = {"color": "0.6", "lw": 3.0} if index == 0 else {"color": f"C{index - 1}"}
        axes[0].plot(times, after_end, label=name, **style)
        axes[1].plot(-times, before_start, **style)
    axes[0].set(xlabel="seconds after the agent's phrase ends", ylabel="wrist speed (cm/s)")
    axes[1].set(xlabel="seconds before its next phrase starts")
    axes[0].legend(fontsize=8)
    fig.suptitle("the agent's short pauses: the hands retract, rest and rise again", fontsize=9)
    fig.tight_layout()
    return fig


def plot_overlays(motions: dict, seconds: float = 10.0, every_s: float = 1.0) -> plt.Figure:
    """Each system's pose once every ``every_s`` over the first ``seconds`` of the first
    conversation, overlaid (front view): where its hands go, at a glance. Six panels a row."""
    from gesturelib import viz

    columns = min(6, len(motions))
    rows = -(-len(motions) // columns)
    fig, axes = plt.subplots(
        rows, columns, figsize=(2.2 * columns, 2.5 * rows), squeeze=False, sharex=True, sharey=True
    )
    for ax, (name, motion) in zip(axes.flat, motions.items(), strict=False):  # spare panels
        poses = motion[0][: int(seconds * FPS) : int(every_s * FPS)]
        viz.plot_pose(poses, views=("front",), axes=[ax], alpha=0.35)
        ax.set_title(name, fontsize=9)
    for ax in axes.flat[len(motions) :]:
        ax.axis("off")
    fig.tight_layout()
    return fig
