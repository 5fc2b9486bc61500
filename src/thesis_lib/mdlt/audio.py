"""Audio features for music-to-dance translation (thesis 6.3.2).

The 438-dimensional feature vector of the thesis, extracted with librosa at 60 frames per
second: the audio is resampled to ``fps * 512`` Hz (30 720 Hz at 60 fps) and every feature uses
a hop of 512 samples and ``n_fft = 2048``, as the authors' code did.

========================  =====  ===============================================
block                     dims   how (librosa)
========================  =====  ===============================================
MFCC                      20     ``mfcc(S=power_to_db(melspectrogram, ref=max))``
MFCC delta                20     ``delta(mfcc, width=3)``
constant-Q chroma         12     ``chroma_cqt`` of the HPSS harmonic part, 7 octaves
onset strength            1      ``onset_strength`` of the HPSS percussive part
beat one-hot              1      ``beat_track(onset_envelope=...)``
tempogram                 384    ``tempogram(onset_envelope=...)``
========================  =====  ===============================================

:func:`audio_features` returns the raw (unscaled) features. :class:`FeatureScaler` is the
per-dimension min-max scaling to [0.1, 0.9]; :func:`fit_feature_scaler` fits it on the training
split only (the authors fitted it on every file, validation included: ``paper_compat=True``).
:func:`cached_audio_features` caches the features of a file on disk, keyed by its content.

Speed: the harmonic/percussive separation uses the same median filters as
``librosa.decompose.hpss`` (31 bins, reflect edges, soft masks with power 2), computed with
bottleneck's running median, several times faster than ``scipy.ndimage.median_filter``;
the STFT is shared by the mel spectrogram and the separation. Thesis chapter 6.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from thesis_lib._io import atomic_write
from thesis_lib.paths import data_dir

HOP_LENGTH = 512
"""Samples between feature frames (the authors' value); the sample rate is ``fps * HOP_LENGTH``."""
N_FFT = 2048
N_FEATURES = 438
FEATURE_SLICES: dict[str, slice] = {
    "mfcc": slice(0, 20),
    "mfcc_delta": slice(20, 40),
    "chroma_cqt": slice(40, 52),
    "onset_strength": slice(52, 53),
    "beat": slice(53, 54),
    "tempogram": slice(54, 438),
}
"""Where each feature block lives in the 438-dimensional vector."""
FEATURE_VERSION = "mdlt-features-v1"
"""Changes whenever the extraction changes, so stale cache entries are not reused."""

_HPSS_KERNEL = 31  # librosa.decompose.hpss default kernel_size
_SILENCE_PEAK = 1e-5  # peak amplitude below which a signal counts as silent


class AudioError(ValueError):
    """Audio that cannot be used: unreadable, empty, silent, too short or not finite."""


def feature_sample_rate(fps: int = 60) -> int:
    """Sample rate the audio is resampled to so that ``fps`` frames/s come from a hop of 512.

    >>> feature_sample_rate(60)
    30720
    """
    if int(fps) != fps or fps <= 0:
        raise ValueError(f"fps must be a positive integer, got {fps!r}.")
    return int(fps) * HOP_LENGTH


def _check_sr(sr: object, where: str) -> int:
    """``sr`` as an int, or a ``ValueError`` naming ``sr`` unless it is a whole number of Hz > 0."""
    try:
        ok = not isinstance(sr, bool) and int(sr) == sr and sr > 0  # type: ignore[call-overload,operator]
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"{where}: expect a positive sample rate `sr` in Hz, actually: {sr!r}.")
    return int(sr)  # type: ignore[call-overload]


def load_audio(path: str | os.PathLike, sr: int | None = None) -> tuple[np.ndarray, int]:
    """Read an audio file as mono float32, resampled to ``sr`` when given.

    Any format libsndfile reads (wav, flac, ogg, ...) works; several channels are averaged.

    Args:
        path: the audio file.
        sr: target sample rate in Hz; ``None`` keeps the file's rate.

    Returns:
        ``(y, sr)``: samples (n,) float32 and their sample rate.

    Raises:
        FileNotFoundError: no such file.
        AudioError: the file is not audio libsndfile can read, or holds no samples.
    """
    import soundfile as sf

    if sr is not None:
        sr = _check_sr(sr, "load_audio")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"No audio file at {path}.")
    try:
        y, file_sr = sf.read(str(path), dtype="float32", always_2d=True)
    except Exception as e:  # soundfile raises LibsndfileError / RuntimeError / TypeError
        raise AudioError(
            f"Cannot read {path} as audio ({type(e).__name__}: {e}). Expected a file libsndfile "
            "reads (wav, flac, ogg, aiff); convert mp3/m4a first, e.g. "
            "'ffmpeg -i song.mp3 song.wav'."
        ) from e
    if y.size == 0:
        raise AudioError(f"{path} holds no audio samples.")
    y = y.mean(axis=1)
    if sr is not None and int(sr) != int(file_sr):
        y = _resample(y, int(file_sr), int(sr))
        file_sr = int(sr)
    return np.ascontiguousarray(y, dtype=np.float32), int(file_sr)


def _resample(y: np.ndarray, orig_sr: int, target_sr: int) -> np.ndarray:
    import librosa

    return librosa.resample(y, orig_sr=orig_sr, target_sr=target_sr, res_type="soxr_hq")


def _check_signal(y: np.ndarray, where: str) -> np.ndarray:
    y = np.asarray(y)
    if y.ndim == 2 and 1 in y.shape:
        y = y.reshape(-1)
    if y.ndim != 1:
        raise AudioError(
            f"{where}: expected a 1-D (mono) signal, got shape {y.shape}. Average the channels "
            "first (y.mean(axis=0) for librosa's (channels, n) layout)."
        )
    if not np.all(np.isfinite(y)):
        raise AudioError(
            f"{where}: the signal holds {int((~np.isfinite(y)).sum())} NaN/inf samples."
        )
    if y.size < N_FFT:
        raise AudioError(f"{where}: {y.size} samples is too short; at least {N_FFT} are needed.")
    peak = float(np.max(np.abs(y)))
    if peak < _SILENCE_PEAK:
        raise AudioError(
            f"{where}: the signal is silent (peak amplitude {peak:.2e} < {_SILENCE_PEAK:.0e}); "
            "no features can be extracted from silence."
        )
    return y.astype(np.float32, copy=False)


def _rolling_median(x: np.ndarray, axis: int, width: int = _HPSS_KERNEL) -> np.ndarray:
    """Centred running median along ``axis`` with reflected edges.

    Equals ``scipy.ndimage.median_filter(x, size=width along axis, mode='reflect')``, which
    librosa's HPSS uses, computed with bottleneck's ``move_median`` (a double heap, O(n log w))
    or, without bottleneck, pandas' rolling median.
    """
    half = width // 2
    a = np.moveaxis(x, axis, -1)  # median along the last axis
    padded = np.pad(
        a, [(0, 0)] * (a.ndim - 1) + [(half, half)], mode="symmetric"
    )  # == scipy 'reflect'
    try:
        import bottleneck as bn

        med = bn.move_median(padded, width, axis=-1)[..., 2 * half :]
    except ImportError:  # pragma: no cover - bottleneck is in requirements.txt
        import pandas as pd

        med = (
            pd.DataFrame(padded.T)
            .rolling(width, center=True)
            .median()
            .to_numpy()
            .T[..., half:-half]
        )
    return np.moveaxis(med.astype(x.dtype, copy=False), -1, axis)


def _hpss_stft(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Harmonic and percussive STFTs, as ``librosa.decompose.hpss(D)`` (margin 1, power 2)."""
    import librosa

    S = np.abs(D)
    harm = _rolling_median(S, axis=1)  # along time: sustained partials
    perc = _rolling_median(S, axis=0)  # along frequency: broadband clicks
    mask_h = librosa.util.softmask(harm, perc, power=2.0, split_zeros=False)
    mask_p = librosa.util.softmask(perc, harm, power=2.0, split_zeros=False)
    return D * mask_h, D * mask_p


def audio_features(
    audio: str | os.PathLike | np.ndarray, sr: int | None = None, fps: int = 60
) -> np.ndarray:
    """The raw 438-dimensional features of a piece of music, ``fps`` frames per second.

    Args:
        audio: a path to an audio file, or a 1-D signal (then ``sr`` is required). Files and
            signals at another rate are resampled to ``fps * 512`` Hz.
        sr: sample rate of ``audio`` when it is an array; ignored for paths.
        fps: feature frames per second (the thesis: 60).

    Returns:
        (T, 438) float32, unscaled, in the order of :data:`FEATURE_SLICES`;
        ``T = 1 + n // 512`` for ``n`` samples at the feature rate; frame ``i`` is centred at
        ``i / fps`` seconds.

    Raises:
        AudioError: unreadable, silent, too short or non-finite audio.
        ValueError: an array without ``sr``, or ``sr`` not a positive number of Hz.
    """
    import librosa

    target_sr = feature_sample_rate(fps)
    if isinstance(audio, (str, os.PathLike)):
        y, _ = load_audio(audio, sr=target_sr)
        where = str(audio)
    else:
        if sr is None:
            raise ValueError("audio_features: pass sr= (Hz) with an array signal.")
        sr = _check_sr(sr, "audio_features")
        y = _check_signal(audio, "audio_features")
        if sr != target_sr:
            y = _resample(y, sr, target_sr)
        where = "audio_features"
    y = _check_signal(y, where)

    hop = HOP_LENGTH
    D = librosa.stft(y, n_fft=N_FFT, hop_length=hop)  # (1025, T) complex
    mel = librosa.feature.melspectrogram(
        S=np.abs(D) ** 2, sr=target_sr, n_fft=N_FFT, hop_length=hop
    )
    mfcc = librosa.feature.mfcc(S=librosa.power_to_db(mel, ref=np.max), n_mfcc=20)
    mfcc_delta = librosa.feature.delta(mfcc, width=3)

    D_h, D_p = _hpss_stft(D)
    y_h = librosa.istft(D_h, hop_length=hop, n_fft=N_FFT, length=len(y))
    y_p = librosa.istft(D_p, hop_length=hop, n_fft=N_FFT, length=len(y))
    if np.max(np.abs(y_h)) > 0:
        chroma = librosa.feature.chroma_cqt(y=y_h, sr=target_sr, hop_length=hop, n_octaves=7)
    else:  # a purely percussive signal has no pitch content
        chroma = np.zeros((12, D.shape[1]), dtype=np.float32)
    onset = librosa.onset.onset_strength(y=y_p, sr=target_sr, hop_length=hop, n_fft=N_FFT)
    _, beat_frames = librosa.beat.beat_track(onset_envelope=onset, sr=target_sr, hop_length=hop)
    beat = np.zeros_like(onset)
    beat[np.asarray(beat_frames, dtype=int)] = 1.0
    tempogram = librosa.feature.tempogram(
        onset_envelope=onset, sr=target_sr, hop_length=hop, win_length=384
    )

    blocks = [mfcc, mfcc_delta, chroma, onset[None], beat[None], tempogram]
    T = min(b.shape[1] for b in blocks)
    feats = np.concatenate([b[:, :T] for b in blocks], axis=0).T.astype(np.float32)
    assert feats.shape[1] == N_FEATURES, f"expected {N_FEATURES} features, got {feats.shape[1]}"
    return np.ascontiguousarray(feats)


def default_cache_dir() -> Path:
    """Feature cache: ``$THESIS_MDLT_CACHE``, else ``<data dir>/thesis-mdlt/feature-cache``."""
    p = os.environ.get("THESIS_MDLT_CACHE")
    if p:
        return Path(p)

    return data_dir() / "thesis-mdlt" / "feature-cache"


def _file_digest(path: Path) -> str:
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def cached_audio_features(
    path: str | os.PathLike, fps: int = 60, cache_dir: str | os.PathLike | None | bool = None
) -> np.ndarray:
    """:func:`audio_features` of a file, cached on disk by the file's content.

    The key is the SHA-1 of the file's bytes, ``fps`` and :data:`FEATURE_VERSION`, so a changed
    file or a changed extraction is never served stale features, and read-only data roots (a
    real AIST++ download) work.

    Args:
        path: the audio file.
        fps: feature frames per second.
        cache_dir: where ``.npy`` files go; ``None`` uses :func:`default_cache_dir`;
            ``False`` disables the cache.
    """
    path = Path(path)
    if cache_dir is False:
        return audio_features(path, fps=fps)
    if not path.is_file():
        raise FileNotFoundError(f"No audio file at {path}.")
    cdir = default_cache_dir() if cache_dir is None or cache_dir is True else Path(cache_dir)
    key = hashlib.sha1(f"{_file_digest(path)}|{fps}|{FEATURE_VERSION}".encode()).hexdigest()[:20]
    cfile = cdir / f"{path.stem}-{key}.npy"
    if cfile.is_file():
        try:
            x = np.load(cfile)
            if x.ndim == 2 and x.shape[1] == N_FEATURES:
                return x
        except Exception:  # a truncated cache file: recompute it
            pass
    x = audio_features(path, fps=fps)
    atomic_write(cfile, lambda tmp: np.save(tmp, x), keep_suffix=True)  # workers share the cache
    return x


def check_feature_groups(groups: Iterable[str], where: str) -> None:
    """Raise ``ValueError`` naming ``where`` if a group is not a :data:`FEATURE_SLICES` name."""
    unknown = [g for g in groups if g not in FEATURE_SLICES]
    if unknown:
        raise ValueError(
            f"Unknown feature group(s) {unknown} {where}. Valid: {', '.join(FEATURE_SLICES)}."
        )


class FeatureScaler:
    """Per-dimension min-max scaling of features to ``[low, high]`` (thesis: [0.1, 0.9]).

    ``transform`` maps the fitted minimum of each dimension to ``low`` and the maximum to
    ``high``; values outside the fitted range (unseen music) land outside ``[low, high]`` unless
    ``clip=True``. A dimension that was constant while fitting is only shifted
    (``low + (high - low) * (x - min)``) instead of divided by zero; the authors added 1e-9 to
    the range, which blows such a dimension up by 1e9 on unseen music.

    >>> s = FeatureScaler().fit([np.array([[0.0, 5.0], [2.0, 5.0]])])
    >>> s.transform(np.array([[1.0, 5.0]])).astype(float).round(3).tolist()
    [[0.5, 0.1]]
    """

    def __init__(
        self, low: float = 0.1, high: float = 0.9, clip: bool = False, mute: Sequence[str] = ()
    ):
        if not low < high:
            raise ValueError(f"FeatureScaler needs low < high, got low={low}, high={high}.")
        check_feature_groups(mute, "to mute")
        self.low, self.high, self.clip = float(low), float(high), bool(clip)
        self.mute = tuple(mute)
        """Feature groups (:data:`FEATURE_SLICES` names) that ``transform`` holds at ``low``: a
        model then gets no information from them (the input size stays 438)."""
        self.min_: np.ndarray | None = None
        self.max_: np.ndarray | None = None

    def fit(self, features: Sequence[np.ndarray] | np.ndarray) -> FeatureScaler:
        """Fit the per-dimension minimum and maximum over a list of (T_i, D) arrays."""
        arrays = [features] if isinstance(features, np.ndarray) else list(features)
        if not arrays:
            raise ValueError("FeatureScaler.fit needs at least one (T, D) array, got none.")
        dims = {a.shape[-1] for a in arrays}
        if len(dims) != 1 or any(np.ndim(a) != 2 for a in arrays):
            raise ValueError(
                f"FeatureScaler.fit expects (T, D) arrays with one D, got shapes {[np.shape(a) for a in arrays]}."
            )
        self.min_ = np.min([np.nanmin(a, axis=0) for a in arrays], axis=0).astype(np.float64)
        self.max_ = np.max([np.nanmax(a, axis=0) for a in arrays], axis=0).astype(np.float64)
        return self

    def transform(self, x: np.ndarray) -> np.ndarray:
        """Scale (..., D) features; returns float32."""
        if self.min_ is None or self.max_ is None:
            raise RuntimeError("FeatureScaler.transform called before fit (or from_state_dict).")
        x = np.asarray(x)
        if x.shape[-1] != self.min_.shape[0]:
            raise ValueError(
                f"FeatureScaler was fitted on {self.min_.shape[0]} dimensions, got input of shape {x.shape}."
            )
        rng = self.max_ - self.min_
        rng = np.where(rng > 0, rng, 1.0)
        y = self.low + (self.high - self.low) * (x - self.min_) / rng
        if self.clip:
            y = np.clip(y, self.low, self.high)
        for group in self.mute:
            y[..., FEATURE_SLICES[group]] = self.low
        return y.astype(np.float32)

    def fit_transform(self, features: Sequence[np.ndarray]) -> list[np.ndarray]:
        self.fit(features)
        return [self.transform(a) for a in features]

    def state_dict(self) -> dict:
        """Plain lists and floats, so a checkpoint (torch.save / json) can carry the scaler."""
        if self.min_ is None or self.max_ is None:
            raise RuntimeError("FeatureScaler.state_dict called before fit.")
        return {
            "low": self.low,
            "high": self.high,
            "clip": self.clip,
            "mute": list(self.mute),
            "min": self.min_.tolist(),
            "max": self.max_.tolist(),
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> FeatureScaler:
        s = cls(
            low=state["low"],
            high=state["high"],
            clip=state.get("clip", False),
            mute=state.get("mute", ()),
        )
        s.min_ = np.asarray(state["min"], dtype=np.float64)
        s.max_ = np.asarray(state["max"], dtype=np.float64)
        if s.min_.shape != s.max_.shape or s.min_.ndim != 1:
            raise ValueError(
                "FeatureScaler state: 'min' and 'max' must be 1-D lists of one length."
            )
        return s


def fit_feature_scaler(
    train: Iterable[np.ndarray],
    held_out: Iterable[np.ndarray] = (),
    paper_compat: bool = False,
    low: float = 0.1,
    high: float = 0.9,
    clip: bool | None = None,
    mute: Sequence[str] = (),
) -> FeatureScaler:
    """The thesis's min-max scaler, fitted on the training features only.

    Args:
        train: (T_i, 438) raw features of the training sequences.
        held_out: features of validation/test sequences; used only when ``paper_compat``.
        paper_compat: fit on train + held-out data, as the authors' preprocessing did (it scaled
            the whole corpus before splitting: information from the validation music leaks into
            the inputs).
        clip: clip transformed values to ``[low, high]``. Default: on, unless ``paper_compat``.
            A scaler fitted on the training songs only sees unseen music leave its range, and
            the tempogram's 384 dimensions do so most: a lag that hardly varied in the training
            songs maps a new song's value far outside (on the default smoke set, per-genre
            folds: values up to 6-8, 7-8 % of all values outside [0.1, 0.9]), inputs no model
            was trained on. The authors' fit on every song hid this (nothing is out
            of range then); clipping is what keeps the honest split usable (sklearn's
            ``MinMaxScaler(clip=True)`` does the same).
        mute: feature groups held constant (:attr:`FeatureScaler.mute`); not in the thesis, for
            experiments such as the MDLT chapter's tempogram probe.
    """
    arrays = list(train) + (list(held_out) if paper_compat else [])
    clip = (not paper_compat) if clip is None else bool(clip)
    return FeatureScaler(low=low, high=high, clip=clip, mute=mute).fit(arrays)
