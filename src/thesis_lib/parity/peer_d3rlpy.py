"""The peer side of the parity harness: d3rlpy's DT or BC on an exported data set.

Run by :func:`thesis_lib.parity.peer_run` in the peer environment (its own venv: d3rlpy 2.8.1
pins gymnasium 1.0.0), as a script, so it imports nothing of ``thesis_lib``::

    peer-venv/bin/python peer_d3rlpy.py --data set.npz --config run.json --out result.json

``set.npz`` holds the episodes flattened (``observations, actions, rewards, terminals,
timeouts``); ``run.json`` the run (:func:`thesis_lib.parity.peer_config`). The result holds
the evaluation returns and lengths, the training time and d3rlpy's version.

The settings are mapped onto d3rlpy's so that both sides train the same model on the same
windows: a linear state embedding (``VectorEncoderFactory([d_model],
exclude_last_activation=True)``), z-scored states, returns-to-go divided by ``rtg_scale``,
AdamW with the same weight decay, linear warm-up and gradient clip. BC sees as many states per
batch as ours (``batch_size x K``: ours trains BC on the same K-step windows as the DT). What
cannot be made equal is said in :data:`thesis_lib.parity.KNOWN_DIFFERENCES`.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _dataset(path: str):
    import d3rlpy

    z = np.load(path)
    return d3rlpy.dataset.MDPDataset(
        observations=z["observations"].astype(np.float32),
        actions=z["actions"].astype(np.float32),
        rewards=z["rewards"].astype(np.float32),
        terminals=z["terminals"].astype(np.float32),
        timeouts=z["timeouts"].astype(np.float32),
    )


def _optim(cfg: dict):
    import d3rlpy

    return d3rlpy.optimizers.AdamWFactory(
        weight_decay=cfg["weight_decay"],
        clip_grad_norm=cfg["grad_clip"] or None,
        lr_scheduler_factory=d3rlpy.optimizers.WarmupSchedulerFactory(
            warmup_steps=cfg["warmup_steps"]
        ),
    )


def _algo(cfg: dict, device: str):
    import d3rlpy

    scaler = d3rlpy.preprocessing.StandardObservationScaler()
    if cfg["method"] == "DT":
        return d3rlpy.algos.DecisionTransformerConfig(
            batch_size=cfg["batch_size"],
            learning_rate=cfg["lr"],
            context_size=cfg["K"],
            max_timestep=cfg["max_timestep"],
            num_heads=cfg["n_heads"],
            num_layers=cfg["n_layers"],
            attn_dropout=cfg["dropout"],
            resid_dropout=cfg["dropout"],
            embed_dropout=cfg["dropout"],
            activation_type="relu",
            encoder_factory=d3rlpy.models.VectorEncoderFactory(
                hidden_units=[cfg["d_model"]], exclude_last_activation=True
            ),
            optim_factory=_optim(cfg),
            observation_scaler=scaler,
            reward_scaler=d3rlpy.preprocessing.MultiplyRewardScaler(1.0 / cfg["rtg_scale"]),
        ).create(device=device)
    if cfg["method"] == "BC":
        return d3rlpy.algos.BCConfig(
            batch_size=cfg["batch_size"] * cfg["K"],
            learning_rate=cfg["lr"],
            encoder_factory=d3rlpy.models.VectorEncoderFactory(
                hidden_units=[cfg["bc_hidden_dim"]] * 2, dropout_rate=cfg["dropout"] or None
            ),
            optim_factory=_optim(cfg),
            observation_scaler=scaler,
        ).create(device=device)
    raise ValueError(f"Unknown peer method {cfg['method']!r}. Valid: DT, BC.")


def _evaluate(algo, cfg: dict) -> tuple[list[float], list[int]]:
    import gymnasium as gym

    env = gym.make(cfg["env_id"])
    returns, lengths = [], []
    for i in range(cfg["episodes"]):
        obs, _ = env.reset(seed=cfg["episode_seed"] + i)
        if cfg["method"] == "DT":
            policy = algo.as_stateful_wrapper(target_return=cfg["target_return"])
            policy.reset()
        total, reward, n, done = 0.0, 0.0, 0, False
        while not done:
            if cfg["method"] == "DT":
                action = policy.predict(np.asarray(obs, dtype=np.float32), reward)
            else:
                action = algo.predict(np.asarray(obs, dtype=np.float32)[None])[0]
            obs, r, terminated, truncated, _ = env.step(action)
            reward = float(r)
            total, n = total + reward, n + 1
            done = terminated or truncated or n >= cfg["max_steps"]
        returns.append(total)
        lengths.append(n)
    env.close()
    return returns, lengths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    cfg = json.loads(open(args.config).read())

    import d3rlpy
    import torch

    torch.set_num_threads(1)
    d3rlpy.seed(cfg["seed"])
    algo = _algo(cfg, "cpu")
    t0 = time.process_time()
    algo.fit(
        _dataset(args.data),
        n_steps=cfg["iterations"],
        n_steps_per_epoch=cfg["iterations"],
        show_progress=False,
        save_interval=10**9,
        logger_adapter=d3rlpy.logging.NoopAdapterFactory(),
    )
    train_s = time.process_time() - t0
    returns, lengths = _evaluate(algo, cfg) if cfg["episodes"] > 0 else ([], [])
    out = {
        "returns": returns,
        "lengths": lengths,
        "train_s": round(train_s, 1),
        "peer": f"d3rlpy {d3rlpy.__version__}",
    }
    with open(args.out, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()
