"""Statistical checks of rendered images: z-tests whose tolerance comes from the render's own
per-pixel variance estimate, Sidak-corrected for the number of comparisons made."""
import numpy as np
from scipy.stats import norm

# One family-wise significance for the whole suite's image tests; each check corrects for the
# number of comparisons it makes itself.
ALPHA = 1e-3


def z_limit(comparisons: int, alpha: float = ALPHA) -> float:
    """Two-sided |z| bound keeping the chance of any false failure among `comparisons` at alpha."""
    per = 1 - (1 - alpha) ** (1 / max(comparisons, 1))
    return float(norm.isf(per / 2))


def assert_mean_matches(result, expected, blocks: int = 4, mask=None, what="image", expected_variance=None):
    """The render's mean equals `expected` (scalar, rgb or per-pixel (h, w, 3) array) within its
    standard error: over the whole image per channel, and over blocks x blocks regions.
    expected_variance: per-pixel variance of an `expected` that is itself an estimate."""
    img = result.image.astype(np.float64)
    var = result.variance.astype(np.float64)
    if expected_variance is not None:
        var = var + np.broadcast_to(np.asarray(expected_variance, np.float64), img.shape)
    exp = np.broadcast_to(np.asarray(expected, np.float64), img.shape)
    m = np.ones(img.shape[:2], bool) if mask is None else mask
    h, w = img.shape[:2]
    regions = [(slice(None), slice(None))]
    if blocks > 1:
        ys = np.linspace(0, h, blocks + 1).astype(int)
        xs = np.linspace(0, w, blocks + 1).astype(int)
        regions += [(slice(ys[i], ys[i + 1]), slice(xs[j], xs[j + 1])) for i in range(blocks) for j in range(blocks)]
    limit = z_limit(3 * len(regions))
    failures = []
    for k, (sy, sx) in enumerate(regions):
        sel = m[sy, sx]
        n = sel.sum()
        if n == 0:
            continue
        diff = (img[sy, sx][sel] - exp[sy, sx][sel]).sum(0) / n
        se = np.sqrt(var[sy, sx][sel].sum(0)) / n
        for c in range(3):
            if se[c] == 0:
                ok = abs(diff[c]) <= 1e-5 * max(1.0, abs(exp[sy, sx][sel][:, c]).mean())
                z = 0.0 if ok else np.inf
            else:
                z = diff[c] / se[c]
            if not abs(z) < limit:
                failures.append(f"region {k} channel {c}: mean {img[sy, sx][sel][:, c].mean():.6g} expected "
                                f"{exp[sy, sx][sel][:, c].mean():.6g} (z = {z:.2f}, limit {limit:.2f})")
    assert not failures, f"{what}: " + "; ".join(failures[:6])
    assert result.invalid == 0, f"{what}: {result.invalid} invalid samples"


def assert_same_image(a, b, blocks: int = 4, what="images"):
    """Two independent renders (different seeds) estimate the same image: block means of their
    difference are zero within the standard error both renders' variances predict."""
    diff = a.image.astype(np.float64) - b.image.astype(np.float64)
    var = a.variance.astype(np.float64) + b.variance.astype(np.float64)
    h, w = diff.shape[:2]
    ys = np.linspace(0, h, blocks + 1).astype(int)
    xs = np.linspace(0, w, blocks + 1).astype(int)
    limit = z_limit(3 * blocks * blocks)
    failures = []
    for i in range(blocks):
        for j in range(blocks):
            d = diff[ys[i]:ys[i + 1], xs[j]:xs[j + 1]].reshape(-1, 3)
            v = var[ys[i]:ys[i + 1], xs[j]:xs[j + 1]].reshape(-1, 3)
            n = len(d)
            se = np.sqrt(v.sum(0)) / n
            z = np.where(se > 0, d.mean(0) / np.where(se > 0, se, 1), np.where(np.abs(d.mean(0)) < 1e-6, 0, np.inf))
            for c in range(3):
                if not abs(z[c]) < limit:
                    failures.append(f"block ({i},{j}) channel {c}: difference {d.mean(0)[c]:.4g} (z = {z[c]:.2f})")
    assert not failures, f"{what}: " + "; ".join(failures[:6])
    assert a.invalid == 0 and b.invalid == 0, f"{what}: invalid samples {a.invalid}, {b.invalid}"


def assert_images_match(a, b, blocks: int = 4, what="images"):
    """Two independent renders (different seeds) estimate the same image: their difference is zero
    within the standard error of both, over the whole image and over blocks x blocks regions."""
    assert b.invalid == 0, f"{what}: {b.invalid} invalid samples in the second render"
    assert_mean_matches(a, b.image, blocks=blocks, what=what, expected_variance=b.variance)
