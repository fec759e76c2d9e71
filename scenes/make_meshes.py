"""Make the meshes in scenes/meshes/ with trimesh (run: ``python scenes/make_meshes.py [OUT_DIR]``).

Every mesh is in metres, in the camera-frame convention of the scene files (y points down), with
its origin at the centre of its base, so a scene places it with ``translate_m`` = where the base
stands.  Deterministic: the relief noise uses fixed seeds, and PLY output is binary with a fixed
vertex order, so re-running rewrites identical files.

Shapes (paper Fig. 11-13 stand-ins; sizes are assumptions of tabletop plaster casts and objects):

* ``vase``: a surface of revolution, convex body and concave neck (Fig. 11);
* ``cylinder``, ``cone``: smooth solids with sharp rims (Fig. 11);
* ``bust``: a head on a neck and shoulders, with nose, ears, brow, a wavy hair relief and a
  moustache of fine grooves (0.5-2 mm relief, Fig. 12);
* ``pot``, ``pear``, ``hat``: the glazed pot, pear and straw hat of the cluttered scenes (Fig. 13).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

OUT = Path(__file__).resolve().parent / "meshes"

# +z up (trimesh's revolve axis) -> -y up (camera frame, y down): rotate +90 deg about x
Z_UP_TO_CAMERA = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])


def revolve(profile_rz: list[tuple[float, float]], sections: int = 128) -> trimesh.Trimesh:
    """Closed surface of revolution of a (radius, height) profile that starts and ends on the axis."""
    return trimesh.creation.revolve(np.asarray(profile_rz, dtype=np.float64), sections=sections)


def vase() -> trimesh.Trimesh:
    z = np.linspace(0.0, 0.30, 90)
    # convex body (max radius 0.075 m at z = 0.10), concave neck (min 0.028 m at z = 0.24), lip
    r = 0.045 + 0.030 * np.sin(np.pi * np.clip(z / 0.20, 0, 1)) ** 1.5
    neck = np.clip((z - 0.17) / 0.13, 0, 1)
    r = (1 - neck) * r + neck * (0.028 + 0.012 * ((z - 0.24) / 0.06) ** 2)
    profile = [(0.0, 0.0)] + list(zip(r, z)) + [(0.0, 0.30)]
    return revolve(profile)


def bust(seed: int = 11) -> trimesh.Trimesh:
    head = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
    v = head.vertices.copy()  # unit sphere; +z up, -y towards the viewer
    x, y, z = v.T
    r = np.ones(len(v))

    def bump(cx, cy, cz, width, height):
        d2 = (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2
        return height * np.exp(-d2 / (2 * width**2))

    r += bump(0.0, -1.0, -0.05, 0.12, 0.22)  # nose
    r += bump(-0.98, 0.0, 0.0, 0.10, 0.12) + bump(0.98, 0.0, 0.0, 0.10, 0.12)  # ears
    r += bump(0.0, -0.92, 0.32, 0.25, 0.05)  # brow
    r += bump(0.0, -0.85, -0.45, 0.22, 0.06)  # chin
    # hair: wavy relief (about 2 mm on a 0.1 m head) over the top and back
    rng = np.random.default_rng(seed)
    hair = (z > 0.35) | ((y > 0.2) & (z > -0.3))
    phase = rng.uniform(0, 2 * np.pi, 3)
    waves = sum(np.sin(28 * (a * x + b * z) + p) for (a, b), p in zip(((1.0, 0.3), (0.6, 1.0), (-0.8, 0.7)), phase))
    r += np.where(hair, 0.02 * waves / 3 + 0.03, 0.0)
    # moustache: fine grooves (about 0.5 mm) under the nose
    must = np.exp(-(((z + 0.22) / 0.07) ** 2) - ((x / 0.32) ** 2)) * (y < -0.5)
    r += 0.03 * must * (0.5 + 0.5 * np.sin(90 * x))
    v = v * r[:, None] * np.array([0.075, 0.085, 0.105])
    head = trimesh.Trimesh(v, head.faces, process=False)
    head.apply_translation([0, 0, 0.26])
    neck = trimesh.creation.cylinder(radius=0.042, height=0.12, sections=96)
    neck.apply_translation([0, 0, 0.16])
    shoulders = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    shoulders.apply_scale([0.17, 0.09, 0.07])
    shoulders.apply_translation([0, 0, 0.07])
    return trimesh.util.concatenate([head, neck, shoulders])


def pot() -> trimesh.Trimesh:
    z = np.linspace(0.0, 0.14, 60)
    r = 0.055 + 0.035 * np.sin(np.pi * z / 0.16)
    profile = [(0.0, 0.0)] + list(zip(r, z)) + [(0.075, 0.15), (0.0, 0.15)]
    return revolve(profile)


def pear() -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    x, y, z = m.vertices.T
    # two lobes: a wide bottom (r 0.045 m) narrowing to a neck (0.025 m) at the top
    t = (z + 1) / 2
    scale = 0.045 * (1 - 0.45 * np.clip((t - 0.45) / 0.55, 0, 1) ** 1.2)
    v = np.column_stack([x * scale, y * scale, 0.055 * (z + 1)])
    return trimesh.Trimesh(v, m.faces, process=False)


def hat() -> trimesh.Trimesh:
    # a straw braid's ridges: concentric rings 10 mm apart in rad + z (on the brim top and the
    # crown top in the radius, on the crown side in the height; 10-13 mm along the surface), their
    # height modulated 60-fold round the crown away from its centre - up to 1 mm from trough to
    # crest, 0.77 mm near the centre; each ridge sampled 5 times (~2 mm profile steps, 400 sections
    # round: an angular term of as many periods as sections would sit on its zeros at the vertices)
    brim_r = np.linspace(0.18, 0.087, 47)
    crown_z = np.linspace(0.012, 0.10, 44)
    crown_r = 0.085 - 0.01 * ((crown_z - 0.012) / 0.088) ** 2
    top_r = np.linspace(0.073, 0.002, 36)
    profile = (
        [(0.0, 0.0), (0.18, 0.0)]
        + [(r, 0.012) for r in brim_r]
        + list(zip(crown_r, crown_z))
        + [(r, 0.10) for r in top_r]
        + [(0.0, 0.10)]
    )
    m = revolve(profile, sections=400)
    x, y, z = m.vertices.T
    ang = np.arctan2(y, x)
    rad = np.hypot(x, y)
    twist = 0.3 * np.clip((rad - 0.03) / 0.03, 0, 1) * np.sin(60 * ang)
    weave = 0.0005 * np.sin(2 * np.pi * (rad + z) / 0.010) * (1 + twist) / 1.3
    n = np.zeros_like(m.vertices)
    for k in range(3):  # area-weighted vertex normals (numpy only)
        np.add.at(n, m.faces[:, k], m.face_normals * m.area_faces[:, None])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return trimesh.Trimesh(m.vertices + n * weave[:, None], m.faces, process=False)


MESHES = {
    "vase": vase,
    "cylinder": lambda: trimesh.creation.cylinder(
        radius=0.06, height=0.18, sections=128, transform=trimesh.transformations.translation_matrix([0, 0, 0.09])
    ),
    "cone": lambda: trimesh.creation.cone(radius=0.07, height=0.16, sections=128),
    "bust": bust,
    "pot": pot,
    "pear": pear,
    "hat": hat,
}


def crease_normals(mesh: trimesh.Trimesh, *, angle_deg: float = 30.0) -> trimesh.Trimesh:
    """One vertex per face corner with a normal averaged over the faces around the vertex that
    are within ``angle_deg`` of the corner's face: smooth shading that keeps rims sharp."""
    fn = mesh.face_normals
    area = mesh.area_faces
    corners = mesh.faces.reshape(-1)
    # faces around each vertex, (V, max degree) padded with -1 (numpy only: no scipy needed)
    order = np.argsort(corners, kind="stable")
    deg = np.bincount(corners, minlength=len(mesh.vertices))
    first = np.concatenate([[0], np.cumsum(deg)[:-1]])
    slot = np.arange(len(corners)) - np.repeat(first, deg)
    vf = np.full((len(mesh.vertices), max(1, deg.max())), -1, dtype=np.int64)
    vf[corners[order], slot] = order // 3
    own = np.repeat(np.arange(len(mesh.faces)), 3)
    adj = vf[corners]
    ok = adj >= 0
    adj_c = np.where(ok, adj, 0)
    ok &= np.einsum("ij,ikj->ik", fn[own], fn[adj_c]) > np.cos(np.radians(angle_deg))
    n = np.einsum("ik,ikj->ij", ok * area[adj_c], fn[adj_c])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    # corners of one vertex with the same normal (smooth regions) share one output vertex
    key = np.column_stack([corners, np.round(n * 1e6)]).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    keep = np.sort(first)
    remap = np.empty(len(first), dtype=np.int64)
    remap[np.argsort(first)] = np.arange(len(first))  # unique-row order -> first-seen order
    out = trimesh.Trimesh(mesh.vertices[corners[keep]], remap[inverse.reshape(-1)].reshape(-1, 3), process=False)
    out.vertex_normals = n[keep]
    return out


def export(mesh: trimesh.Trimesh, path: Path) -> None:
    mesh = mesh.copy()
    mesh.apply_transform(Z_UP_TO_CAMERA)
    mesh = crease_normals(mesh)
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=True, include_attributes=False)
    tmp = path.with_suffix(".tmp")
    tmp.write_bytes(data)
    tmp.replace(path)


def main(out: Path = OUT) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name, make in MESHES.items():
        mesh = make()
        export(mesh, out / f"{name}.ply")
        lo, hi = mesh.bounds
        print(f"{name}: {len(mesh.faces)} faces, extent {np.round(hi - lo, 3).tolist()} m")


if __name__ == "__main__":
    import sys

    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
