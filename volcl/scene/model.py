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
    """A phase function; volcl/phase.py says what each kind means and how the kernels get it."""
    kind: str = "isotropic"          # 'isotropic' | 'hg' | 'rayleigh' | 'blend' | 'tabulated' | 'draine'
                                     # | 'cornette_shanks' | 'fournier_forand' | 'mie'
    g: float = 0.0                   # hg, draine, cornette_shanks
    alpha: float = 0.0               # draine
    weight: float = 0.5              # blend: (1 - weight) * phases[0] + weight * phases[1]
    phases: tuple = ()               # blend: the two phases blended
    values: Optional[np.ndarray] = None  # tabulated: values at cosines evenly spaced over [-1, 1], 1 forward
    n: float = 0.0                   # fournier_forand: relative refractive index of the particles
    mu: float = 0.0                  # fournier_forand: slope of the Junge size distribution
    diameter: float = 0.0            # mie: droplet diameter in micrometres
    tolerance: float = 1e-3          # fournier_forand: bound on |value / pdf - 1| of its sampling table


@dataclass
class Volume:
    """A scalar or rgb field. kind 'const': value only. kind 'grid': data of shape (z, y, x, c).
    kind 'sparse': an OpenVDB or NanoVDB grid in bricks (volcl.vdb.SparseGrid), filling the unit
    cube of to_world as a grid of sparse.padded_counts() * 8 voxels would."""
    kind: str                        # 'const' | 'grid' | 'sparse'
    value: np.ndarray = field(default_factory=lambda: rgb(1.0))
    data: Optional[np.ndarray] = None
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    filter: str = "trilinear"        # 'trilinear' | 'nearest'
    filename: str = ""
    sparse: Optional[object] = None  # volcl.vdb.SparseGrid
    grid_name: str = ""              # sparse: the grid's name in its file

    @property
    def channels(self) -> int:
        if self.kind == "grid":
            return self.data.shape[-1]
        if self.kind == "sparse":
            return self.sparse.channels
        return 1 if np.ptp(self.value) == 0 else 3

    def values(self) -> np.ndarray:
        """Every value the field holds, (n, channels) or (3,) for a constant (range checks)."""
        if self.kind == "grid":
            return self.data
        if self.kind == "sparse":
            sg = self.sparse
            return np.concatenate([sg.bricks.reshape(-1, sg.channels), sg.tile_values.reshape(-1, sg.channels),
                                   sg.background.reshape(1, -1)])
        return self.value


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
    # volcl extension, heterogeneous media: a spatially varying emission, either the radiance
    # itself ('radiance') or a temperature (volcl.blackbody) ('temperature'); times emission_scale
    emission_kind: str = "none"               # 'none' | 'radiance' | 'temperature'
    emission_volume: Optional[Volume] = None
    emission_scale: float = 1.0
    temperature_scale: float = 1.0
    temperature_offset: float = 0.0

    @property
    def emissive(self) -> bool:
        return self.emission_kind != "none" or (self.radiance is not None and bool(np.any(self.radiance > 0)))


@dataclass
class Texture:
    """A texture giving a colour or float parameter (Mitsuba's bitmap and checkerboard; kernels/
    textures.h has the lookup rules). Bitmaps hold linear float32 texels (h, w, 1 or 3), row 0 the
    image's top row; checkerboards hold two colours (rgb arrays) or nested Textures."""
    kind: str                        # 'bitmap' | 'checkerboard'
    data: Optional[np.ndarray] = None
    filter: str = "bilinear"         # bitmap: 'bilinear' | 'nearest'
    wrap: str = "repeat"             # bitmap: 'repeat' | 'mirror' | 'clamp'
    raw: bool = False
    to_uv: np.ndarray = field(default_factory=lambda: np.eye(3))   # 3x3 affine map of uv
    color0: object = field(default_factory=lambda: rgb(0.4))
    color1: object = field(default_factory=lambda: rgb(0.2))
    filename: str = ""
    id: str = ""
    source: Optional[Source] = None

    def mean(self) -> float:
        """Mitsuba's Texture::mean(): a bitmap's mean texel (luminance for colour), a checkerboard's
        mean of its two colours."""
        if self.kind == "bitmap":
            d = np.asarray(self.data, np.float64)
            return float((d[..., 0] if d.shape[-1] == 1 else d @ LUMINANCE).mean())
        return 0.5 * (texture_mean(self.color0) + texture_mean(self.color1))


# Mitsuba's luminance weights for linear sRGB
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def texture_mean(value) -> float:
    """mean() of a parameter: a texture's, or a constant colour's channel mean (Mitsuba's srgb)."""
    if isinstance(value, Texture):
        return value.mean()
    return float(np.mean(np.asarray(value, np.float64)))


@dataclass
class Bsdf:
    """A bsdf. Colour parameters are rgb arrays or Textures, float ones (alpha, opacity) floats or
    Textures. Wrappers (mask, bumpmap, normalmap) hold the bsdf they wrap in `nested`."""
    kind: str                        # 'diffuse' | 'dielectric' | 'conductor' | 'null' | 'roughconductor' |
                                     # 'roughdielectric' | 'plastic' | 'roughplastic' | 'thindielectric' |
                                     # 'mask' | 'bumpmap' | 'normalmap'
    reflectance: object = field(default_factory=lambda: rgb(0.5))   # diffuse; plastics' diffuse_reflectance
    int_ior: float = 1.5046
    ext_ior: float = 1.000277
    eta: object = None               # conductors; None = perfect mirror (material="none")
    k: object = None
    specular_reflectance: object = field(default_factory=lambda: rgb(1.0))
    specular_transmittance: object = field(default_factory=lambda: rgb(1.0))
    twosided: bool = False
    id: str = ""
    source: Optional[Source] = None
    # a two-sided bsdf is a copy of the one it wraps; edits of that one's values reach it too
    twosided_of: Optional["Bsdf"] = None
    material: str = ""               # conductors: the `material` preset eta and k came from
    distribution: str = "beckmann"   # microfacet bsdfs
    alpha_u: object = 0.1
    alpha_v: object = 0.1
    anisotropic: bool = False        # given as alpha_u / alpha_v (Mitsuba's tangent-frame roughness)
    sample_visible: bool = True
    nonlinear: bool = False          # plastics
    opacity: object = 0.5            # mask
    nested: Optional["Bsdf"] = None  # mask, bumpmap, normalmap
    map_texture: Optional[Texture] = None   # bumpmap: heights; normalmap: normals
    scale: float = 1.0               # bumpmap
    flip_invalid_normals: bool = True
    use_shadowing_function: bool = True


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
    uv_map: str = ""                 # 'disk': a disk mesh with Mitsuba's analytic disk uvs (u = r, v = phi / 2 pi)
    group: Optional["ShapeGroup"] = None      # the shapegroup this shape belongs to, if any
    # Mitsuba's rectangle and disk are analytic: their normal is to_world's inverse transpose of +z,
    # so a mirroring to_world does not turn them around as it turns a mesh's winding
    normal_by_transform: bool = False


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
    kind: str                        # 'point' | 'spot' | 'directional' | 'constant' | 'envmap'
    value: np.ndarray                # intensity (W/sr: point, spot) | irradiance | radiance; envmap: 1
    position: Optional[np.ndarray] = None     # point; spot: to_world's origin
    direction: Optional[np.ndarray] = None    # directional: direction the light travels
    source: Optional[Source] = None
    id: str = ""
    to_world: Optional[np.ndarray] = None     # spot, envmap: the emitter's frame (4x4)
    cutoff_angle: float = 20.0       # spot: degrees from its axis (+z of to_world) to where it is dark
    beam_width: float = 15.0         # spot: degrees of full intensity (falls off linearly beyond)
    image: Optional[np.ndarray] = None        # envmap: linear pixels (h, w, c) as read (volcl.scene.images)
    scale: float = 1.0               # envmap: radiance multiplier
    filename: str = ""               # envmap: the image file
    texture: Optional["Texture"] = None     # spot: Mitsuba's projection texture (a colour texture)


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
    # Mitsuba's hdrfilm sample_border: pixels at the image's edge sample their whole filter; off (its
    # default, and Nori's only way) cuts the filter at the edge
    sample_border: bool = False
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
