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
    """A shape in world space, or, for a member of a ShapeGroup (`group`), in the group's space:
    the group's instances place it in the world (Scene.instances)."""
    kind: str                        # 'mesh' | 'sphere' | 'cylinder'
    bsdf: Bsdf
    vertices: Optional[np.ndarray] = None     # (n, 3) float64, world space
    faces: Optional[np.ndarray] = None        # (m, 3) int64
    normals: Optional[np.ndarray] = None      # (n, 3) world-space shading normals, or None
    uvs: Optional[np.ndarray] = None          # (n, 2) texture coordinates from the mesh file, or None
    center: Optional[np.ndarray] = None       # sphere, world space
    radius: float = 0.0
    cylinder: Optional[np.ndarray] = None     # cylinder: the 4x4 map of the unit cylinder (radius 1,
                                              # z in [0, 1]) to the world, to_world @ local
    flip_normals: bool = False
    emitter_radiance: Optional[np.ndarray] = None   # area emitter on this shape
    interior: Optional[Medium] = None
    exterior: Optional[Medium] = None
    id: str = ""
    source: Optional[Source] = None
    # What the world-space fields were made from (volcl.scene.shapes places it again when the
    # transform is edited): the object-space mesh (a volcl.mesh.TriangleMesh), sphere
    # (center, radius) or cylinder frame (4x4), the to_world matrix, whether the file asked for face
    # normals, whether a mesh file without normals gets Mitsuba's computed ones, and the matrix
    # its normals turn with where that is not to_world's inverse transpose (Mitsuba's rotate).
    local: object = None
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    face_normals: bool = False
    smooth_normals: bool = False
    normal_matrix: Optional[np.ndarray] = None
    emitter_id: str = ""             # the area emitter's own id, if it has one
    group: Optional["ShapeGroup"] = None      # the shapegroup this shape belongs to, if any


@dataclass
class ShapeGroup:
    """Mitsuba's shapegroup: shapes that render only where an Instance places them. Its shapes are
    also in Scene.shapes (after the scene's own), each with `group` set to it; the device keeps one
    copy of their geometry, however many instances there are."""
    shapes: list = field(default_factory=list)
    id: str = ""
    source: Optional[Source] = None


@dataclass
class Instance:
    """Mitsuba's instance: a ShapeGroup placed in the world by an affine to_world (4x4)."""
    group: ShapeGroup
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    id: str = ""
    source: Optional[Source] = None


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
    kind: str = "perspective"        # 'perspective' | 'thinlens' | 'orthographic'
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    fov: float = 40.0                # degrees, along fov_axis (perspective, thin lens)
    fov_axis: str = "x"              # 'x' | 'y' | 'diagonal' | 'smaller' | 'larger'
    width: int = 768
    height: int = 576
    near_clip: float = 1e-2
    far_clip: float = 1e4
    rfilter: Filter = field(default_factory=Filter)
    medium: Optional[Medium] = None
    principal_point: tuple = (0.0, 0.0)   # Mitsuba's principal_point_offset_x/y, in image fractions
    aperture_radius: float = 0.0     # thin lens
    focus_distance: float = 0.0      # thin lens: distance along the view axis that is in focus
    id: str = ""


@dataclass
class Sensor:
    """One of a scene's sensors: its camera and its sampler's settings."""
    camera: Camera
    spp: int = 4
    seed: int = 0
    source: Optional[Source] = None


@dataclass
class Integrator:
    kind: str = "volpathmis"         # as written in the file ('direct': Mitsuba's direct integrator)
    max_depth: int = -1              # Mitsuba meaning: 1 = emitters only, 2 = direct lighting, -1 = unlimited
    rr_depth: int = 5
    hide_emitters: bool = False
    specular_chains_only: bool = False   # Nori 'whitted': diffuse vertices end after direct lighting
    emitter_samples: int = 1         # 'direct': light samples per camera ray's first surface
    bsdf_samples: int = 1            # 'direct': BSDF samples there
    moment: bool = False             # Mitsuba's 'moment' wrapper: also write the second moment


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
    sensors: list = field(default_factory=list)     # every Sensor of the file; camera/spp/seed are one's
    sensor_index: int = 0
    instances: list = field(default_factory=list)   # Instance placements of shape groups


def select_sensor(scene: Scene, index: int) -> None:
    """Render the scene through its sensor number `index` (0-based, in file order; Mitsuba's
    mi.render(scene, sensor=index)): its camera, sample count and seed."""
    from ..errors import VolclError
    count = len(scene.sensors)
    if not 0 <= index < max(count, 1):
        raise VolclError(f"--sensor {index}: the scene has {count} sensor{'s' if count != 1 else ''} "
                         f"(0 to {max(count - 1, 0)})", file=scene.path)
    if not scene.sensors:
        return
    sensor = scene.sensors[index]
    scene.camera, scene.spp, scene.seed, scene.sensor_index = sensor.camera, sensor.spp, sensor.seed, index
    seen: dict = {}
    for medium in [scene.camera.medium] + [m for s in scene.shapes for m in (s.interior, s.exterior)]:
        if medium is not None:
            seen.setdefault(id(medium), medium)
    scene.media = list(seen.values())


@dataclass
class TTest:
    """Nori's <test type="ttest">: each scene's mean radiance must match its reference."""
    path: str
    scenes: list
    references: list
    significance: float = 0.01
