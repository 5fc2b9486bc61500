"""Speed of the MDLT audio features (thesis 6.3.2) on one core: times faster than real time.

Cases:
  (a) ``thesis_lib.mdlt.audio.audio_features`` on synthesised music (the default data set's
      genres), seconds of music per second of compute; the issue asks for >= 10x.
  (b) the authors' recipe with plain librosa calls (separate mel STFT, ``librosa.effects.hpss``
      with scipy's median filter, then the same features), for comparison.
  (c) with --dataset: making the smoke default AIST++-layout data set and extracting all its
      features from scratch (fresh cache), the budget being < ~60 s.

Threads are pinned to one (OMP/OpenBLAS/MKL/numba) before numpy is imported. Both wall time
and process CPU time are reported: on a busy machine the CPU time is the fairer number.
librosa's numba JIT warm-up is done once before timing and reported separately.

    python benchmarks/bench_mdlt.py --repeats 5 [--dataset]
"""

from __future__ import annotations

import argparse
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_v] = "1"

import platform  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--repeats", type=int, default=5, help="timed runs per method")
    p.add_argument("--seconds", type=float, default=30.0, help="length of each test piece")
    p.add_argument(
        "--dataset", action="store_true", help="also time the smoke default data set end to end"
    )
    return p.parse_args()


def authors_features(y, sr):
    """The authors' recipe (notes/original-code.md), librosa defaults, no shared STFT."""
    import librosa
    import numpy as np

    mel = librosa.feature.melspectrogram(y=y, sr=sr)
    mfcc = librosa.feature.mfcc(S=librosa.power_to_db(mel, ref=np.max))
    delta = librosa.feature.delta(mfcc, width=3)
    h, p = librosa.effects.hpss(y)
    chroma = librosa.feature.chroma_cqt(y=h, sr=sr, n_octaves=7)
    onset = librosa.onset.onset_strength(y=p, sr=sr)
    tg = librosa.feature.tempogram(onset_envelope=onset, sr=sr)
    _, beats = librosa.beat.beat_track(onset_envelope=onset, sr=sr)
    b = np.zeros_like(onset)
    b[beats] = 1
    return np.concatenate([mfcc, delta, chroma, onset[None], b[None], tg]).T


def timed(fn, repeats):
    walls, cpus = [], []
    for _ in range(repeats):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    walls.sort()
    cpus.sort()
    return walls[0], walls[len(walls) // 2], cpus[0], cpus[len(cpus) // 2]


def main() -> None:
    args = parse_args()
    import librosa
    import numpy as np

    from thesis_lib.mdlt import audio, synth

    print(f"python {platform.python_version()}, librosa {librosa.__version__}, numpy {np.__version__}, "
          f"{platform.machine()}, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")  # fmt: skip
    pieces = [
        synth.synth_music(g, bpm, args.seconds, seed=i)
        for i, (g, bpm) in enumerate([("mHO", 124.0), ("mKR", 92.0)])
    ]
    sr = audio.feature_sample_rate(60)
    ys = [librosa.resample(p.audio, orig_sr=synth.AUDIO_SR, target_sr=sr) for p in pieces]
    dur = sum(len(y) for y in ys) / sr
    t = time.perf_counter()
    for y in ys:
        audio.audio_features(y, sr=sr)
    print(f"warm-up (numba JIT, first calls): {time.perf_counter() - t:.1f} s")

    rows = []
    for name, fn in [
        ("thesis_lib audio_features", lambda: [audio.audio_features(y, sr=sr) for y in ys]),
        ("authors' recipe (librosa)", lambda: [authors_features(y, sr) for y in ys]),
    ]:
        bw, mw, bc, mc = timed(fn, args.repeats)
        rows.append((name, bw, mw, bc, mc))
    print(f"\n(a)/(b) {dur:.0f} s of music at {sr} Hz, 60 frames/s, one core, {args.repeats} runs")
    print(
        f"{'method':28s} {'wall best':>9s} {'wall med':>9s} {'cpu best':>9s} {'x real time (cpu)':>18s} {'x real time (wall)':>19s}"
    )
    for name, bw, mw, bc, _mc in rows:
        print(f"{name:28s} {bw:9.2f} {mw:9.2f} {bc:9.2f} {dur / bc:18.1f} {dur / bw:19.1f}")
    print(f"speed-up over the authors' recipe (cpu best): {rows[1][3] / rows[0][3]:.2f}x")
    ours = audio.audio_features(ys[0], sr=sr)
    theirs = authors_features(ys[0], sr)
    T = min(len(ours), len(theirs))
    err = np.abs(ours[:T] - theirs[:T]).max(axis=0)
    print(f"max |ours - authors'| per block: mfcc {err[:20].max():.2e}, chroma {err[40:52].max():.2e}, "
          f"onset {err[52]:.2e}, tempogram {err[54:].max():.2e}")  # fmt: skip

    if args.dataset:
        from thesis_lib.mdlt import readers

        with tempfile.TemporaryDirectory() as tmp:
            os.environ["THESIS_MDLT_CACHE"] = os.path.join(tmp, "cache")
            w, c = time.perf_counter(), time.process_time()
            root = synth.default_dataset(
                "aist", "smoke", seed=0, root=os.path.join(tmp, "aist"), progress=False
            )
            w1, c1 = time.perf_counter(), time.process_time()
            seqs = readers.load_aist(root, progress=False)
            w2, c2 = time.perf_counter(), time.process_time()
            music = sum(len(s) for s in seqs) / 60
            print(f"\n(c) smoke AIST++-layout set: {len(seqs)} sequences, {music:.0f} s of music")
            print(f"generate {w1 - w:.1f} s wall / {c1 - c:.1f} s cpu; features + angles + sync "
                  f"{w2 - w1:.1f} s wall / {c2 - c1:.1f} s cpu; total {w2 - w:.1f} s wall / {c2 - c:.1f} s cpu")  # fmt: skip


if __name__ == "__main__":
    main()
