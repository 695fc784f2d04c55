"""The models of the course, one family per file, each with its config dataclass.

Every model follows the protocol of :mod:`gesturelib.train`: ``model.loss(batch)`` returns a dict
with ``"loss"`` and other scalars to log, ``model.config`` is its config, and ``Model(config)``
rebuilds it (``Model.config_class``). Configs have working defaults for the course's data and a
``quick()`` variant for tests and quick mode.

* :mod:`~gesturelib.models.vae`: :class:`PoseAutoencoder` and :class:`PoseVAE` (single poses),
  and :class:`CVAE`, the recurrent conditional VAE baseline of the Flow-VAE paper.
* :mod:`~gesturelib.models.baselines`: the deterministic regressors of Kucherenko et al.,
  :class:`Aud2Pose` and :class:`Aud2Repr2Pose` (trained after its
  :class:`MotionDenoisingAutoencoder`).
* :mod:`~gesturelib.models.moglow`: :class:`MoGlow`, the autoregressive speech-conditioned flow.
* :mod:`~gesturelib.models.flowvae`: :class:`FlowVAE`, the conditional Flow-VAE of Taylor et al.,
  and :class:`VariationalFlowVAE`, its variant whose loss is an ELBO.
* :mod:`~gesturelib.models.control`: the control those flows are conditioned on.
* :mod:`~gesturelib.models.styleflow`: :class:`StyleFlow`, Ye et al.'s flow with a global
  encoder, whose style follows a reference motion, and :class:`GestureFeatureNetwork`, the motion
  autoencoder of its perceptual loss.
* :mod:`~gesturelib.models.diffusion`: :class:`GestureDiffusion`, a denoising diffusion model
  writing short chunks of poses.
"""

from gesturelib.models.baselines import (
    Aud2Pose,
    Aud2PoseConfig,
    Aud2Repr2Pose,
    Aud2Repr2PoseConfig,
    MotionDAEConfig,
    MotionDenoisingAutoencoder,
    SpeechWindowNet,
)
from gesturelib.models.diffusion import DiffusionConfig, GestureDiffusion, Sampling
from gesturelib.models.flowvae import (
    FlowVAE,
    FlowVAEConfig,
    VariationalFlowVAE,
    VariationalFlowVAEConfig,
)
from gesturelib.models.moglow import MoGlow, MoGlowConfig
from gesturelib.models.styleflow import (
    GestureFeatureConfig,
    GestureFeatureNetwork,
    StyleFlow,
    StyleFlowConfig,
)
from gesturelib.models.vae import (
    CVAE,
    CVAEConfig,
    PoseAutoencoder,
    PoseAutoencoderConfig,
    PoseVAE,
    PoseVAEConfig,
    gaussian_kl,
    reparameterise,
)

__all__ = [
    "CVAE",
    "Aud2Pose",
    "Aud2PoseConfig",
    "Aud2Repr2Pose",
    "Aud2Repr2PoseConfig",
    "CVAEConfig",
    "DiffusionConfig",
    "FlowVAE",
    "FlowVAEConfig",
    "GestureDiffusion",
    "GestureFeatureConfig",
    "GestureFeatureNetwork",
    "MoGlow",
    "MoGlowConfig",
    "MotionDAEConfig",
    "MotionDenoisingAutoencoder",
    "PoseAutoencoder",
    "PoseAutoencoderConfig",
    "PoseVAE",
    "PoseVAEConfig",
    "Sampling",
    "SpeechWindowNet",
    "StyleFlow",
    "StyleFlowConfig",
    "VariationalFlowVAE",
    "VariationalFlowVAEConfig",
    "gaussian_kl",
    "reparameterise",
]
