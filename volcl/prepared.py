"""A scene ready to render: its model, its packed kernel arrays, and its uploads, one per device.

This is what volcl.load_file returns (as volcl.Scene). Renders on a device reuse the upload that
device already has; volcl.traverse edits the model, and `apply` repacks only the parts the edits
touched (volcl.pack.PARTS) and re-uploads, to every device the scene is on, only the arrays whose
bytes changed.
"""
from __future__ import annotations

import hashlib
import json
import threading
from dataclasses import dataclass, field
from pathlib import Path

from . import features as feat
from .pack import ARG_ORDER, PARTS, Packer
from .scene.model import Scene as ModelScene
from .upload import SCENE_BUFFERS, DeviceScene


def file_sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def defines_key(defines: dict) -> str:
    """The -D overrides that change the image (all but spp), as one canonical string."""
    return json.dumps({k: str(defines[k]) for k in sorted(defines) if k != "spp"})


@dataclass
class Update:
    """What Scene.apply did: the parameters applied, the arrays that changed (and were uploaded to
    each device the scene is on), and the kernel feature sets before and after."""
    keys: list = field(default_factory=list)
    arrays: list = field(default_factory=list)
    uploaded_bytes: int = 0
    features_before: dict = field(default_factory=dict)
    features_after: dict = field(default_factory=dict)
    devices: list = field(default_factory=list)

    @property
    def features_changed(self) -> bool:
        return self.features_before != self.features_after

    def feature_change(self) -> str:
        """'+hg, -chromatic_media': the flags turned on and off."""
        on = [f"+{k.lower()}" for k in feat.FLAGS if self.features_after.get(k) and not self.features_before.get(k)]
        off = [f"-{k.lower()}" for k in feat.FLAGS if self.features_before.get(k) and not self.features_after.get(k)]
        return ", ".join(on + off)

    def __repr__(self) -> str:
        feats = f"; kernel features {self.feature_change()}" if self.features_changed else ""
        return (f"<volcl update: {len(self.keys)} parameters, arrays {', '.join(self.arrays) or 'none'} changed "
                f"({self.uploaded_bytes} bytes to each of {len(self.devices)} devices){feats}>")


class Scene:
    """A loaded scene: `model` (volcl.scene.model.Scene), where it came from, and its state on the
    devices it was rendered on."""

    def __init__(self, model: ModelScene, path: str | None = None, defines: dict | None = None,
                 majorant_cells: int | None = None, max_leaf: int = 4):
        if not isinstance(model, ModelScene):
            raise TypeError(f"expected a volcl.scene.model.Scene, not {type(model).__name__}")
        self.model = model
        self.path = None if path is None else str(Path(path).resolve())
        self.defines = {str(k): str(v) for k, v in (defines or {}).items()}
        # what renders of it record (EXR metadata, checkpoints): the file, its contents, the -D values
        self.info = {}
        if self.path is not None:
            self.info = {"scene": self.path, "scene_sha256": file_sha256(self.path),
                         "defines": defines_key(self.defines)}
        self._packer = Packer(model, max_leaf=max_leaf, majorant_cells=majorant_cells)
        self.packed = self._packer.pack()
        self.version = 0                # counts applied updates
        self._uploads: dict = {}        # Device -> DeviceScene
        self._lock = threading.Lock()
        from .params import Pending
        self.pending = Pending()        # values set through volcl.traverse, not yet applied

    def __getstate__(self):
        """Pickled (to send a scene to another process or machine): the model, its packed arrays and
        where it came from; uploads stay behind, each process makes its own."""
        state = dict(self.__dict__)
        state["_uploads"], state["_lock"] = {}, None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        m = self.model
        where = self.path or m.path
        return (f"<volcl.Scene {where}: {m.camera.width}x{m.camera.height}, {m.spp} spp, {len(m.shapes)} shapes, "
                f"{len(m.emitters)} emitters, {len(m.media)} media; features {feat.describe(self.features)}>")

    @property
    def width(self) -> int:
        return self.model.camera.width

    @property
    def height(self) -> int:
        return self.model.camera.height

    @property
    def spp(self) -> int:
        return self.model.spp

    @property
    def seed(self) -> int:
        return self.model.seed

    @property
    def features(self) -> dict:
        """The kernel features the scene calls for (volcl.features.detect)."""
        return self.packed.features

    @property
    def devices(self) -> list:
        """The devices the scene is uploaded to."""
        return list(self._uploads)

    def buffer_sizes(self) -> dict:
        return {name: self.packed.arrays[name].nbytes for name in ARG_ORDER}

    def upload(self, device) -> DeviceScene:
        """The scene's buffers on `device` (a volcl Device), uploaded on the first call."""
        with self._lock:
            up = self._uploads.get(device)
            if up is None:
                up = self._uploads[device] = DeviceScene(device, self.packed.arrays)
            return up

    def release(self, device=None):
        """Free the scene's buffers on `device` (every device by default); a later render uploads again."""
        with self._lock:
            for d in ([device] if device is not None else list(self._uploads)):
                self._uploads.pop(d, None)

    def apply(self, parts, keys=()) -> Update:
        """Repack `parts` after their values were edited in the model, and upload the arrays whose
        bytes changed to every device the scene is on."""
        unknown = set(parts) - set(PARTS)
        if unknown:
            raise ValueError(f"unknown parts {sorted(unknown)}; parts: {', '.join(PARTS)}")
        before = self.packed
        with self._lock:
            after = self._packer.pack(parts)
            changed = [name for name in ARG_ORDER
                       if before.arrays[name].dtype != after.arrays[name].dtype
                       or before.arrays[name].tobytes() != after.arrays[name].tobytes()]
            self.packed = after
            self.version += 1
            uploads = [name for name in changed if name in SCENE_BUFFERS]
            for up in self._uploads.values():
                up.upload(after.arrays, uploads)
        return Update(keys=list(keys), arrays=changed,
                      uploaded_bytes=sum(after.arrays[n].nbytes for n in uploads),
                      features_before=dict(before.features), features_after=dict(after.features),
                      devices=list(self._uploads))
