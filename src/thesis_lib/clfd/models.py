"""Encoders and the projection head of CLfD (thesis 4.2.1, Fig 4.1).

- :class:`ResNet18`: the standard ResNet-18 (He et al. 2016), written here because torchvision's
  PyPI wheel for torch 2.13 needs the CUDA build of torch (``import torchvision`` fails on the CPU
  build: "operator torchvision::nms does not exist"). Module names follow torchvision's, so an
  ImageNet state dict saved from ``torchvision.models.resnet18`` loads with
  :meth:`ResNet18.load_imagenet`. ``width`` scales the channels (64 = the real ResNet-18;
  the smoke profile uses 16 to fit a 2-core CPU). The 1000-way classifier is replaced by
  Linear(8·width → 32), as the authors did.
- :class:`TCNEncoder`: the TCN baseline's head (Sermanet et al. 2018; the authors' "TCN"
  encoder): two conv-BN-ReLU layers, a spatial softmax (expected image coordinates of every
  channel), a fully connected layer to 32 features, L2-normalised and scaled by 10. The original
  puts this head on Inception-v3 up to Mixed_5d with ImageNet weights; neither can be had here,
  so a three-layer convolutional trunk trained from scratch stands in for it.
- :class:`ProjectionHead`: the MLP with one hidden layer of N = 32 units to the 64-d space
  where the loss is applied (SimCLR's projection head).

Used in: CLfD (thesis 4.2), chapter 02_clfd.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal, get_args

import torch
import torch.nn.functional as F
from torch import nn

EncoderName = Literal["resnet18", "tcn"]
ENCODERS: tuple[str, ...] = get_args(EncoderName)

# Images are scaled to [0, 1], then standardised with ImageNet's statistics (what pre-trained
# weights expect; harmless from scratch).
_MEAN = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
_STD = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)


def to_tensor(frames) -> torch.Tensor:
    """uint8 frames (..., H, W, 3) → float (N, 3, H, W), standardised."""
    x = torch.as_tensor(frames)
    if x.dtype != torch.uint8:
        raise ValueError(f"Frames must be uint8 images (..., H, W, 3), got dtype {x.dtype}.")
    if x.ndim < 3 or x.shape[-1] != 3:
        raise ValueError(f"Frames must have shape (..., H, W, 3), got {tuple(x.shape)}.")
    x = x.reshape(-1, *x.shape[-3:]).permute(0, 3, 1, 2).float().div_(255.0)
    return (x - _MEAN) / _STD


class BasicBlock(nn.Module):
    """ResNet's two 3x3 convolutions with a shortcut (torchvision's names)."""

    def __init__(self, c_in: int, c_out: int, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(c_out)
        self.downsample = None
        if stride != 1 or c_in != c_out:
            self.downsample = nn.Sequential(
                nn.Conv2d(c_in, c_out, 1, stride, bias=False), nn.BatchNorm2d(c_out)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return F.relu(out + (x if self.downsample is None else self.downsample(x)))


class ResNet18(nn.Module):
    """ResNet-18 ending in a ``feature_dim`` linear layer. Input (B, 3, H, W), output (B, feature_dim)."""

    def __init__(self, feature_dim: int = 32, width: int = 64) -> None:
        super().__init__()
        w = width
        self.conv1 = nn.Conv2d(3, w, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(w)
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        self.layer1 = nn.Sequential(BasicBlock(w, w), BasicBlock(w, w))
        self.layer2 = nn.Sequential(BasicBlock(w, 2 * w, 2), BasicBlock(2 * w, 2 * w))
        self.layer3 = nn.Sequential(BasicBlock(2 * w, 4 * w, 2), BasicBlock(4 * w, 4 * w))
        self.layer4 = nn.Sequential(BasicBlock(4 * w, 8 * w, 2), BasicBlock(8 * w, 8 * w))
        self.fc = nn.Linear(8 * w, feature_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.maxpool(F.relu(self.bn1(self.conv1(x))))
        x = self.layer4(self.layer3(self.layer2(self.layer1(x))))
        return self.fc(torch.flatten(F.adaptive_avg_pool2d(x, 1), 1))  # (B, feature_dim)

    def load_imagenet(self, path: str | Path) -> list[str]:
        """Load a torchvision ``resnet18`` state dict (e.g. ImageNet weights) from a local file.

        The classifier (``fc``) is skipped. Returns the keys that were not loaded.

        Raises:
            FileNotFoundError: no such file.
            ValueError: the file's shapes do not fit (e.g. ``width`` is not 64).
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(
                f"No weights file {path}. Give the path of a torchvision resnet18 state dict."
            )
        state = torch.load(path, map_location="cpu", weights_only=True)
        state = {k: v for k, v in state.items() if not k.startswith("fc.")}
        own = self.state_dict()
        bad = [k for k, v in state.items() if k in own and own[k].shape != v.shape]
        if bad:
            raise ValueError(
                f"Weights in {path} do not fit this ResNet18 (width {self.conv1.out_channels}): e.g. {bad[0]} is "
                f"{tuple(state[bad[0]].shape)}, expected {tuple(own[bad[0]].shape)}. ImageNet weights need width=64."
            )
        missing, _ = self.load_state_dict(state, strict=False)
        return list(missing)


class SpatialSoftmax(nn.Module):
    """Expected (x, y) image coordinates of each channel's softmax over pixels: (B, C, H, W) → (B, 2C).

    The softmax has a learned inverse temperature (as in Levine et al.'s spatial softmax); it
    starts at ``beta`` so that the keypoints are not all at the image centre at initialisation.
    """

    def __init__(self, beta: float = 5.0) -> None:
        super().__init__()
        self.log_beta = nn.Parameter(torch.tensor(float(beta)).log())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, h, w = x.shape
        p = F.softmax(self.log_beta.exp() * x.reshape(b, c, h * w), dim=-1).reshape(b, c, h, w)
        ys = torch.linspace(-1, 1, h, device=x.device)
        xs = torch.linspace(-1, 1, w, device=x.device)
        ex = (p.sum(2) * xs).sum(-1)  # (B, C)
        ey = (p.sum(3) * ys).sum(-1)  # (B, C)
        return torch.cat([ex, ey], dim=1)


class TCNEncoder(nn.Module):
    """A small convolutional trunk with the TCN head; output L2-normalised × ``alpha``: (B, feature_dim)."""

    def __init__(self, feature_dim: int = 32, width: int = 32, alpha: float = 10.0) -> None:
        super().__init__()
        w = width

        def block(c_in: int, c_out: int, stride: int) -> nn.Sequential:
            return nn.Sequential(
                nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU()
            )

        # trunk: stands in for Inception-v3 up to Mixed_5d (not available without downloads)
        self.trunk = nn.Sequential(block(3, w, 2), block(w, 2 * w, 2), block(2 * w, 2 * w, 1))
        # TCN head: two conv-BN layers (the second without ReLU: the softmax needs signed logits),
        # spatial softmax, fully connected
        self.head = nn.Sequential(
            block(2 * w, 2 * w, 1), nn.Conv2d(2 * w, w, 3, 1, 1, bias=False), nn.BatchNorm2d(w)
        )
        self.softmax = SpatialSoftmax()
        self.fc = nn.Linear(2 * w, feature_dim)
        self.alpha = alpha

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.fc(self.softmax(self.head(self.trunk(x))))
        return self.alpha * F.normalize(h, dim=1)


class ProjectionHead(nn.Module):
    """g: MLP with one hidden layer of ``hidden`` units, (B, feature_dim) → (B, out_dim)."""

    def __init__(self, feature_dim: int = 32, hidden: int = 32, out_dim: int = 64) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(feature_dim, hidden), nn.ReLU(), nn.Linear(hidden, out_dim)
        )

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return self.net(h)


def make_encoder(name: str, feature_dim: int = 32, width: int | None = None) -> nn.Module:
    """``"resnet18"`` or ``"tcn"`` (the TCN-style encoder); ``width`` None = the default of each."""
    if name == "resnet18":
        return ResNet18(feature_dim, width or 64)
    if name == "tcn":
        return TCNEncoder(feature_dim, width or 32)
    raise ValueError(f"Unknown encoder {name!r}. Valid: {', '.join(ENCODERS)}.")
