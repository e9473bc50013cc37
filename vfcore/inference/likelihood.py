"""Gaussian likelihoods of an aligned simulated GAW segment against the observed one.

* :func:`gaussian_loglik`: Hadwin et al. (2019), Eq. 15, the noise sd ``sigma`` known.
* :func:`marginal_gaussian_loglik`: Eq. 15 with the noise sd integrated out (log-uniform prior).
* :func:`scaled_gaussian_loglik`, :func:`scaled_marginal_gaussian_loglik`: the recorded area is ``k`` times
  the true area, ``k`` unknown (an uncalibrated video: ``k = (true px/mm / assumed px/mm)^2``), uniform on
  ``[k_lo, k_hi]`` and integrated out analytically; :func:`sample_area_scale` draws ``k`` from its conditional
  posterior given one draw's segment (:ref:`inference-scale-unknown-area-scale`).

All in log space; a non-finite residual gives ``-inf``.
"""

from __future__ import annotations

import math

import numpy as np


def _residual(sim, obs) -> np.ndarray | None:
    """``sim - obs`` as float64 (ValueError if their shapes differ); None if it is not finite."""
    sim = np.asarray(sim, dtype=float)
    obs = np.asarray(obs, dtype=float)
    if sim.shape != obs.shape:
        raise ValueError(f"simulated and observed GAW differ in shape: {sim.shape} vs {obs.shape}")
    r = sim - obs
    return r if np.all(np.isfinite(r)) else None


def gaussian_loglik(sim, obs, sigma: float) -> float:
    """Eq. 15 in log space: sum of independent N(obs_k | sim_k, sigma^2) log densities."""
    r = _residual(sim, obs)
    if r is None:
        return -math.inf
    r = r / sigma
    return float(-0.5 * np.dot(r, r) - r.size * (math.log(sigma) + 0.5 * math.log(2 * math.pi)))


def marginal_gaussian_loglik(sim, obs, sigma_lo: float, sigma_hi: float) -> float:
    """Eq. 15 with the noise sd integrated out under a log-uniform prior on ``[sigma_lo, sigma_hi]``:

        L = ∫ prod_k N(obs_k | sim_k, s^2) p(s) ds,   p(s) = 1 / (s log(sigma_hi / sigma_lo)),

    which with ``R = sum (obs - sim)^2`` and ``a = n / 2`` is exactly

        log L = -a log(pi R) + log Gamma(a) - log 2 - log log(sigma_hi / sigma_lo)
                + log[P(a, R / (2 sigma_lo^2)) - P(a, R / (2 sigma_hi^2))],

    ``P`` the regularised lower incomplete gamma function (substitute ``u = R / (2 s^2)``; the
    scale-invariant prior of Jeffreys, truncated so that the evidence is proper; Bretthorst 1988,
    "Bayesian Spectrum Analysis and Parameter Estimation", ch. 2; Sivia & Skilling 2006, "Data
    Analysis", section 3.3). The last term is 0 to double precision unless ``sqrt(R / n)`` lies near
    or beyond a bound. The noise sd given a draw is then inverse-gamma: ``s^2 | R ~ IG(a, R / 2)``."""
    r = _residual(sim, obs)
    if r is None:
        return -math.inf
    n = r.size
    if n == 0:
        return 0.0
    return log_marginal_rss(float(np.dot(r, r)), n, sigma_lo, sigma_hi)


def log_marginal_rss(R: float, n: int, sigma_lo: float, sigma_hi: float) -> float:
    """:func:`marginal_gaussian_loglik` from the residual sum of squares ``R`` of ``n`` frames:
    ``log ∫ (2 pi s^2)^(-n/2) exp(-R / (2 s^2)) p(s) ds`` with ``p`` log-uniform on the bounds."""
    from scipy.special import gammainc, gammaincc, gammaln

    a = 0.5 * n
    log_norm = math.log(math.log(sigma_hi / sigma_lo))
    if R == 0.0:  # the integral of s^(-n-1) alone
        return float(
            -a * math.log(2 * math.pi)
            - math.log(n)
            - n * math.log(sigma_lo)
            + math.log1p(-((sigma_lo / sigma_hi) ** n))
            - log_norm
        )
    x_hi, x_lo = R / (2.0 * sigma_lo**2), R / (2.0 * sigma_hi**2)
    if x_hi < a:
        # the fit is closer than sigma_lo: P(a, x) underflows, take its series in logs; the
        # -a log(pi R) of the general form cancels against P's x^a, leaving -a log(2 pi sigma_lo^2)
        lp_hi = _log_p_lower_series(a, x_hi) - a * math.log(x_hi)
        lp_lo = _log_p_lower_series(a, x_lo) - a * math.log(x_lo)
        ratio = math.exp(lp_lo - lp_hi + a * math.log(x_lo / x_hi))
        return float(
            -a * math.log(2 * math.pi * sigma_lo**2)
            + gammaln(a)
            - math.log(2.0)
            - log_norm
            + lp_hi
            + math.log1p(-ratio)
        )
    # P(a, x_hi) - P(a, x_lo), from whichever tail keeps its digits
    mass = gammaincc(a, x_lo) - gammaincc(a, x_hi) if x_lo >= a else gammainc(a, x_hi) - gammainc(a, x_lo)
    if not mass > 0.0:
        return -math.inf
    return float(-a * math.log(math.pi * R) + gammaln(a) - math.log(2.0) - log_norm + math.log(mass))


def _log_p_lower_series(a: float, x: float) -> float:
    """``log P(a, x)`` for ``0 < x < a`` from ``P = x^a e^-x / Gamma(a+1) sum_k x^k / ((a+1)..(a+k))``
    (Abramowitz & Stegun 6.5.29), which converges geometrically there."""
    from scipy.special import gammaln

    term = total = 1.0
    k = 0
    while term > 1e-17 * total and k < 100000:
        k += 1
        term *= x / (a + k)
        total += term
    return a * math.log(x) - x - float(gammaln(a + 1.0)) + math.log(total)


# ---------------------------------------------------------------------------- unknown area scale
def best_area_scale(sim, obs) -> tuple[float, float, float] | None:
    """The least-squares scale of ``sim`` onto ``obs``: ``(k_hat, S, R)`` with ``S = sim . sim``,
    ``k_hat = obs . sim / S`` and ``R = |obs - k_hat sim|^2`` (mm^4); None if the residual is not finite.
    ``S = 0`` (a closed glottis throughout) gives ``k_hat = 0``."""
    r = _residual(sim, obs)
    if r is None:
        return None
    s = np.asarray(sim, dtype=float)
    y = np.asarray(obs, dtype=float)
    S = float(np.dot(s, s))
    k = float(np.dot(y, s)) / S if S > 0.0 else 0.0
    e = y - k * s
    return k, S, float(np.dot(e, e))


def _log_phi_diff(a: float, b: float) -> float:
    """``log(Phi(b) - Phi(a))`` for ``a <= b``, accurate in either tail (``Phi`` the standard normal CDF)."""
    from scipy.special import log_ndtr

    if a > 0.0:  # both in the upper tail: reflect into the lower one
        a, b = -b, -a
    lb, la = float(log_ndtr(b)), float(log_ndtr(a))
    if not la < lb:
        return -math.inf
    d = la - lb
    return lb + (math.log(-math.expm1(d)) if d > -math.log(2.0) else math.log1p(-math.exp(d)))


def scaled_gaussian_loglik(sim, obs, sigma: float, k_lo: float, k_hi: float) -> float:
    """Eq. 15 for a recording ``obs = k sim + noise`` with the area scale ``k`` uniform on ``[k_lo, k_hi]``
    and integrated out. With ``S = sim . sim``, ``k_hat``, ``R`` of :func:`best_area_scale` and
    ``tau = sigma / sqrt(S)`` the exponent is ``-(R + S (k - k_hat)^2) / (2 sigma^2)``, Gaussian in ``k``, so

        log L = -(n-1)/2 log(2 pi sigma^2) - R / (2 sigma^2) - 1/2 log S - log(k_hi - k_lo)
                + log[Phi((k_hi - k_hat) / tau) - Phi((k_lo - k_hat) / tau)]

    (the Gaussian integral over a linear amplitude; Sivia & Skilling 2006, "Data Analysis", section 3.3;
    Bretthorst 1988, ch. 3). ``S = 0``: ``k`` has no effect and this is Eq. 15 at ``sim``."""
    fit = best_area_scale(sim, obs)
    if fit is None:
        return -math.inf
    k, S, R = fit
    if S == 0.0:
        return gaussian_loglik(sim, obs, sigma)
    n = np.size(obs)
    t = math.sqrt(S) / sigma
    return float(
        -0.5 * R / sigma**2
        - (n - 1) * (math.log(sigma) + 0.5 * math.log(2 * math.pi))
        - 0.5 * math.log(S)
        - math.log(k_hi - k_lo)
        + _log_phi_diff((k_lo - k) * t, (k_hi - k) * t)
    )


def scaled_marginal_gaussian_loglik(sim, obs, sigma_lo: float, sigma_hi: float, k_lo: float, k_hi: float) -> float:
    """:func:`marginal_gaussian_loglik` with the area scale ``k`` (uniform on ``[k_lo, k_hi]``) integrated out
    as well. Integrating ``k`` first (:func:`scaled_gaussian_loglik`) leaves, per noise sd ``s``,
    ``(2 pi s^2)^(-(n-1)/2) exp(-R / (2 s^2)) S^(-1/2) D(s) / (k_hi - k_lo)`` with
    ``D(s) = Phi((k_hi - k_hat) sqrt(S) / s) - Phi((k_lo - k_hat) sqrt(S) / s)`` the prior box's share of
    ``k``'s conditional. So

        log L = log_marginal_rss(R, n - 1) - 1/2 log S - log(k_hi - k_lo) + log E[D(s)],

    the first term the closed form of :func:`marginal_gaussian_loglik` with ``n - 1`` degrees of freedom at
    the best scale's residual, and the expectation over ``s`` weighted by that term's integrand
    (:func:`_log_mean_box_share`: ``u = R / (2 s^2)`` is then Gamma((n-1)/2) on the prior's range). Where
    ``k_hat`` lies well inside its box, ``D = 1`` and the last term vanishes."""
    fit = best_area_scale(sim, obs)
    if fit is None:
        return -math.inf
    k, S, R = fit
    n = int(np.size(obs))
    if S == 0.0:
        return marginal_gaussian_loglik(sim, obs, sigma_lo, sigma_hi)
    if n < 2:
        raise ValueError("an unknown area scale needs at least two compared frames")
    base = log_marginal_rss(R, n - 1, sigma_lo, sigma_hi)
    if base == -math.inf:
        return base
    return float(
        base
        - 0.5 * math.log(S)
        - math.log(k_hi - k_lo)
        + _log_mean_box_share(k, S, R, n - 1, sigma_lo, sigma_hi, k_lo, k_hi)
    )


def _log_mean_box_share(
    k: float, S: float, R: float, nu: int, sigma_lo: float, sigma_hi: float, k_lo: float, k_hi: float
) -> float:
    """``log E[D(s)]`` of :func:`scaled_marginal_gaussian_loglik`, ``u = R / (2 s^2)`` ~ Gamma(nu / 2, 1)
    truncated to ``[R / (2 sigma_hi^2), R / (2 sigma_lo^2)]``.

    Without the truncation the expectation is Student's t: ``k`` given the data is then
    ``k_hat + sqrt(R / (nu S)) t_nu`` (a Gaussian whose variance is inverse-gamma; Gelman et al. 2013,
    "Bayesian Data Analysis", 3rd ed., section 3.2), so ``E[D] = T_nu(t_hi) - T_nu(t_lo)`` with
    ``t = (k_bound - k_hat) / sqrt(R / (nu S))``. The truncation moves it by at most the prior-excluded mass
    ``m`` of the Gamma (``|E_trunc - E_full| <= m``), so the t form is used when ``m <= 1e-14`` and
    ``E_full >= 1e-3`` (relative error below 1e-11) or when ``k_hat`` is so deep inside its box that
    ``1 - E_full <= 1e-12 (1 - m)`` (then ``1 - E_trunc <= 1e-12``); otherwise ``E[D]`` is integrated
    numerically in ``log u`` over the truncated range (adaptive quadrature of the log-scaled integrand)."""
    from scipy.special import gammainc, gammaincc, stdtr

    if R == 0.0:  # a perfect fit at k_hat: the weight s^-(nu+1) piles at sigma_lo (approximate)
        t = math.sqrt(S) / sigma_lo
        return _log_phi_diff((k_lo - k) * t, (k_hi - k) * t)
    a = 0.5 * nu
    x_lo, x_hi = R / (2.0 * sigma_hi**2), R / (2.0 * sigma_lo**2)
    m = float(gammainc(a, x_lo) + gammaincc(a, x_hi))
    scale = math.sqrt(R / (nu * S))
    t_lo, t_hi = (k_lo - k) / scale, (k_hi - k) / scale
    full = (
        float(stdtr(nu, t_hi) - stdtr(nu, t_lo))
        if t_hi <= 0 or t_lo <= 0
        else float(stdtr(nu, -t_lo) - stdtr(nu, -t_hi))
    )
    outside = float(stdtr(nu, t_lo) + stdtr(nu, -t_hi))
    if (m <= 1e-14 and full >= 1e-3) or (k_lo < k < k_hi and outside <= 1e-12 * (1.0 - m)):
        return math.log(full) if full < 1.0 else 0.0
    return _log_mean_box_share_quad(k, S, R, a, x_lo, x_hi, k_lo, k_hi)


def _log_mean_box_share_quad(k, S, R, a, x_lo, x_hi, k_lo, k_hi) -> float:
    from scipy.integrate import quad
    from scipy.special import gammaln

    c = math.sqrt(2.0 * S / R)  # z_bound = (k_bound - k_hat) c sqrt(u)

    def log_g(t):  # log Gamma(a) density of u = e^t, times du/dt
        return a * t - math.exp(t) - float(gammaln(a))

    def log_d(t):
        r = c * math.exp(0.5 * t)
        return _log_phi_diff((k_lo - k) * r, (k_hi - k) * r)

    t0, t1 = math.log(x_lo), math.log(x_hi)
    grid = np.linspace(t0, t1, 4001)
    hg = np.array([log_g(t) for t in grid])
    hd = np.array([log_d(t) for t in grid])
    out = []
    for h, with_d in ((hg + hd, True), (hg, False)):
        top = float(np.max(h))
        if not math.isfinite(top):
            return -math.inf
        keep = np.nonzero(h > top - 60.0)[0]
        lo = grid[max(int(keep[0]) - 1, 0)]
        hi = grid[min(int(keep[-1]) + 1, grid.size - 1)]
        peak = float(grid[int(np.argmax(h))])
        f = (lambda t: math.exp(log_g(t) + log_d(t) - top)) if with_d else (lambda t: math.exp(log_g(t) - top))
        val, _ = quad(f, lo, hi, points=[peak] if lo < peak < hi else None, epsabs=0.0, epsrel=1e-13, limit=400)
        out.append(top + math.log(val) if val > 0 else -math.inf)
    return min(out[0] - out[1], 0.0)


def sample_area_scale(
    sim,
    obs,
    rng: np.random.Generator,
    k_bounds,
    *,
    sigma: float | None = None,
    sigma_bounds=None,
    max_tries: int = 1000,
) -> float:
    """One draw of the area scale ``k`` from its posterior given one draw's aligned segment ``sim``.

    Fixed noise (``sigma``): ``k`` is the Gaussian ``N(k_hat, sigma^2 / S)`` truncated to ``k_bounds``.
    Unknown noise (``sigma_bounds``): first the noise sd from its marginal, ``u = R / (2 s^2)`` from the
    truncated Gamma((n-1)/2) by inversion, accepted with probability ``D(s)`` (the box's share of ``k``'s
    conditional, :func:`scaled_marginal_gaussian_loglik`), which makes the pair exact; then ``k`` given ``s``.
    After ``max_tries`` rejections (only when ``k_hat`` lies far outside its box) the last ``s`` is kept.
    ``nan`` when the segment is not finite."""
    from scipy.special import gammainc, gammaincinv
    from scipy.stats import truncnorm

    k_lo, k_hi = (float(b) for b in k_bounds)
    fit = best_area_scale(sim, obs)
    if fit is None:
        return math.nan
    k, S, R = fit
    if S == 0.0:  # k has no effect: its prior
        return float(rng.uniform(k_lo, k_hi))
    if sigma is None:
        s_lo, s_hi = (float(b) for b in sigma_bounds)
        a = 0.5 * (np.size(obs) - 1)
        if R == 0.0:
            s = s_lo
        else:
            p_lo, p_hi = float(gammainc(a, R / (2 * s_hi**2))), float(gammainc(a, R / (2 * s_lo**2)))
            for _ in range(max_tries):
                u = float(gammaincinv(a, rng.uniform(p_lo, p_hi))) if p_hi > p_lo else R / (2 * s_hi**2)
                s = math.sqrt(R / (2.0 * max(u, 1e-300)))
                t = math.sqrt(S) / s
                if math.log(rng.uniform()) < _log_phi_diff((k_lo - k) * t, (k_hi - k) * t):
                    break
        sigma = s
    tau = float(sigma) / math.sqrt(S)
    return float(truncnorm.rvs((k_lo - k) / tau, (k_hi - k) / tau, loc=k, scale=tau, random_state=rng))
