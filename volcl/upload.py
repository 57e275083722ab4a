"""A packed scene's buffers on one device, re-uploading only what changed."""
from __future__ import annotations

import numpy as np

from .opencl import cl
from .pack import ARG_ORDER

# Every kernel buffer but RenderParams, which each render owns (it holds the seed and the estimator).
SCENE_BUFFERS = tuple(name for name in ARG_ORDER if name != "params")


class DeviceScene:
    """The scene arrays (all but RenderParams) uploaded to one volcl Device."""

    def __init__(self, device, arrays: dict):
        self.device = device
        self.buffers: dict = {}
        self.uploads = 0                # buffer uploads so far, the first one included
        self.uploaded_bytes = 0
        self.upload(arrays, SCENE_BUFFERS)

    def upload(self, arrays: dict, names) -> list:
        """Upload arrays[name] for each of `names`: into the buffer already there when the size is
        the same, else into a new one (the old one is released once no render uses it)."""
        ctx, queue = self.device.ctx, self.device.queue
        mf = cl.mem_flags
        for name in names:
            a = np.ascontiguousarray(arrays[name])
            old = self.buffers.get(name)
            if old is not None and old.size == a.nbytes:
                # blocking: renders may use other queues, and `a` may be freed once this returns
                cl.enqueue_copy(queue, old, a, is_blocking=True)
            else:
                self.buffers[name] = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
            self.uploads += 1
            self.uploaded_bytes += a.nbytes
        return list(names)

    def args(self, params_buffer) -> list:
        """The kernel's buffer arguments in order, with a render's own RenderParams buffer."""
        return [params_buffer if name == "params" else self.buffers[name] for name in ARG_ORDER]
