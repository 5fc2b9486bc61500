"""One RL layer for every RL chapter: a thin layer over stable-baselines3's SAC, TD3 and DDPG.

`train(RLConfig(...))` builds and seeds an SB3 model, trains it with a per-episode log
(return, length, terminated/truncated, crash) and a progress bar, and returns a `TrainResult`.
`learning_curves` runs algorithms x seeds as joblib tasks and returns one tidy DataFrame;
`evaluate` rolls out any object with `predict`. `train(..., checkpoint=folder)` keeps a run
resumable: killed and run again, it continues from its last checkpoint and ends exactly where
the run never stopped would (`latest_checkpoint` names the checkpoint it would resume from).

Speed on the 2-core CI machine: env steps per second of training on Pendulum-v1 (one gradient
step per env step, batch 256, one torch thread, `nice`, 2,000 steps, other jobs sharing the
cores at load 1-2; at load 4-5 expect about 0.6x):

======  ===================  ==========
algo    SB3's default net    [64, 64]
======  ===================  ==========
SAC     71 (256-256)         167-177
TD3     74 (400-300)         306-351
DDPG    82 (400-300)         296-323
======  ===================  ==========

With small nets TD3 and DDPG run about twice as fast as SAC: TD3 updates its actor on every
second step only, DDPG has a single critic, and neither samples a squashed Gaussian nor tunes
an entropy coefficient. The smoke scale uses [64, 64] nets with learning rate 1e-3 and
the step counts in `SMOKE_DEFAULTS`: SAC reaches returns of about -150 after ~3,000 steps,
DDPG after ~4,500, TD3 after ~5,000-7,000 (seeds 0-2; episodes start near -1,500, one
episode is 200 steps). Measured with
`learning_curves(["DDPG", "TD3", "SAC"], **SMOKE_DEFAULTS)`: 60 s at load ~2.5 with
`n_jobs=1` (SAC 21 s, TD3 23 s, DDPG 14 s; up to about 2 minutes when other jobs load the
cores harder), mean return of the last 5 episodes SAC -159,
TD3 -209, DDPG -132. `n_jobs=2` was slower (74 s) on the busy 2-core box.

`SMOKE_DEFAULTS` is the book's default scale for the Background chapter's learning curves,
`THESIS_DEFAULTS` the thesis's (DEFENDER's hyper-parameters, Sec. 4.3).

Used in: Background (thesis 2.5-2.7), CLfD (4.2), DEFENDER (4.3).
"""

from __future__ import annotations

from typing import Any

from thesis_lib.rl.callbacks import (
    EPISODE_COLUMNS,
    EpisodeLogger,
    ProgressBar,
    find_horizon,
    is_crash,
)
from thesis_lib.rl.config import ALGOS, AUTO_NOISE, RLConfig
from thesis_lib.rl.resume import ResetRecorder, latest_checkpoint
from thesis_lib.rl.training import (
    CURVE_COLUMNS,
    EVAL_COLUMNS,
    Predictor,
    TrainResult,
    config_dict,
    config_from_params,
    evaluate,
    learning_curves,
    make_action_noise,
    make_model,
    silent_logger,
    train,
)

SMOKE_DEFAULTS: dict[str, Any] = {
    "env_id": "Pendulum-v1",
    "seeds": [0],
    "total_timesteps": {"SAC": 4000, "TD3": 8000, "DDPG": 5000},
    "net_arch": [64, 64],
    "learning_rate": 1e-3,
}
"""Background chapter, smoke scale: keyword arguments for `learning_curves`
(`learning_curves(["DDPG", "TD3", "SAC"], **SMOKE_DEFAULTS)`). See the module
docstring for the measurements behind it."""

THESIS_DEFAULTS: dict[str, Any] = {
    "env_id": "Pendulum-v1",
    "seeds": [0, 1, 2],
    "total_timesteps": {"SAC": 100_000, "TD3": 100_000, "DDPG": 100_000},
    "net_arch": [256, 256],
    "learning_rate": 3e-4,
    "batch_size": 256,
    "action_noise_sigma": 0.1,
}
"""Thesis scale: the authors' DEFENDER hyper-parameters (lr 3e-4, batch 256, 256-256 nets,
TD3 policy delay 2 and target noise 0.2 clipped at 0.5, which are SB3's defaults, exploration
noise 0.1), 1e5 steps per run and three seeds, as in the thesis's experiments. About 25 min
per SAC run on this machine (71 steps/s); DEFENDER's own runs (5000 episodes) are longer."""

__all__ = [
    "ALGOS",
    "AUTO_NOISE",
    "CURVE_COLUMNS",
    "EPISODE_COLUMNS",
    "EVAL_COLUMNS",
    "SMOKE_DEFAULTS",
    "THESIS_DEFAULTS",
    "EpisodeLogger",
    "Predictor",
    "ProgressBar",
    "RLConfig",
    "ResetRecorder",
    "TrainResult",
    "config_dict",
    "config_from_params",
    "evaluate",
    "find_horizon",
    "is_crash",
    "latest_checkpoint",
    "learning_curves",
    "make_action_noise",
    "make_model",
    "silent_logger",
    "train",
]
