"""Generate the assets of the default scene, deterministically.

Run ``python scenes/default/make_assets.py`` (from anywhere). It (re)writes, next to this file:

- ``env.exr``: 256x128 lat-long HDR environment of a dark enclosure (walls ~0.02) lit by four
  slightly cool-white LED tubes (radiance ~35-45) overhead and to the sides.
- ``checkerboard.png``: 960x640 sRGB texture of the printed backdrop, 48 px per 3 cm square,
  grey 0.3 / white 0.8 linear reflectance.
- ``sphere.ply``: welded icosphere (4 subdivisions), radius 0.04 m, centre (0, 0.04, 0).
- ``bowl.ply``: closed thin-walled bowl (revolved profile), welded and watertight, its flat base
  0.1 mm above y = 0 (a base in the cloth's plane leaves what a ray meets there to rounding).
- ``cloth.ply``: the tablecloth, 0.6 x 0.6 m in the plane y = 0.
- ``backdrop.ply``: the checkerboard backdrop, 0.6 x 0.4 m in the plane z = -0.15.

Meshes are binary little-endian PLY in world coordinates (metres), with per-vertex normals and,
for the planes, UVs in Mitsuba's convention (v = 0 is the top row of the texture image). Nothing
is random, so reruns give byte-identical files.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import cv2
import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
if str(HERE.parents[1]) not in sys.path:  # run as a script: make the repository's abs importable
    sys.path.insert(0, str(HERE.parents[1]))

from abs.colour.srgb import linear_to_srgb  # noqa: E402
from abs.io.images import write_exr  # noqa: E402

# --- Scene geometry (metres) ------------------------------------------------------------------
SPHERE_RADIUS = 0.04
SPHERE_CENTER = np.array([0.0, 0.04, 0.0])
CLOTH_HALF = 0.3  # cloth spans x, z in [-0.3, 0.3] at y = 0
BACKDROP_Z = -0.15
BOWL_GAP = 1e-4  # m between the bowl's flat base and the cloth (see make_bowl)
BACKDROP_WIDTH, BACKDROP_HEIGHT = 0.6, 0.4
SQUARE = 0.03  # checkerboard square size
GREY, WHITE = 0.3, 0.8  # linear reflectance of the printed squares
TEXELS_PER_SQUARE = 48  # 0.625 mm per texel; 0.6 x 0.4 m -> 960 x 640 px exactly

# --- Environment ----------------------------------------------------------------------------
ENV_WIDTH, ENV_HEIGHT = 256, 128
WALL_RADIANCE = 0.02
LED_COLOUR = np.array([0.94, 1.0, 1.07])  # slightly cool white (about 6500-7000 K), linear RGB
# LED tubes as capsules (end A, end B, radius m, radiance) seen from the scene centre. The
# environment is infinitely distant; these positions only shape the bands' directions and widths.
TUBES = (
    ((-0.5, 0.9, 0.0), (0.5, 0.9, 0.0), 0.015, 36.0),      # overhead, running left-right
    ((-0.4, 0.8, 0.6), (0.4, 0.8, 0.6), 0.015, 30.0),      # overhead, in front (behind camera)
    ((-0.8, 0.15, 0.35), (-0.8, 0.75, 0.35), 0.015, 30.0),  # left side, vertical, front-left
    ((0.8, 0.15, -0.1), (0.8, 0.75, -0.1), 0.015, 30.0),   # right side, vertical, slightly behind
)
SUPERSAMPLE = 8  # per axis, to anti-alias the thin tubes


def envmap_directions(u: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Unit directions of lat-long coordinates in Mitsuba's ``envmap`` layout.

    Mitsuba (src/emitters/envmap.cpp, checked by evaluating the emitter): column i is centred at
    u = (i + 0.5) / W, row j lies at theta = pi * j / (H - 1) (rows 0 and H-1 sit exactly on the
    poles), phi = 2 pi u, d = (sin phi sin theta, cos theta, -cos phi sin theta): +y up (top row),
    u = 0 faces -z, u = 1/4 faces +x, u = 1/2 faces +z.
    """
    phi = 2.0 * np.pi * u
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)],
                    axis=-1)


def _tube_mask(d: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Whether rays from the origin along unit directions ``d`` hit the capsule a-b."""
    e = b - a
    de, da = d @ e, d @ a
    # Squared distance from the line {lambda d} to a + s e is |a + s e|^2 - (d.(a + s e))^2,
    # a quadratic in s; minimise it over the segment s in [0, 1].
    quad = e @ e - de**2
    s = np.clip(-(a @ e - da * de) / np.maximum(quad, 1e-12), 0.0, 1.0)
    p = a + s[..., None] * e
    along = np.einsum("...k,...k->...", d, p)
    dist2 = np.einsum("...k,...k->...", p, p) - along**2
    return (dist2 <= radius**2) & (along > 0)


def make_env() -> np.ndarray:
    """The (H, W, 3) linear RGB radiance of the LED enclosure."""
    w, h, n = ENV_WIDTH, ENV_HEIGHT, SUPERSAMPLE
    offsets = (np.arange(n) + 0.5) / n - 0.5  # sub-pixel offsets in (-0.5, 0.5)
    cols = (np.arange(w)[:, None] + 0.5 + offsets[None, :]).reshape(-1) / w
    rows = np.clip((np.arange(h)[:, None] + offsets[None, :]).reshape(-1) / (h - 1), 0.0, 1.0)
    uu, tt = np.meshgrid(cols, rows * np.pi)  # (h n, w n)
    d = envmap_directions(uu, tt)

    # Dim enclosure: a little lighter overhead (light scattered by the ceiling), darker floor.
    wall = WALL_RADIANCE * (1.0 + 0.25 * d[..., 1])
    radiance = np.repeat(wall[..., None], 3, axis=-1)
    for a, b, radius, level in TUBES:
        hit = _tube_mask(d, np.asarray(a, float), np.asarray(b, float), radius)
        radiance[hit] = level * LED_COLOUR
    env = radiance.reshape(h, n, w, n, 3).mean(axis=(1, 3))
    # All columns of a pole row are the same direction: make them equal, as Mitsuba assumes.
    env[0] = env[0].mean(axis=0)
    env[-1] = env[-1].mean(axis=0)
    return env.astype(np.float32)


def cloth_irradiance(env: np.ndarray) -> float:
    """Irradiance (luminance) on an unoccluded upward-facing surface, for tuning brightness."""
    h, w = env.shape[:2]
    theta = np.pi * np.arange(h) / (h - 1)
    d_omega = (2 * np.pi / w) * (np.pi / (h - 1)) * np.sin(theta)  # solid angle per pixel
    lum = env @ np.array([0.2126, 0.7152, 0.0722])
    return float(np.sum(lum * (np.maximum(np.cos(theta), 0) * d_omega)[:, None]))


def make_checkerboard() -> np.ndarray:
    """The backdrop texture as (H, W, 3) uint8 sRGB; row 0 is the top edge (y = 0.4 m)."""
    px = SQUARE / TEXELS_PER_SQUARE
    width = int(round(BACKDROP_WIDTH / px))
    height = int(round(BACKDROP_HEIGHT / px))
    x = (np.arange(width) + 0.5) * px  # metres from the backdrop's left edge
    y = BACKDROP_HEIGHT - (np.arange(height) + 0.5) * px  # metres above the cloth
    # Squares counted from the bottom-left corner, so whole squares start at the cloth and the
    # partial row (0.4 m is 13 1/3 squares) is at the top; the bottom-left square is grey.
    ix = np.floor(x / SQUARE).astype(int)
    iy = np.floor(y / SQUARE).astype(int)
    grey = (ix[None, :] + iy[:, None]) % 2 == 0
    linear = np.where(grey, GREY, WHITE)
    srgb = np.round(linear_to_srgb(linear) * 255).astype(np.uint8)
    return np.repeat(srgb[..., None], 3, axis=-1)


# --- Meshes -----------------------------------------------------------------------------------


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
              uvs: np.ndarray | None = None) -> None:
    """Write a binary little-endian PLY with float32 positions, normals and optional UVs."""
    props = ["x", "y", "z", "nx", "ny", "nz"] + (["u", "v"] if uvs is not None else [])
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}"]
    header += [f"property float {p}" for p in props]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices",
               "end_header"]
    columns = [vertices, normals] + ([uvs] if uvs is not None else [])
    vdata = np.concatenate(columns, axis=1).astype("<f4").tobytes()
    fdata = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    fdata["n"], fdata["i"] = 3, faces
    path.write_bytes(("\n".join(header) + "\n").encode("ascii") + vdata + fdata.tobytes())


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation matrix taking unit vector a to unit vector b (not antiparallel)."""
    v, c = np.cross(a, b), float(a @ b)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def make_sphere() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Welded icosphere resting on y = 0: (vertices, faces, normals)."""
    ico = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    unit = np.asarray(ico.vertices, dtype=np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    # Turn the lowest vertex to point straight down, so the mesh touches the cloth at one vertex
    # (an icosphere has no vertex on the y axis by default and would float slightly).
    low = unit[np.argmin(unit[:, 1])]
    unit = unit @ _rotation_between(low, np.array([0.0, -1.0, 0.0])).T
    vertices = SPHERE_CENTER + SPHERE_RADIUS * unit
    vertices[:, 1] = np.maximum(vertices[:, 1], 0.0)  # clean -1e-18 rounding at the contact
    return vertices, np.asarray(ico.faces, dtype=np.int64), unit


def make_bowl() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed glass bowl (outer radius 6 cm, height 4.5 cm, 3 mm walls), its base BOWL_GAP above y = 0.

    The gap: a flat base in the cloth's plane is two surfaces in one place, and which one a ray
    meets is decided by rounding, differently on the CPU (Embree) and the GPU (OptiX): renders of
    the pixels seen through the bowl differed by 0.5 % (``abs.render.contacts``)."""
    r_base, r_rim, height, wall = 0.025, 0.06, 0.045, 0.003
    a = np.linspace(0.0, np.pi / 2, 24)
    # Profile (radius, height), from the axis under the base round the rim back to the axis
    # inside: flat base, quarter ellipse up, half-round rim, inner quarter ellipse, inner floor.
    # Each joint is tangent-continuous, so smooth vertex normals are right everywhere.
    outer = np.stack([r_base + (r_rim - r_base) * np.sin(a), height * (1 - np.cos(a))], 1)
    rim_a = np.linspace(0.0, np.pi, 10)[1:-1]
    rim = np.stack([r_rim - wall / 2 + wall / 2 * np.cos(rim_a),
                    height + wall / 2 * np.sin(rim_a)], 1)
    inner = np.stack([r_base + (r_rim - wall - r_base) * np.sin(a[::-1]),
                      wall + (height - wall) * (1 - np.cos(a[::-1]))], 1)
    base = np.linspace(0.0, r_base, 8)
    profile = np.concatenate([np.stack([base[:-1], np.zeros(7)], 1), outer, rim, inner,
                              np.stack([base[::-1][1:], np.full(7, wall)], 1)])
    mesh = trimesh.creation.revolve(profile, sections=96)
    mesh.merge_vertices()
    # revolve() turns about +z; map z (height) to +y with a proper rotation (x, y, z) -> (x, z, -y).
    rot = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    mesh.apply_transform(np.block([[rot, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))
    if mesh.volume < 0:
        mesh.invert()
    mesh.apply_translation([0.0, BOWL_GAP, 0.0])
    assert mesh.is_watertight and mesh.is_winding_consistent, "bowl mesh is not closed"
    return (np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64),
            np.asarray(mesh.vertex_normals))


def make_quad(corners: np.ndarray, normal: np.ndarray,
              uvs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Two-triangle quad from 4 corners in order, wound so its geometric normal is ``normal``."""
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    if np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ normal < 0:
        faces = faces[:, ::-1]
    return corners, faces, np.tile(normal, (4, 1)), uvs


def make_cloth():
    """The tablecloth: y = 0, x and z in [-0.3, 0.3], normal +y, UVs over [0, 1]^2."""
    h = CLOTH_HALF
    corners = np.array([[-h, 0, -h], [h, 0, -h], [h, 0, h], [-h, 0, h]], dtype=float)
    uvs = (corners[:, [0, 2]] + h) / (2 * h)  # u along +x, v along +z (towards the camera)
    return make_quad(corners, np.array([0.0, 1.0, 0.0]), uvs)


def make_backdrop():
    """The backdrop: z = -0.15, x in [-0.3, 0.3], y in [0, 0.4], facing +z; UVs span the texture,
    v = 0 at the top edge (Mitsuba's bitmap has v = 0 on the image's first row)."""
    w, top = BACKDROP_WIDTH / 2, BACKDROP_HEIGHT
    corners = np.array([[-w, 0, BACKDROP_Z], [w, 0, BACKDROP_Z], [w, top, BACKDROP_Z],
                        [-w, top, BACKDROP_Z]])
    uvs = np.stack([(corners[:, 0] + w) / (2 * w), 1.0 - corners[:, 1] / top], axis=1)
    return make_quad(corners, np.array([0.0, 0.0, 1.0]), uvs)


def main(out: Path = HERE) -> None:
    """Write every asset into ``out``."""
    env = make_env()
    write_exr(out / "env.exr", env)
    ok, png = cv2.imencode(".png", make_checkerboard()[:, :, ::-1])
    assert ok
    (out / "checkerboard.png").write_bytes(png.tobytes())

    vertices, faces, normals = make_sphere()
    write_ply(out / "sphere.ply", vertices, faces, normals)
    vertices, faces, normals = make_bowl()
    write_ply(out / "bowl.ply", vertices, faces, normals)
    write_ply(out / "cloth.ply", *make_cloth())
    write_ply(out / "backdrop.ply", *make_backdrop())

    e = cloth_irradiance(env)
    print(f"env: max radiance {env.max():.1f}, irradiance on the open cloth {e:.2f} "
          f"-> cloth radiance ~{0.8 * e / np.pi:.2f} (reflectance 0.8, unshadowed)")


if __name__ == "__main__":
    main()
