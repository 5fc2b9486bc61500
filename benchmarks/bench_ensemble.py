"""Does training several seeds as one vectorised ensemble (``torch.func``) pay on this CPU?

The sequence-model study (``params/04_hdt.study.yml``) trains 1-layer d32 DTs at batch 64:
models so small that one update is mostly Python and dispatch overhead. Stacking the seeds'
parameters (``torch.func.stack_module_state``) and computing every seed's loss in one
``torch.func.vmap(functional_call)`` amortises that overhead over the seeds. This script
times, in one process and in turns (so that background load affects both alike):

* **sequential**: ``n`` separate models, one forward + backward + AdamW step each;
* **ensemble**: one vmapped forward over the ``n`` stacked models (a different batch and
  dropout mask per seed, ``randomness="different"``), one backward, one AdamW step on the
  stacked parameters (AdamW is elementwise, so each seed's slice is updated as it would be
  alone). Per-seed gradient clipping, which the Trainer does, and the padding mask (the
  trunk branches on its values, which vmap cannot trace) are left out of both.

It reports the median time per *seed-update* of each and their ratio (sequential /
ensemble): above 1, the ensemble pays.

Measured here (2026-11-24, 2-core CPU, beside a running study; 5 seeds, 20 updates x 5
repeats): sequential 91 ms, ensemble 97 ms per seed-update, ratio 0.94. The ensemble does not
pay on this CPU, so the studies train one seed per task and use both cores as two tasks.

Why (2026-11-27, same machine, one process, in turns; issue #36's throughput question): an
update at this size is compute-bound, not overhead-bound. One ``Trainer.step`` of the d32
1-layer DT at batch 320 (five seeds' batches in one) costs 4.6x the step at batch 64 (88 against
19 ms), so stacking five seeds can save at most about 8%. Dropout is 30% of a step (20.5 ms
with p = 0.1, 14.5 ms without: PyTorch's CPU Bernoulli draws cost about 12 ns an element, and
the attention weights alone are 64 x 60 x 60 per step). ``torch.compile`` of the GPT blocks made
the step slower (34 against 20 ms). A 2x at equal config needs another lever than batching.

Where a whole v1 run goes (2026-11-27, cProfile of one ``hdt:study_run`` task, DT on
hopper/medium smoke, 10k updates, 5 evaluations, beside two other processes): 194 s, of which
the 10k ``Trainer.step`` calls take 186 s (forward 96 s: the attention call 34 s, dropout 24 s,
the Linears 16 s; backward 58 s; AdamW 14 s), the 5 evaluations 5 s (already batched over the
10 episodes), batch sampling 4 s and data loading under 1 s. Tried, in one process and in turns:

* a cheaper dropout mask (16/32-bit lanes of ``random_`` on int64, 4x cheaper than
  ``bernoulli_`` per element) in every Dropout and in a hand-written attention, plus AdamW
  ``fused=True``: 10-15% off a step (17 against 19.5 ms), since the hand-written attention
  gives back part of what the mask saves;
* ``torch.compile`` of the whole model, with a static-shape loss (no boolean indexing) and no
  data-dependent branch: 36 against 21 ms, slower still.

So on this CPU the levers add up to about 1.3x at most (ensemble 8%, dropout and optimizer
10-15%). Not tried then: bfloat16 mixed precision, which this CPU runs natively (AVX-512
BF16): ``bench_throughput.py`` measures 1.5-2.0x the runs per CPU-hour at d128 with 3 layers
and 1.2-1.55x at d64 with 2 (two days). The cheaper dropout mask and fused AdamW are now
``TrainConfig(kernels="fast")`` (32-bit lanes, exact to 2^-32); on top of bfloat16 they take
a tenth to a fifth off a transformer's step (2026-11-29).

Does bfloat16 change that? (2026-12-02, beside a running two-process study, d64 with 2 layers,
the v2 studies' size, 20 updates x 4 repeats in turns.) One ``Trainer.step`` at batch 320 against
batch 64 costs 4.72x in float32 and 4.25x in bf16 with the fast kernels for the DT (346.5
against 73.5 ms, 232.5 against 54.7), 4.28x and 4.31x for the HDT. Stacking five seeds could
save at most 15% on top of bf16+fast: with it, about 1.45 x 1.15 = 1.7x, still short of 2x.

    python benchmarks/bench_ensemble.py                 # 5 seeds, d32, 1 layer, batch 64
    python benchmarks/bench_ensemble.py --d-model 128 --n-layer 3
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time

import torch
from bench_seq import make_data
from torch.func import functional_call, stack_module_state, vmap

from thesis_lib.seq import models as seq_models_mod
from thesis_lib.seq.models import DecisionTransformer, DTConfig
from thesis_lib.seq.trainer import batch_to_torch


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--seeds", type=int, default=5, help="models trained together")
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--K", type=int, default=20)
    p.add_argument("--d-model", type=int, default=32)
    p.add_argument("--n-layer", type=int, default=1)
    p.add_argument("--iters", type=int, default=20, help="updates per timed run")
    p.add_argument("--repeats", type=int, default=5)
    return p.parse_args()


def main() -> None:
    args = parse_args()
    torch.set_num_threads(1)
    sd, ad = 11, 3  # Hopper's sizes
    seq = make_data(args.K, sd, ad)
    cfg = DTConfig(sd, ad, K=args.K, d_model=args.d_model, n_layers=args.n_layer, n_heads=1)
    models = []
    for s in range(args.seeds):
        torch.manual_seed(s)
        models.append(DecisionTransformer(cfg))
    seq_models = [copy.deepcopy(m) for m in models]
    seq_opts = [torch.optim.AdamW(m.parameters(), lr=3e-4) for m in seq_models]

    params, buffers = stack_module_state(models)  # leaves of shape (seeds, ...)
    ens_opt = torch.optim.AdamW(list(params.values()), lr=3e-4)
    base = copy.deepcopy(models[0]).to("meta")

    def one_loss(p, b, batch):
        # the model's own loss logs a float (.item()), which vmap cannot: the same MSE here
        pred = functional_call(base, (p, b), (batch,)).actions
        return ((pred - batch["actions"]) ** 2).mean()

    vmapped = vmap(one_loss, in_dims=(0, 0, 0), randomness="different")
    check = seq_models_mod._check_inputs

    def ens_loss(p, b, stacked):
        # The models' input check reads a value (the largest time step), which vmap cannot;
        # the sequential run checks the same kind of batches, so the ensemble skips it here.
        seq_models_mod._check_inputs = lambda model, batch, keys: (
            batch["states"].shape[0],
            batch["states"].shape[1],
        )
        try:
            return vmapped(p, b, stacked)
        finally:
            seq_models_mod._check_inputs = check

    def batches() -> list[dict[str, torch.Tensor]]:
        # Without the padding mask, in both runs: the trunk branches on the mask's values
        # (the fused causal kernel when every step is real), which vmap cannot trace.
        out = []
        for _ in range(args.seeds):
            b = batch_to_torch(seq, seq.sample(args.batch), "cpu")
            b.pop("mask", None)
            out.append(b)
        return out

    def run_sequential() -> float:
        t = time.perf_counter()
        for _ in range(args.iters):
            for m, opt, batch in zip(seq_models, seq_opts, batches()):
                m.train()
                loss = ((m(batch).actions - batch["actions"]) ** 2).mean()
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
        return (time.perf_counter() - t) / (args.iters * args.seeds)

    def run_ensemble() -> float:
        base.train()
        t = time.perf_counter()
        for _ in range(args.iters):
            bs = batches()
            stacked = {k: torch.stack([b[k] for b in bs]) for k in bs[0]}
            loss = ens_loss(params, buffers, stacked).sum()
            ens_opt.zero_grad(set_to_none=True)
            loss.backward()
            ens_opt.step()
        return (time.perf_counter() - t) / (args.iters * args.seeds)

    run_sequential(), run_ensemble()  # warm-up
    seq_t, ens_t = [], []
    for _ in range(args.repeats):  # in turns
        seq_t.append(run_sequential())
        ens_t.append(run_ensemble())
    s, e = statistics.median(seq_t), statistics.median(ens_t)
    n_par = sum(p.numel() for p in models[0].parameters())
    print(
        f"DT d{args.d_model} x{args.n_layer} layer(s), {n_par:,} parameters, batch {args.batch}, "
        f"K {args.K}, {args.seeds} seeds, {args.iters} updates x {args.repeats} repeats"
    )
    print(f"sequential: {1e3 * s:7.2f} ms per seed-update (best {1e3 * min(seq_t):.2f})")
    print(f"ensemble:   {1e3 * e:7.2f} ms per seed-update (best {1e3 * min(ens_t):.2f})")
    print(f"ratio sequential / ensemble: {s / e:.2f} (above 1: the ensemble pays)")


if __name__ == "__main__":
    main()
