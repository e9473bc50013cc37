"""From simulated motion to what a camera sees, and alignment with a recording.

Hadwin et al. (2019), Section 4.1: glottal width W = 2 * min distance of the free
surface to the midline; area A = L * W with L = 17 mm; the simulated GAW is
downsampled to the camera rate and phase-aligned to the observation by
cross-correlating the first two cycles.
"""

from __future__ import annotations

import math

import numpy as np

from .measures import estimate_f0


def downsample(t: np.ndarray, y: np.ndarray, fps: float, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``y(t)`` at camera instants ``t0 + k/fps`` (linear interpolation).

    Returns (times relative to t0 in s, samples). ``y`` may be 1D (n,) or 2D (n, m).
    """
    t_end = t[-1]
    n = int(math.floor((t_end - t0) * fps + 1e-9)) + 1
    tc = t0 + np.arange(n) / fps
    if y.ndim == 1:
        return tc - t0, np.interp(tc, t, y)
    out = np.empty((n, y.shape[1]))
    for j in range(y.shape[1]):
        out[:, j] = np.interp(tc, t, y[:, j])
    return tc - t0, out


#: lag ranges of :func:`alignment_window`
LAG_SEARCHES = ("window", "periods")


def alignment_window(obs: np.ndarray, fps: float, n_sim: int, search: str = "window") -> tuple[int, int]:
    """Lag range and compared length for aligning a simulation to ``obs``.

    The length depends only on the observation and the simulation length, so every
    simulation in an ensemble is compared over the same number of frames (the
    likelihoods are then comparable).

    ``search="window"`` (default): every start the simulated window offers,
    ``max_lag = max(ceil(1.5 periods), n_sim - obs.size)``, so the whole observation is compared
    and the recording may sit anywhere in the kept simulation. ``"periods"``: lags up to 1.5
    periods, enough for a settled limit cycle, whose cycles repeat; but a vibration that is
    still drifting, or repeats only every few cycles, looks different 100 frames on, and the
    1.5-period search cannot reach the part of the simulation that matches (measured on a
    concealed-effect suite, at the true parameters without the effect: misfits up to
    18 mm^2 RMS with ``"periods"``, at most 0.14 mm^2 in every case with ``"window"``;
    :ref:`model-numerics-observation`). Either way, when the simulation is too short for the whole observation the
    observation is trimmed to ``n_sim - max_lag`` frames.

    Returns (max_lag, n_compare) in frames.
    """
    if search not in LAG_SEARCHES:
        raise ValueError(f"lag search must be one of {LAG_SEARCHES}, got {search!r}")
    f0 = estimate_f0(obs, fps)
    if not math.isfinite(f0):
        raise ValueError("observed GAW shows no periodic oscillation (f0 could not be estimated)")
    period = fps / f0
    max_lag = int(math.ceil(1.5 * period))
    if search == "window":
        max_lag = max(max_lag, int(n_sim) - obs.size)
    n_cmp = min(obs.size, n_sim - max_lag)
    if n_cmp < 2 * period:
        raise ValueError(
            f"simulation ({n_sim} frames) too short to align an observation with period {period:.1f} frames"
        )
    return max_lag, n_cmp


ALIGNMENTS = ("profile", "xcorr")


#: conjugate spectra of zero-stuffed templates, by (oversample, FFT length, template bytes): one
#: observation is aligned against thousands of waveforms of the same length
_TEMPLATE_SPECTRA: dict = {}


def _profile_scores(hr: np.ndarray, tmpl: np.ndarray, q: int, j_max: int) -> np.ndarray:
    """``-sum_i (hr[j + q i] - tmpl[i])^2`` for every fine lag ``j = 0..j_max``, as
    ``-(S2(j) - 2 C(j) + |tmpl|^2)``. The cross term ``C`` is one FFT correlation of the record
    with the template stuffed with ``q - 1`` zeros between samples (the template's spectrum is
    cached: the same observation meets every simulation); the windowed energy ``S2`` is a
    difference of running sums taken per residue ``j mod q`` (one cumulative sum over the record
    folded into rows of ``q``). Equal to the direct sum to ~1e-11 relative (cancellation in
    ``S2 - 2C``); 1.7-1.9x faster than ``q`` direct correlations of the decimated record (400
    frames, 200 lags of 10 fine steps; ``benchmarks/studies/bench_alignment.py``), which are 5x faster
    than gathering every window.

    ``hr`` may hold several records, one per row (``(m, N)``; scores ``(m, j_max + 1)``): the
    transforms and sums then run over all rows at once, and each row's scores are the same bytes
    as its own call's (every step acts on a row alone, in the same order)."""
    from scipy import fft as sfft

    n = tmpl.size
    span = j_max + q * (n - 1) + 1  # the samples any window reads
    if hr.shape[-1] < span:
        raise ValueError(f"record of {hr.shape[-1]} samples is too short for lags up to {j_max} of a {n}-frame window")
    x = hr[..., :span]
    nfft = sfft.next_fast_len(span, real=True)  # circular wrap cannot reach lags <= j_max
    key = (q, nfft, tmpl.tobytes())
    spec = _TEMPLATE_SPECTRA.get(key)
    if spec is None:
        u = np.zeros(q * (n - 1) + 1)
        u[::q] = tmpl
        spec = np.conj(sfft.rfft(u, nfft))
        if len(_TEMPLATE_SPECTRA) >= 8:
            _TEMPLATE_SPECTRA.clear()
        _TEMPLATE_SPECTRA[key] = spec
    c = sfft.irfft(sfft.rfft(x, nfft, axis=-1) * spec, nfft, axis=-1)[..., : j_max + 1]
    rows = -(-span // q)
    lead = x.shape[:-1]
    y = np.zeros(lead + (rows * q,))
    y[..., :span] = x * x
    # e[..., k q + r]: sum of y[..., k' q + r] over k' < k
    e = np.concatenate(
        [np.zeros(lead + (q,)), np.cumsum(y.reshape(lead + (rows, q)), axis=-2).reshape(lead + (rows * q,))], axis=-1
    )
    s2 = e[..., q * n : q * n + j_max + 1] - e[..., : j_max + 1]
    return -(s2 - 2.0 * c + float(tmpl @ tmpl))


def _read_at_best(cs: np.ndarray, js: np.ndarray, hr: np.ndarray, q: int, n_cmp: int) -> tuple[np.ndarray, np.ndarray]:
    """Each row's aligned segment from its fine-lag scores ``cs`` (m, len(js)) over the records
    ``hr`` (m, N): the best fine lag, refined by a parabola through it and its neighbours, and the
    segment read there by linear interpolation. Returns (segments (m, n_cmp), lags in frames (m,))."""
    m = np.argmax(cs, axis=-1)
    rows = np.arange(cs.shape[0])
    inner = (m > 0) & (m < cs.shape[-1] - 1)
    mi = np.clip(m, 1, max(1, cs.shape[-1] - 2))
    frac = np.zeros(cs.shape[0])
    if cs.shape[-1] >= 3:
        c0, c1, c2 = cs[rows, mi - 1], cs[rows, mi], cs[rows, mi + 1]
        den = c0 - 2.0 * c1 + c2
        use = inner & (den < 0)
        frac[use] = np.clip(0.5 * (c0[use] - c2[use]) / den[use], -0.5, 0.5)
    pos = js[m] + frac  # fine-grid position of the aligned start
    x = pos[:, None] + q * np.arange(n_cmp)[None, :]
    i0 = np.minimum(np.floor(x).astype(np.int64), hr.shape[-1] - 2)
    w = x - i0
    seg = (1.0 - w) * np.take_along_axis(hr, i0, axis=-1) + w * np.take_along_axis(hr, i0 + 1, axis=-1)
    return seg, pos / q


def align_many(
    sims_hr: np.ndarray, obs: np.ndarray, fps: float, window: tuple[int, int], oversample: int, method: str = "profile"
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`align` of several oversampled simulated GAWs of one length, ``sims_hr`` (m, N), to one
    observation: the many waveforms one simulation yields under an extension's parameters. Each
    row's segment and lag are the same bytes as :func:`align` of that row alone (``sim`` its
    every ``oversample``-th sample). Returns (segments (m, n_compare), lags in frames (m,))."""
    if method not in ALIGNMENTS:
        raise ValueError(f"alignment method must be one of {ALIGNMENTS}, got {method!r}")
    hr = np.atleast_2d(np.asarray(sims_hr, dtype=float))
    q = int(oversample) if oversample is not None else 0
    if q < 1:
        raise ValueError(f"oversample must be >= 1, got {oversample!r}")
    n_sim = (hr.shape[-1] - 1) // q + 1
    if n_sim < window[1]:
        raise ValueError(f"records of {n_sim} frames are shorter than the {window[1]} frames to compare")
    if method == "xcorr":
        out = [align(h[::q], obs, fps, window, sim_hr=h, oversample=q, method=method) for h in hr]
        return (np.array([o[0] for o in out]).reshape(hr.shape[0], -1), np.array([o[2] for o in out]))
    obs = np.asarray(obs, dtype=float)
    max_lag, n_cmp = window
    js = np.arange(0, min(q * max_lag, q * (n_sim - n_cmp)) + 1)
    cs = _profile_scores(hr, obs[:n_cmp], q, int(js[-1]))
    return _read_at_best(cs, js, hr, q, n_cmp)


def align(
    sim: np.ndarray,
    obs: np.ndarray,
    fps: float,
    window: tuple[int, int] | None = None,
    sim_hr: np.ndarray | None = None,
    oversample: int | None = None,
    method: str = "xcorr",
) -> tuple[np.ndarray, np.ndarray, float]:
    """Phase-align a simulated GAW to an observed one over lags 0..max_lag frames.

    ``method="xcorr"`` (the paper, Section 4.1): the lag maximises the cross-correlation of
    the simulation with the first two observed cycles. ``method="profile"``: the lag
    minimises the squared residual over the whole compared window, i.e. it maximises the
    Gaussian likelihood over the unknown phase (the profile likelihood of the phase
    nuisance). For an exactly periodic simulation the two agree up to whole periods; when
    cycles differ slightly the first-two-cycle correlation is nearly tied between lags one
    period apart and flips between them as the parameters change, which makes the
    likelihood jump (:ref:`model-numerics-observation`).

    Without ``sim_hr`` the lag is a whole number of frames. With ``sim_hr`` (the same
    simulated GAW sampled ``oversample`` times faster from the same start, e.g.
    :attr:`vfcore.result.SimResult.gaw_hr`) it is refined below one frame: the criterion
    is evaluated at every fine lag, its optimum is refined by a parabola through the three best fine lags, and the segment is read from
    ``sim_hr`` at the fractional lag by linear interpolation, so the aligned segment varies
    continuously with the simulation.

    Returns (sim_segment, obs_segment, lag in frames), segments of length ``n_compare``.
    """
    if method not in ALIGNMENTS:
        raise ValueError(f"alignment method must be one of {ALIGNMENTS}, got {method!r}")
    sim = np.asarray(sim, dtype=float)
    obs = np.asarray(obs, dtype=float)
    max_lag, n_cmp = window if window is not None else alignment_window(obs, fps, sim.size)
    if method == "xcorr":
        f0 = estimate_f0(obs, fps)
        n_tmpl = min(n_cmp, int(math.ceil(2 * fps / f0)) if math.isfinite(f0) else n_cmp)
        tmpl = obs[:n_tmpl] - obs[:n_tmpl].mean()

        def score(segs):  # larger is better
            return (segs - segs.mean(axis=-1, keepdims=True)) @ tmpl
    else:
        n_tmpl = n_cmp
        tmpl = obs[:n_cmp]

        def score(segs):
            d = segs - tmpl
            return -np.einsum("...i,...i->...", d, d)

    if sim_hr is None:
        lags = np.arange(0, max_lag + 1)
        segs = sim[lags[:, None] + np.arange(n_tmpl)[None, :]]
        best_lag = int(lags[int(np.argmax(score(segs)))])
        return sim[best_lag : best_lag + n_cmp], obs[:n_cmp], float(best_lag)
    q = int(oversample) if oversample is not None else 0
    hr = np.asarray(sim_hr, dtype=float)
    if q < 1 or hr.size < q * (sim.size - 1) + 1:
        raise ValueError(f"sim_hr ({hr.size} samples) does not hold {sim.size} frames at oversample {oversample!r}")
    # every fine lag j/q frame over the whole lag range (a whole-frame pre-search can miss the
    # right cycle: lags one period apart score almost alike), kept inside the record
    js = np.arange(0, min(q * max_lag, q * (sim.size - n_cmp)) + 1)
    if method == "profile":
        cs = _profile_scores(hr, tmpl, q, int(js[-1]))
    else:
        cs = np.concatenate(
            [score(hr[js[b : b + 64, None] + q * np.arange(n_tmpl)[None, :]]) for b in range(0, js.size, 64)]
        )
    seg, lag = _read_at_best(cs[None, :], js, hr[None, :], q, n_cmp)
    return seg[0], obs[:n_cmp], float(lag[0])
