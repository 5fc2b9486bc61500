"""The default offline music-dance data sets, written in the AIST++ and PhantomDance layouts.

No dance data set can be downloaded here, so the project makes its own and writes it in the real
file formats; :func:`readers.load_aist` / :func:`readers.load_phantomdance` load it exactly as
they load a real download.

**Music** (numpy, written with soundfile): 10 genres named after AIST's (``mBR`` ... ``mJB``), 6
pieces each (the thesis's subset of AIST++), at tempos spread over AIST's 80-135 BPM. Genres
differ in rhythm (drum patterns, swing), harmony (major/minor) and timbre (bass wave, pad
partials, brightness, distortion). Each piece has its own key, tempo and chord sequence (one
chord per 4/4 bar, a crash on every downbeat) and alternates two-bar sections: verse, then a
louder chorus with an arpeggio.

**Dance**: every genre has a vocabulary of three two-beat moves of the right arm (verse, chorus,
solo: a key pose every beat or half-beat) drawn from a genre-specific style (where the arm
tends to be, how far it swings, smooth or sharp transitions, :class:`GenreStyle`). The music
decides *what* (the section picks the move), *where* (each chord root shifts the pose,
:func:`chord_offsets`) and *when* (key poses land on the beats). Three rules hold in every
genre, so that songs of one genre teach the others (generator v6; in v5 they were genre-specific
and a small MLP barely beat the mean pose on unseen music): the chorus move is bigger (the arm higher and
more extended, :data:`ENERGY_SHIFT`), the first beat of each two-beat move is accented
(:data:`BEAT_ACCENT`), and a chord root moves the arm the same way in every genre. Dancers vary
(:class:`Dancer`): timing lag, amplitude, pose bias, a slow wander, and an improvised move in
4-12 % of the bars. The trunk turns, leans and bounces on the beat, so the pose -> angle
alignment has work to do. Pose timestamps (60 fps nominal) carry ~1 ms jitter and dropped
frames (2 %, some in runs of 2-4).

Learnable but not trivial. On the smoke set, "All Genres" folds 2-3 (held-out music), AJE in
rad: the mean training pose 0.52 / 0.55; the genre's mean pose (told the genre) 0.43 / 0.46;
the mean pose per genre, section and beat parity (told all three) 0.31 / 0.35; a small MLP on
one second of the 54 non-tempogram features, 1,500 updates, 0.46 / 0.44 (v5: 0.52 / 0.53).
A model has to recover genre, section and beat from the audio.

**Sizes** (:data:`SIZES`): ``smoke`` (6 pieces of 8 s per genre), ``full`` (6 of 32 s) and,
for the C13 study, ``study``: 12 pieces of 60 s per genre with a song form (:func:`song_form`:
intro without drums, verse/chorus sections of 2-8 bars, half-time breakdowns danced with the
solo move) on AIST's tempo grid (:data:`TEMPO_GRID`: six tempos per genre, each shared by two
of its pieces). The smoke and full sets are unchanged by the study size (byte-identical files).
The tempogram is nearly constant within a piece in every size (between-piece share of its
variance: smoke 0.67, study 0.70), but at the study size the nearest piece mean names a frame's
piece 32% of the time among 120 pieces (smoke: 80% among 60;
:func:`thesis_lib.chapters.mdlt.piece_fingerprint`), so a model can no longer tell each
training piece apart by its tempogram alone.

Poses are SMPL parameters of the project's skeleton (:mod:`.angles`); the four UR3 angles come
from the same pipeline as for real data (forward kinematics -> :func:`angles.pose_to_ur3_angles`).

Everything is deterministic by seed. Thesis chapter 6.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np

from thesis_lib.paths import data_dir

from .angles import forward_kinematics, upper_arm_direction
from .readers import PHANTOM_BONES, PHANTOM_FPS, smpl_to_phantom

GENERATOR_VERSION = "mdlt-synth-v7"
"""Changes whenever the generated data change; a cached default set of another version is remade."""
AUDIO_SR = 22050
"""Sample rate of the written music (the feature extractor resamples it, as for real music)."""
POSE_FPS = 60


@dataclass(frozen=True)
class GenreStyle:
    """Music and dance parameters of one genre."""

    code: str  # AIST music genre code
    bpm: tuple[float, float]  # tempo range over the genre's pieces
    minor: bool
    kick: str  # 16 sixteenth steps, 'x' = hit
    snare: str
    hat: str
    swing: float  # delay of the off 16ths, fraction of a 16th
    bass_wave: str  # 'sine' | 'saw' | 'square'
    pad_partials: tuple[float, ...]  # relative amplitudes of the pad's harmonics
    brightness: float  # 0..1, amount of high partials / hat level
    drive: float  # soft-clipping amount (krump, break)
    arp: bool  # the chorus arpeggio an octave higher
    # dance style: mean key pose (theta1, theta2, elbow flexion, wrist flexion), spread, sharpness
    center: tuple[float, float, float, float]
    spread: tuple[float, float, float, float]
    sharp: float  # easing exponent: 1 smooth ... 4 hits
    per_beat: int  # key poses per beat (1 or 2)
    bounce: float  # trunk bounce (rad)
    turn: float  # trunk yaw wander (rad)


GENRES: dict[str, GenreStyle] = {
    s.code: s
    for s in [
        GenreStyle("mBR", (80, 130), True, "x.....x...x.....", "....x.......x...", "x.x.x.x.x.x.x.x.", 0.10, "square",
                   (1, 0.5, 0.3, 0.2), 0.6, 0.5, False, (0.6, -0.7, 1.2, 0.4), (0.7, 0.4, 0.5, 0.3), 3.0, 2, 0.10, 0.5),
        GenreStyle("mPO", (80, 130), False, "x...x...x...x...", "....x.......x...", "..x...x...x...x.", 0.0, "sine",
                   (1, 0.6, 0.4, 0.2, 0.1), 0.7, 0.0, True, (1.0, -0.4, 0.8, 0.3), (0.6, 0.3, 0.4, 0.2), 2.5, 1, 0.06, 0.3),
        GenreStyle("mLO", (80, 130), False, "x.....x.x.......", "....x.......x...", "x.x.x.x.x.x.x.x.", 0.25, "saw",
                   (1, 0.3, 0.5, 0.1), 0.8, 0.1, True, (1.3, -0.3, 1.4, 0.6), (0.8, 0.3, 0.4, 0.3), 4.0, 2, 0.08, 0.2),
        GenreStyle("mMH", (80, 130), True, "x......xx.......", "....x.......x...", "x...x...x...x...", 0.30, "sine",
                   (1, 0.2, 0.1), 0.4, 0.2, False, (0.4, -0.2, 1.0, 0.2), (0.5, 0.3, 0.5, 0.2), 1.5, 1, 0.12, 0.4),
        GenreStyle("mLH", (80, 130), True, "x.x.......x.....", "....x..x....x...", "x.xxx.xxx.xxx.xx", 0.15, "saw",
                   (1, 0.4, 0.2, 0.3), 0.5, 0.3, False, (0.8, -0.9, 0.9, 0.5), (0.6, 0.4, 0.5, 0.3), 2.0, 2, 0.10, 0.6),
        GenreStyle("mHO", (110, 135), False, "x...x...x...x...", "....x.......x...", "..x...x...x...x.", 0.0, "sine",
                   (1, 0.7, 0.5, 0.4, 0.3, 0.2), 0.9, 0.0, True, (0.3, -0.3, 0.6, 0.2), (0.45, 0.3, 0.4, 0.15), 1.0, 2, 0.14, 0.2),
        GenreStyle("mWA", (80, 130), False, "x...x...x...x...", "....x.......x...", "xxxxxxxxxxxxxxxx", 0.0, "square",
                   (1, 0.8, 0.6, 0.4), 1.0, 0.1, True, (2.0, -0.6, 0.7, 0.8), (0.9, 0.5, 0.5, 0.4), 3.5, 2, 0.05, 0.3),
        GenreStyle("mKR", (80, 130), True, "x..x..x...x..x..", "....x.......x...", "x...x...x...x...", 0.05, "saw",
                   (1, 0.9, 0.7, 0.5), 0.3, 0.8, False, (1.1, -0.5, 1.7, 0.3), (0.9, 0.5, 0.4, 0.2), 4.0, 1, 0.15, 0.7),
        GenreStyle("mJS", (80, 130), True, "x.......x.x.....", "....x.......x...", "x.x.x.x.x.x.x.x.", 0.20, "sine",
                   (1, 0.5, 0.3, 0.3, 0.2), 0.6, 0.0, True, (1.5, -1.0, 0.5, 0.4), (0.7, 0.3, 0.4, 0.3), 1.5, 1, 0.07, 0.4),
        GenreStyle("mJB", (80, 130), False, "x.......x.......", "........x.......", "x...x...x...x...", 0.0, "sine",
                   (1, 0.3, 0.15, 0.1, 0.05), 0.3, 0.0, True, (1.9, -0.8, 0.3, 0.2), (0.8, 0.4, 0.3, 0.2), 1.0, 1, 0.03, 0.3),
    ]
}  # fmt: skip
"""The ten genres, keyed by AIST music genre code."""

_MAJOR = (0, 2, 4, 5, 7, 9, 11)
_MINOR = (0, 2, 3, 5, 7, 8, 10)
ENERGY_SHIFT = np.array([1.0, -0.3, -0.6, 0.2])
"""Shift of every genre's chorus move from its verse move (theta1 up = arm higher, elbow more
extended): louder music, bigger moves, in all genres."""
BEAT_ACCENT = np.array([0.15, 0.0, 0.25, 0.0])
"""Added to the key poses of a move's first beat, subtracted on its second (all genres)."""
_LIMITS = np.array([[-0.9, 2.9], [-1.25, 0.3], [0.0, 2.4], [0.0, 1.2]])  # key-pose bounds
SIZES = {
    # per layout: pieces per genre (aist) or pieces (phantomdance), seconds per piece, dancers/music
    ("aist", "smoke"): dict(per_genre=6, seconds=8.0, dancers=2),
    ("aist", "full"): dict(per_genre=6, seconds=32.0, dancers=3),
    # the study's (C13): minute-long songs with a form, twice the pieces per genre, one dancer
    ("aist", "study"): dict(per_genre=12, seconds=60.0, dancers=1, form=True, tempo_grid=True),
    ("phantomdance", "smoke"): dict(n=20, seconds=8.0),
    ("phantomdance", "full"): dict(n=260, seconds=24.0),
}


# ----------------------------------------------------------------------------- music


def _rng(seed: int, *keys: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *map(int, keys)]))


def _midi_hz(m: np.ndarray | float) -> np.ndarray:
    return 440.0 * 2.0 ** ((np.asarray(m, dtype=np.float64) - 69.0) / 12.0)


def _add(buf: np.ndarray, start: float, sig: np.ndarray, sr: int) -> None:
    i = int(round(start * sr))
    if i >= len(buf):
        return
    n = min(len(sig), len(buf) - i)
    buf[i : i + n] += sig[:n]


def _osc(wave: str, f: float, t: np.ndarray) -> np.ndarray:
    ph = 2 * np.pi * f * t
    if wave == "sine":
        return np.sin(ph)
    if wave == "square":  # first odd harmonics: band-limited enough at bass pitches
        return cast(np.ndarray, sum(np.sin(k * ph) / k for k in (1, 3, 5, 7))) * 0.8
    return cast(np.ndarray, sum(np.sin(k * ph) / k for k in range(1, 8))) * 0.6  # saw


def _kick(sr: int, accent: float) -> np.ndarray:
    t = np.arange(int(0.25 * sr)) / sr
    f = 45 + 90 * np.exp(-t * 30)
    return accent * np.sin(2 * np.pi * np.cumsum(f) / sr) * np.exp(-t * 14)


def _snare(sr: int, rng: np.random.Generator, bright: float) -> np.ndarray:
    t = np.arange(int(0.18 * sr)) / sr
    noise = rng.standard_normal(len(t))
    noise = noise - (1 - bright) * np.convolve(noise, np.ones(4) / 4, mode="same")
    return (
        0.5 * noise * np.exp(-t * 25) + 0.4 * np.sin(2 * np.pi * 185 * t) * np.exp(-t * 30)
    ) * 0.6


def _hat(sr: int, rng: np.random.Generator, bright: float) -> np.ndarray:
    t = np.arange(int(0.05 * sr)) / sr
    noise = np.diff(rng.standard_normal(len(t) + 1))  # high-passed
    return 0.12 * (0.5 + bright) * noise * np.exp(-t * 80)


def _crash(sr: int, rng: np.random.Generator) -> np.ndarray:
    t = np.arange(int(0.6 * sr)) / sr
    return 0.12 * np.diff(rng.standard_normal(len(t) + 1)) * np.exp(-t * 6)


@dataclass
class Piece:
    """A synthesised piece of music and what the dance needs to know about it."""

    audio: np.ndarray  # (n,) float32 at AUDIO_SR
    bpm: float
    beat_times: np.ndarray  # (n_beats,) seconds
    bar_roots: np.ndarray  # (n_bars,) pitch class of each bar's chord root
    bar_chorus: np.ndarray  # (n_bars,) bool: chorus bars (louder, with an arpeggio)
    duration: float
    bar_break: np.ndarray | None = None
    """(n_bars,) bool: breakdown / intro bars (``form=True`` only): half-time or no drums."""


def song_form(n_bars: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Chorus and breakdown flags per bar of a song with a form (the ``study`` size).

    Two intro bars without drums, then sections of 2-8 bars: verse, chorus, verse, chorus, ...
    with a two-bar half-time breakdown after every second chorus, section lengths drawn per
    piece. Real songs change their rhythm within a piece; the smoke set's pieces do not.

    Returns:
        ``(chorus, breakdown)``: (n_bars,) bool each; intro bars count as breakdown bars.
    """
    chorus = np.zeros(n_bars, bool)
    brk = np.zeros(n_bars, bool)
    brk[: min(2, n_bars)] = True
    b, k = 2, 0
    while b < n_bars:
        if k % 4 == 3:  # after every second chorus: a two-bar breakdown
            brk[b : b + 2] = True
            b += 2
        else:
            n = int(rng.choice([2, 4, 4, 8]))
            chorus[b : b + n] = k % 2 == 1
            b += n
        k += 1
    return chorus, brk


def synth_music(genre: str, bpm: float, seconds: float, seed: int, sr: int = AUDIO_SR,
                form: bool = False) -> Piece:  # fmt: skip
    """Synthesise one piece of ``genre`` at ``bpm``, about ``seconds`` long (whole bars).

    ``form``: a song form (:func:`song_form`: intro without drums, verse/chorus sections of
    2-8 bars, half-time breakdowns); ``False``: two-bar verse/chorus alternation (the smoke and
    full sets, unchanged).
    """
    g = GENRES[genre]
    rng = _rng(seed, 1)
    spb = 60.0 / bpm
    n_bars = max(2, int(round(seconds / (4 * spb))))
    lead_in = 0.1
    dur = lead_in + n_bars * 4 * spb + 0.4
    n = int(dur * sr)
    out = np.zeros(n)
    key = int(rng.integers(0, 12))
    scale = _MINOR if g.minor else _MAJOR
    degrees = rng.choice(
        [0, 3, 4, 5, 1, 2, 6], size=n_bars, p=[0.25, 0.18, 0.2, 0.17, 0.08, 0.07, 0.05]
    )
    degrees[0] = 0
    roots = (key + np.array([scale[d] for d in degrees])) % 12
    if form:
        chorus, brk = song_form(n_bars, _rng(seed, 4))
    else:
        chorus = (np.arange(n_bars) // 2) % 2 == 1  # sections of two bars: verse, chorus, ...
        brk = np.zeros(n_bars, bool)
    beat_times = lead_in + np.arange(n_bars * 4) * spb
    sixteenth = spb / 4
    snare, hat, crash = _snare(sr, rng, g.brightness), _hat(sr, rng, g.brightness), _crash(sr, rng)
    open_hat = 0.6 * _crash(sr, rng)[: int(0.15 * sr)]
    for b in range(n_bars):
        bar_t = lead_in + b * 4 * spb
        gain = 1.0 if not chorus[b] else 1.4
        # drums (none in the intro, half time in a breakdown)
        intro = bool(brk[b]) and b < 2
        for s in range(16):
            t = bar_t + s * sixteenth + (g.swing * sixteenth if s % 2 else 0.0)
            if brk[b]:
                if not intro and s in (0, 8):  # half time: kick on 1, snare on 3
                    _add(out, t, (_kick(sr, 1.3) if s == 0 else snare) * gain, sr)
                continue
            if g.kick[s] == "x":
                _add(out, t, _kick(sr, 1.0 if s else 1.3) * gain, sr)
            if g.snare[s] == "x":
                _add(out, t, snare * gain, sr)
            if g.hat[s] == "x":
                _add(out, t, hat * (1.3 if s % 4 == 0 else 0.8) * (1.0 if chorus[b] else 0.5), sr)
            if chorus[b] and s % 4 == 2:  # open hi-hat on the off-beats: the chorus is busier
                _add(out, t, open_hat, sr)
        if not intro:
            _add(out, bar_t, crash * gain, sr)  # downbeat accent: the bar is audible
        # harmony: a pad chord for the bar, a bass note per beat
        third = 3 if g.minor else 4
        chord = 48 + roots[b] + np.array([0, third, 7, 12])
        tpad = np.arange(int(4 * spb * sr)) / sr
        env = np.minimum(1.0, tpad / 0.03) * np.exp(-tpad * (0.4 + 0.6 * g.brightness))
        pad = np.zeros_like(tpad)
        for m in chord:
            f = float(_midi_hz(m))
            for k, a in enumerate(g.pad_partials, start=1):
                if f * k < sr / 2:
                    pad += a * np.sin(2 * np.pi * f * k * tpad + k)
        _add(out, bar_t, 0.05 * gain * pad * env, sr)
        fb = float(_midi_hz(36 + roots[b]))
        tb = np.arange(int(0.9 * spb * sr)) / sr
        for q in range(4):
            note = fb * (1.5 if (q == 2 and g.minor) else 1.0)
            _add(
                out,
                bar_t + q * spb,
                0.25 * gain * _osc(g.bass_wave, note, tb) * np.exp(-tb * 3),
                sr,
            )
        if chorus[b]:  # an arpeggio lead in the chorus: the section is audible in the timbre
            ta = np.arange(int(sixteenth * 2 * sr)) / sr
            for s in range(8):
                m = (84 if g.arp else 72) + roots[b] + [0, third, 7, 12][s % 4]
                _add(
                    out,
                    bar_t + s * 2 * sixteenth,
                    0.15 * np.sin(2 * np.pi * float(_midi_hz(m)) * ta) * np.exp(-ta * 8),
                    sr,
                )
    if g.drive > 0:
        out = np.tanh(out * (1 + 4 * g.drive)) / (1 + g.drive)
    out = out / (np.max(np.abs(out)) + 1e-9) * 0.8
    # a -60 dB noise floor: recordings are never digitally silent, and pure zeros in the lead-in
    # would give MFCC outliers that squeeze every other frame in the min-max scaling
    out = out + 1e-3 * rng.standard_normal(n)
    return Piece(
        out.astype(np.float32), float(bpm), beat_times, roots, chorus, n / sr, brk if form else None
    )


# ----------------------------------------------------------------------------- dance


_MOVES = ("verse", "chorus", "solo")


def genre_moves(genre: str, seed: int) -> np.ndarray:
    """(3, 2 * per_beat, 5) key poses of the genre's vocabulary: verse, chorus and solo moves.

    A move spans two beats (a key pose every beat or half-beat) and repeats. Columns: theta1,
    theta2, elbow flexion, wrist flexion (radians, :func:`angles.upper_arm_direction`
    convention) and the upper-arm twist.
    """
    g = GENRES[genre]
    rng = _rng(seed, 2, list(GENRES).index(genre))
    k = 2 * g.per_beat
    base = np.array(g.center) + np.array(g.spread) * rng.standard_normal((len(_MOVES), k, 4))
    # the chorus is bigger in every genre: the arm higher and more extended (ENERGY_SHIFT), plus
    # a genre-specific part of the genre's own spread
    base[1] += ENERGY_SHIFT + 0.5 * np.array(g.spread) * rng.choice([-1.0, 1.0], size=4)
    # the first beat of every two-beat move is accented, the second answers it (BEAT_ACCENT)
    beat = np.arange(k) // g.per_beat
    base += np.where(beat == 0, 1.0, -1.0)[None, :, None] * BEAT_ACCENT
    base = np.clip(base, _LIMITS[:, 0], _LIMITS[:, 1])
    twist = rng.uniform(-0.8, 0.8, size=(len(_MOVES), k, 1))
    return np.concatenate([base, twist], axis=2)


def chord_offsets(genre: str, seed: int) -> np.ndarray:
    """(12, 5) pose offset of each chord root pitch class (the harmony shapes the pose).

    One rule for every genre (``genre`` is accepted for symmetry with :func:`genre_moves` and
    checked): the pitch class moves round a circle in the (theta1, theta2) plane, so songs of
    other genres teach it too. The circle's phase depends on ``seed``.
    """
    if genre not in GENRES:
        raise ValueError(f"Unknown genre {genre!r}. Valid: {', '.join(GENRES)}.")
    phase = _rng(seed, 3).uniform(0, 2 * np.pi)
    a = 2 * np.pi * np.arange(12) / 12 + phase
    out = np.zeros((12, 5))
    out[:, 0] = 0.3 * np.sin(a)
    out[:, 1] = 0.2 * np.cos(a)
    out[:, 2] = 0.2 * np.sin(2 * a)
    return out


@dataclass
class Dancer:
    """How one dancer deviates from the genre's vocabulary."""

    lag: float  # seconds late (negative: early)
    amplitude: float  # scaling of the key poses' distance from the genre centre
    bias: np.ndarray  # (5,) constant pose offset
    improvise: float  # probability of dancing another move in a bar
    scaling: float  # body size (AIST++ smpl_scaling)

    @classmethod
    def sample(cls, rng: np.random.Generator) -> Dancer:
        return cls(
            lag=float(rng.uniform(-0.03, 0.04)),
            amplitude=float(rng.uniform(0.85, 1.15)),
            bias=rng.normal(0, [0.05, 0.04, 0.05, 0.03, 0.1]),
            improvise=float(rng.uniform(0.04, 0.12)),
            scaling=float(rng.uniform(88, 102)),
        )


def _ease(s: np.ndarray, sharp: float) -> np.ndarray:
    """0 -> 1 transition: cosine for sharp = 1, faster (a hit, then a hold) for larger values."""
    s = np.clip(s, 0.0, 1.0)
    s = 1.0 - (1.0 - s) ** sharp
    return 0.5 - 0.5 * np.cos(np.pi * s)


def choreograph(
    genre: str, piece: Piece, dancer: Dancer, times: np.ndarray, seed: int, rng: np.random.Generator
) -> np.ndarray:
    """Right-arm parameters (T, 5) at ``times``: theta1, theta2, elbow, wrist, twist.

    Per bar: the section's move (verse or chorus; an improvised move with the dancer's
    probability), looped every two beats, scaled by the dancer's amplitude, shifted by the
    chord's offset and the dancer's bias; key poses land on the (lagged) beats.
    """
    g = GENRES[genre]
    moves = genre_moves(genre, seed)
    offsets = chord_offsets(genre, seed)
    center = np.r_[np.array(g.center), 0.0]
    spb = 60.0 / piece.bpm
    k = 2 * g.per_beat
    kf_ts: list[np.ndarray] = []
    kf_vs: list[np.ndarray] = []
    for b, root in enumerate(piece.bar_roots):
        m = 1 if piece.bar_chorus[b] else 0
        if piece.bar_break is not None and piece.bar_break[b]:
            m = 2  # a song with a form: the breakdown gets the solo move
        elif rng.random() < dancer.improvise:
            m = int(rng.choice([1 - m, 2]))
        v = center + dancer.amplitude * (moves[m] - center) + offsets[root] + dancer.bias
        for half in range(2):  # the two-beat move, twice per bar
            kf_vs.append(v)
            kf_ts.append(
                piece.beat_times[4 * b + 2 * half] + np.arange(k) * spb / g.per_beat + dancer.lag
            )
    kf_t = np.concatenate(kf_ts)
    kf_v = np.concatenate(kf_vs)
    rest = np.array([0.05, -0.1, 0.2, 0.1, 0.0])  # arm hanging loosely before the first key pose
    kf_t = np.r_[kf_t[0] - spb, kf_t]
    kf_v = np.vstack([rest, kf_v])
    kf_v[:, :4] = np.clip(kf_v[:, :4], _LIMITS[:, 0], _LIMITS[:, 1])
    # each key pose is reached on its beat; the move towards it starts at the previous key pose
    i = np.clip(np.searchsorted(kf_t, times, side="right"), 1, len(kf_t) - 1)
    seg = kf_t[i] - kf_t[i - 1]
    s = np.where(times >= kf_t[-1], 1.0, (times - kf_t[i - 1]) / seg)
    s = np.where(times < kf_t[0], 0.0, s)
    w = _ease(s, g.sharp)[:, None]
    arm = (1 - w) * kf_v[i - 1] + w * kf_v[i]
    # a slow, smooth wander: no dancer repeats a move exactly
    for _ in range(3):
        f = rng.uniform(0.05, 0.4)
        arm += rng.normal(0, [0.03, 0.025, 0.03, 0.02, 0.05]) * np.sin(
            2 * np.pi * f * times[:, None] + rng.uniform(0, 2 * np.pi)
        )
    arm[:, :4] = np.clip(arm[:, :4], _LIMITS[:, 0] - 0.1, _LIMITS[:, 1] + 0.1)
    arm[:, 2:4] = np.maximum(arm[:, 2:4], 0.0)
    return arm


def _swing_rotvec(rest_dir: np.ndarray, target: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """(T, 3) axis-angle of the rotation taking ``rest_dir`` onto ``target`` (T, 3), then ``twist``."""
    from scipy.spatial.transform import Rotation

    a = np.broadcast_to(rest_dir, target.shape)
    axis = np.cross(a, target)
    s = np.linalg.norm(axis, axis=1, keepdims=True)
    c = np.sum(a * target, axis=1, keepdims=True)
    angle = np.arctan2(s, c)
    axis = np.where(s > 1e-9, axis / np.maximum(s, 1e-12), np.array([0.0, 0.0, 1.0]))
    swing = Rotation.from_rotvec(axis * angle)
    tw = Rotation.from_rotvec(target * twist[:, None])
    return (tw * swing).as_rotvec()


def smpl_poses_for(
    genre: str, piece: Piece, dancer: Dancer, times: np.ndarray, seed: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """SMPL parameters (T, 72) and root translation (T, 3, in metres) of the dance at ``times``."""
    from scipy.spatial.transform import Rotation

    g = GENRES[genre]
    T = len(times)
    arm = choreograph(genre, piece, dancer, times, seed, rng)
    phase = np.interp(
        times,
        piece.beat_times,
        np.arange(len(piece.beat_times)),
        left=0.0,
        right=len(piece.beat_times),
    )
    bounce = g.bounce * (0.5 - 0.5 * np.cos(2 * np.pi * (phase - dancer.lag / (60 / piece.bpm))))
    poses = np.zeros((T, 24, 3))
    yaw0, f_yaw = rng.uniform(-np.pi, np.pi), rng.uniform(0.03, 0.12)
    yaw = yaw0 + g.turn * np.sin(2 * np.pi * f_yaw * times + rng.uniform(0, 6.3))
    lean = 0.08 * np.sin(2 * np.pi * rng.uniform(0.05, 0.2) * times + rng.uniform(0, 6.3))
    poses[:, 0] = (
        Rotation.from_euler("y", yaw[:, None])
        * Rotation.from_euler("x", (lean + 0.5 * bounce)[:, None])
    ).as_rotvec()
    for jnt in (3, 6, 9):  # the spine curls a little with the bounce, and sways sideways
        poses[:, jnt, 0] = 0.3 * bounce
        poses[:, jnt, 2] = 0.03 * np.sin(2 * np.pi * 0.3 * times + jnt)
    poses[:, 1, 0] = poses[:, 2, 0] = -1.2 * bounce  # hips flex ...
    poses[:, 4, 0] = poses[:, 5, 0] = 2.0 * bounce  # ... knees bend ...
    poses[:, 7, 0] = poses[:, 8, 0] = -0.8 * bounce  # ... ankles compensate
    u = upper_arm_direction(arm[:, 0], arm[:, 1])
    poses[:, 17] = _swing_rotvec(np.array([-1.0, 0, 0]), u, arm[:, 4])
    poses[:, 19, 1] = arm[:, 2]  # elbow flexion about the upper arm's y axis
    poses[:, 21, 2] = -arm[:, 3]  # wrist flexion
    # the left arm echoes the right, mirrored and softened, half a beat late
    lag = 0.5 * 60 / piece.bpm
    left = np.stack([np.interp(times - lag, times, arm[:, c]) for c in range(5)], axis=1)
    ul = upper_arm_direction(0.7 * left[:, 0], 0.7 * left[:, 1]) * np.array([-1.0, 1.0, 1.0])
    poses[:, 16] = _swing_rotvec(np.array([1.0, 0, 0]), ul, -left[:, 4])
    poses[:, 18, 1] = -0.7 * left[:, 2]
    drift = np.stack(
        [0.2 * np.sin(0.3 * times + yaw0), -0.3 * bounce, 0.2 * np.cos(0.2 * times)], axis=1
    )
    return poses.reshape(T, 72), drift


def pose_timestamps(
    duration: float, rng: np.random.Generator, fps: float = POSE_FPS, drop: float = 0.02
) -> np.ndarray:
    """Pose capture times in microseconds: ``fps`` nominal, ~1 ms jitter, dropped frames."""
    n = int(duration * fps)
    t = np.arange(n) / fps + rng.normal(0, 0.001, n)
    t[0] = max(t[0], 0.0)
    keep = rng.random(n) >= drop
    burst = np.flatnonzero(rng.random(n) < drop / 4)  # occasional runs of 2-4 lost frames
    for s in burst:
        keep[s : s + int(rng.integers(2, 5))] = False
    keep[0] = keep[-1] = True
    t = np.round(np.sort(t[keep]) * 1e6)
    t = np.maximum.accumulate(t + np.arange(len(t)) * 1e-3)  # strictly increasing
    return np.round(t).astype(np.int64)


COCO_FROM_SKELETON = (15, 15, 15, 15, 15, 16, 17, 18, 19, 20, 21, 1, 2, 4, 5, 7, 8)
"""Skeleton joint used for each COCO-17 keypoint (nose/eyes/ears get the head plus an offset)."""


def skeleton_to_coco17(joints: np.ndarray) -> np.ndarray:
    """(T, 17, 3) COCO-17 keypoints from (T, 24, 3) skeleton joints (face points near the head)."""
    kp = joints[:, list(COCO_FROM_SKELETON)].copy()
    fwd = np.cross(joints[:, 16] - joints[:, 17], joints[:, 12] - joints[:, 0])
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True) + 1e-12
    side = (joints[:, 16] - joints[:, 17]) / (
        np.linalg.norm(joints[:, 16] - joints[:, 17], axis=1, keepdims=True) + 1e-12
    )
    scale = np.linalg.norm(joints[:, 12] - joints[:, 15], axis=1, keepdims=True)
    kp[:, 0] += 0.6 * scale * fwd
    kp[:, 1] += 0.4 * scale * fwd + 0.2 * scale * side
    kp[:, 2] += 0.4 * scale * fwd - 0.2 * scale * side
    kp[:, 3] += 0.4 * scale * side
    kp[:, 4] -= 0.4 * scale * side
    return kp


# ----------------------------------------------------------------------------- writers


def _write_wav(path: Path, y: np.ndarray, sr: int) -> None:
    import soundfile as sf

    sf.write(str(path), y, sr, subtype="PCM_16")


def _dump(path: Path, obj) -> None:
    with open(path, "wb") as f:
        pickle.dump(obj, f, protocol=4)


def _tempo(genre: str, k: int, n: int, rng: np.random.Generator, grid: bool = False) -> float:
    lo, hi = GENRES[genre].bpm
    jitter = rng.uniform(-2, 2)  # drawn either way: the rest of the piece's draws stay put
    if grid:  # AIST's: six tempos per genre, shared by the pieces k, k + 6, ...
        return float(lo + (hi - lo) * (k % TEMPO_GRID) / (TEMPO_GRID - 1))
    return float(np.clip(lo + (hi - lo) * k / max(n - 1, 1) + jitter, 80, 135))


TEMPO_GRID = 6
"""Tempos per genre of the ``study`` size: as AIST's music (six pieces per genre at 80, 90 ...
130 BPM for most genres), so several pieces share each tempo and a tempogram names the tempo,
not the piece."""


def write_aist_layout(root: str | Path, per_genre: int = 6, seconds: float = 8.0, dancers: int = 2,
                      seed: int = 0, genres: tuple[str, ...] | None = None, progress: bool = True,
                      form: bool = False, tempo_grid: bool = False) -> Path:  # fmt: skip
    """Write a synthetic data set in the AIST++ layout under ``root`` (see module docstring).

    Writes ``motions/``, ``keypoints3d/``, ``keypoints2d/`` (timestamps; one orthographic view),
    ``splits/crossmodal_{train,val,test}.txt`` (pieces 0-3 / 4 / 5 of each genre),
    ``ignore_list.txt`` (one extra sequence) and ``wav/mXX#.wav``; ``dancers`` sequences per music
    (the reader keeps the first by name unless ``all_sequences=True``). ``form``: songs with a
    form (:func:`song_form`); ``tempo_grid``: tempos on the genre's grid of
    :data:`TEMPO_GRID` (pieces ``k`` and ``k + 6`` share one); both as the ``study`` size.
    """
    root = Path(root)
    for sub in ("motions", "keypoints3d", "keypoints2d", "splits", "wav"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    genres = tuple(genres or GENRES)
    splits: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    ignore: list[str] = []
    jobs = [(g, k) for g in genres for k in range(per_genre)]
    it = jobs
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(jobs, desc="synth AIST++", leave=False)
    for g, k in it:
        gi = list(GENRES).index(g)
        rng = _rng(seed, 10, gi, k)
        music_id = f"{g}{k}"
        piece = synth_music(
            g,
            _tempo(g, k, per_genre, rng, tempo_grid),
            seconds,
            seed=int(rng.integers(2**31)),
            form=form,
        )
        _write_wav(root / "wav" / f"{music_id}.wav", piece.audio, AUDIO_SR)
        for d in range(dancers):
            dancer_no = 1 + (gi * 3 + (k + d) % 3) % 30
            name = f"g{g[1:]}_sBM_cAll_d{dancer_no:02d}_{music_id}_ch{d + 1:02d}"
            drng = _rng(seed, 11, gi, k, d)
            dancer = Dancer.sample(_rng(seed, 12, dancer_no))
            ts = pose_timestamps(piece.duration, drng)
            poses, drift = smpl_poses_for(g, piece, dancer, ts / 1e6, seed, drng)
            trans = (drift + np.array([0.0, 0.95, 0.0])) * dancer.scaling
            _dump(root / "motions" / f"{name}.pkl", {
                "smpl_poses": poses.astype(np.float32), "smpl_trans": trans.astype(np.float32),
                "smpl_scaling": np.array([dancer.scaling], dtype=np.float32),
                "smpl_loss": np.float32(0.0)})  # fmt: skip
            joints = forward_kinematics(poses, trans, dancer.scaling)
            kp3 = skeleton_to_coco17(joints).astype(np.float32)
            _dump(
                root / "keypoints3d" / f"{name}.pkl", {"keypoints3d": kp3, "keypoints3d_optim": kp3}
            )
            kp2 = np.concatenate(
                [kp3[None, :, :, :2], np.ones((1, *kp3.shape[:2], 1), np.float32)], axis=-1
            )
            _dump(root / "keypoints2d" / f"{name}.pkl", {
                "keypoints2d": kp2, "det_scores": np.ones(kp2.shape[:2], np.float32), "timestamps": ts})  # fmt: skip
            split = "train" if k < per_genre - 2 else ("val" if k == per_genre - 2 else "test")
            splits[split].append(name)
            if d == dancers - 1 and d > 0 and g == genres[0] and k == 0:
                ignore.append(name)
    for s, names in splits.items():
        (root / "splits" / f"crossmodal_{s}.txt").write_text("\n".join(sorted(names)) + "\n")
    (root / "ignore_list.txt").write_text("\n".join(ignore) + ("\n" if ignore else ""))
    return root


def write_phantomdance_layout(root: str | Path, n: int = 20, seconds: float = 8.0, seed: int = 0,
                              progress: bool = True) -> Path:  # fmt: skip
    """Write a synthetic data set in the PhantomDance layout (``motion/*.json``, ``music/*.wav``).

    Pieces cycle through the genres; each has its own dancer (PhantomDance has 100+ subjects);
    poses at exactly 30 fps, in the official format (:func:`readers.smpl_to_phantom`): world
    rotations as (x, y, z, w) quaternions and root positions in Unity's left-handed frame.
    """
    root = Path(root)
    (root / "motion").mkdir(parents=True, exist_ok=True)
    (root / "music").mkdir(parents=True, exist_ok=True)
    genres = list(GENRES)
    it = range(n)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc="synth PhantomDance", leave=False)
    for i in it:
        g = genres[i % len(genres)]
        rng = _rng(seed, 20, i)
        bpm = float(rng.uniform(80, 135))
        piece = synth_music(
            g, bpm, seconds * float(rng.uniform(0.85, 1.2)), seed=int(rng.integers(2**31))
        )
        name = f"{i:03d}"
        _write_wav(root / "music" / f"{name}.wav", piece.audio, AUDIO_SR)
        dancer = Dancer.sample(_rng(seed, 21, i))
        times = np.arange(int(piece.duration * PHANTOM_FPS)) / PHANTOM_FPS
        poses, drift = smpl_poses_for(g, piece, dancer, times, seed, rng)
        q, root_pos = smpl_to_phantom(poses, drift + np.array([0.0, 0.95, 0.0]))
        obj = {
            "bone_name": list(PHANTOM_BONES),
            "root_positions": np.round(root_pos, 5).tolist(),
            "rotations": np.round(q, 6).tolist(),
            "fps": PHANTOM_FPS,
            "genre": g,
        }
        (root / "motion" / f"{name}.json").write_text(json.dumps(obj, separators=(",", ":")))
    return root


def default_root(layout: str = "aist", size: str = "smoke", seed: int = 0) -> Path:
    """Where :func:`default_dataset` keeps a set: ``<data dir>/thesis-mdlt/<layout>-<size>-seed<seed>``."""
    return data_dir() / "thesis-mdlt" / f"{layout}-{size}-seed{seed}"


def default_dataset(layout: str = "aist", size: str = "smoke", seed: int = 0, root: str | Path | None = None,
                    progress: bool = True) -> Path:  # fmt: skip
    """Make the default offline data set on first use and return its root.

    Args:
        layout: ``"aist"`` (10 genres x 6 pieces, :func:`readers.load_aist`) or
            ``"phantomdance"`` (:func:`readers.load_phantomdance`).
        size: ``"smoke"`` (8 s pieces, 2 dancers per music / 20 pieces), ``"full"``
            (32 s pieces, 3 dancers / 260 pieces of 24 s, PhantomDance's count) or, AIST++
            layout only, ``"study"`` (the C13 study's: 12 pieces per genre of 60 s with a song
            form, :func:`song_form`, one dancer each).
        seed: everything generated is a function of it.
        root: where to write; default :func:`default_root`. An existing complete set is reused.

    Returns:
        The data set's root folder.
    """
    if (layout, size) not in SIZES:
        raise ValueError(
            f"Unknown layout/size {layout!r}/{size!r}. Valid: "
            + ", ".join(f"{a}/{b}" for a, b in SIZES)
            + "."
        )
    root = Path(root) if root is not None else default_root(layout, size, seed)
    marker = root / ".complete.json"
    spec = {
        "generator": GENERATOR_VERSION,
        "layout": layout,
        "size": size,
        "seed": int(seed),
        **SIZES[(layout, size)],
    }
    if marker.is_file():
        try:
            old = json.loads(marker.read_text())
        except ValueError:
            old = {}
        if old == spec:
            return root
        if {k: v for k, v in old.items() if k != "generator"} == {
            k: v for k, v in spec.items() if k != "generator"
        }:
            # our own set, made by an older generator: remake it
            warnings.warn(
                f"{root} was made by {old.get('generator')}; remaking it with {GENERATOR_VERSION}.",
                stacklevel=2,
            )
            shutil.rmtree(root)
        else:
            raise FileExistsError(
                f"{root} holds another data set ({json.dumps(old)[:200]}); delete it or pass another root."
            )
    if root.exists() and any(root.iterdir()):
        raise FileExistsError(
            f"{root} exists and is not a complete default data set; delete it or pass another root."
        )
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{root.name}-", dir=root.parent))
    try:
        p = SIZES[(layout, size)]
        if layout == "aist":
            write_aist_layout(
                tmp,
                per_genre=int(p["per_genre"]),
                seconds=p["seconds"],
                dancers=int(p["dancers"]),
                seed=seed,
                progress=progress,
                form=bool(p.get("form", False)),
                tempo_grid=bool(p.get("tempo_grid", False)),
            )
        else:
            write_phantomdance_layout(
                tmp, n=int(p["n"]), seconds=p["seconds"], seed=seed, progress=progress
            )
        (tmp / ".complete.json").write_text(json.dumps(spec))
        if root.exists():
            root.rmdir()
        try:
            # atomic: a concurrent maker either wins or finds it complete (a folder swap, so
            # not thesis_lib._io.atomic_write, which writes one file)
            os.replace(tmp, root)
        except OSError:
            if not marker.is_file():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return root
