"""Plain data a loaded scene is made of.

Everything here is already validated and in world space: the parser resolves references, defaults,
transforms and files, so the renderer never sees XML. Colours are float64 arrays of shape (3,).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np


def rgb(value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    return np.full(3, float(a)) if a.ndim == 0 else a.reshape(3).copy()


@dataclass
class Source:
    """Where an element came from, for error messages."""
    file: str
    line: int
    element: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: <{self.element}>"


@dataclass
class Phase:
    kind: str = "isotropic"          # 'isotropic' | 'hg'
    g: float = 0.0


@dataclass
class Volume:
    """A scalar or rgb field. kind 'const': value only. kind 'grid': data of shape (z, y, x, c)."""
    kind: str                        # 'const' | 'grid'
    value: np.ndarray = field(default_factory=lambda: rgb(1.0))
    data: Optional[np.ndarray] = None
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    filter: str = "trilinear"        # 'trilinear' | 'nearest'
    filename: str = ""


@dataclass
class Medium:
    kind: str                        # 'homogeneous' | 'heterogeneous'
    sigma_t: object                  # np.ndarray (3,) or Volume
    albedo: object                   # np.ndarray (3,) or Volume
    scale: float = 1.0
    phase: Phase = field(default_factory=Phase)
    radiance: Optional[np.ndarray] = None    # volcl extension: emits sigma_a * radiance
    id: str = ""
    source: Optional[Source] = None


@dataclass
class Bsdf:
    kind: str                        # 'diffuse' | 'dielectric' | 'conductor' | 'null'
    reflectance: np.ndarray = field(default_factory=lambda: rgb(0.5))
    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    eta: Optional[np.ndarray] = None          # conductor; None = perfect mirror (material="none")
    k: Optional[np.ndarray] = None
    specular_reflectance: np.ndarray = field(default_factory=lambda: rgb(1.0))
    twosided: bool = False
    id: str = ""
    source: Optional[Source] = None
    # a two-sided bsdf is a copy of the one it wraps; edits of that one's values reach it too
    twosided_of: Optional["Bsdf"] = None


@dataclass
class Shape:
    kind: str                        # 'mesh' | 'sphere'
    bsdf: Bsdf
    vertices: Optional[np.ndarray] = None     # (n, 3) float64, world space
    faces: Optional[np.ndarray] = None        # (m, 3) int64
    normals: Optional[np.ndarray] = None      # (n, 3) world-space shading normals, or None
    center: Optional[np.ndarray] = None       # sphere, world space
    radius: float = 0.0
    flip_normals: bool = False
    emitter_radiance: Optional[np.ndarray] = None   # area emitter on this shape
    interior: Optional[Medium] = None
    exterior: Optional[Medium] = None
    id: str = ""
    source: Optional[Source] = None
    # What the world-space fields were made from (volcl.scene.shapes places it again when the
    # transform is edited): the object-space mesh (a volcl.mesh.TriangleMesh) or sphere
    # (center, radius), the to_world matrix, and whether the file asked for face normals.
    local: object = None
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    face_normals: bool = False
    emitter_id: str = ""             # the area emitter's own id, if it has one


@dataclass
class Emitter:
    kind: str                        # 'point' | 'directional' | 'constant'
    value: np.ndarray                # intensity (W/sr) | irradiance | radiance
    position: Optional[np.ndarray] = None
    direction: Optional[np.ndarray] = None    # directional: direction the light travels
    source: Optional[Source] = None
    id: str = ""


@dataclass
class Filter:
    kind: str = "gaussian"           # 'box' | 'gaussian' | 'tent'
    radius: float = 2.0              # in pixels; gaussian default is 4 * stddev (Mitsuba) or 2 (Nori)
    stddev: float = 0.5


@dataclass
class Camera:
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    fov: float = 40.0                # degrees, along fov_axis
    fov_axis: str = "x"              # 'x' | 'y' | 'diagonal' | 'smaller' | 'larger'
    width: int = 768
    height: int = 576
    near_clip: float = 1e-2
    far_clip: float = 1e4
    rfilter: Filter = field(default_factory=Filter)
    medium: Optional[Medium] = None
    id: str = ""


@dataclass
class Integrator:
    kind: str = "volpathmis"         # as written in the file
    max_depth: int = -1              # Mitsuba meaning: 1 = emitters only, 2 = direct lighting, -1 = unlimited
    rr_depth: int = 5
    hide_emitters: bool = False
    specular_chains_only: bool = False   # Nori 'whitted': diffuse vertices end after direct lighting


@dataclass
class Scene:
    path: str
    dialect: str                     # 'mitsuba' | 'nori'
    integrator: Integrator = field(default_factory=Integrator)
    camera: Camera = field(default_factory=Camera)
    spp: int = 4
    seed: int = 0
    shapes: list = field(default_factory=list)
    emitters: list = field(default_factory=list)
    media: list = field(default_factory=list)       # every distinct medium referenced
    warnings: list = field(default_factory=list)


@dataclass
class TTest:
    """Nori's <test type="ttest">: each scene's mean radiance must match its reference."""
    path: str
    scenes: list
    references: list
    significance: float = 0.01
