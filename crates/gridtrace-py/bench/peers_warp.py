"""Warp (CPU device) kernels for queries_vs_peers.py: closest hit, any hit, hit count, closest
point and signed distance (winding-number sign) over a wp.Mesh, one launch per query."""

import numpy as np
import warp as wp


@wp.kernel
def _cast(mesh: wp.uint64, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), t: wp.array(dtype=float), face: wp.array(dtype=int)):
    i = wp.tid()
    q = wp.mesh_query_ray(mesh, o[i], d[i], 1.0e30)
    if q.result:
        t[i] = q.t
        face[i] = q.face
    else:
        t[i] = wp.inf
        face[i] = -1


@wp.kernel
def _any(mesh: wp.uint64, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), hit: wp.array(dtype=int)):
    i = wp.tid()
    hit[i] = int(wp.mesh_query_ray_anyhit(mesh, o[i], d[i], 1.0e30))


@wp.kernel
def _count(mesh: wp.uint64, o: wp.array(dtype=wp.vec3), d: wp.array(dtype=wp.vec3), n: wp.array(dtype=int)):
    i = wp.tid()
    n[i] = wp.mesh_query_ray_count_intersections(mesh, o[i], d[i], -1)


@wp.kernel
def _closest(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, p[i], 1.0e30)
    out[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)


@wp.kernel
def _signed(mesh: wp.uint64, p: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    q = wp.mesh_query_point_sign_winding_number(mesh, p[i], 1.0e30)
    x = wp.mesh_eval_position(mesh, q.face, q.u, q.v)
    out[i] = wp.length(x - p[i]) * q.sign


class WarpMesh:
    def __init__(self, vertices, faces):
        wp.config.quiet = True
        wp.init()
        self.dev = "cpu"
        self.mesh = wp.Mesh(
            points=wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=self.dev),
            indices=wp.array(faces.astype(np.int32).ravel(), dtype=wp.int32, device=self.dev),
            support_winding_number=True,
        )

    def _v3(self, a):
        return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=wp.vec3, device=self.dev)

    def cast(self, o, d):
        n = len(o)
        t, face = wp.empty(n, dtype=float, device=self.dev), wp.empty(n, dtype=int, device=self.dev)
        wp.launch(_cast, n, [self.mesh.id, self._v3(o), self._v3(d), t, face], device=self.dev)
        wp.synchronize_device(self.dev)
        return t.numpy(), face.numpy()

    def occluded(self, o, d):
        hit = wp.empty(len(o), dtype=int, device=self.dev)
        wp.launch(_any, len(o), [self.mesh.id, self._v3(o), self._v3(d), hit], device=self.dev)
        wp.synchronize_device(self.dev)
        return hit.numpy().astype(bool)

    def count(self, o, d):
        n = wp.empty(len(o), dtype=int, device=self.dev)
        wp.launch(_count, len(o), [self.mesh.id, self._v3(o), self._v3(d), n], device=self.dev)
        wp.synchronize_device(self.dev)
        return n.numpy()

    def closest(self, p):
        out = wp.empty(len(p), dtype=wp.vec3, device=self.dev)
        wp.launch(_closest, len(p), [self.mesh.id, self._v3(p), out], device=self.dev)
        wp.synchronize_device(self.dev)
        return out.numpy()

    def signed(self, p):
        out = wp.empty(len(p), dtype=float, device=self.dev)
        wp.launch(_signed, len(p), [self.mesh.id, self._v3(p), out], device=self.dev)
        wp.synchronize_device(self.dev)
        return out.numpy()
