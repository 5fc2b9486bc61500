"""Peer parity: one of our methods and a peer library's, trained at equal config on the same
data, and the difference of their scores with a 95% interval over seeds.

``thesis parity`` (or ``make parity``) reads ``params/parity.yml``: a list of comparisons,
each a method (``DT``, ``BC``), a data set, a size (the architecture and training) and seeds.
Every (side, seed) run is one :class:`~thesis_lib.sweep.Task`, stored at once under
``studies/parity/tasks/`` (resumable, committed), and the table of
:func:`parity_table` is written to ``studies/parity/parity.csv``.

* **ours** (:func:`ours_run`): :func:`~thesis_lib.seq.runner.run_offline` with the
  comparison's ``init`` (``auto``; ``torch`` for the v1 code's scheme; ``d3rlpy`` for the
  peer's, :func:`~thesis_lib.seq.models.init_transformer`) and window
  ``sampling`` (``end``, d3rlpy's and today's default; comparisons that name none ran with
  ``start``, the default before, and keep their stored runs);
* **peer** (:func:`peer_run`): d3rlpy 2.8.1 (``DecisionTransformer``, ``BC``) in its own venv
  (``$THESIS_CACHE_DIR/peer-venv``, made by ``thesis parity --setup``: d3rlpy pins gymnasium
  1.0.0), on the same episodes exported to ``.npz``, evaluated on the same Hopper-v5 (MuJoCo
  3.11, gymnasium 1.0.0's copy of the environment) from the same reset seeds.

Both sides report the D4RL-normalised score of the final model, mean over the evaluation
episodes, at the data set's best return as the DT's target. The difference ours - peer gets a
Welch t interval over seeds (the seeds of the two sides are unpaired).

Methods without a package to compare against, and what stands in for them, are listed in
:data:`NO_PEER` (the reproduction report shows both tables).
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from thesis_lib._io import hash_arrays
from thesis_lib.data import normalized_score
from thesis_lib.data.minari_sets import is_minari_id, open_dataset
from thesis_lib.data.recipe import GENERATOR_VERSION
from thesis_lib.data.sequence import resolve_sampling
from thesis_lib.paths import cache_dir
from thesis_lib.seq import ArchSpec, EvalSpec, TrainSpec, run_offline
from thesis_lib.seq.evaluation import target_returns
from thesis_lib.seq.models import resolve_init
from thesis_lib.seq.registry import LEGACY_SAMPLING, check_methods
from thesis_lib.seq.trainer import LEFT_OUT_AT, TrainConfig
from thesis_lib.sweep import Task, resumed_cpu_s, scratch_file

__all__ = [
    "can_redo",
    "KNOWN_DIFFERENCES",
    "MIN_PARITY_SEEDS",
    "NO_PEER",
    "PEER_METHODS",
    "PEER_REQUIREMENTS",
    "Comparison",
    "export_npz",
    "load_parity_file",
    "ours_run",
    "parity_table",
    "parity_tasks",
    "peer_python",
    "peer_run",
    "run_peer",
    "setup_peer",
    "unique_tasks",
    "welch_interval",
]

PEER_METHODS: tuple[str, ...] = ("DT", "BC")
"""Methods the peer library has."""

PEER_REQUIREMENTS: tuple[str, ...] = (
    "d3rlpy==2.8.1",
    "torch==2.13.0",
    "mujoco==3.11.0",
    "imageio==2.38.1",
)
"""What the peer venv holds (d3rlpy brings its pinned gymnasium 1.0.0)."""

KNOWN_DIFFERENCES: dict[str, str] = {
    "loss": "d3rlpy sums the squared error over action dimensions and averages over all "
    "window positions (padding counted as zero); ours averages over real steps and dimensions",
    "init": "d3rlpy draws the trunk and the time-step table from N(0, 0.02) and leaves the "
    "state, action and return embeddings and the head at PyTorch's defaults (ours does the "
    "same with `init: d3rlpy`)",
    "timesteps": "d3rlpy counts time steps from 1, ours from 0",
    "windows": "both draw a window's last step uniformly (d3rlpy left-pads, ours right-pads: the "
    "same under the causal mask); comparisons that name no `sampling` ran with ours drawing "
    "the window's start",
    "layer norm": "d3rlpy's blocks and final LayerNorm use eps 0.003, ours PyTorch's 1e-5",
    "environment": "gymnasium 1.0.0's Hopper-v5 against 1.4.0's, both on MuJoCo 3.11",
}
"""What the harness cannot make equal between the two sides."""

NO_PEER: dict[str, str] = {
    "HDT": "no package; its low level is our DT (parity above) with a sub-goal token, and its "
    "high level the same trunk regressing states. The thesis reports HDT above DT on 7 of 9 "
    "locomotion sets (Table 5.3).",
    "DM / HDM": "no package; the DM swaps the DT's trunk for our Mamba, whose kernel matches "
    "the selective-scan reference (tests/test_mamba.py). The thesis reports DM above DT "
    "(Table 5.5).",
    "SAC / TD3 (DEFENDER)": "SB3 itself is the implementation (thesis_lib.rl wraps it), so "
    "the peer is the method; DEFENDER's filter and dynamics model have no package.",
    "CLfD encoders": "no maintained TCN or CMC package; the closed-form checks are the "
    "losses' tests (tests/test_clfd.py) and the untrained-encoder control of the study.",
    "MDLT": "no package; the mean training pose is the baseline it must beat (chapter 06).",
}
"""Methods the claims rest on that have no peer package, and what stands in for one."""


# ----------------------------------------------------------------------------------------------
# The parity file


@dataclass(frozen=True)
class Comparison:
    """One row of ``params/parity.yml``: a method at one size, on one data set, over seeds."""

    name: str
    method: str
    dataset: str = "hopper/medium"
    dataset_size: str = "smoke"
    seeds: tuple[int, ...] = (0, 1, 2)
    init: str = "auto"
    sampling: str | None = None
    """How our side draws its training windows (``end`` / ``start``,
    :class:`~thesis_lib.data.SequenceDataset`); ``None``: the runs made before the option, with
    ``start`` (their task keys hold no ``sampling``)."""
    arch: dict[str, Any] = field(default_factory=dict)
    train: dict[str, Any] = field(default_factory=dict)
    episodes: int = 10
    peer: bool = True
    data_recipe: int | None = None
    """The data recipe (:data:`thesis_lib.data.recipe.GENERATOR_VERSION`) the runs' ``task/tier``
    set was made by; ``None``: this checkout's. Runs of another recipe cannot be redone (the
    generator makes only its own); their stored rows stay readable as a record."""

    def __post_init__(self) -> None:

        check_methods([self.method])
        resolve_sampling(self.sampling, where=f" in parity comparison {self.name!r}")
        try:
            resolve_init(self.init, False)
        except ValueError as e:
            raise ValueError(f"{e} (in parity comparison {self.name!r})") from None
        if self.peer and self.method not in PEER_METHODS:
            raise ValueError(
                f"No peer for {self.method!r} (d3rlpy has {', '.join(PEER_METHODS)}); "
                f"give it `peer: false` to run our side alone (see NO_PEER)."
            )
        if isinstance(self.seeds, str) or not self.seeds:
            raise ValueError(f"Expect `seeds` as a non-empty list, got {self.seeds!r}.")


def load_parity_file(path: str | Path) -> list[Comparison]:
    """The comparisons of a parity file (unknown keys are errors, naming the comparison)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"No parity file {p}.")
    data = yaml.safe_load(p.read_text()) or {}
    common = data.get("common", {})
    out = []
    valid = set(Comparison.__dataclass_fields__)
    for c in data.get("comparisons", []):
        merged = {**common, **c}
        for k in ("arch", "train"):
            merged[k] = {**common.get(k, {}), **c.get(k, {})}
        bad = set(merged) - valid
        if bad:
            raise ValueError(
                f"Unknown key(s) {sorted(bad)} in parity comparison {c.get('name')!r} of {p}; "
                f"valid: {sorted(valid)}."
            )
        merged["seeds"] = tuple(merged.get("seeds", (0, 1, 2)))
        out.append(Comparison(**merged))
    if not out:
        raise ValueError(f"{p} lists no comparison.")
    return out


# ----------------------------------------------------------------------------------------------
# One run of each side


#: The data recipe of runs stored before the recipe was part of a run's key (issue #34 made
#: version 3); a run of this recipe keeps its old key.
LEGACY_DATA_RECIPE = 2


def data_recipe(comparison: Comparison) -> int | None:
    """The recipe a comparison's runs use: its own, else this checkout's for a ``task/tier``
    set; ``None`` for a Minari id (not made here)."""
    if is_minari_id(comparison.dataset):
        return None
    return comparison.data_recipe or GENERATOR_VERSION


def can_redo(config: Mapping[str, Any]) -> bool:
    """Whether this checkout can make a run's data again: a Minari id, or a ``task/tier`` set
    of this checkout's data recipe (a run without ``data_recipe`` is of recipe 2)."""
    if is_minari_id(config["dataset"]):
        return True
    return config.get("data_recipe", LEGACY_DATA_RECIPE) == GENERATOR_VERSION


def _load(dataset: str, size: str, recipe: int | None = LEGACY_DATA_RECIPE) -> Any:
    """The run's data set; refused where it needs another data recipe than this checkout's."""
    if not is_minari_id(dataset) and recipe is not None and recipe != GENERATOR_VERSION:
        raise ValueError(
            f"This run needs {dataset} made by data recipe {recipe}, and this checkout makes "
            f"recipe {GENERATOR_VERSION}: it cannot be redone (its stored rows stay a record). "
            f"Add a comparison with `data_recipe: {GENERATOR_VERSION}` to run it on today's data."
        )
    return open_dataset(dataset, size)


def _data_sha(ds: Any) -> str:
    import hashlib

    h = hashlib.sha256()
    for ep in ds.episodes:
        hash_arrays(h, (ep.observations, ep.actions, ep.rewards))
    return h.hexdigest()[:16]


def _row(config: dict[str, Any], side: str, returns: Any, lengths: Any, ds: Any, **extra: Any):
    """One parity row: the run's D4RL-normalised score (of the mean return), the data set's."""
    task = config["dataset"].split("/")[0]
    r = float(np.mean(returns))
    return {
        "side": side,
        "method": config["method"],
        "dataset": config["dataset"],
        "seed": int(config["train"]["seed"]),
        "init": config.get("init", ""),
        "score": float(normalized_score(task, r)),
        "return_mean": r,
        "length_mean": float(np.mean(lengths)),
        "data_score_mean": float(np.mean(ds.normalized_scores())),
        "data_sha": _data_sha(ds),
        **extra,
    }


def ours_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """Our side of one parity run (a sweep task): train and evaluate with
    :func:`~thesis_lib.seq.runner.run_offline`; one row."""
    import time

    import torch

    torch.set_num_threads(1)
    ds = _load(
        config["dataset"], config["dataset_size"], config.get("data_recipe", LEGACY_DATA_RECIPE)
    )
    arch = ArchSpec(**config["arch"], init=config["init"])
    train = TrainSpec(
        **config["train"], eval_every=0, sampling=config.get("sampling", LEGACY_SAMPLING)
    )
    ev = EvalSpec(episodes=config["episodes"], targets=("max",), episode_seed="run")
    checkpoint = scratch_file("train.pt")  # in a stored grid: a run cut off resumes
    t0 = time.process_time()
    rows = run_offline(
        config["method"],
        ds,
        arch,
        train,
        ev,
        task=config["dataset"].split("/")[0],
        checkpoint=checkpoint,
    )
    last = rows[-1]  # the final evaluation: its mean return and length over the episodes
    return [
        _row(
            config,
            "ours",
            [last["return_mean"]],
            [last["length_mean"]],
            ds,
            peer="thesis_lib",
            train_s=round(time.process_time() - t0 + resumed_cpu_s(), 1),
        )
    ]


def peer_python() -> Path:
    """The peer venv's python (``$THESIS_CACHE_DIR/peer-venv``)."""
    return cache_dir() / "peer-venv" / "bin" / "python"


def setup_peer() -> Path:
    """Make the peer venv (d3rlpy 2.8.1 and its gymnasium 1.0.0) if it is missing; its python."""
    py = peer_python()
    if not py.exists():
        venv = py.parent.parent
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(py), "-m", "pip", "install", *PEER_REQUIREMENTS], check=True)
    return py


def export_npz(ds: Any, path: str | Path) -> Path:
    """The episodes of ``ds`` flattened for d3rlpy's ``MDPDataset``: ``observations`` (the
    states the actions were taken in, not the final one), ``actions``, ``rewards``,
    ``terminals``, ``timeouts`` (the last step of an episode that did not terminate)."""
    obs, act, rew, term, tout = [], [], [], [], []
    for ep in ds.episodes:
        n = len(ep.actions)
        obs.append(ep.observations[:n])
        act.append(ep.actions)
        rew.append(ep.rewards)
        t = np.asarray(ep.terminations, dtype=bool)
        term.append(t)
        to = np.zeros(n, dtype=bool)
        if not t[-1]:
            to[-1] = True
        tout.append(to)
    path = Path(path)
    np.savez(
        path,
        observations=np.concatenate(obs),
        actions=np.concatenate(act),
        rewards=np.concatenate(rew),
        terminals=np.concatenate(term),
        timeouts=np.concatenate(tout),
    )
    return path


def peer_config(config: dict[str, Any], ds: Any) -> dict[str, Any]:
    """The JSON the peer script reads: the run's settings in plain numbers."""
    arch = ArchSpec(**config["arch"])
    tr = config["train"]
    defaults = TrainConfig()
    return {
        "method": config["method"],
        "seed": int(tr["seed"]),
        "iterations": int(tr["iterations"]),
        "batch_size": int(tr.get("batch_size", 64)),
        "lr": float(tr.get("lr", 1e-4)),
        "warmup_steps": int(tr.get("warmup_steps", 10_000)),
        "weight_decay": defaults.weight_decay,
        "grad_clip": defaults.grad_clip,
        "d_model": arch.d_model,
        "n_layers": arch.n_layers,
        "n_heads": arch.n_heads,
        "K": arch.K,
        "dropout": arch.dropout,
        "bc_hidden_dim": arch.bc_hidden_dim,
        "max_timestep": arch.max_timestep,
        "rtg_scale": float(tr.get("rtg_scale") or 1000.0),
        "target_return": float(target_returns(ds)["max"]),
        "env_id": ds.env_id if hasattr(ds, "env_id") else ds.metadata["thesis_info"]["env_id"],
        "episodes": int(config["episodes"]),
        "episode_seed": int(tr["seed"]),
        "max_steps": 1000,
    }


def run_peer(config: dict[str, Any], ds: Any) -> dict[str, Any]:
    """Run the peer script on ``ds`` in the peer venv; its result (``returns``, ``lengths``,
    ``train_s``: the CPU seconds of d3rlpy's ``fit``, ``peer``). ``config["episodes"] = 0``
    trains without evaluating (the speed benchmark)."""
    py = peer_python()
    if not py.exists():
        raise FileNotFoundError(
            f"No peer environment at {py.parent.parent}. Make it with `thesis parity --setup` "
            f"(pip installs {', '.join(PEER_REQUIREMENTS)})."
        )
    script = Path(__file__).with_name("peer_d3rlpy.py")
    with tempfile.TemporaryDirectory(prefix="thesis-parity-") as tmp:
        data = export_npz(ds, Path(tmp) / "data.npz")
        cfg_path = Path(tmp) / "run.json"
        cfg_path.write_text(json.dumps(peer_config(config, ds)))
        out = Path(tmp) / "out.json"
        env = {**os.environ, "OMP_NUM_THREADS": "1"}
        proc = subprocess.run(
            [
                str(py),
                str(script),
                "--data",
                str(data),
                "--config",
                str(cfg_path),
                "--out",
                str(out),
            ],
            env=env,
            cwd=tmp,
            capture_output=True,
            text=True,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"The peer run failed ({py}):\n{proc.stderr[-3000:]}")
        return json.loads(out.read_text())


def peer_run(config: dict[str, Any]) -> list[dict[str, Any]]:
    """The peer's side of one parity run (a sweep task): :func:`run_peer`; one row."""
    ds = _load(
        config["dataset"], config["dataset_size"], config.get("data_recipe", LEGACY_DATA_RECIPE)
    )
    res = run_peer(config, ds)
    return [
        _row(
            config,
            "peer",
            res["returns"],
            res["lengths"],
            ds,
            peer=res["peer"],
            train_s=res["train_s"],
        )
    ]


#: The ``train`` keys of a comparison that only our side reads (the peer trains in float32, with
#: torch's kernels).
OURS_ONLY = ("precision", "kernels")


def parity_tasks(comparisons: list[Comparison]) -> dict[str, dict[str, list[Any]]]:
    """Each comparison's tasks, one per side and seed: ``{name: {"ours": [...], "peer": [...]}}``.

    A peer run's config holds no ``init``, ``sampling``, training ``precision`` or ``kernels``
    (they are ours to vary; d3rlpy trains in float32), so comparisons that differ only there
    share their peer runs (the same task keys: run and stored once).
    """
    out: dict[str, dict[str, list[Any]]] = {}
    for c in comparisons:
        sides: dict[str, list[Any]] = {"ours": [], "peer": []}
        for seed in c.seeds:
            train = {**c.train, "seed": int(seed)}
            config: dict[str, Any] = {
                "method": c.method,
                "dataset": c.dataset,
                "dataset_size": c.dataset_size,
                "arch": dict(c.arch),
                "train": train,
                "episodes": c.episodes,
            }
            recipe = data_recipe(c)
            if recipe is not None and recipe != LEGACY_DATA_RECIPE:  # old runs keep their keys
                config["data_recipe"] = recipe
            ours = {**config, "init": c.init}
            # as TrainSpec.task_dict: the runs before these options keep their keys
            ours["train"] = {
                k: v for k, v in train.items() if not (k in LEFT_OUT_AT and LEFT_OUT_AT[k] == v)
            }
            if c.sampling is not None:  # runs from before the option keep their keys
                ours["sampling"] = c.sampling
            sides["ours"].append(Task(ours_run, ours))
            if c.peer:
                peer_train = {k: v for k, v in train.items() if k not in OURS_ONLY}
                sides["peer"].append(Task(peer_run, {**config, "train": peer_train}))
        out[c.name] = sides
    return out


def unique_tasks(tasks: dict[str, dict[str, list[Any]]]) -> list[Any]:
    """Every task of :func:`parity_tasks` once (by key), in the order that gives a comparison
    both sides early: its first seed ours then the peer's, then its second seed, and so on.
    A run cut short (a session's end) then leaves seeds a side to compare, not one side done.

    Example:
        >>> from types import SimpleNamespace as T
        >>> run = lambda k: T(key=k)
        >>> tasks = {"a": {"ours": [run("o0"), run("o1")], "peer": [run("p0"), run("p1")]}}
        >>> [t.key for t in unique_tasks(tasks)]
        ['o0', 'p0', 'o1', 'p1']
    """
    seen: dict[str, Any] = {}
    for sides in tasks.values():
        for pair in itertools.zip_longest(sides["ours"], sides["peer"]):
            for t in pair:
                if t is not None:
                    seen.setdefault(t.key, t)
    return list(seen.values())


# ----------------------------------------------------------------------------------------------
# The table


def welch_interval(x: Any, y: Any, level: float = 0.95) -> tuple[float, float, float]:
    """``mean(x) - mean(y)`` and its Welch t interval (unequal variances, unpaired).

    Example:
        >>> d, lo, hi = welch_interval([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
        >>> d, round(lo, 2), round(hi, 2)
        (0.0, -2.27, 2.27)
    """
    from scipy import stats

    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) < 2 or len(y) < 2:
        raise ValueError(f"Need >= 2 seeds a side for an interval, got {len(x)} and {len(y)}.")
    d = float(x.mean() - y.mean())
    vx, vy = x.var(ddof=1) / len(x), y.var(ddof=1) / len(y)
    se = float(np.sqrt(vx + vy))
    if se == 0.0:
        return d, d, d
    dof = (vx + vy) ** 2 / (vx**2 / (len(x) - 1) + vy**2 / (len(y) - 1))
    half = float(stats.t.ppf(0.5 + level / 2, dof)) * se
    return d, d - half, d + half


#: The seeds a side before a comparison gets a parity verdict (issue #33: "over >= 3 seeds
#: each"); with 2 it gets its interval only.
MIN_PARITY_SEEDS = 3


def parity_table(
    comparisons: list[Comparison], rows: dict[str, dict[str, list[dict[str, Any]]]]
) -> pd.DataFrame:
    """One line per comparison: ours and the peer's mean score, the difference [95% CI] and
    whether it is within the parity band (the interval holds 0 and ``|difference| <= 3``, over
    at least :data:`MIN_PARITY_SEEDS` seeds a side: issue #33's rule).

    Args:
        comparisons: The parity file's comparisons.
        rows: ``{name: {"ours": rows, "peer": rows}}``: the stored rows of each comparison's
            finished runs (a comparison with fewer than 2 a side gets no interval; with fewer
            than :data:`MIN_PARITY_SEEDS`, an interval but no parity verdict).
    """
    out = []
    for c in comparisons:
        got = rows.get(c.name, {})
        ours = np.array([r["score"] for r in got.get("ours", [])], dtype=float)
        peer = np.array([r["score"] for r in got.get("peer", [])], dtype=float)
        every = got.get("ours", []) + got.get("peer", [])
        size = {"d_model": 128, "n_layers": 3, **c.arch}
        line: dict[str, Any] = {
            "comparison": c.name,
            "method": c.method,
            "init": c.init if c.method != "BC" else "",
            "sampling": c.sampling or LEGACY_SAMPLING,
            "precision": c.train.get("precision", "fp32")
            + (
                ""
                if c.train.get("kernels", "torch") == "torch"
                else f" ({c.train['kernels']} kernels)"
            ),
            "dataset": f"{c.dataset} ({c.dataset_size})",
            "arch": f"d{size['d_model']} L{size['n_layers']}" if c.method != "BC" else "MLP",
            "updates": c.train.get("iterations"),
            "seeds": len(ours),
            "ours": float(ours.mean()) if len(ours) else np.nan,
            "ours_seeds": " ".join(f"{v:.1f}" for v in ours),
            "peer": float(peer.mean()) if len(peer) else np.nan,
            "peer_seeds": " ".join(f"{v:.1f}" for v in peer),
            "peer_name": every[-1]["peer"] if got.get("peer") else "",
            "data_mean": float(every[0]["data_score_mean"]) if every else np.nan,
            "data_sha": every[0]["data_sha"] if every else "",
            "data_recipe": data_recipe(c),
        }
        if len(ours) >= 2 and len(peer) >= 2:
            d, lo, hi = welch_interval(ours, peer)
            line |= {"difference": d, "ci_low": lo, "ci_high": hi}
            enough = min(len(ours), len(peer)) >= MIN_PARITY_SEEDS
            line["parity"] = bool(lo <= 0 <= hi and abs(d) <= 3.0) if enough else None
        else:
            line |= {"difference": np.nan, "ci_low": np.nan, "ci_high": np.nan, "parity": None}
        out.append(line)
    return pd.DataFrame(out)
