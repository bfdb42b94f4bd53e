"""The scale a two-line sample is solved at, under a metric scale prior: s = prior + eps,
eps ~ GGD(0, sigma, beta), sigma such that P(|eps| <= window * prior) = prob."""

from __future__ import annotations

import numpy as np

from ...settings.loading import SolverSettings

SCALE_PRIOR_GGD_SHAPE = 4.0  # (was estimator.solvers.scale_prior_ggd_shape) 2L: shape of the generalised Gaussian on the metric scale (flat-topped: the prior's window is a soft box)


def scale_prior_sigma(scale_prior: float, settings: SolverSettings) -> float:
    """sigma of the GGD(0, sigma, beta) with P(|eps| <= window * prior) = prob.

    For a generalised Gaussian, |eps / sigma|^beta ~ Gamma(1 / beta), so
    P(|eps| <= a) = P(Gamma(1/beta) <= (a / sigma)^beta) and
    sigma = a / gammaincinv(1/beta, prob)^(1/beta).
    """
    from scipy.special import gammaincinv  # here, not at import: a CLI error must not pay for it

    beta = SCALE_PRIOR_GGD_SHAPE
    a = settings.scale_prior_window * scale_prior
    return float(a / gammaincinv(1.0 / beta, settings.scale_prior_prob) ** (1.0 / beta))


def sample_scale_noise(n: int, scale_prior: float, settings: SolverSettings, rng: np.random.Generator) -> np.ndarray:
    """n draws of eps ~ GGD(0, sigma, beta) from the given generator."""
    beta = SCALE_PRIOR_GGD_SHAPE
    sigma = scale_prior_sigma(scale_prior, settings)
    magnitude = rng.gamma(1.0 / beta, 1.0, size=n) ** (1.0 / beta)
    sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    return sigma * sign * magnitude
