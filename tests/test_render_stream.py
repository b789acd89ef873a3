"""A video's log in bounded memory (issue 23 item 1): uvms_mj.analysis.render_stream.

Oracles: numpy's interpolation over the whole arrays, a brute-force search for each frame's last
sample, normalised lerp of each bracketing pair of quaternions computed here, and the replay of
the same log read whole (read_log).
"""

from __future__ import annotations

import numpy as np
import pytest

from uvms_mj.analysis.render_stream import (FiniteSpans, FrameStates, continuous_quaternions, read_render_log,
                                            streamed_blocks)


def _blocks(t: np.ndarray, x: np.ndarray, cuts: list[int]):
    """The series (t, x) cut at ``cuts``, each block reduced to its finite rows."""
    edges = [0, *cuts, len(t)]
    for a, b in zip(edges[:-1], edges[1:]):
        tb, xb = t[a:b], x[a:b]
        ok = np.isfinite(xb).all(axis=1)
        yield {"x": (tb[ok], xb[ok])}


def _random_series(rng, n: int = 400):
    t = np.cumsum(rng.uniform(0.005, 0.03, n))
    x = rng.normal(size=(n, 6))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x = np.hstack([x, q])  # a quaternion at columns 6..9, its signs random
    x[rng.random(n) < 0.1] = np.nan  # gaps
    x[:5] = np.nan  # no valid sample at the start
    return t, x


@pytest.mark.parametrize("cuts", [[], [1], [7, 8, 9, 200], list(range(3, 400, 13)), list(range(1, 400))])
def test_frame_states_are_the_whole_series_interpolated(cuts) -> None:
    """Whatever the blocks (one, many, one sample each, blocks without a valid sample), every
    frame's linear columns are np.interp over the whole finite series (to 1e-12: the same two
    bracketing samples), clamped before the first and after the last; the quaternion is the
    normalised lerp of the bracketing samples (up to sign, 1e-12); the last sample is the last
    valid one at or before the frame (exactly), NaN before the first."""
    rng = np.random.default_rng(7)
    t, x = _random_series(rng)
    frame_t = np.linspace(t[0] - 0.5, t[-1] + 0.5, 333)
    got = list(FrameStates(frame_t, {"x": [6]}).run(_blocks(t, x, cuts)))
    assert len(got) == len(frame_t)
    ok = np.isfinite(x).all(axis=1)
    tv, xv = t[ok], x[ok]
    for tf, state in zip(frame_t, got):
        now, last = state["x"]
        want = [np.interp(tf, tv, xv[:, j]) for j in range(6)]
        assert np.allclose(now[:6], want, rtol=0, atol=1e-12)
        k = np.searchsorted(tv, tf, side="right")
        i, j = max(k - 1, 0), min(k, len(tv) - 1)
        a = 0.0 if i == j else (tf - tv[i]) / (tv[j] - tv[i])
        q0, q1 = xv[i, 6:], xv[j, 6:]
        q1 = q1 if q0 @ q1 >= 0 else -q1
        nl = (1 - a) * q0 + a * q1
        nl /= np.linalg.norm(nl)
        assert abs(abs(nl @ now[6:]) - 1) < 1e-12
        prior = np.flatnonzero(tv <= tf)
        if len(prior):
            assert np.array_equal(np.abs(last[:6]), np.abs(xv[prior[-1], :6]))
        else:
            assert np.isnan(last).all()


def test_continuous_quaternions_carries_the_sign_across_blocks() -> None:
    """Cut anywhere, the sign choice continued from the previous block's last sample is the
    whole series' (exactly: only signs change)."""
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    whole = continuous_quaternions(q, [0])
    a = continuous_quaternions(q[:17], [0])
    b = continuous_quaternions(q[17:], [0], previous=a[-1])
    assert np.array_equal(np.vstack([a, b]), whole)
    assert (np.sum(whole[1:] * whole[:-1], axis=1) >= 0).all()


def test_frames_come_while_the_blocks_arrive() -> None:
    """Streaming, not collecting: the first frame is yielded after the first block, and frames
    are never more than one block behind the blocks read."""
    t = np.arange(10_000) * 0.01
    x = np.c_[t, np.sin(t)]
    frame_t = t[::3] + 0.001
    read = [0]

    def blocks():
        for k in range(0, len(t), 500):
            read[0] += 1
            yield {"x": (t[k:k + 500], x[k:k + 500])}

    lag = 0
    for i, state in enumerate(FrameStates(frame_t).run(blocks())):
        lag = max(lag, read[0] - 1 - int(frame_t[i] // 5.0))
        assert abs(state["x"][0][1] - np.interp(frame_t[i], t, x[:, 1])) < 1e-12
    assert lag <= 1


def test_finite_spans_are_the_whole_arrays() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(1000) * 0.1
    q = rng.normal(size=(1000, 3))
    q[:40] = np.nan
    q[900:, 1] = np.nan
    spans = FiniteSpans()
    for k in range(0, 1000, 64):
        spans.add(t[k:k + 64], {"q": q[k:k + 64], "s": np.full(len(t[k:k + 64]), np.nan)})
    ok = np.isfinite(q).all(axis=1)
    assert spans.spans["q"] == (t[ok][0], t[ok][-1]) == (4.0, 89.9)
    assert "s" not in spans.spans and spans.span(["s"]) is None and spans.span(["q", "s"]) == (4.0, 89.9)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    from conftest import run_logs

    from uvms_mj.io.recorder import McapRecorder, read_log
    from uvms_mj.plant.plant import Plant

    folder = tmp_path_factory.mktemp("stream")
    out = run_logs(folder, [("paper", "paper", 6), ("robot", "bluerov2_alpha_circle_current", 5)])
    # A run that ends in NaN (as a diverging one may): the paper log's samples after 241 not
    # finite, and held constant over 200..240 so that the last finite sample (240) is no extreme
    # of its bucket (every bucket size from 64 up starts at or before 200): the envelope does
    # not keep it, only the finite spans know where the video ends.
    src = read_log(out["paper"])
    names = ("q_true", "tip_true", "p_desired")
    out["diverged"] = folder / "diverged.mcap"
    with McapRecorder(out["diverged"], Plant().params, {"scenario": "diverged"}) as rec:
        for k, t in enumerate(src.t):
            row = {n: np.asarray(src.signals[n][min(k, 200) if k <= 240 and k >= 200 else k], dtype=float)
                   for n in names}
            if k > 240:
                row["q_true"] = np.full_like(row["q_true"], np.nan)
            rec.write_sample(float(t), row)
    return out


@pytest.mark.parametrize("which", ["paper", "robot", "diverged"])
def test_a_thinned_log_replays_the_whole_logs_frames(logs, which) -> None:
    """A log thinned to a small envelope (rows 64, 8 buckets: the path a 3600 s log takes) streams
    its frames from the file again: the same frame times (a diverged run's video ends at its last
    finite sample, as the whole log's) and the same replayed qpos (to 1e-12) as the log read
    whole, and pictures that differ in under 0.1 % of their pixels by more than 32 levels (the
    camera's framing and the drawn paths come from the envelope's samples)."""
    from uvms_mj.analysis.render_robot import _replay
    from uvms_mj.io.recorder import read_log

    whole = read_log(logs[which])
    thin = read_render_log(logs[which], rows=64, buckets=8)
    assert thin.bucket > 1 and len(thin.t) < len(whole.t) / 3
    assert streamed_blocks(thin, ["q_true"]) is not None and streamed_blocks(whole, ["q_true"]) is None
    a = _replay(whole, 10, (320, 240), None, 1.0, None, None, True)
    b = _replay(thin, 10, (320, 240), None, 1.0, None, None, True)
    try:
        assert np.array_equal(a.frame_t, b.frame_t)
        assert np.allclose(a.qpos_frames(), b.qpos_frames(), rtol=0, atol=1e-12)
        worst = 0.0
        for (ta, fa), (tb, fb) in zip(a, b):
            assert ta == tb
            worst = max(worst, float(np.mean(np.abs(fa.astype(int) - fb).max(axis=2) > 32)))
        assert worst < 1e-3, worst
    finally:
        a.close()
        b.close()
    if which == "diverged":  # the video ends at the last finite sample, not at the envelope's
        assert not np.isfinite(whole.signals["q_true"][-1]).all()
        last = whole.t[np.isfinite(whole.signals["q_true"]).all(axis=1)][-1]
        assert last - 0.1 < b.frame_t[-1] <= last
        kept = thin.t[np.isfinite(thin.signals["q_true"]).all(axis=1)]
        assert kept[-1] < last - 0.5  # what the envelope alone would have shown


def test_reading_a_log_for_a_video_imports_no_matplotlib(logs) -> None:
    """The envelope and the error series live outside the figures' package: a video's reading
    costs no matplotlib import (about a second; the labels are drawn with Pillow)."""
    import subprocess
    import sys

    code = ("import sys; from uvms_mj.analysis.render_stream import read_render_log; "
            f"log = read_render_log({str(logs['robot'])!r}, rows=64, buckets=8); "
            "assert log.bucket > 1; print('matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False", out.stderr
