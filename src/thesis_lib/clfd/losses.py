"""The three training objectives of the CLfD chapter (thesis 4.2.1 and 4.2.2.1).

- :func:`nt_xent`: CLfD's loss (Eq 4.1, Algorithm 1): for a batch of N anchor-positive pairs the
  other 2(N-1) frames of the batch, from both views, are the negatives.
- :func:`triplet_loss`: the TCN baseline (Sermanet et al. 2018): anchor and positive are the same
  instant from two cameras, the negative another instant of the anchor's camera.
- :func:`cmc_loss`: the CMC baseline (Tian et al. 2020) as the thesis adapted it: the two "views"
  are two cameras (not L and ab colour channels); each anchor is contrasted with the frames of
  the *other* view only, in both directions, at CMC's temperature 0.07.

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def nt_xent(z_a: torch.Tensor, z_p: torch.Tensor, temperature: float = 0.5) -> torch.Tensor:
    """Normalised temperature-scaled cross-entropy (SimCLR), Eq 4.1 averaged as in Algorithm 1.

    Args:
        z_a: (N, D) projections of the anchors.
        z_p: (N, D) projections of the positives; row k pairs with row k of ``z_a``.
        temperature: τ (the thesis uses 0.5).

    Returns:
        The scalar loss ``1/(2N) Σ_k [ℓ(a_k, p_k) + ℓ(p_k, a_k)]`` with
        ``ℓ(i, j) = -log exp(sim(z_i, z_j)/τ) / Σ_{k≠i} exp(sim(z_i, z_k)/τ)`` over all 2N items.

    >>> z = torch.eye(4)
    >>> round(float(nt_xent(z[:2], z[:2])), 4)  # identical pairs, orthogonal negatives
    0.2395
    """
    if z_a.shape != z_p.shape or z_a.ndim != 2:
        raise ValueError(
            f"nt_xent expects two (N, D) tensors of the same shape, got {tuple(z_a.shape)} and "
            f"{tuple(z_p.shape)}."
        )
    n = z_a.shape[0]
    if n < 2:
        raise ValueError(
            f"nt_xent needs at least 2 pairs per batch (negatives come from the batch), got {n}."
        )
    z = F.normalize(torch.cat([z_a, z_p], dim=0), dim=1)  # (2N, D)
    sim = z @ z.T / temperature  # (2N, 2N) cosine similarities / τ
    sim = sim.masked_fill(
        torch.eye(2 * n, dtype=torch.bool, device=z.device), float("-inf")
    )  # k ≠ i
    target = torch.cat([torch.arange(n, 2 * n), torch.arange(0, n)]).to(z.device)  # i's positive
    return F.cross_entropy(sim, target)


def triplet_loss(
    anchor: torch.Tensor, positive: torch.Tensor, negative: torch.Tensor, margin: float = 0.2
) -> torch.Tensor:
    """TCN's triplet loss on L2-normalised embeddings: mean of ``max(0, |a-p|² - |a-n|² + margin)``.

    >>> a = torch.tensor([[1.0, 0.0]]); n = torch.tensor([[0.0, 1.0]])
    >>> float(triplet_loss(a, a, n))  # positive = anchor, negative far: no loss
    0.0
    """
    a, p, n = (F.normalize(x, dim=1) for x in (anchor, positive, negative))
    d_ap = (a - p).pow(2).sum(1)
    d_an = (a - n).pow(2).sum(1)
    return F.relu(d_ap - d_an + margin).mean()


def cmc_loss(z_a: torch.Tensor, z_p: torch.Tensor, temperature: float = 0.07) -> torch.Tensor:
    """Cross-view InfoNCE (CMC): view a's frame k against all frames of view b, and back.

    Unlike :func:`nt_xent`, frames of the anchor's own view are never negatives.

    >>> z = torch.eye(3)
    >>> bool(cmc_loss(z, z) < cmc_loss(z, z.flip(0)))
    True
    """
    if z_a.shape != z_p.shape or z_a.ndim != 2:
        raise ValueError(
            f"cmc_loss expects two (N, D) tensors of the same shape, got {tuple(z_a.shape)} and "
            f"{tuple(z_p.shape)}."
        )
    a, p = F.normalize(z_a, dim=1), F.normalize(z_p, dim=1)
    logits = a @ p.T / temperature  # (N, N)
    target = torch.arange(a.shape[0], device=a.device)
    return 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))
