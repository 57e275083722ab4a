"""Guide tables for the kernels' searches of float32 CDFs (kernels/sampling.h,
sample_discrete_cdf_guided): the reconstruction filter's table (volcl.pack.filter_table) and the
environment map's marginal and conditional CDFs (volcl.envmap)."""
from __future__ import annotations

import numpy as np


def guide(cdf: np.ndarray) -> np.ndarray:
    """Where the kernel's search of each float32 CDF (last axis, n entries) starts: entry g is the
    first index whose CDF exceeds g / n, that quotient rounded to float32 as the kernel's u is (n - 1
    if no entry does), as float32 (exact below 2^24). Any start gives the same index (the search
    walks back and forth to it); this one makes the walk a step or two on average, where a binary
    search's random branches cost most of a sample on PoCL."""
    n = cdf.shape[-1]
    at = np.arange(n, dtype=np.float32) / np.float32(n)
    rows = np.asarray(cdf, np.float32).reshape(-1, n)
    # a search per row: the vectorized forms tried (one search of every entry against `at`, or
    # ceil(c n) corrected, then a count per row and a running sum) were no faster on an
    # 8192 x 4095 table (best of 3, interleaved: 0.78 s this way, 0.83 and 0.91 s those)
    g = np.stack([np.searchsorted(r, at, side="right") for r in rows])
    return np.minimum(g, n - 1).astype(np.float32).reshape(cdf.shape)
