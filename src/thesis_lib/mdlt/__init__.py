"""Music-to-dance translation (thesis chapter 6): audio features, poses -> UR3 joint angles,
AIST++/PhantomDance readers, the default offline data set, MDLT-T and MDLT-M, their trainer,
metrics and baselines, and :func:`dance` (:mod:`~thesis_lib.mdlt.translate`: any music file to
joint angles with a trained checkpoint). Tables 6.1-6.3 are the chapter's:
:mod:`thesis_lib.chapters.mdlt`."""

from __future__ import annotations

# --- data side (audio, angles, readers, sync, default data set) ---
from .angles import (
    JOINT_NAMES,
    PARENTS,
    REST_JOINTS,
    align_skeleton,
    forward_kinematics,
    plot_angle_extraction,
    pose_to_ur3_angles,
)
from .audio import (
    FEATURE_SLICES,
    N_FEATURES,
    AudioError,
    FeatureScaler,
    audio_features,
    cached_audio_features,
    fit_feature_scaler,
    load_audio,
)

# --- model side (models, metrics, training, dance command) ---
from .metrics import (
    BASELINES,
    aje,
    beat_alignment,
    evaluate_songs,
    frechet_distance,
    mae_degrees,
)
from .models import MDLTConfig, MDLTMamba, MDLTTransformer, build_model
from .readers import (
    AIST_GENRES,
    DanceSequence,
    DatasetLayoutError,
    load_aist,
    load_dance_dataset,
    load_phantomdance,
)
from .sync import nearest_pose_indices, synchronize
from .synth import GENRES, default_dataset
from .train import DanceWindows, MDLTTrainer, load_checkpoint, save_checkpoint
from .translate import (
    DanceResult,
    animate_arm,
    dance,
    packaged_checkpoint,
    packaged_recording,
    plot_angles,
    ur3_joint_positions,
)
