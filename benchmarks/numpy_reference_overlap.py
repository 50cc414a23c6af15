"""Plain-numpy overlap ratio (no numba): the clipping algorithm of ``continuum_gym.geometry.overlap``.

Benchmark reference only: the same divergence-theorem volume, V = 1/3 Σ_f (n_f · x_f) area(face_f ∩ other),
with Python loops over faces and planes, so the speed-up of the compiled kernel can be measured
against an implementation of the same algorithm rather than against the scipy polytope recipe.
"""

from __future__ import annotations

import numpy as np

from continuum_gym.geometry.frustum import FACE_VERTICES, Frustum
from continuum_gym.geometry.overlap import COPLANAR_NORMAL_TOL, COPLANAR_OFFSET_TOL


def _clip(polygon: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Sutherland–Hodgman: the part of the convex polygon (m, 3) with plane[:3]·x + plane[3] <= 0."""
    if len(polygon) == 0:
        return polygon
    distances = polygon @ plane[:3] + plane[3]
    if np.all(distances <= 0.0):
        return polygon
    if np.all(distances > 0.0):
        return polygon[:0]
    out = []
    previous, d_previous = polygon[-1], distances[-1]
    for current, d_current in zip(polygon, distances):
        if d_current <= 0.0:
            if d_previous > 0.0 and d_current < 0.0:
                out.append(previous + d_previous / (d_previous - d_current) * (current - previous))
            out.append(current)
        elif d_previous < 0.0:
            out.append(previous + d_previous / (d_previous - d_current) * (current - previous))
        previous, d_previous = current, d_current
    return np.array(out)


def _signed_area(polygon: np.ndarray, normal: np.ndarray) -> float:
    if len(polygon) < 3:
        return 0.0
    edges = polygon[1:] - polygon[0]
    return 0.5 * float(np.sum(np.cross(edges[:-1], edges[1:]) @ normal))


def overlap_ratio_numpy(p_a, R_a, p_b, R_b, frustum: Frustum | None = None) -> float:
    """OR = vol(F_a ∩ F_b) / vol(F_a) for one pair (p: (3,), R: (3, 3)), by face clipping in numpy."""
    frustum = Frustum() if frustum is None else frustum
    p_a, R_a, p_b, R_b = (np.asarray(x, dtype=np.float64) for x in (p_a, R_a, p_b, R_b))
    # everything in camera frame a, whose apex is the origin
    p = R_a.T @ (p_b - p_a)
    R = R_a.T @ R_b
    vertices_a = frustum.local_vertices()
    planes_a = frustum.local_halfspaces()
    vertices_b = p + vertices_a @ R.T
    planes_b = frustum.halfspaces(p, R)

    skip_b = set()
    no_cut_a = {}
    for i in range(6):
        for j in range(6):
            if (np.max(np.abs(planes_a[i, :3] - planes_b[j, :3])) <= COPLANAR_NORMAL_TOL
                    and abs(planes_a[i, 3] - planes_b[j, 3]) <= COPLANAR_OFFSET_TOL):
                skip_b.add(j)
                no_cut_a[i] = j
            if (np.max(np.abs(planes_a[i, :3] + planes_b[j, :3])) <= COPLANAR_NORMAL_TOL
                    and abs(planes_a[i, 3] + planes_b[j, 3]) <= COPLANAR_OFFSET_TOL):
                return 0.0

    def face_term(vertices, face, own, others, skip):
        polygon = vertices[FACE_VERTICES[face]]
        for k, plane in enumerate(others):
            if k == skip:
                continue
            s = 1.0 if plane[:3] @ own[:3] >= 0.0 else -1.0
            polygon = _clip(polygon, plane - s * own)  # equals plane on the face's own plane
            if len(polygon) == 0:
                return 0.0
        return -own[3] * _signed_area(polygon, own[:3])

    total = 0.0
    for i in range(2):  # a's side planes contain the origin and contribute 0
        total += face_term(vertices_a, i, planes_a[i], planes_b, no_cut_a.get(i, -1))
    for j in range(6):
        if j not in skip_b:
            total += face_term(vertices_b, j, planes_b[j], planes_a, -1)
    return float(min(max(total / 3.0 / frustum.volume, 0.0), 1.0))


if __name__ == "__main__":  # python benchmarks/numpy_reference_overlap.py: time the four implementations
    import timeit

    from scipy.spatial.transform import Rotation

    from continuum_gym.geometry.overlap import overlap_ratio
    from continuum_gym.geometry.overlap_reference import overlap_ratio_reference

    rng = np.random.default_rng(0)
    n = 4096
    R_a = Rotation.random(n, random_state=rng).as_matrix()
    p_a = rng.uniform(-0.05, 0.05, (n, 3))
    R_b = R_a @ Rotation.from_rotvec(rng.normal(size=(n, 3)) * 0.5).as_matrix()
    p_b = p_a + rng.uniform(-0.05, 0.05, (n, 3))
    one = (p_a[0], R_a[0], p_b[0], R_b[0])
    overlap_ratio(*one), overlap_ratio(p_a, R_a, p_b, R_b)  # compile / load the numba cache

    def best(function, number, repeat=5):
        return min(timeit.repeat(function, number=number, repeat=repeat)) / number

    single = best(lambda: overlap_ratio(*one), 20_000)
    batched = best(lambda: overlap_ratio(p_a, R_a, p_b, R_b), 10) / n
    scipy_reference = best(lambda: overlap_ratio_reference(*one), 50, 3)
    numpy_clipping = best(lambda: overlap_ratio_numpy(*one), 50, 3)
    print(f"overlap_ratio, one pair:        {single * 1e6:9.2f} us")
    print(f"overlap_ratio, N={n}, per pair: {batched * 1e6:9.2f} us")
    print(f"scipy reference, one pair:      {scipy_reference * 1e6:9.2f} us")
    print(f"numpy clipping, one pair:       {numpy_clipping * 1e6:9.2f} us")
