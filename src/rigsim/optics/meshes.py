"""Triangle meshes of the rig's optical parts (screen with a hole, cube, plano-convex lens, stop),
as trimesh objects.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from rigsim.optics.autocollimator import PlanoConvexObjective

HOLE_POLYGON_SIDES = 256


def screen_with_hole_mesh(width_mm: float, height_mm: float, hole_radius_mm: float | None,
                          sides: int = HOLE_POLYGON_SIDES, aspect: float = 4.0):
    """Screen rectangle centred on the hole, in its local frame (z = 0), front normal −z.

    The hole is a ``sides``-gon whose edges are tangent to the circle of ``hole_radius_mm``
    (vertices at r / cos(π / sides)): the circle is never clipped. ``hole_radius_mm=None``: no
    hole (two triangles).
    """
    import trimesh

    w2, h2 = 0.5 * width_mm, 0.5 * height_mm
    if hole_radius_mm is None:
        v = np.array([[-w2, -h2, 0.0], [w2, -h2, 0.0], [w2, h2, 0.0], [-w2, h2, 0.0]])
        f = np.array([[0, 1, 2], [0, 2, 3]])
    else:
        rv = hole_radius_mm / math.cos(math.pi / sides)
        if rv >= min(w2, h2):
            raise ValueError("the hole does not fit on the screen")
        corners = [math.atan2(h2, w2), math.atan2(h2, -w2), math.atan2(-h2, -w2), math.atan2(-h2, w2)]
        ang = np.unique(np.mod(np.concatenate([np.linspace(0.0, 2 * math.pi, sides, endpoint=False),
                                               np.mod(corners, 2 * math.pi)]), 2 * math.pi))
        c, s = np.cos(ang), np.sin(ang)
        n = len(ang)
        with np.errstate(divide="ignore"):
            tx = np.where(np.abs(c) > 1e-15, w2 / np.abs(c), np.inf)
            ty = np.where(np.abs(s) > 1e-15, h2 / np.abs(s), np.inf)
        t_edge = np.minimum(tx, ty)
        # concentric rings whose cells are at most ``aspect`` times longer (radially) than wide:
        # long slivers have overlapping bounding boxes, so every ray near the hole would test
        # hundreds of them (measured: a fan of slivers made renders 5x slower than a plain
        # rectangle); the last ring joins the rectangle's edge
        q = 1.0 + aspect * 2.0 * math.pi / sides
        radii = [rv]
        while q * radii[-1] < 0.9 * min(w2, h2):
            radii.append(q * radii[-1])
        rings = [np.stack([r_ * c, r_ * s, np.zeros_like(c)], axis=1) for r_ in radii]
        rings.append(np.stack([t_edge * c, t_edge * s, np.zeros_like(c)], axis=1))
        v = np.vstack(rings)
        j = np.arange(n)
        k = (j + 1) % n
        faces = []
        for q in range(len(rings) - 1):
            a, b = q * n, (q + 1) * n
            faces += [np.stack([a + j, a + k, b + k], axis=1), np.stack([a + j, b + k, b + j], axis=1)]
        f = np.vstack(faces)
    # wind every triangle clockwise seen from +z, so that the front normal is −z (towards the cube)
    e = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])[:, 2]
    f = np.where((e > 0)[:, None], f[:, ::-1], f)
    m = trimesh.Trimesh(vertices=v, faces=f, process=False)
    m.unmerge_vertices()
    return m


def cube_mesh(edge_mm: float) -> trimesh.Trimesh:
    """Axis-aligned cube of side ``edge_mm`` centred at the origin of the cube frame.

    Its faces' outward normals are the cube frame's ±X, ±Y, ±Z (face "+Z" = the XY face).
    """
    box = trimesh.creation.box(extents=[edge_mm] * 3)
    box.unmerge_vertices()  # flat faces: no shared, averaged vertex normals
    return box


def face_normals_ok(mesh: trimesh.Trimesh) -> bool:
    """True if every face normal is one of the six axis directions (a sanity check for tests)."""
    n = np.round(mesh.face_normals, 12)
    return bool(np.all(np.sum(np.abs(n) == 1.0, axis=1) == 1))


# ------------------------------------------------------------------------------ meshes
def lens_mesh(obj: PlanoConvexObjective, n_rings: int = 64, n_seg: int = 256) -> trimesh.Trimesh:
    """Closed plano-convex lens in the A frame, outward analytic vertex normals (sphere: from
    the centre of curvature; rim: radial; flat face: −z). Split vertices along the edges."""
    R, rl = obj.radius_mm, obj.lens_radius_mm
    C = np.array([0.0, 0.0, obj.z_centre])
    ph = np.arange(n_seg) * (2 * math.pi / n_seg)
    cph, sph = np.cos(ph), np.sin(ph)
    V, N, F = [], [], []

    def add(v, n):
        V.append(np.asarray(v, float))
        N.append(np.asarray(n, float))
        return sum(len(x) for x in V[:-1])

    def rings(z_of_r, n_of_p, facing_up: bool, n_rings: int):
        r = rl * np.arange(1, n_rings + 1) / n_rings
        pts = [np.array([[0.0, 0.0, z_of_r(0.0)]])]
        for rk in r:
            pts.append(np.column_stack([rk * cph, rk * sph, np.full(n_seg, z_of_r(rk))]))
        P = np.vstack(pts)
        base = add(P, n_of_p(P))
        tri = []
        for j in range(n_seg):  # centre fan
            a, b = 1 + j, 1 + (j + 1) % n_seg
            tri.append((0, a, b))
        for k in range(n_rings - 1):
            o0, o1 = 1 + k * n_seg, 1 + (k + 1) * n_seg
            for j in range(n_seg):
                j1 = (j + 1) % n_seg
                tri.append((o0 + j, o1 + j, o1 + j1))
                tri.append((o0 + j, o1 + j1, o0 + j1))
        tri = np.array(tri)
        if not facing_up:
            tri = tri[:, ::-1]
        F.append(tri + base)
        return P

    def cap_z(r):
        return obj.z_centre + math.sqrt(R * R - r * r)

    rings(cap_z, lambda P: (P - C) / R, True, n_rings)
    # the flat face needs no tessellation (one fan of n_seg triangles)
    rings(lambda r: obj.z_flat, lambda P: np.tile([0.0, 0.0, -1.0], (len(P), 1)), False, 1)
    # rim wall from the flat face (z_flat) up to the cap's edge
    z_top = cap_z(rl)
    bot = np.column_stack([rl * cph, rl * sph, np.full(n_seg, obj.z_flat)])
    top = np.column_stack([rl * cph, rl * sph, np.full(n_seg, z_top)])
    radial = np.column_stack([cph, sph, np.zeros(n_seg)])
    base = add(np.vstack([bot, top]), np.vstack([radial, radial]))
    tri = []
    for j in range(n_seg):
        j1 = (j + 1) % n_seg
        tri.append((j, j1, n_seg + j1))
        tri.append((j, n_seg + j1, n_seg + j))
    F.append(np.array(tri) + base)
    V, N, F = np.vstack(V), np.vstack(N), np.vstack(F)
    m = trimesh.Trimesh(V, F, vertex_normals=N, process=False)
    return m


def stop_mesh(obj: PlanoConvexObjective, outer_radius_mm: float | None = None, n_seg: int = 512) -> trimesh.Trimesh:
    """Flat annulus (the clear-aperture stop) at ``obj.z_stop``, facing +z."""
    r0 = obj.stop_radius_mm
    r1 = outer_radius_mm or max(2.5 * r0, r0 + 20.0)
    ph = np.arange(n_seg) * (2 * math.pi / n_seg)
    inner = np.column_stack([r0 * np.cos(ph), r0 * np.sin(ph), np.full(n_seg, obj.z_stop)])
    outer = np.column_stack([r1 * np.cos(ph), r1 * np.sin(ph), np.full(n_seg, obj.z_stop)])
    tri = []
    for j in range(n_seg):
        j1 = (j + 1) % n_seg
        tri.append((j, n_seg + j, n_seg + j1))
        tri.append((j, n_seg + j1, j1))
    return trimesh.Trimesh(np.vstack([inner, outer]), np.array(tri), process=False)


def tilt_cube_faces(mesh: trimesh.Trimesh, edge_mm: float, tilts_arcsec: dict) -> trimesh.Trimesh:
    """A copy of the cube ``mesh`` (:func:`cube_mesh`, unmerged vertices) with each face named in
    ``tilts_arcsec`` (``{"-Z": [rx, ry, rz]}``, a rotation vector in the cube frame, arcsec) turned
    about its ideal centre: its outward normal becomes Rot(tilt)·n0. Same vertices and faces order."""
    from scipy.spatial.transform import Rotation

    from rigsim.optics.cube import FACE_NORMALS

    v = np.array(mesh.vertices, float)
    fn = np.array(trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False).face_normals, float)
    for face, rv in tilts_arcsec.items():
        n0 = np.asarray(FACE_NORMALS[face], float)
        rot = Rotation.from_rotvec(np.radians(np.asarray(rv, float) / 3600.0)).as_matrix()
        tri = np.where(fn @ n0 > 0.999)[0]
        idx = np.unique(np.asarray(mesh.faces)[tri].ravel())
        c = 0.5 * edge_mm * n0
        v[idx] = (v[idx] - c) @ rot.T + c
    return trimesh.Trimesh(vertices=v, faces=np.array(mesh.faces), process=False)


def face_basis(n: np.ndarray, n0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """In-plane axes (e1, e2) of a cube face of normal ``n`` (≈ the ideal ``n0``): e1 follows the first
    cube axis ⟂ n0 (x for ±Y, ±Z; y for ±X), e2 = n × e1."""
    n0 = np.asarray(n0, float)
    a = np.array([1.0, 0.0, 0.0]) if abs(n0[0]) < 0.5 else np.array([0.0, 1.0, 0.0])
    e1 = a - (a @ n) * n
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def figured_cube_mesh(mesh: trimesh.Trimesh, edge_mm: float, figures: dict, grid: int = 32) -> trimesh.Trimesh:
    """The cube ``mesh`` (flat faces, unmerged vertices) with analytic vertex normals, each face named in
    ``figures`` replaced by a ``grid`` × ``grid`` patch of the surface h(x, y) = −c(x² + y²) − a(x'² − y'²)
    (height along the face's normal; x, y in its plane from its centre; x', y' turned by the
    astigmatism's angle): ``figures = {face: (c, a, angle_rad)}`` (1/mm). The patch's vertex normals are
    the surface's analytic normals; the flat faces' are their plane normals (float64). Render with
    ``face_normals = False``."""
    from rigsim.optics.cube import FACE_NORMALS

    v = np.array(mesh.vertices, float)
    f = np.array(mesh.faces)
    tri_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    tri_n /= np.linalg.norm(tri_n, axis=1, keepdims=True)
    keep = np.ones(len(f), bool)
    for face in figures:
        keep &= ~(tri_n @ np.asarray(FACE_NORMALS[face], float) > 0.999)
    V = [v[f[keep]].reshape(-1, 3)]
    N = [np.repeat(tri_n[keep], 3, axis=0)]
    F = [np.arange(3 * keep.sum()).reshape(-1, 3)]
    h = 0.5 * edge_mm
    x = np.linspace(-h, h, grid + 1)
    X, Y = (g.ravel() for g in np.meshgrid(x, x))
    j = np.arange(grid)
    i00 = (j[:, None] * (grid + 1) + j[None, :]).ravel()
    quads = np.stack([i00, i00 + 1, i00 + grid + 2, i00 + grid + 1], axis=1)
    for face, (c, a, ang) in figures.items():
        n0 = np.asarray(FACE_NORMALS[face], float)
        tri = np.where(tri_n @ n0 > 0.999)[0]
        pts = v[np.unique(f[tri].ravel())]
        n = tri_n[tri[0]]
        centre = pts.mean(axis=0)
        e1, e2 = face_basis(n, n0)
        ca, sa = math.cos(ang), math.sin(ang)
        xp, yp = ca * X + sa * Y, -sa * X + ca * Y
        hgt = -c * (X * X + Y * Y) - a * (xp * xp - yp * yp)
        # ∂h/∂x, ∂h/∂y (chain rule through the turned axes)
        hx = -2 * c * X - 2 * a * (xp * ca + yp * sa)
        hy = -2 * c * Y - 2 * a * (xp * sa - yp * ca)
        P = centre + X[:, None] * e1 + Y[:, None] * e2 + hgt[:, None] * n
        Nn = n[None, :] - hx[:, None] * e1 - hy[:, None] * e2
        Nn /= np.linalg.norm(Nn, axis=1, keepdims=True)
        base = sum(len(p) for p in V)
        t = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        # wind so that the geometric normal is outward
        g0 = np.cross(P[t[0, 1]] - P[t[0, 0]], P[t[0, 2]] - P[t[0, 0]])
        if g0 @ n < 0:
            t = t[:, ::-1]
        V.append(P)
        N.append(Nn)
        F.append(t + base)
    return trimesh.Trimesh(np.vstack(V), np.vstack(F), vertex_normals=np.vstack(N), process=False)
