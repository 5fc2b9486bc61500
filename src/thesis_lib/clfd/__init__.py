"""CLfD: viewpoint-invariant representations from multi-view demonstrations (thesis 4.2).

- :class:`MultiViewPickPlace`: the pick-and-place task in MuJoCo with five fixed cameras, and
  :class:`ScriptedPickPlace`, its demonstrator; :func:`make_pick_place_dataset` renders the
  thesis's 150-demonstration data set (smaller at the smoke scale).
- :class:`MultiViewVideos` and :func:`read_multiview_folder`: synchronised multi-view videos,
  yours or Multi-View Pouring's.
- :class:`CLfD`: train a ResNet-18 or TCN-style encoder with CLfD's NT-Xent loss or the TCN /
  CMC baselines, then ``embed`` frames or use the embedding reward (Eq 4.2).
- :func:`alignment_error` (Table 4.1), stage classification (Table 4.2), and
  :mod:`thesis_lib.clfd.rl` (Fig 4.4): DDPG with the embedding reward.

Rendering uses ``MUJOCO_GL=egl`` unless the environment sets another back end; it is set here,
before MuJoCo is imported.

Used in: chapter 02_clfd.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from thesis_lib.clfd.data import MultiViewVideos, make_pick_place_dataset, read_multiview_folder
from thesis_lib.clfd.env import (
    CAMERAS,
    STAGES,
    MultiViewPickPlace,
    ScriptedPickPlace,
    run_demonstration,
)
from thesis_lib.clfd.losses import cmc_loss, nt_xent, triplet_loss
from thesis_lib.clfd.metrics import alignment_distance, alignment_error
from thesis_lib.clfd.models import ProjectionHead, ResNet18, TCNEncoder
from thesis_lib.clfd.train import CLfD, mean_alignment_error

__all__ = [
    "CAMERAS",
    "STAGES",
    "CLfD",
    "MultiViewPickPlace",
    "MultiViewVideos",
    "ProjectionHead",
    "ResNet18",
    "ScriptedPickPlace",
    "TCNEncoder",
    "alignment_distance",
    "alignment_error",
    "cmc_loss",
    "make_pick_place_dataset",
    "mean_alignment_error",
    "nt_xent",
    "read_multiview_folder",
    "run_demonstration",
    "triplet_loss",
]
