"""How accurate an image is: the error a render estimates for itself, the error against a reference,
and the time an estimator needs to reach a given error.

One measure throughout, so that a render's own estimate and a measurement against a reference are
the same quantity (README, "Accuracy"):

    relative error = sqrt(mean over pixels and channels of the squared error) / mean over pixels and
                     channels of the true image.

For a render's own estimate the squared error of each pixel is its variance of the mean (estimated
from the samples: s^2 / n) and the true image is approximated by the render itself; against a
reference it is (image - reference)^2 less the reference's own variance of the mean (its noise would
otherwise count as the render's error). Normalizing by the image's mean rather than pixel by pixel
keeps dark pixels (whose relative error is large but invisible) from dominating, needs no threshold,
and makes the squared error additive: an unbiased estimator's relative error falls as 1/sqrt(spp).
"""
from __future__ import annotations

import math

import numpy as np


def relative_standard_error(image: np.ndarray, variance: np.ndarray) -> float:
    """The render's own estimate of its relative error: sqrt(mean variance of the mean) / mean image.
    0 for an image with no variance (e.g. black), inf for a noisy image whose mean is 0."""
    var = float(np.mean(np.asarray(variance, np.float64)))
    mean = float(np.mean(np.asarray(image, np.float64)))
    if var <= 0.0:
        return 0.0
    return math.sqrt(var) / mean if mean > 0.0 else math.inf


def relative_mse(image: np.ndarray, reference: np.ndarray, reference_variance: np.ndarray | None = None) -> float:
    """Squared relative error of `image` against `reference` (see the module docstring). With the
    reference's variance of the mean, its expected contribution is taken out (an independent
    reference adds its variance to the expected squared difference); the result can then come out
    slightly negative by chance when the image is much better than the reference, and is kept as is
    so that averages over repeated measurements stay unbiased."""
    img = np.asarray(image, np.float64)
    ref = np.asarray(reference, np.float64)
    mse = float(np.mean((img - ref) ** 2))
    if reference_variance is not None:
        mse -= float(np.mean(np.asarray(reference_variance, np.float64)))
    mean = float(np.mean(ref))
    if mean <= 0.0:
        return 0.0 if mse <= 0.0 else math.inf
    return mse / (mean * mean)


def relative_rmse(image, reference, reference_variance=None) -> float:
    """sqrt of relative_mse, 0 where the reference's noise accounts for all of the difference."""
    return math.sqrt(max(relative_mse(image, reference, reference_variance), 0.0))


def time_to_error(seconds, errors, target: float) -> float | None:
    """Time from which the error stays at or below `target` for the rest of the measurements,
    interpolated linearly in log(time) against log(error) between the last measurement above the
    target and the next one (an unbiased estimator's error falls on a straight line of slope -1/2
    there). Not the first crossing: a heavy-tailed estimator's error dips below a target by luck and
    comes back up with the next rare bright path. None when the last measurement is above the
    target. When every measurement is below it, the line of slope -1/2 through the first one is
    followed back."""
    t = np.asarray(seconds, np.float64)
    e = np.asarray(errors, np.float64)
    if e.size == 0 or e[-1] > target:
        return None
    above = np.flatnonzero(e > target)
    if above.size == 0:
        return float(t[0] * (e[0] / target) ** 2) if e[0] > 0 else float(t[0])
    i = int(above[-1]) + 1
    t0, t1, e0, e1 = t[i - 1], t[i], e[i - 1], e[i]
    if not (t0 > 0 and e1 > 0):
        return float(t1)
    f = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e1))
    return float(math.exp(math.log(t0) + f * (math.log(t1) - math.log(t0))))
