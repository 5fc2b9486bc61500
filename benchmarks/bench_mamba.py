"""Time thesis_lib's Mamba against mambapy (pure PyTorch) and a same-size GPT stack on CPU.

The thesis's DM size (6 layers, d_model 128, K 20 timesteps -> 60 tokens, batch 16):

  train  one AdamW step (forward, MSE loss, backward, update) on a (16, 60, 128) batch:
         thesis_lib Mamba (numba scan), the same with the vectorised torch-loop scan,
         the same with the authors' per-block gated MLP, mambapy 1.2.0 (same weights'
         layout, parallel scan), and 6 thesis_lib.seq.Block (causal attention, 1 head).
  act    per-action inference for one environment (batch 1, no grad): re-running the 60-token
         window (what the original DM code does) for each model, against thesis_lib's
         recurrent ``Mamba.step_tokens`` fed the 3 tokens (R, s, a) of one new timestep
         (fused kernel; the unfused torch-op path for reference).
  models per-action inference of whole models (batch 1, no grad), as the evaluator calls them:
         DT (``DecisionTransformer.act`` on the K-step history, 6 GPT blocks), DM with RTG
         (gated MLP) re-running the window (``DecisionMamba.act``, the authors' way) and the
         DM's ``RecurrentPolicy.act`` (embed 3 new tokens, one fused step, action head).

Methods take turns repeat by repeat, so background load hits them alike; medians are reported,
and ratios are taken between medians of one run. Numba's compile (cached on disk after the
first run) happens in the warm-up, outside the timings.

    python benchmarks/bench_mamba.py --repeats 15            # one torch thread (default)
    python benchmarks/bench_mamba.py --repeats 15 --threads 0

Measured 2026-11-22 on the shared 2-core CI machine (load 3-4), one thread, 15 repeats:
train ours 184 ms, mambapy 774 ms (4.2x), GPT x6 141 ms (ours 1.3x); per action: ours window
12.1 ms, recurrent 2.0 ms (6.1x), GPT window 6.9 ms (3.5x the recurrent step).
Whole models, 2026-11-23 (load 8-9, 7 repeats): DT act 17.3 ms, DM w/ RTG window 39.3 ms,
DM recurrent policy step 6.5 ms (6.0x the DM window, 2.7x faster than the DT).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from collections.abc import Callable

import torch
from torch import nn

from thesis_lib.seq import (
    Block,
    DecisionMamba,
    DecisionTransformer,
    DMConfig,
    DTConfig,
    GPTBlockConfig,
)
from thesis_lib.seq.mamba import Mamba, MambaConfig

try:
    import mambapy
    from mambapy.mamba import Mamba as MambaPy
    from mambapy.mamba import MambaConfig as MambaPyConfig
except ImportError:  # pragma: no cover
    mambapy = MambaPy = MambaPyConfig = None


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--repeats", type=int, default=15, help="timed repeats per method (median reported)"
    )
    p.add_argument("--act-loops", type=int, default=20, help="actions timed per inference repeat")
    p.add_argument("--layers", type=int, default=6)
    p.add_argument("--d-model", type=int, default=128)
    p.add_argument("--K", type=int, default=20, help="context in timesteps; 3 tokens each")
    p.add_argument("--batch", type=int, default=16)
    p.add_argument("--n-head", type=int, default=1, help="heads of the transformer baseline")
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads (0: torch's default). 1 by default: on the shared 2-core CI machine "
        "2 OpenMP threads made every model 5-10x slower (spinning against other jobs)",
    )
    p.add_argument("--seed", type=int, default=0)
    return p.parse_args()


class Stack(nn.Module):
    """n thesis_lib.seq.Block, causal, plus a final LayerNorm (GPT-2 layout)."""

    def __init__(self, n_layers: int, d_model: int, n_head: int) -> None:
        super().__init__()
        cfg = GPTBlockConfig(d_model=d_model, n_heads=n_head, dropout=0.1, causal=True)
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(n_layers))
        self.ln_f = nn.LayerNorm(d_model)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for b in self.blocks:
            x = b(x)
        return self.ln_f(x)


def train_step_fn(model: nn.Module, x: torch.Tensor, target: torch.Tensor) -> Callable[[], None]:
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=1e-4)
    model.train()

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        loss = ((model(x) - target) ** 2).mean()
        loss.backward()
        opt.step()

    return step


def timed(
    fns: dict[str, Callable[[], object]], repeats: int, loops: dict[str, int]
) -> dict[str, float]:
    """Median seconds per loop of each fn; the fns take turns within every repeat."""
    for fn in fns.values():  # warm-up (numba compile, allocator)
        fn()
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            n = loops.get(name, 1)
            t0 = time.perf_counter()
            for _ in range(n):
                fn()
            times[name].append((time.perf_counter() - t0) / n)
    return {k: statistics.median(v) for k, v in times.items()}


def main() -> None:
    args = parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    L, d, n_layers = 3 * args.K, args.d_model, args.layers
    x = torch.randn(args.batch, L, d)
    target = torch.randn(args.batch, L, d)

    ours = Mamba(MambaConfig(d_model=d, n_layers=n_layers))
    ours_torch = Mamba(MambaConfig(d_model=d, n_layers=n_layers), scan_backend="torch")
    ours_mlp = Mamba(MambaConfig(d_model=d, n_layers=n_layers, gated_mlp=True))
    gpt = Stack(n_layers, d, args.n_head)
    train = {
        "thesis_lib Mamba (numba scan)": train_step_fn(ours, x, target),
        "thesis_lib Mamba (torch-loop scan)": train_step_fn(ours_torch, x, target),
        "thesis_lib Mamba + gated MLP": train_step_fn(ours_mlp, x, target),
        f"GPT Block x{n_layers} ({args.n_head} head)": train_step_fn(gpt, x, target),
    }
    if MambaPy is not None:
        mp = MambaPy(MambaPyConfig(d_model=d, n_layers=n_layers, pscan=True))
        train["mambapy 1.2.0 (pscan)"] = train_step_fn(mp, x, target)

    # Per-action inference, one environment. Windowed: the last L tokens, re-run every action.
    window = torch.randn(1, L, d)
    new_tokens = torch.randn(1, 3, d)  # (R, s, a) of one timestep
    eval_models = {"thesis_lib Mamba": ours.eval(), f"GPT Block x{n_layers}": gpt.eval()}
    if MambaPy is not None:
        eval_models["mambapy 1.2.0"] = mp.eval()
    act: dict[str, Callable[[], object]] = {}
    for name, model in eval_models.items():
        act[f"{name}: re-run {L}-token window"] = (lambda m: lambda: m(window)[:, -1])(model)
    with torch.no_grad():
        _, state0 = ours(window, return_state=True)
    act["thesis_lib Mamba: recurrent step, 3 tokens"] = lambda: ours.step_tokens(
        new_tokens, state0
    )[0][:, -1]
    act["  same, unfused torch ops"] = lambda: ours.step_tokens(new_tokens, state0, fused=False)[0][
        :, -1
    ]

    # Whole models, as thesis_lib.seq.evaluate calls them (Hopper sizes: state 11, action 3).
    sd, ad = 11, 3
    size = dict(state_dim=sd, act_dim=ad, K=args.K, d_model=d, n_layers=n_layers)
    dt = DecisionTransformer(DTConfig(**size)).eval()
    dm = DecisionMamba(DMConfig(use_rtg=True, **size)).eval()
    history = {
        "states": torch.randn(1, args.K, sd),
        "actions": torch.rand(1, args.K, ad) * 2 - 1,
        "returns_to_go": torch.randn(1, args.K, 1),
        "timesteps": torch.arange(args.K)[None],
    }
    history["prev_actions"] = torch.cat([torch.zeros(1, 1, ad), history["actions"][:, :-1]], 1)
    policy = dm.recurrent_policy(1)
    with torch.no_grad():
        policy.act(history)  # the first step (no action token yet); later calls feed 3 tokens
    model_act: dict[str, Callable[[], object]] = {
        f"DT ({n_layers} GPT blocks): act on {args.K}-step window": lambda: dt.act(history),
        f"DM w/ RTG (gated MLP): act on {args.K}-step window": lambda: dm.act(history),
        "DM w/ RTG (gated MLP): recurrent policy step": lambda: policy.act(history),
    }

    with torch.no_grad():
        for m in eval_models.values():
            m.eval()
        act_t = timed(act, args.repeats, {k: args.act_loops for k in act})
        model_t = timed(model_act, args.repeats, {k: args.act_loops for k in model_act})
    for m in (ours, ours_torch, ours_mlp, gpt) + ((mp,) if MambaPy is not None else ()):
        m.train()
    train_t = timed(train, args.repeats, {})

    print(
        f"torch {torch.__version__}, threads {torch.get_num_threads()}, mambapy "
        f"{getattr(mambapy, '__version__', '1.2.0' if mambapy else 'missing')}, {platform.processor() or platform.machine()}"
    )
    print(
        f"{n_layers} layers, d_model {d}, {L} tokens, batch {args.batch} (train) / 1 (act); "
        f"medians of {args.repeats} interleaved repeats\n"
    )
    print(f"{'train step (fwd+bwd+AdamW)':<48}{'ms':>10}")
    for k, v in train_t.items():
        print(f"  {k:<46}{v * 1e3:>10.1f}")
    print(f"\n{'per-action inference (batch 1)':<48}{'ms':>10}")
    for k, v in act_t.items():
        print(f"  {k:<46}{v * 1e3:>10.2f}")
    print(f"\n{'per-action inference, whole models (batch 1)':<48}{'ms':>10}")
    for k, v in model_t.items():
        print(f"  {k:<46}{v * 1e3:>10.2f}")

    ours_train = train_t["thesis_lib Mamba (numba scan)"]
    gpt_train = train_t[f"GPT Block x{n_layers} ({args.n_head} head)"]
    rec = act_t["thesis_lib Mamba: recurrent step, 3 tokens"]
    print("\nratios (target)")
    if MambaPy is not None:
        r = train_t["mambapy 1.2.0 (pscan)"] / ours_train
        print(
            f"  train: mambapy / ours                       {r:6.2f}x  (>= 3)  {'met' if r >= 3 else 'NOT met'}"
        )
    r = ours_train / gpt_train
    print(
        f"  train: ours / transformer                   {r:6.2f}x  (<= 2)  {'met' if r <= 2 else 'NOT met'}"
    )
    r = ours_train / train_t["thesis_lib Mamba (torch-loop scan)"]
    print(f"  train: ours numba / ours torch-loop         {r:6.2f}x  (info)")
    r = act_t[f"thesis_lib Mamba: re-run {L}-token window"] / rec
    print(
        f"  act: ours window / ours recurrent           {r:6.2f}x  (>= 5)  {'met' if r >= 5 else 'NOT met'}"
    )
    r = act_t[f"GPT Block x{n_layers}: re-run {L}-token window"] / rec
    print(
        f"  act: transformer window / ours recurrent    {r:6.2f}x  (> 1)   {'met' if r > 1 else 'NOT met'}"
    )
    dt_t, dm_w, dm_r = model_t.values()
    print(
        f"  models: DM window / DM recurrent            {dm_w / dm_r:6.2f}x  (>= 5)  {'met' if dm_w / dm_r >= 5 else 'NOT met'}"
    )
    print(
        f"  models: DT act / DM recurrent act           {dt_t / dm_r:6.2f}x  (> 1)   {'met' if dt_t > dm_r else 'NOT met'}"
    )


if __name__ == "__main__":
    main()
