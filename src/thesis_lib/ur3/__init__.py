"""The UR3 methods (thesis 5.2.5.4 and chapter 6's application), on a simulated UR3.

Table 5.4 and the chapter's figures live in :mod:`thesis_lib.chapters.ur3`.

* :mod:`thesis_lib.ur3.model` - DH parameters, limits, forward kinematics, the MJCF model
  (``assets/ur3.xml``);
* :mod:`thesis_lib.ur3.reach` - the reaching task (a gymnasium env, ``thesis/UR3Reach-v0``),
  scripted teleoperation-like demonstrations, their Minari data set;
* :mod:`thesis_lib.ur3.safety` - joint, speed and workspace limits: check or clip;
* :mod:`thesis_lib.ur3.dance` - MDLT's four angles on the arm, with the limit checks;
* :mod:`thesis_lib.ur3.render`, :mod:`thesis_lib.ur3.viewer` - frames, GIF, meshcat 3-D viewer;
* :mod:`thesis_lib.ur3.driver` - one driver for the simulation and a real UR3 (URScript or
  ``ur_rtde``), dry-run by default, refusing unsafe motion, with an emergency stop.

Used in: UR3 deployment chapter (notebook ``07_ur3_deployment``).
"""

from __future__ import annotations

from .dance import DanceMapping, DancePlayback, demo_angles, map_dance, prepare_dance
from .driver import PlayResult, RobotStopped, RTDEBackend, SimBackend, UR3Driver, URScriptBackend
from .model import (
    DH,
    JOINT_NAMES,
    MAX_SPEED,
    POSITION_LIMITS,
    UR3Kinematics,
    build_mjcf,
    dh_transform,
    fk_dh,
    load_model,
    tcp_position,
)
from .reach import (
    DATASET_ID,
    ENV_ID,
    GOALS,
    HOME,
    REACH_SETS,
    TeleopController,
    UR3ReachEnv,
    get_reach_dataset,
    make_demonstrations,
    split_demonstrations,
)
from .safety import (
    SafetyLimits,
    SafetyReport,
    UnsafeTrajectoryError,
    check_trajectory,
    clip_trajectory,
)
from .viewer import trajectory_html  # meshcat is imported only when it is called

__all__ = [
    "DATASET_ID",
    "DH",
    "ENV_ID",
    "GOALS",
    "HOME",
    "JOINT_NAMES",
    "MAX_SPEED",
    "POSITION_LIMITS",
    "REACH_SETS",
    "DanceMapping",
    "DancePlayback",
    "PlayResult",
    "RTDEBackend",
    "RobotStopped",
    "SafetyLimits",
    "SafetyReport",
    "SimBackend",
    "TeleopController",
    "UR3Driver",
    "UR3Kinematics",
    "UR3ReachEnv",
    "URScriptBackend",
    "UnsafeTrajectoryError",
    "build_mjcf",
    "check_trajectory",
    "clip_trajectory",
    "demo_angles",
    "dh_transform",
    "fk_dh",
    "get_reach_dataset",
    "load_model",
    "make_demonstrations",
    "map_dance",
    "prepare_dance",
    "split_demonstrations",
    "tcp_position",
    "trajectory_html",
]
